"""Pure-core controller benchmark: time of one ``PathController.command`` and one ``KitePlant.step`` in the closed loop.

Flies the pure closed loop (``make_closed_loop``: default plant, default setpoints, seed ``--seed``) for
``--duration`` s of simulated time and records every measurement and every steering command. Then, ``--repeats``
times, replays the measurements into a fresh controller of this tree and into one of ``--baseline`` (the package
at that git revision, exported to a temporary folder and imported as ``kite_rto_baseline``), alternating which goes
first, and times the replay: the controller's commands depend only on the measurements, so a replay is exactly the
closed loop's work, and each replay must give the recorded commands bit for bit. Each variant's plant ``step`` is
timed the same way, on the recorded commands. Reports medians, in µs per call, as wall-clock time
(``perf_counter``) and CPU time of this process (``process_time``: less sensitive to other processes on the cores).

``--profile`` also prints the cProfile of one replay of this tree's controller (top 15 by own time).

Usage: ``python benchmarks/bench_controller.py [--duration 60] [--repeats 7] [--baseline 78e9f26] [--profile]``
(``--baseline ''`` times this tree only). Prints a markdown table ``benchmark | value | target | met``; ``main()``
returns its rows.
"""
from __future__ import annotations

import argparse
import cProfile
import importlib
import io
import os
import pstats
import statistics
import subprocess
import sys
import tarfile
import tempfile
import time
from pathlib import Path

from kite_rto.flight.closed_loop import make_closed_loop

from _table import print_table

ROOT = Path(__file__).resolve().parent.parent
BASELINE = "78e9f26"
"""The commit before the controller's per-sample work was made faster (the reference of test_controller_bits.py)."""


def fly(duration: float, seed: int) -> tuple[list, list]:
    """``(measurements, commands)`` of ``duration`` s of the default closed loop."""
    plant, ctl = make_closed_loop(seed=seed)
    ms, cmds = [], []
    m = plant.measure()
    for _ in range(int(round(duration / plant.dt))):
        delta = ctl.command(m)
        ms.append(m)
        cmds.append(delta)
        m = plant.step(delta)
    return ms, cmds


def load_baseline(rev: str, into: str):
    """``kite_rto.flight.closed_loop`` of git revision ``rev`` of this repository, as package ``kite_rto_baseline``."""
    data = subprocess.run(["git", "-C", str(ROOT), "archive", rev, "kite_rto"], check=True,
                          capture_output=True).stdout
    with tarfile.open(fileobj=io.BytesIO(data)) as tar:
        tar.extractall(into, filter="data")
    os.rename(os.path.join(into, "kite_rto"), os.path.join(into, "kite_rto_baseline"))
    sys.path.insert(0, into)
    return importlib.import_module("kite_rto_baseline.flight.closed_loop")


def time_commands(make, ms: list, cmds: list) -> tuple[float, float]:
    """Wall and CPU µs per ``command`` of a fresh controller from ``make()`` replaying ``ms``; checks that
    it answers ``cmds`` bit for bit."""
    command = make()[1].command
    out = []
    append = out.append
    w0, c0 = time.perf_counter(), time.process_time()
    for m in ms:
        append(command(m))
    w, c = time.perf_counter() - w0, time.process_time() - c0
    if out != cmds:
        k = next(i for i, (a, b) in enumerate(zip(out, cmds)) if a != b)
        raise SystemExit(f"replayed command {k} is {out[k]!r}, the closed loop's {cmds[k]!r}")
    return w / len(ms) * 1e6, c / len(ms) * 1e6


def time_plant(make, cmds: list) -> tuple[float, float]:
    """Wall and CPU µs per ``step`` of a fresh plant from ``make()`` fed ``cmds``."""
    step = make()[0].step
    w0, c0 = time.perf_counter(), time.process_time()
    for d in cmds:
        step(d)
    return (time.perf_counter() - w0) / len(cmds) * 1e6, (time.process_time() - c0) / len(cmds) * 1e6


def profile(make, ms: list, top: int = 15) -> None:
    """Print the cProfile of one replay of ``ms`` (the ``top`` functions by own time)."""
    command = make()[1].command
    prof = cProfile.Profile()
    prof.enable()
    for m in ms:
        command(m)
    prof.disable()
    pstats.Stats(prof).strip_dirs().sort_stats("tottime").print_stats(top)


def main(argv=None) -> list[tuple]:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--duration", type=float, default=60.0, help="simulated flight, s")
    ap.add_argument("--repeats", type=int, default=7)
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--baseline", default=BASELINE, help="git revision to compare with ('' for none)")
    ap.add_argument("--profile", action="store_true", help="print the cProfile of one replay")
    args = ap.parse_args(argv)

    load0 = os.getloadavg()[0]
    ms, cmds = fly(args.duration, args.seed)
    variants = {"this tree": lambda: make_closed_loop(seed=args.seed)}
    with tempfile.TemporaryDirectory() as tmp:
        if args.baseline:
            base = load_baseline(args.baseline, tmp)
            variants[f"baseline {args.baseline}"] = lambda: base.make_closed_loop(seed=args.seed)
        names = list(variants)
        runs = {n: [] for n in names}
        plant_runs = {n: [] for n in names}
        for name in names:                                   # warm-up
            time_commands(variants[name], ms[:500], cmds[:500])
        for r in range(args.repeats):
            for name in (names if r % 2 == 0 else names[::-1]):
                runs[name].append(time_commands(variants[name], ms, cmds))
                plant_runs[name].append(time_plant(variants[name], cmds))
    load1 = os.getloadavg()[0]

    rows = []
    for what, unit, timings in (("PathController.command", "call", runs), ("KitePlant.step", "step", plant_runs)):
        med = {n: (statistics.median(w for w, _ in timings[n]), statistics.median(c for _, c in timings[n]))
               for n in names}
        for n in names:
            rows.append((f"{what} ({n}), wall, µs/{unit}", f"{med[n][0]:.1f}", "", ""))
            rows.append((f"{what} ({n}), CPU, µs/{unit}", f"{med[n][1]:.1f}", "", ""))
        if len(names) == 2:
            rows.append((f"{what}: speed-up of this tree, CPU", f"{med[names[1]][1] / med[names[0]][1]:.2f}x", "", ""))
    rows += [
        ("commands bit-identical to the closed loop's" + (" and the baseline's" if len(names) == 2 else ""),
         "yes", "yes", "yes"),
        ("load average (1 min) before/after, cores", f"{load0:.1f}/{load1:.1f}, {os.cpu_count()}", "", ""),
    ]
    print(f"bench_controller: {args.repeats} replays of {len(ms)} samples ({args.duration:g} s, seed {args.seed}), "
          f"alternating; CPU µs min/max: " + ", ".join(
              f"{n} {min(c for _, c in runs[n]):.1f}/{max(c for _, c in runs[n]):.1f}" for n in names))
    print_table(rows)
    if args.profile:
        profile(variants["this tree"], ms)
    return rows


if __name__ == "__main__":
    main()
