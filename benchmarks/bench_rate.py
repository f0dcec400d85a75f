"""A real-time rate the machine cannot hold: crashes, achieved rate and command lag of plant + controller.

The plant (``mode:=realtime``, ``rate_factor`` ``--rate``, default wind and noise) and the controller run as
separate processes in an isolated ``ROS_DOMAIN_ID`` for ``--wall`` wall seconds after the first answer. Measured:
kite crashes (the plant's ``kite crashed`` lines), simulated seconds per wall second (the plant's ``/clock`` seen
by a probe), the lag of the steering commands (sample index of ``/clock`` minus that of the command's stamp when
the probe receives it: median and 90th percentile over the last half of the run), the plant's warnings about the
rate and its rejected (stale) commands.

Usage: ``python benchmarks/bench_rate.py [--rate 100] [--wall 20] [--seed 0]``. Prints a markdown table
``benchmark | value | target | met``; ``main()`` returns its rows. Target: no crash; an unholdable rate is warned.
"""
from __future__ import annotations

import argparse
import os
import random
import statistics
import sys
import time


from bench_stall import _env, _spin, probe_node, start_realtime

from _table import print_table

DT = 0.02


def run_rate(rate: float, wall: float, env: dict, seed: int = 0) -> dict:
    """Fly plant + controller at ``rate`` for ``wall`` s; returns crashes, rates, lags and the plant's log."""
    node, executor, probe = probe_node("bench_rate")
    ctrl = plant = None
    out = {}
    try:
        ctrl, plant = start_realtime(node, executor, probe, env, rate, seed)
        w0, c0 = time.monotonic(), probe.clock_ns
        _spin(executor, wall / 2)
        w1, c1, n1 = time.monotonic(), probe.clock_ns, len(probe.answers)
        _spin(executor, wall / 2)
        w2, c2 = time.monotonic(), probe.clock_ns
        lags = sorted((clock - stamp) / (DT * 1e9) for _, stamp, clock in probe.answers[n1:] if clock >= 0)
        out = {"sim_rate": (c2 - c0) * 1e-9 / (w2 - w0), "sim_rate_2nd_half": (c2 - c1) * 1e-9 / (w2 - w1),
               "lag_median": statistics.median(lags) if lags else float("nan"),
               "lag_p90": lags[int(0.9 * (len(lags) - 1))] if lags else float("nan"), "answers": len(lags)}
    finally:
        if plant is not None:
            out["plant"] = plant.stop()
        if ctrl is not None:
            out["controller"] = ctrl.stop()
        executor.remove_node(node)
        node.destroy_node()
    lines = out.get("plant", "").splitlines()
    out["crashes"] = sum("kite crashed" in ln for ln in lines)
    out["rate_warnings"] = [ln for ln in lines if "cannot hold rate_factor" in ln]
    out["rejected"] = sum("rejected steering" in ln for ln in lines)
    out["neutral"] = sum("flying neutral" in ln for ln in lines)
    return out


def main(argv=None) -> list[tuple]:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--rate", type=float, default=100.0, help="rate_factor (sim s per wall s)")
    ap.add_argument("--wall", type=float, default=20.0, help="wall seconds of flight")
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--domain", type=int, default=None, help="ROS_DOMAIN_ID (default: from the pid, 101-200)")
    args = ap.parse_args(argv)
    domain = args.domain if args.domain is not None else random.Random(os.getpid()).randint(101, 200)
    env = _env(domain, True)
    os.environ.update({k: env[k] for k in ("ROS_DOMAIN_ID", "ROS_AUTOMATIC_DISCOVERY_RANGE", "RMW_IMPLEMENTATION")})
    load0 = os.getloadavg()[0]
    r = run_rate(args.rate, args.wall, env, args.seed)
    load1 = os.getloadavg()[0]
    rows = [
        ("kite crashes", str(r["crashes"]), "0", "yes" if r["crashes"] == 0 else "NO"),
        ("simulated s per wall s (whole run / second half)",
         f"{r.get('sim_rate', float('nan')):.1f} / {r.get('sim_rate_2nd_half', float('nan')):.1f}",
         f"requested {args.rate:g}", ""),
        ("steering lag at the probe, samples: median / 90 %, second half",
         f"{r.get('lag_median', float('nan')):.1f} / {r.get('lag_p90', float('nan')):.1f}", "", ""),
        ("'cannot hold rate_factor' warnings", str(len(r["rate_warnings"])), ">= 1 if unholdable", ""),
        ("'flying neutral' / 'rejected steering' log lines", f"{r['neutral']} / {r['rejected']}", "", ""),
        ("load average (1 min) before/after, cores", f"{load0:.1f}/{load1:.1f}, {os.cpu_count()}", "", ""),
    ]
    print(f"bench_rate: realtime rate_factor {args.rate:g} for {args.wall:g} s wall, seed {args.seed}, "
          f"ROS_DOMAIN_ID {domain}")
    for ln in r["rate_warnings"][:3]:
        print("  " + ln)
    print_table(rows)
    return rows


if __name__ == "__main__":
    main()
    sys.stdout.flush()
