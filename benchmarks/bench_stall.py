"""A frozen controller in real time: how long until the plant steers again after the controller resumes.

The plant (``mode:=realtime``, ``rate_factor`` 1, default wind and noise) and the controller run as separate
processes in an isolated ``ROS_DOMAIN_ID`` with localhost discovery. Each stall: the loop flies ``--settle`` wall
seconds, then the controller is frozen with SIGSTOP for ``--stall`` wall seconds (the plant flies neutral after its
``command_timeout`` of 1 s) and resumed with SIGCONT. Measured per stall, in wall seconds from the SIGCONT:

- *steering back*: the plant's ``steering commands are back`` log line (its ROS log stamp): the first command the
  plant accepted and flies after the stall;
- *first answer*: the first ``/kite/steering`` message a probe in this process receives (any stamp: answers to
  samples queued during the stall come first and are rejected by the plant as stale);
- *first fresh answer*: the first ``/kite/steering`` stamped within 0.5 s of the plant's ``/clock``;

and the kite crashes (``kite crashed`` lines of the plant) from the SIGSTOP until the next stall.

Usage: ``python benchmarks/bench_stall.py [--stalls 20] [--stall 3] [--settle 5] [--rate-factor 1]``. Prints one
line per stall and a markdown table ``benchmark | value | target | met``; ``main()`` returns its rows,
:func:`run_stalls` the measurements (``test/ros/test_fault_plant_side.py`` runs it with 3 stalls).
Target: steering back within 0.2 s of the SIGCONT, no crash in 20 stalls.
"""
from __future__ import annotations

import argparse
import math
import os
import random
import re
import signal
import statistics
import sys
import threading
import time

import rclpy
from rclpy.executors import SingleThreadedExecutor
from rclpy.node import Node
from rclpy.qos import QoSProfile, ReliabilityPolicy
from rosgraph_msgs.msg import Clock
from sensor_msgs.msg import JointState

from kite_rto.testing.launch import start_node, stop_node

from _table import print_table

TARGET_BACK = 0.2          # wall s from SIGCONT to the first steering command the plant flies
FRESH_NS = 500_000_000     # an answer stamped within this of the plant's clock is fresh (the plant's own window)
_STAMP = re.compile(r"\[\w+\] \[(\d+\.\d+)\]")


def log_stamp(line: str) -> float:
    """The wall-clock stamp (s since the epoch) of a ROS log line ``[LEVEL] [seconds] [node]: ...``, else NaN."""
    m = _STAMP.match(line)
    return float(m.group(1)) if m else math.nan


class Logged:
    """A node process whose output lines are collected by a reader thread."""

    def __init__(self, name: str, params: dict, env: dict):
        self.proc = start_node(name, params, env)
        self.lines: list[str] = []
        self._reader = threading.Thread(target=self._read, daemon=True)
        self._reader.start()

    def _read(self):
        for line in self.proc.stdout:
            self.lines.append(line.rstrip("\n"))

    def stamps(self, needle: str) -> list[float]:
        return [log_stamp(ln) for ln in list(self.lines) if needle in ln]

    def signal(self, sig) -> None:
        os.killpg(self.proc.pid, sig)

    def stop(self) -> str:
        stop_node(self.proc)
        self._reader.join(timeout=5.0)
        return "\n".join(self.lines)


class _Steering:
    """Probe: wall time (time.time()) and stamp of every /kite/steering message; the plant's latest /clock."""

    def __init__(self, node: Node):
        self.clock_ns = -1
        self.answers: list[tuple[float, int]] = []
        node.create_subscription(Clock, "/clock", self._clock, 10)
        node.create_subscription(JointState, "/kite/steering", self._steer,
                                 QoSProfile(depth=1000, reliability=ReliabilityPolicy.RELIABLE))

    def _clock(self, msg):
        self.clock_ns = msg.clock.sec * 1_000_000_000 + msg.clock.nanosec

    def _steer(self, msg):
        stamp = msg.header.stamp.sec * 1_000_000_000 + msg.header.stamp.nanosec
        self.answers.append((time.time(), stamp, self.clock_ns))

    def first_after(self, t: float, fresh: bool) -> float:
        for wall, stamp, clock in list(self.answers):
            if wall >= t and (not fresh or 0 <= clock - stamp <= FRESH_NS):
                return wall - t
        return math.nan


def probe_node(name: str):
    """(node, executor, steering probe) of this process, rclpy initialized if it was not."""
    if not rclpy.ok():
        rclpy.init()
    node = Node(f"{name}_{os.getpid()}")
    executor = SingleThreadedExecutor()
    executor.add_node(node)
    return node, executor, _Steering(node)


def start_realtime(node, executor, probe, env: dict, rate_factor: float, seed: int):
    """Start a controller, then a real-time plant; return both once the probe has heard an answer (or 120 s)."""
    ctrl = Logged("controller", {}, env)
    end = time.monotonic() + 120.0
    while node.count_publishers("/kite/steering") == 0 and time.monotonic() < end:
        _spin(executor, 0.1)
    _spin(executor, 0.5)
    plant = Logged("plant", {"mode": "realtime", "rate_factor": rate_factor, "seed": seed}, env)
    end = time.monotonic() + 120.0
    while not probe.answers and time.monotonic() < end:
        _spin(executor, 0.05)
    return ctrl, plant


def _spin(executor, seconds: float) -> None:
    end = time.monotonic() + seconds
    while time.monotonic() < end:
        executor.spin_once(timeout_sec=0.01)


def run_stalls(n: int, env: dict, stall: float = 3.0, settle: float = 5.0, rate_factor: float = 1.0,
               seed: int = 0, progress=None) -> dict:
    """Fly plant + controller in real time and freeze the controller ``n`` times (see the module docstring).

    ``env`` is the node processes' environment (its ``ROS_DOMAIN_ID``; rclpy in this process must be initialized
    in the same domain, or not yet). Returns ``{"stalls": [per-stall dict], "crashes": total, "plant": log text,
    "controller": log text}``; each stall dict holds ``back``, ``first``, ``fresh`` (wall s after SIGCONT, NaN when
    not seen within 15 s) and ``crashes``.
    """
    node, executor, probe = probe_node("bench_stall")
    ctrl = plant = None
    out = {"stalls": [], "crashes": 0, "plant": "", "controller": ""}
    try:
        ctrl, plant = start_realtime(node, executor, probe, env, rate_factor, seed)
        if not probe.answers:
            raise RuntimeError("the controller never answered:\n" + "\n".join(plant.lines[-20:] + ctrl.lines[-20:]))
        stops = []
        for i in range(n):
            _spin(executor, settle)
            stops.append(time.time())
            ctrl.signal(signal.SIGSTOP)
            _spin(executor, stall)
            t_cont = time.time()
            ctrl.signal(signal.SIGCONT)
            end = time.monotonic() + 15.0
            while time.monotonic() < end and not [t for t in plant.stamps("steering commands are back")
                                                  if t >= t_cont]:
                _spin(executor, 0.02)
            back = [t for t in plant.stamps("steering commands are back") if t >= t_cont]
            out["stalls"].append({"t_stop": stops[-1], "t_cont": t_cont,
                                  "back": back[0] - t_cont if back else math.nan})
        _spin(executor, settle)
        crashes = plant.stamps("kite crashed")
        for i, s in enumerate(out["stalls"]):
            later = out["stalls"][i + 1]["t_stop"] if i + 1 < n else math.inf
            s["crashes"] = sum(s["t_stop"] <= t < later for t in crashes)
            s["first"] = probe.first_after(s["t_cont"], fresh=False)       # the probe may lag behind the plant
            s["fresh"] = probe.first_after(s["t_cont"], fresh=True)
            if progress:
                progress(i, s)
        out["crashes"] = len(crashes)
    finally:
        if plant is not None:
            out["plant"] = plant.stop()
        if ctrl is not None:
            ctrl.signal(signal.SIGCONT)
            out["controller"] = ctrl.stop()
        executor.remove_node(node)
        node.destroy_node()
    return out


def _env(domain: int, profile: bool) -> dict:
    env = dict(os.environ)
    env["ROS_DOMAIN_ID"] = str(domain)
    env["ROS_AUTOMATIC_DISCOVERY_RANGE"] = "LOCALHOST"
    env.setdefault("RMW_IMPLEMENTATION", "rmw_fastrtps_cpp")
    env["PYTHONUNBUFFERED"] = "1"
    if not profile:
        env["KITE_RTO_DDS_PROFILE"] = "none"             # the nodes leave Fast DDS at its defaults
    return env


def _stats(values) -> tuple[float, float]:
    ok = [v for v in values if not math.isnan(v)]
    return (statistics.median(ok), max(ok)) if ok else (math.nan, math.nan)


def main(argv=None) -> list[tuple]:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--stalls", type=int, default=20)
    ap.add_argument("--stall", type=float, default=3.0, help="wall seconds the controller is frozen")
    ap.add_argument("--settle", type=float, default=5.0, help="wall seconds of flight before each stall")
    ap.add_argument("--rate-factor", type=float, default=1.0)
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--domain", type=int, default=None, help="ROS_DOMAIN_ID (default: from the pid, 101-200)")
    ap.add_argument("--log", default=None, help="folder to write the plant's and the controller's output to")
    ap.add_argument("--no-profile", action="store_true",
                    help="KITE_RTO_DDS_PROFILE=none: Fast DDS defaults instead of the shipped profile")
    args = ap.parse_args(argv)
    domain = args.domain if args.domain is not None else random.Random(os.getpid()).randint(101, 200)
    env = _env(domain, not args.no_profile)
    os.environ.update({k: env[k] for k in ("ROS_DOMAIN_ID", "ROS_AUTOMATIC_DISCOVERY_RANGE", "RMW_IMPLEMENTATION")})
    load0 = os.getloadavg()[0]

    def progress(i, s):
        print(f"stall {i + 1}: steering back {s['back']:.3f} s, first answer {s['first']:.3f} s, first fresh "
              f"answer {s['fresh']:.3f} s after SIGCONT; crashes {s['crashes']}", flush=True)

    res = run_stalls(args.stalls, env, args.stall, args.settle, args.rate_factor, args.seed, progress)
    if args.log:
        os.makedirs(args.log, exist_ok=True)
        for name in ("plant", "controller"):
            with open(os.path.join(args.log, f"{name}.log"), "w", encoding="utf-8") as f:
                f.write(res[name] + "\n")
    load1 = os.getloadavg()[0]
    st = res["stalls"]
    back_med, back_max = _stats([s["back"] for s in st])
    fresh_med, fresh_max = _stats([s["fresh"] for s in st])
    missing = sum(math.isnan(s["back"]) for s in st)
    crashes = sum(s["crashes"] for s in st)
    rows = [
        (f"steering back after SIGCONT, median / max over {len(st)} stalls, s", f"{back_med:.3f} / {back_max:.3f}",
         f"<= {TARGET_BACK:g}", "yes" if back_max <= TARGET_BACK and not missing else "NO"),
        ("first fresh answer on /kite/steering after SIGCONT, median / max, s", f"{fresh_med:.3f} / {fresh_max:.3f}",
         "", ""),
        ("stalls after which steering never came back (15 s)", str(missing), "0", "yes" if not missing else "NO"),
        ("kite crashes during and after the stalls", str(crashes), "0", "yes" if crashes == 0 else "NO"),
        ("load average (1 min) before/after, cores", f"{load0:.1f}/{load1:.1f}, {os.cpu_count()}", "", ""),
    ]
    print(f"bench_stall: {args.stalls} stalls of {args.stall:g} s (SIGSTOP/SIGCONT of the controller), "
          f"{args.settle:g} s flight before each, realtime rate_factor {args.rate_factor:g}, seed {args.seed}, "
          f"ROS_DOMAIN_ID {domain}, DDS profile {'Fast DDS defaults' if args.no_profile else 'shipped'}")
    print_table(rows)
    return rows


if __name__ == "__main__":
    main()
    sys.stdout.flush()
