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
import time

import rclpy
from rclpy.clock import Clock, ClockType
from rclpy.executors import ExternalShutdownException
from rclpy.node import Node

from ..kite.params import ParameterError
from .dds_profile import use_shipped_profile

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

    Under :func:`run_node`'s events executor loop this only sets a flag (an exception escaping a callback would be
    logged as FATAL by the C++ executor); under ``rclpy.spin(node)`` or any other executor it raises
    :class:`SystemExit`, which propagates out of the spin call as before. Callbacks should return right after it.
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


def _spin_events(node, executor) -> int:
    # The Jazzy backport's ``EventsExecutor.spin()`` holds the GIL while it waits and did not dispatch timers on
    # these machines (signals and other threads starve); ``spin_once`` with a timeout works: the GIL is released
    # while waiting, timers (also STEADY_TIME ones) fire, Ctrl-C raises KeyboardInterrupt here.
    node._kite_run_loop = True
    node._kite_exit_code = None
    executor.add_node(node)
    ok = node.context.ok
    spin_once = executor.spin_once
    try:
        while ok():
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

    Before ``rclpy.init`` the shipped Fast DDS profile is put in force unless the user chose one
    (:mod:`kite_rto.nodes.dds_profile`); the node logs which profile it runs with (``DDS profile: ...``).
    """
    profile, why = use_shipped_profile()
    rclpy.init(args=args)
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
        if executor is not None:
            code = _spin_events(node, executor)
        else:
            rclpy.spin(node)
    except ParameterError as exc:
        print(f"[kite_rto] refusing to start: {exc}", file=sys.stderr, flush=True)
        code = 2
    except (KeyboardInterrupt, ExternalShutdownException):
        pass
    except RuntimeError:
        if rclpy.ok():
            raise
        # Ctrl-C shut rclpy down while a call into it was in flight: rclpy's C++ layer then raises a RuntimeError
        # (pybind11 "Unable to convert call argument ...") instead of ExternalShutdownException. A clean stop.
    except SystemExit as exc:
        code = exc.code if isinstance(exc.code, int) else 0
    finally:
        if node is not None:
            node.destroy_node()
        rclpy.try_shutdown()
    return code
