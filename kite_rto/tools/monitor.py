"""Watch a running kite_rto graph: one line per lap, per RTO iteration and per phase or setpoint change.

``python -m kite_rto.tools.monitor [--count N] [--duration S] [--use-sim-time] [--namespace NS]`` (console script
``kite_monitor``; ``ros2 run kite_rto kite_monitor`` after colcon build). Subscribes ``/kite/laps``,
``/rto/status``, ``/rto/setpoints`` and ``/kite/crashes`` (it never subscribes the per-sample topics, so it costs
the lockstep loop nothing). Lines look like::

    12:00:03 setpoints  (30.00, 42.00, 6.50) deg
    12:00:04 rto        iteration 0  phase experiment  experiment k0-0-nominal (nominal) at (30.00, 42.00, 6.50) deg
    12:00:06 lap     3  t 62.1 s  c (30.00, 42.00, 6.50) deg  tension 551.9 kN  min alt 131 m  xtrack 0.31 deg
             [it 0 experiment nominal]          (one line: wrapped here)
    12:00:31 rto        iteration 0 done: measured 566.6 kN, g -31.40 m, c_1 = (30.00, 43.92, 6.50) deg (step)
    12:00:40 CRASH   #1  t 95.4 s

``--count N`` exits after N lines, ``--duration S`` after S seconds (wall, or simulated with ``--use-sim-time``).
"""
from __future__ import annotations

import argparse
import math
import sys
import time

from rclpy.node import Node
from rclpy.parameter import Parameter
from rclpy.utilities import remove_ros_args

from ..nodes.namespace import add_namespace_option, tool_ros_args
from ..nodes.topics import CRASHES, LAPS, SETPOINTS, STATUS
from .echo import run_cli
from .record import TOPICS, subscriber_qos

__all__ = ["format_lap", "format_status", "format_iteration", "format_setpoints", "format_crash", "Monitor",
           "main"]


def _deg3(c) -> str:
    if c is None:
        return "(?)"
    return "(" + ", ".join(f"{math.degrees(x):.2f}" for x in c) + ")"


def format_setpoints(c) -> str:
    """Line for new setpoints ``c`` (rad)."""
    return f"setpoints  {_deg3(c)} deg"


def format_lap(lap: dict, t: float | None, setpoints=None, status: dict | None = None) -> str:
    """Line for one ``/kite/laps`` message: ``lap`` = dict of its fields (names of
    ``controller_node.LAP_FIELDS``: N, m, deg), ``t`` = its stamp (sim s), the current setpoints (rad) and the last
    RTO status key/values (for the phase)."""
    parts = [f"lap {int(lap.get('lap', -1)):5d}"]
    if t is not None:
        parts.append(f"t {t:.1f} s")
    if setpoints is None and all(k in lap for k in ("theta_0", "A_phi", "A_theta")):
        parts.append(f"flown {_deg3([lap['theta_0'], lap['A_phi'], lap['A_theta']])} deg")
    elif setpoints is not None:
        parts.append(f"c {_deg3(setpoints)} deg")
    if "mean_tension" in lap:
        parts.append(f"tension {lap['mean_tension'] / 1e3:.1f} kN")
    if "min_altitude" in lap:
        parts.append(f"min alt {lap['min_altitude']:.0f} m")
    if "rms_cross_track_deg" in lap:
        parts.append(f"xtrack {lap['rms_cross_track_deg']:.2f} deg")
    if status:
        tag = f"it {status.get('iteration', '?')} {status.get('phase', '')}".strip()
        if status.get("purpose"):
            tag += f" {status['purpose']}"
        parts.append(f"[{tag}]")
    return "  ".join(parts)


def format_status(kv: dict) -> str:
    """Line for an RTO phase change: ``kv`` = the key/values of the optimizer's ``/rto/status``."""
    line = f"rto        iteration {kv.get('iteration', '?')}  phase {kv.get('phase', '?')}"
    if kv.get("experiment"):
        line += f"  experiment {kv['experiment']}"
        if kv.get("purpose"):
            line += f" ({kv['purpose']})"
        if kv.get("setpoints_deg"):
            line += f" at {kv['setpoints_deg']}"
    return line


def format_iteration(kv: dict) -> str:
    """Line for a finished RTO iteration: ``kv`` = ``/rto/status`` key/values after iteration ``k`` =
    ``iteration`` - 1 (measured cost and constraint at c_k, the next iterate c_{k+1} and GMA's decision)."""
    try:
        n = int(kv.get("iteration"))
    except (TypeError, ValueError):
        n = None
    line = f"rto        iteration {'?' if n is None else n - 1} done:"
    try:
        line += f" measured {-float(kv['measured_cost_kN']):.1f} kN,"
    except (KeyError, ValueError):
        pass
    if "measured_constraint_m" in kv:
        line += f" g {kv['measured_constraint_m']} m,"
    line += f" c_{'?' if n is None else n} = {kv.get('c_next_deg', '?')}"
    if kv.get("decision"):
        line += f" ({kv['decision']})"
    return line


def format_crash(count: int, t: float | None) -> str:
    """Line for the plant's crash counter rising to ``count``."""
    return f"CRASH   #{count}" + (f"  t {t:.1f} s" if t is not None else "")


class Monitor:
    """Turns messages into lines (no ROS here: :meth:`lap`, :meth:`status`, ... return the new lines)."""

    def __init__(self):
        self.setpoints = None
        self.status: dict = {}
        self.t = None
        self.crashes = 0
        self._phase_key = None
        self._iterations_shown = None

    def lap(self, names, values, t: float) -> list:
        self.t = t
        return [format_lap(dict(zip(names, values)), t, self.setpoints, self.status)]

    def setpoint(self, names, values) -> list:
        c = dict(zip(names, values))
        new = [c.get("theta_0"), c.get("A_phi"), c.get("A_theta")]
        if None in new or new == self.setpoints:
            return []
        self.setpoints = new
        return [format_setpoints(new)]

    def status_message(self, kv: dict) -> list:
        lines = []
        self.status = kv
        iteration = kv.get("iteration")
        if "c_next_deg" in kv and iteration != self._iterations_shown and iteration not in (None, "0"):
            lines.append(format_iteration(kv))
        self._iterations_shown = iteration
        key = (iteration, kv.get("phase"), kv.get("experiment"))
        if key != self._phase_key:
            self._phase_key = key
            lines.append(format_status(kv))
        return lines

    def crash(self, count: int) -> list:
        if count > self.crashes:
            self.crashes = count
            return [format_crash(count, self.t)]
        self.crashes = count
        return []


def _stamp(msg) -> float:
    return msg.header.stamp.sec + msg.header.stamp.nanosec * 1e-9


def parse_args(argv):
    ap = argparse.ArgumentParser(prog="kite_monitor", description=__doc__,
                                 formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--count", type=int, default=0, help="exit after N lines")
    ap.add_argument("--duration", type=float, default=0.0,
                    help="exit after S seconds (wall; simulated with --use-sim-time)")
    ap.add_argument("--use-sim-time", action="store_true", help="the node's clock follows /clock")
    add_namespace_option(ap)
    return ap.parse_args(argv)


def main(argv=None) -> int:
    argv = sys.argv[1:] if argv is None else list(argv)
    args = parse_args(remove_ros_args(["kite_monitor", *argv])[1:])
    mon = Monitor()
    printed = [0]

    def emit(lines):
        for line in lines:
            if args.count and printed[0] >= args.count:
                return
            sys.stdout.write(f"{time.strftime('%H:%M:%S')} {line}\n")
            printed[0] += 1
        sys.stdout.flush()

    def status_cb(msg):
        for st in msg.status:
            if st.name == "kite_rto/optimizer":
                emit(mon.status_message({kv.key: kv.value for kv in st.values}))

    def make_node():
        overrides = [Parameter("use_sim_time", value=True)] if args.use_sim_time else []
        node = Node("kite_monitor", parameter_overrides=overrides)
        node.create_subscription(TOPICS[LAPS][0], LAPS,
                                 lambda m: emit(mon.lap(m.name, m.position, _stamp(m))), subscriber_qos(LAPS, 100))
        node.create_subscription(TOPICS[SETPOINTS][0], SETPOINTS, lambda m: emit(mon.setpoint(m.name, m.position)),
                                 subscriber_qos(SETPOINTS))
        node.create_subscription(TOPICS[STATUS][0], STATUS, status_cb, subscriber_qos(STATUS, 100))
        node.create_subscription(TOPICS[CRASHES][0], CRASHES, lambda m: emit(mon.crash(int(m.data))),
                                 subscriber_qos(CRASHES))
        return node

    return run_cli(make_node, tool_ros_args("kite_monitor", argv, args.namespace),
                   lambda: bool(args.count) and printed[0] >= args.count,
                   duration=args.duration)


if __name__ == "__main__":
    sys.exit(main())
