"""The main job's wall time with and without a recording, and what the recording holds.

Runs the main job (``python -m kite_rto.tools.demo``, lockstep, seed 0) ``--repeats`` times each way: without a
recording, and with ``--record`` (the lossless recorder: the lockstep plant waits for it). With ``--baseline
CHECKOUT`` (another clone of the repository with its own ``.venv``, e.g. of an earlier release) it also times that
checkout's ``--record``, and the target is that the lossless recording costs at most 10 % more wall time than the
baseline's. Each run's flight wall time is read from the demo's ``flew ... in N s wall`` line (the oracle and the
report are not counted), and the recording's ``/kite/state`` samples and missing count from the recorder's line.
Median over the repeats; runs alternate between the variants so that a change of the machine's load hits them alike.

Usage: ``python benchmarks/bench_record.py [--iterations 3] [--repeats 3] [--baseline PATH]`` (3 iterations: 1926 s
of flight, about 25 minutes of wall time without a baseline on a quiet 2-core machine; ``--iterations 10`` for the
whole main job). Prints a markdown table ``benchmark | value | target | met``.
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
from pathlib import Path

from _table import print_table

ROOT = Path(__file__).resolve().parent.parent
_FLEW = re.compile(r"flew ([0-9.]+) s of simulated time in ([0-9.]+) s wall")
_STATE = re.compile(r"/kite/state (\d+)")
TARGET = 1.10


def run_once(checkout: Path, record: bool, iterations: int, domain: int) -> dict:
    """One main job in ``checkout`` (its own ``.venv``); returns the flight's wall time and the recorder's line."""
    env = dict(os.environ, ROS_DOMAIN_ID=str(domain), ROS_AUTOMATIC_DISCOVERY_RANGE="LOCALHOST",
               PYTHONUNBUFFERED="1")
    env.pop("PYTHONPATH", None)
    with tempfile.TemporaryDirectory() as out:
        cmd = [str(checkout / ".venv" / "bin" / "python"), "-m", "kite_rto.tools.demo", "--out", out,
               "--iterations", str(iterations), "--progress", "60"]
        if record:
            cmd += ["--record", str(Path(out) / "run.mcap")]
        res = subprocess.run(cmd, cwd=checkout, env=env, capture_output=True, text=True, timeout=7200)
    flew = _FLEW.search(res.stdout)
    wrote = next((ln for ln in res.stdout.splitlines() if "wrote" in ln), "")
    state = _STATE.search(wrote)
    return {"code": res.returncode, "sim": float(flew.group(1)) if flew else None,
            "wall": float(flew.group(2)) if flew else None, "wrote": wrote,
            "state": int(state.group(1)) if state else None, "complete": "no sample missing" in wrote}


def main(argv=None) -> list:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--iterations", type=int, default=3, help="GMA iterations (10: the whole main job)")
    ap.add_argument("--repeats", type=int, default=3)
    ap.add_argument("--baseline", type=Path, help="another checkout (with .venv) whose --record is timed too")
    args = ap.parse_args(argv)
    variants = [("no recording", ROOT, False), ("--record (lossless)", ROOT, True)]
    if args.baseline:
        variants.append((f"--record at {args.baseline.name}", args.baseline.resolve(), True))
    runs = {name: [] for name, _, _ in variants}
    domain = random.Random(os.getpid()).randint(120, 200)
    for i in range(args.repeats):
        for name, checkout, record in variants:
            r = run_once(checkout, record, args.iterations, domain)
            runs[name].append(r)
            print(f"repeat {i + 1} {name}: exit {r['code']}, {r['sim']} s simulated in {r['wall']} s wall; "
                  f"{r['wrote'].strip()[:160]}", flush=True)
    wall = {name: statistics.median([r["wall"] for r in rs if r["wall"] is not None] or [float("nan")])
            for name, rs in runs.items()}
    rows = [(f"main job ({args.iterations} iterations) wall, {name}, median of {args.repeats}", f"{wall[name]:.1f} s",
             "", "") for name, _, _ in variants]
    lossless = runs["--record (lossless)"]
    ok = all(r["complete"] for r in lossless)
    rows.append(("lossless recordings with every sample (no sample missing)", f"{sum(r['complete'] for r in lossless)}"
                 f"/{len(lossless)}", "all", "yes" if ok else "NO"))
    if args.baseline:
        ratio = wall["--record (lossless)"] / wall[variants[-1][0]]
        rows.append(("lossless --record over the baseline's --record", f"{ratio:.3f}", f"<= {TARGET:.2f}",
                     "yes" if ratio <= TARGET else "NO"))
    print_table(rows)
    return rows


if __name__ == "__main__":
    sys.exit(0 if all(r[3] != "NO" for r in main()) else 1)
