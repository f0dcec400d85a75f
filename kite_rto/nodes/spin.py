"""Running a node: :func:`run_node` (init, build, spin with the events executor or rclpy's default, shut down,
exit code) and :func:`request_exit` (end the process from a callback).

Fault injection for load tests (``scripts/stress.sh``): with ``KITE_RTO_INJECT_DELAY=MAX[:SEED]`` in the
environment every subscription of the node hands each message to its callback after a random wall delay, uniform in
[0, MAX] s (per-topic order kept, order across topics shuffled), the way a busy machine or network delivers them.
"""
from __future__ import annotations

import heapq
import itertools
import os
import random
import sys
import threading
import time

import rclpy
from rclpy.clock import Clock, ClockType
from rclpy.executors import ExternalShutdownException, SingleThreadedExecutor
from rclpy.node import Node
from rclpy.signals import SignalHandlerOptions

from ..kite.params import ParameterError
from .dds_profile import use_shipped_profile
from .namespace import with_graph_clock
from .stop_signals import STOP, StopSignals

__all__ = ["EXECUTOR_ENV", "DELAY_ENV", "run_node", "request_exit"]

EXECUTOR_ENV = "KITE_RTO_EXECUTOR"
"""Environment variable: ``single`` forces rclpy's SingleThreadedExecutor where :func:`run_node` would use the
events executor (``events``, the default for nodes that opt in)."""


DELAY_ENV = "KITE_RTO_INJECT_DELAY"
"""Environment variable ``MAX[:SEED]``: deliver every received message after a random delay in [0, MAX] wall s."""


class _DelayedDelivery:
    """Holds received messages for a random wall delay before their callbacks run (see the module docstring)."""

    def __init__(self, spec: str):
        max_s, _, seed = spec.partition(":")
        try:
            self.max_s = float(max_s)
            seed = int(seed or 0)
        except ValueError:
            raise ParameterError(f"{DELAY_ENV} = {spec!r}: expected MAX[:SEED], e.g. 0.002:1 (max delay in wall "
                                 "seconds, integer seed)") from None
        if not 0.0 <= self.max_s <= 1.0:
            raise ParameterError(f"{DELAY_ENV} = {spec!r}: expected a maximum delay in [0, 1] s")
        self.rng = random.Random(seed * 1_000_003 + os.getpid())
        self.queue, self.seq = [], itertools.count()
        self.created = Node.create_subscription

    def wrap(self, callback):
        last = [0.0]                                   # per subscription: delivery times never decrease

        def delayed(msg):
            due = max(time.monotonic() + self.rng.uniform(0.0, self.max_s), last[0])
            last[0] = due
            heapq.heappush(self.queue, (due, next(self.seq), callback, msg))
        return delayed

    def install(self) -> None:
        wrap, created = self.wrap, self.created

        def create_subscription(node, msg_type, topic, callback, qos_profile, **kwargs):
            return created(node, msg_type, topic, wrap(callback), qos_profile, **kwargs)
        Node.create_subscription = create_subscription

    def release(self) -> None:
        now, queue = time.monotonic(), self.queue
        while queue and queue[0][0] <= now:
            _, _, callback, msg = heapq.heappop(queue)
            callback(msg)


def request_exit(node, code: int = 0) -> None:
    """Make the node's process exit with ``code`` once the current callback returns.

    Under :func:`run_node`'s spin loop this only sets a flag (an exception escaping a callback would be logged as
    FATAL by the C++ executor); under ``rclpy.spin(node)`` or any other executor it raises :class:`SystemExit`,
    which propagates out of the spin call as before. Callbacks should return right after it.
    """
    if getattr(node, "_kite_run_loop", False):
        node._kite_exit_code = code
        return
    raise SystemExit(code)


def _events_executor(context):
    """rclpy's C++ events executor (Jazzy: ``rclpy.experimental``), or None when unavailable or disabled."""
    if os.environ.get(EXECUTOR_ENV, "events").strip().lower() in ("single", "singlethreaded", "default"):
        return None
    try:
        from rclpy.experimental import EventsExecutor
    except ImportError:
        return None
    return EventsExecutor(context=context)


def _spin(node, executor, stop: StopSignals) -> int:
    # The Jazzy backport's ``EventsExecutor.spin()`` holds the GIL while it waits and did not dispatch timers on
    # these machines (signals and other threads starve); ``spin_once`` with a timeout works: the GIL is released
    # while waiting, timers (also STEADY_TIME ones) fire, and a stop signal is seen within 0.25 s.
    node._kite_run_loop = True
    node._kite_exit_code = None
    executor.add_node(node)
    ok = node.context.ok
    spin_once = executor.spin_once
    try:
        while ok() and stop.signum is None:
            spin_once(timeout_sec=0.25)
            if node._kite_exit_code is not None:
                return node._kite_exit_code
        return 0
    finally:
        try:
            executor.remove_node(node)
        except Exception:  # noqa: BLE001 - best effort at shutdown
            pass


def run_node(factory, args=None, *, events: bool = False) -> int:
    """Init rclpy, build the node with ``factory()``, spin, shut down; return the process exit code.

    A :class:`ParameterError` at construction is reported on stderr and gives exit code 2. With ``events=True``
    the node is spun by rclpy's C++ events executor (several times less overhead per callback than the
    SingleThreadedExecutor; no coroutine callbacks), unless ``KITE_RTO_EXECUTOR=single`` is set or it is not
    available; the node should then end with :func:`request_exit` rather than raising ``SystemExit``.
    SIGINT (Ctrl-C) and SIGTERM stop it cleanly between callbacks with exit code 0 (:mod:`.stop_signals`); a
    second signal while it stops interrupts whatever it is doing (exit code 130). A worker thread still inside
    native code (e.g. a CasADi build) cannot be interrupted: once the node is destroyed and rclpy shut down, the
    process then ends without waiting for it (``os._exit``: the interpreter's finalization would crash it).

    Before ``rclpy.init`` the shipped Fast DDS profile is put in force unless the user chose one
    (:mod:`kite_rto.nodes.dds_profile`); the node logs which profile it runs with (``DDS profile: ...``).
    ``args`` (default ``sys.argv``) get the remap rule ``/clock:=clock`` appended
    (:func:`~kite_rto.nodes.namespace.with_graph_clock`): in a namespace the node's time source follows its own graph's
    clock.
    """
    if _wants_help(args if args is not None else sys.argv[1:]):
        print(_usage(factory), end="")
        return 0
    stop = STOP
    stop.install()
    if stop.signum is not None:                # stopped during the imports
        return 0
    profile, why = use_shipped_profile()
    # the graph's own clock for use_sim_time in a namespace (kite_rto.nodes.namespace)
    rclpy.init(args=with_graph_clock(sys.argv if args is None else args),
               signal_handler_options=SignalHandlerOptions.NO)
    node = None
    code = 0
    try:
        delays = _DelayedDelivery(os.environ[DELAY_ENV]) if os.environ.get(DELAY_ENV) else None
        if delays is not None:
            delays.install()
        node = factory()
        node.get_logger().info(f"DDS profile: {profile or 'none'} ({why})")
        if delays is not None:
            node.create_timer(0.001, delays.release, clock=Clock(clock_type=ClockType.STEADY_TIME))
            node.get_logger().warning(f"{DELAY_ENV}: every received message is delivered after a random delay of "
                                      f"up to {delays.max_s * 1e3:g} ms (load test)")
        executor = _events_executor(node.context) if events else None
        code = _spin(node, executor if executor is not None else SingleThreadedExecutor(context=node.context), stop)
        if stop.signum is not None:
            node.get_logger().info(f"{stop.name}: stopping")
    except ParameterError as exc:
        print(f"[kite_rto] refusing to start: {exc}", file=sys.stderr, flush=True)
        code = 2
    except KeyboardInterrupt:
        code = 130 if stop.signum is not None else 0
    except ExternalShutdownException:
        pass
    except SystemExit as exc:
        code = exc.code if isinstance(exc.code, int) else 0
    finally:
        try:
            if node is not None:
                node.destroy_node()
            rclpy.try_shutdown()
        except KeyboardInterrupt:
            code = 130
        stop.restore()
    if any(t.daemon and t.is_alive() for t in threading.enumerate() if t is not threading.main_thread()):
        sys.stdout.flush()
        sys.stderr.flush()
        os._exit(code)
    return code


def _wants_help(argv) -> bool:
    """``-h``/``--help`` before any ``--ros-args``."""
    argv = list(argv)
    if "--ros-args" in argv:
        argv = argv[:argv.index("--ros-args")]
    return any(a in ("-h", "--help") for a in argv)


def _usage(factory) -> str:
    """Usage text of a node: how to start it and its parameters (from the module's ``PARAMS`` when it has one)."""
    module = sys.modules.get(getattr(factory, "__module__", ""), None)
    spec = getattr(module, "__spec__", None)
    name = (spec.name if spec is not None else getattr(module, "__name__", "node")).rsplit(".", 1)[-1]
    name = name.removesuffix("_node")
    doc = (getattr(module, "__doc__", "") or "").strip().splitlines()
    lines = [f"usage: {name} [--ros-args -p NAME:=VALUE ... --params-file FILE]", ""]
    if doc:
        lines += [doc[0], ""]
    params = getattr(module, "PARAMS", ())
    if params:
        lines.append("parameters (NAME default: description; allowed values):")
        lines += [f"  {p.name} {p.default!r}: {p.doc}; {p.expected()}" for p in params]
    lines += ["", "The full table: docs/parameters.md; a params file: config/kite_rto.yaml."]
    return "\n".join(lines) + "\n"
