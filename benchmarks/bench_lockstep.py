"""Closed-loop lockstep over DDS: plant node process + echo_pilot process, real-time factor.

The plant (``kite_rto.nodes.plant_node``, mode ``lockstep``, dt = 0.02 s) publishes each sample and advances only
when the steering command stamped with that sample arrives; ``kite_rto.nodes.echo_pilot`` (the minimal answering
client) answers every ``/kite/state`` at once. Both run as separate processes in an isolated ``ROS_DOMAIN_ID``
with ``ROS_AUTOMATIC_DISCOVERY_RANGE=LOCALHOST``, like a user's ``ros2 run kite_rto plant`` + a client.

Measured: simulated seconds per wall second over ``--duration`` simulated seconds after discovery, from the
plant's own final log line (wall time from the first answered sample to the last step). Also the end-to-end wall
time of the plant process (start-up, discovery and shutdown included). Median over ``--repeats`` runs.
Target: >= 50x real time (2500 round trips/s at a 50 Hz step).

For comparison in the same run (same machine load), the same runs are repeated with both nodes on rclpy's
SingleThreadedExecutor (``KITE_RTO_EXECUTOR=single``; ``--no-baseline`` skips this).

Usage: ``python benchmarks/bench_lockstep.py [--duration 60] [--repeats 3]``. Prints a markdown table
``benchmark | value | target | met``; ``main()`` returns its rows.
"""
from __future__ import annotations

import argparse
import os
import random
import re
import statistics
import subprocess
import sys
import time

from kite_rto.testing.launch import start_node, stop_node

from _table import print_table

TARGET_RTF = 50.0
DT = 0.02
_LINE = re.compile(r"lockstep: (\d+) steps in ([0-9.eE+-]+) s wall")


def _env(domain: int) -> dict:
    env = dict(os.environ)
    env["ROS_DOMAIN_ID"] = str(domain)
    env["ROS_AUTOMATIC_DISCOVERY_RANGE"] = "LOCALHOST"
    env.setdefault("RMW_IMPLEMENTATION", "rmw_fastrtps_cpp")
    env["PYTHONUNBUFFERED"] = "1"
    return env


def run_once(duration: float, domain: int, timeout: float, extra_env: dict | None = None) -> dict:
    """One lockstep run; returns steps, in-plant wall time, end-to-end wall time, exit code and outputs."""
    env = _env(domain)
    env.update(extra_env or {})
    pilot = start_node("echo_pilot", {"delta": 0.0}, env)
    t0 = time.perf_counter()
    plant = start_node("plant", {"duration": duration, "dt": DT, "command_timeout": 5.0}, env)
    try:
        code = plant.wait(timeout=timeout)
    except subprocess.TimeoutExpired:
        code = None
    total = time.perf_counter() - t0
    out_plant = stop_node(plant)
    out_pilot = stop_node(pilot)
    m = _LINE.search(out_plant)
    return {"code": code, "total": total, "steps": int(m.group(1)) if m else None,
            "wall": float(m.group(2)) if m else None, "plant_out": out_plant, "pilot_out": out_pilot}


def main(argv=None) -> list[tuple]:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--duration", type=float, default=60.0, help="simulated seconds per run")
    ap.add_argument("--repeats", type=int, default=3)
    ap.add_argument("--domain", type=int, default=None, help="ROS_DOMAIN_ID (default: from the pid, 101-200)")
    ap.add_argument("--timeout", type=float, default=300.0, help="wall seconds before a run is abandoned")
    ap.add_argument("--no-baseline", action="store_true", help="skip the SingleThreadedExecutor comparison runs")
    args = ap.parse_args(argv)
    domain = args.domain if args.domain is not None else random.Random(os.getpid()).randint(101, 200)

    load0 = os.getloadavg()[0]
    runs, base = [], []
    for _ in range(args.repeats):                # interleaved, so both see the same machine load
        runs.append(run_once(args.duration, domain, args.timeout))
        if not args.no_baseline:
            base.append(run_once(args.duration, domain, args.timeout, {"KITE_RTO_EXECUTOR": "single"}))
    load1 = os.getloadavg()[0]
    base_rtf = [r["steps"] * DT / r["wall"] for r in base if r["code"] == 0 and r["wall"]]
    good = [r for r in runs if r["code"] == 0 and r["wall"]]
    for i, r in enumerate(runs):
        if r not in good:
            print(f"run {i}: exit code {r['code']}; plant output:\n{r['plant_out'][-2000:]}\npilot output:\n"
                  f"{r['pilot_out'][-1000:]}", file=sys.stderr)
    rows = []
    if good:
        rtf = statistics.median(r["steps"] * DT / r["wall"] for r in good)
        rtt = statistics.median(r["wall"] / r["steps"] * 1e6 for r in good)
        e2e = statistics.median(r["total"] for r in good)
        rows += [
            ("lockstep real-time factor (sim s / wall s)", f"{rtf:.1f}", f">= {TARGET_RTF:g}",
             "yes" if rtf >= TARGET_RTF else "NO"),
            ("lockstep round trips/s", f"{rtf / DT:.0f}", f">= {TARGET_RTF / DT:g}",
             "yes" if rtf >= TARGET_RTF else "NO"),
            ("lockstep round trip, µs", f"{rtt:.0f}", f"<= {DT / TARGET_RTF * 1e6:g}",
             "yes" if rtf >= TARGET_RTF else "NO"),
            (f"end-to-end wall for {args.duration:g} sim s (start-up + discovery incl.), s", f"{e2e:.2f}", "", ""),
        ]
    if base_rtf:
        rows.append(("same run, SingleThreadedExecutor: real-time factor", f"{statistics.median(base_rtf):.1f}",
                     "", ""))
    rows += [("successful runs", f"{len(good)}/{len(runs)}", f"{len(runs)}/{len(runs)}",
              "yes" if len(good) == len(runs) else "NO"),
             ("load average (1 min) before/after, cores", f"{load0:.1f}/{load1:.1f}, {os.cpu_count()}", "", "")]
    print(f"bench_lockstep: {args.repeats} x {args.duration:g} sim s, dt {DT} s, ROS_DOMAIN_ID {domain}, "
          f"RMW {os.environ.get('RMW_IMPLEMENTATION', 'rmw_fastrtps_cpp')}; per-run RTF: "
          + ", ".join(f"{r['steps'] * DT / r['wall']:.1f}" for r in good))
    print_table(rows)
    return rows


if __name__ == "__main__":
    main()
