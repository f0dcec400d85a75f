"""What both modes of the main job share around the node processes: rclpy for the in-process observer, the
plant's parameters, the optional recorder and 3-D scene processes, and spinning the observer while waiting.

Imported only once a run starts (it imports rclpy), never for ``--help``.
"""
from __future__ import annotations

import sys
import time
from pathlib import Path

import rclpy
from lifecycle_msgs.msg import Transition
from lifecycle_msgs.srv import ChangeState
from rclpy.signals import SignalHandlerOptions

from ..nodes.namespace import tool_ros_args
from ..nodes.topics import STATE
from .graph import NodeProcess

__all__ = ["ros_init", "plant_params", "start_recorder", "recorder_summary", "spin_until", "warn_if_domain_busy",
           "lifecycle"]

GRAPH_NODES = ("plant", "controller", "optimizer", "echo_pilot")


def ros_init(namespace: str | None = None) -> None:
    """rclpy without its signal handlers: Ctrl-C raises KeyboardInterrupt here, and the demo stops the nodes. The
    observer's node is in ``namespace`` (the demo's graph), with the graph's own clock."""
    rclpy.init(args=tool_ros_args("kite_demo", [], namespace), signal_handler_options=SignalHandlerOptions.NO)


def plant_params(args, wait_subscribers: int, **params) -> dict:
    """The plant node's parameters for a demo run: ``params``, the seed, the /kite/state subscribers to wait for
    and, with ``--no-turbulence``, steady wind and no measurement noise."""
    params.update(seed=args.seed, wait_subscribers=wait_subscribers, wind_model=args.wind_model)
    if args.no_turbulence:
        params.update(turbulence=False, anemometer_noise=0.0, noise_angle_deg=0.0, noise_rate=0.0,
                      noise_tension=0.0)
    return params


def warn_if_domain_busy(node, env: dict, discovery: float = 1.0) -> list:
    """After ``discovery`` wall s, the kite_rto nodes already in this graph: this ROS domain and ``node``'s namespace
    (another graph there, e.g. a test run, would mix its samples and setpoints with the demo's; one in another
    namespace does not); print one warning naming them. Returns their names."""
    spin_until(lambda: False, node, discovery)
    ns = node.get_namespace()
    busy = sorted({n for n, n_ns in node.get_node_names_and_namespaces() if n in GRAPH_NODES and n_ns == ns})
    if busy:
        where = "" if ns == "/" else f" namespace {ns}"
        print(f"kite_rto demo: WARNING: ROS_DOMAIN_ID={env['ROS_DOMAIN_ID']}{where} already has node(s) "
              f"{', '.join(busy)}: another graph shares this domain and will mix with this run; stop it, or set "
              "ROS_DOMAIN_ID to a free domain (or --namespace to another namespace)", flush=True)
    return busy


def spin_until(pred, node, timeout: float, period: float = 0.05) -> bool:
    """Spin ``node`` (``period`` s at a time) until ``pred()`` is true or ``timeout`` wall s passed; return
    ``pred()``."""
    end = time.monotonic() + timeout
    while time.monotonic() < end:
        if pred():
            return True
        rclpy.spin_once(node, timeout_sec=period)
    return pred()


def _start_listener(name: str, cmd: list, log, env, rec, procs) -> None:
    """Start a process that subscribes /kite/state and wait (60 s at most) until it does."""
    before = rec.count_subscribers(STATE)
    proc = NodeProcess(name, log=log, env=env, cmd=cmd)
    procs.append(proc)
    spin_until(lambda: rec.count_subscribers(STATE) > before or not proc.alive(), rec, 60.0, period=0.1)
    if not proc.alive():
        raise RuntimeError(f"{name} exited (code {proc.proc.returncode}): " + " | ".join(proc.lines[-3:]))


def _ns(args) -> list:
    """``--namespace NS`` for a tool of the demo's graph (nothing in the root namespace)."""
    ns = getattr(args, "namespace", None)
    return [] if ns in (None, "/") else ["--namespace", ns]


def start_recorder(args, log, env, rec, procs) -> int:
    """With ``--record``: start kite_record and kite_viz (the 3-D scene, so that the recording holds
    /kite/markers); with ``--viz`` alone: kite_viz. Wait until they listen; return the number of extra /kite/state
    subscribers the plant must wait for (0, 1 or 2)."""
    extra = 0
    if args.record:
        Path(args.record).resolve().parent.mkdir(parents=True, exist_ok=True)
        _start_listener("record", [sys.executable, "-m", "kite_rto.tools.record", "--out", str(args.record),
                                   "--lossless", *_ns(args)], log, env, rec, procs)
        extra += 1
    if args.record or getattr(args, "viz", False):
        # recording: one scene per 0.1 s of the flight, however fast the lockstep loop runs (no wall-rate cap);
        # live only: at most 20 per wall second, what a screen shows
        cap = ["--ros-args", "-p", "max_rate:=0.0"] if args.record else []
        _start_listener("viz", [sys.executable, "-m", "kite_rto.tools.viz", *_ns(args), *cap], log, env, rec, procs)
        extra += 1
        print("  3-D scene on /kite/markers (kite_viz; RViz2 or Foxglove, fixed frame anchor)", flush=True)
    if args.record:
        print(f"  recording every topic to {args.record} (log time = simulated time; lossless: the lockstep plant "
              "waits for the recorder)", flush=True)
    return extra


def recorder_summary(procs) -> None:
    """Print what the recorder process said it wrote (or that it said nothing)."""
    for p in procs:
        if p.name == "record":
            said = [ln for ln in p.lines if "wrote" in ln]
            print(f"  {said[-1].strip()}" if said else f"  the recorder said nothing; see nodes.log (exit code "
                  f"{p.proc.returncode})", flush=True)


def lifecycle(node, label: str, timeout: float = 60.0, target: str = "optimizer") -> None:
    """Ask ``target`` for the lifecycle transition ``label`` (``configure``, ``activate``, ...) through its standard
    ``change_state`` service, spinning ``node``; RuntimeError when it does not answer or refuses."""
    client = node.create_client(ChangeState, f"{target}/change_state")
    try:
        if not spin_until(client.service_is_ready, node, timeout):
            raise RuntimeError(f"{target}/change_state did not answer within {timeout:g} s")
        future = client.call_async(ChangeState.Request(transition=Transition(label=label)))
        if not spin_until(future.done, node, timeout) or not future.result().success:
            raise RuntimeError(f"{target} refused or did not answer the lifecycle transition {label}")
    finally:
        node.destroy_client(client)
