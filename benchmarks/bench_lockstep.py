"""Closed-loop lockstep over DDS, three graphs side by side: real-time factor and wall time per sample.

Every graph runs its nodes as separate processes (``ros2 run kite_rto <node>``'s entry points) in an isolated
``ROS_DOMAIN_ID`` with ``ROS_AUTOMATIC_DISCOVERY_RANGE=LOCALHOST``; the plant (mode ``lockstep``, dt = 0.02 s,
defaults otherwise) publishes each sample and advances only when the steering command stamped with it arrives:

- ``probe``: plant + ``echo_pilot`` (the minimal answering client: what DDS and the plant cost);
- ``pair``: plant + controller (fixed setpoints, no optimizer);
- ``graph``: plant + controller (``sync_optimizer:=true``) + optimizer (the main job's graph, its defaults, a fresh
  database): the controller waits for the optimizer only where a decision is due.

Measured: simulated seconds per wall second over ``--duration`` simulated seconds, from the plant's own final log
line (wall time from the first answered sample to the last step, so start-up and discovery are left out), and
its inverse per sample (µs). Median over ``--repeats`` rounds; the three graphs run interleaved in each round, so
they see the same machine load. Targets: the probe >= 50x real time; the graph >= 60x and within 15 % of the pair.

Usage: ``python benchmarks/bench_lockstep.py [--duration 600] [--repeats 3] [--only probe,pair,graph]``. Prints a
markdown table ``benchmark | value | target | met``; ``main()`` returns its rows.
"""
from __future__ import annotations

import argparse
import os
import random
import re
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

from kite_rto.testing.launch import start_node, stop_node

from _table import print_table

DT = 0.02
TARGETS = {"probe": 50.0, "graph": 60.0}
"""Real-time factors asked for; the graph also within :data:`PAIR_RATIO` of the pair."""
PAIR_RATIO = 0.85
GRAPHS = ("probe", "pair", "graph")
_LINE = re.compile(r"lockstep: (\d+) steps in ([0-9.eE+-]+) s wall")


def _env(domain: int) -> dict:
    env = dict(os.environ)
    env["ROS_DOMAIN_ID"] = str(domain)
    env["ROS_AUTOMATIC_DISCOVERY_RANGE"] = "LOCALHOST"
    env.setdefault("RMW_IMPLEMENTATION", "rmw_fastrtps_cpp")
    env["PYTHONUNBUFFERED"] = "1"
    return env


def _wait_for(proc, pattern: str, timeout: float) -> None:
    """Read ``proc``'s output until a line contains ``pattern`` (the node is up), at most ``timeout`` s."""
    end = time.monotonic() + timeout
    while time.monotonic() < end:
        line = proc.stdout.readline()
        if pattern in line or not line and proc.poll() is not None:
            return
    raise TimeoutError(f"no line with {pattern!r} within {timeout:g} s")


def run_once(graph: str, duration: float, domain: int, timeout: float) -> dict:
    """One lockstep run of ``graph``; returns steps, in-plant wall time, exit code and the plant's output."""
    env = _env(domain)
    others = []
    with tempfile.TemporaryDirectory() as tmp:
        if graph == "probe":
            others.append(start_node("echo_pilot", {"delta": 0.0}, env))
        else:
            if graph == "graph":
                opt = start_node("optimizer", {"db": str(Path(tmp) / "rto.sqlite")}, env)
                others.append(opt)
                _wait_for(opt, "optimizer up", timeout)
            others.append(start_node("controller", {"sync_optimizer": graph == "graph"}, env))
        plant = start_node("plant", {"duration": duration, "dt": DT, "command_timeout": 5.0,
                                     "wait_subscribers": 2 if graph == "graph" else 1}, env)
        try:
            code = plant.wait(timeout=timeout)
        except subprocess.TimeoutExpired:
            code = None
        out = stop_node(plant)
        outs = [stop_node(p) for p in reversed(others)]
    m = _LINE.search(out)
    return {"graph": graph, "code": code, "steps": int(m.group(1)) if m else None,
            "wall": float(m.group(2)) if m else None, "out": out, "others": outs}


def main(argv=None) -> list[tuple]:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--duration", type=float, default=600.0, help="simulated seconds per run")
    ap.add_argument("--repeats", type=int, default=3)
    ap.add_argument("--only", default=",".join(GRAPHS), help=f"graphs to run, of {', '.join(GRAPHS)}")
    ap.add_argument("--domain", type=int, default=None, help="ROS_DOMAIN_ID (default: from the pid, 101-200)")
    ap.add_argument("--timeout", type=float, default=600.0, help="wall seconds before a run is abandoned")
    args = ap.parse_args(argv)
    graphs = [g for g in args.only.split(",") if g]
    bad = sorted(set(graphs) - set(GRAPHS))
    if bad:
        ap.error(f"--only {args.only}: unknown graph(s) {', '.join(bad)}; expected some of {', '.join(GRAPHS)}")
    domain = args.domain if args.domain is not None else random.Random(os.getpid()).randint(101, 200)

    load0 = os.getloadavg()[0]
    runs = {g: [] for g in graphs}
    for _ in range(args.repeats):                # interleaved: every graph sees the same machine load
        for g in graphs:
            runs[g].append(run_once(g, args.duration, domain, args.timeout))
    load1 = os.getloadavg()[0]
    rows, rtf = [], {}
    for g in graphs:
        good = [r for r in runs[g] if r["code"] == 0 and r["wall"]]
        for i, r in enumerate(runs[g]):
            if r not in good:
                print(f"{g} run {i}: exit code {r['code']}; plant output:\n{r['out'][-2000:]}\nother nodes:\n"
                      + "\n".join(o[-1000:] for o in r["others"]), file=sys.stderr)
        if not good:
            rows.append((f"{g}: real-time factor (sim s / wall s)", "no run", "", "NO"))
            continue
        rtf[g] = statistics.median(r["steps"] * DT / r["wall"] for r in good)
        target = TARGETS.get(g)
        rows += [(f"{g}: real-time factor (sim s / wall s)", f"{rtf[g]:.1f}", f">= {target:g}" if target else "",
                  ("yes" if rtf[g] >= target else "NO") if target else ""),
                 (f"{g}: wall per sample, µs", f"{DT / rtf[g] * 1e6:.0f}", "", ""),
                 (f"{g}: successful runs", f"{len(good)}/{len(runs[g])}", f"{len(runs[g])}/{len(runs[g])}",
                  "yes" if len(good) == len(runs[g]) else "NO")]
    if "graph" in rtf and "pair" in rtf:
        ratio = rtf["graph"] / rtf["pair"]
        rows.append(("graph / pair real-time factor", f"{ratio:.2f}", f">= {PAIR_RATIO:g}",
                     "yes" if ratio >= PAIR_RATIO else "NO"))
    rows.append(("load average (1 min) before/after, cores", f"{load0:.1f}/{load1:.1f}, {os.cpu_count()}", "", ""))
    print(f"bench_lockstep: {args.repeats} x {args.duration:g} sim s per graph, dt {DT} s, ROS_DOMAIN_ID {domain}, "
          f"RMW {os.environ.get('RMW_IMPLEMENTATION', 'rmw_fastrtps_cpp')}; per-run real-time factors: "
          + "; ".join(f"{g} " + ", ".join(f"{r['steps'] * DT / r['wall']:.1f}" for r in runs[g] if r["wall"])
                      for g in graphs))
    print_table(rows)
    return rows


if __name__ == "__main__":
    main()
