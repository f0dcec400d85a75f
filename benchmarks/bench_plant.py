"""Pure-core plant benchmark: time of one ``KitePlant.step`` with the default configuration.

Default configuration = turbulence + anemometer noise + measurement noise + 0.25 s dead time + rate limit, dt =
0.02 s, one RK4 substep. Reports the median over ``--repeats`` repetitions of ``--steps`` steps each, in µs per
step, as wall-clock time (``perf_counter``, the issue's target) and as CPU time of this process
(``process_time``; less sensitive to other processes competing for the cores). Also checks that the plant's
block-drawing turbulence gives bit-for-bit the same trajectory as the reference ``wind.Turbulence``.

Usage: ``python benchmarks/bench_plant.py [--steps 20000] [--repeats 7]``. Prints a markdown table
``benchmark | value | target | met``; ``main()`` returns its rows.
"""
from __future__ import annotations

import argparse
import os
import statistics
import time

import numpy as np

from kite_rto.kite.plant import KitePlant, PlantConfig
from kite_rto.kite.wind import Turbulence

TARGET_US = 20.0


def _time_steps(plant: KitePlant, commands: list) -> tuple[float, float]:
    step = plant.step
    w0, c0 = time.perf_counter(), time.process_time()
    for d in commands:
        step(d)
    n = len(commands)
    return (time.perf_counter() - w0) / n * 1e6, (time.process_time() - c0) / n * 1e6


def _reference_equivalence(n: int = 3000, seed: int = 11) -> bool:
    """The plant with its fast turbulence vs. the same plant with the reference ``Turbulence``: bit for bit."""
    cmds = np.sin(np.arange(n) * 0.01).tolist()
    fast = KitePlant(seed=seed)
    ref = KitePlant(seed=seed)
    cfg = ref.config
    gust_ss, _ = np.random.SeedSequence(seed).spawn(2)
    ref.turbulence = Turbulence(cfg.turbulence, cfg.params.w_ref, np.random.default_rng(gust_ss))
    ref.turbulence.anemometer()          # the draw the fast plant's initial measurement already made
    a = [fast.step(d) for d in cmds]
    b = [ref.step(d) for d in cmds]
    return repr(a) == repr(b)


def main(argv=None) -> list[tuple]:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--steps", type=int, default=20000, help="steps per repetition")
    ap.add_argument("--repeats", type=int, default=7)
    ap.add_argument("--seed", type=int, default=0)
    args = ap.parse_args(argv)

    load0 = os.getloadavg()[0]
    plant = KitePlant(PlantConfig(), seed=args.seed)
    rng = np.random.default_rng(1)
    commands = np.clip(np.sin(np.arange(args.steps) * 0.02) + 0.1 * rng.standard_normal(args.steps), -1, 1).tolist()
    _time_steps(plant, commands[:2000])                      # warm up
    wall, cpu = [], []
    for _ in range(args.repeats):
        w, c = _time_steps(plant, commands)
        wall.append(w)
        cpu.append(c)
    # the model's RK4 step alone (pure-Python CasADi translation, not part of this optimisation)
    step_py, x, p = plant.model.step_py, list(plant.state), list(plant._p)
    model_us = []
    for _ in range(args.repeats):
        c0 = time.process_time()
        for _ in range(args.steps // 2):
            step_py(x, 0.1, p, 0.02)
        model_us.append((time.process_time() - c0) / (args.steps // 2) * 1e6)
    same = _reference_equivalence()
    load1 = os.getloadavg()[0]

    w, c = statistics.median(wall), statistics.median(cpu)
    rows = [
        ("plant step (default config), wall, µs/step", f"{w:.1f}", f"<= {TARGET_US:g}", "yes" if w <= TARGET_US else "NO"),
        ("plant step (default config), CPU, µs/step", f"{c:.1f}", f"<= {TARGET_US:g}", "yes" if c <= TARGET_US else "NO"),
        ("  of which model RK4 step_py, CPU, µs", f"{statistics.median(model_us):.1f}", "", ""),
        ("plant steps/s (wall)", f"{1e6 / w:.0f}", "", ""),
        ("bit-identical to reference Turbulence", "yes" if same else "NO", "yes", "yes" if same else "NO"),
        ("load average (1 min) before/after, cores", f"{load0:.1f}/{load1:.1f}, {os.cpu_count()}", "", ""),
    ]
    print(f"bench_plant: {args.repeats} x {args.steps} steps, seed {args.seed}; wall min {min(wall):.1f} "
          f"max {max(wall):.1f} µs")
    print_table(rows)
    return rows


def print_table(rows) -> None:
    print("| benchmark | value | target | met |")
    print("|---|---|---|---|")
    for r in rows:
        print("| " + " | ".join(str(v) for v in r) + " |")


if __name__ == "__main__":
    main()
