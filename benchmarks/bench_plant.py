"""Pure-core plant benchmark: time of one ``KitePlant.step`` with the default configuration and the uniform gust.

Default configuration: turbulence (uniform gust) + anemometer noise + measurement noise + 0.25 s dead time + rate
limit, dt = 0.02 s, one RK4 substep. Reports the median over ``--repeats`` repetitions of ``--steps`` steps each,
in µs per step, as wall-clock time (``perf_counter``, the issue's target) and as CPU time of this process
(``process_time``; less sensitive to other processes competing for the cores). Also checks that the plant's
uniform-gust trajectory is bit-for-bit the one recorded before the wind and actuator were factored out of the plant
(the SHA-256 of the ``repr`` of 3000 measurements, seed 11, at commit 15d9726).

The same for the 3-D field wind (``wind_model="field"``, target <= 30 µs), and the start-up time of a field plant
whose box is cached (target <= 1 s; the box is generated first if it is not in the cache).

Usage: ``python benchmarks/bench_plant.py [--steps 20000] [--repeats 7]``. Prints a markdown table
``benchmark | value | target | met``; ``main()`` returns its rows.
"""
from __future__ import annotations

import argparse
import hashlib
import os
import statistics
import time

import numpy as np

from kite_rto.kite.plant import KitePlant, PlantConfig

from _table import print_table

TARGET_US = 20.0
FIELD_TARGET_US = 30.0
STARTUP_TARGET_S = 1.0
REFERENCE_SHA256 = "3f563b8d9efded09e07e5559cc19172d667e308adba46b0b5edb412b3142c50a"
"""Trajectory fingerprint of the default uniform-gust plant at commit 15d9726 (see :func:`_same_as_reference`)."""


def _time_steps(plant: KitePlant, commands: list) -> tuple[float, float]:
    step = plant.step
    w0, c0 = time.perf_counter(), time.process_time()
    for d in commands:
        step(d)
    n = len(commands)
    return (time.perf_counter() - w0) / n * 1e6, (time.process_time() - c0) / n * 1e6


def _timings(plant: KitePlant, commands: list, repeats: int) -> tuple[list, list]:
    """Wall and CPU µs/step of ``repeats`` runs of ``commands`` after a warm-up."""
    _time_steps(plant, commands[:2000])
    runs = [_time_steps(plant, commands) for _ in range(repeats)]
    return [w for w, _ in runs], [c for _, c in runs]


def _same_as_reference(n: int = 3000, seed: int = 11) -> bool:
    """The uniform-wind plant's measurements for ``sin(0.01 k)`` commands hash to :data:`REFERENCE_SHA256`."""
    cmds = np.sin(np.arange(n) * 0.01).tolist()
    plant = KitePlant(PlantConfig(wind_model="uniform"), seed=seed)
    return hashlib.sha256(repr([plant.step(d) for d in cmds]).encode()).hexdigest() == REFERENCE_SHA256


def main(argv=None) -> list[tuple]:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--steps", type=int, default=20000, help="steps per repetition")
    ap.add_argument("--repeats", type=int, default=7)
    ap.add_argument("--seed", type=int, default=0)
    args = ap.parse_args(argv)

    load0 = os.getloadavg()[0]
    rng = np.random.default_rng(1)
    commands = np.clip(np.sin(np.arange(args.steps) * 0.02) + 0.1 * rng.standard_normal(args.steps), -1, 1).tolist()
    plant = KitePlant(PlantConfig(wind_model="uniform"), seed=args.seed)
    wall, cpu = _timings(plant, commands, args.repeats)
    field_config = PlantConfig(wind_model="field")
    KitePlant(field_config, seed=args.seed)                  # generates the box if it is not cached yet
    t0 = time.perf_counter()
    field_plant = KitePlant(field_config, seed=args.seed)
    startup = time.perf_counter() - t0
    f_wall, f_cpu = _timings(field_plant, commands, args.repeats)
    # the model's RK4 step alone (pure-Python CasADi translation, not part of this optimisation)
    step_py, x, p = plant.model.step_py, list(plant.state), list(plant._p)
    model_us = []
    for _ in range(args.repeats):
        c0 = time.process_time()
        for _ in range(args.steps // 2):
            step_py(x, 0.1, p, 0.02)
        model_us.append((time.process_time() - c0) / (args.steps // 2) * 1e6)
    same = _same_as_reference()
    load1 = os.getloadavg()[0]

    w, c = statistics.median(wall), statistics.median(cpu)
    fw, fc = statistics.median(f_wall), statistics.median(f_cpu)
    rows = [
        ("plant step (uniform gust), wall, µs/step", f"{w:.1f}", f"<= {TARGET_US:g}", "yes" if w <= TARGET_US else "NO"),
        ("plant step (uniform gust), CPU, µs/step", f"{c:.1f}", f"<= {TARGET_US:g}", "yes" if c <= TARGET_US else "NO"),
        ("plant step (3-D field wind), wall, µs/step", f"{fw:.1f}", f"<= {FIELD_TARGET_US:g}",
         "yes" if fw <= FIELD_TARGET_US else "NO"),
        ("plant step (3-D field wind), CPU, µs/step", f"{fc:.1f}", f"<= {FIELD_TARGET_US:g}",
         "yes" if fc <= FIELD_TARGET_US else "NO"),
        ("field plant start-up, box cached, s", f"{startup:.3f}", f"<= {STARTUP_TARGET_S:g}",
         "yes" if startup <= STARTUP_TARGET_S else "NO"),
        ("  of which model RK4 step_py, CPU, µs", f"{statistics.median(model_us):.1f}", "", ""),
        ("plant steps/s (wall)", f"{1e6 / w:.0f}", "", ""),
        ("bit-identical to the 15d9726 trajectory", "yes" if same else "NO", "yes", "yes" if same else "NO"),
        ("load average (1 min) before/after, cores", f"{load0:.1f}/{load1:.1f}, {os.cpu_count()}", "", ""),
    ]
    print(f"bench_plant: {args.repeats} x {args.steps} steps, seed {args.seed}; wall min {min(wall):.1f} "
          f"max {max(wall):.1f} µs")
    print_table(rows)
    return rows


if __name__ == "__main__":
    main()
