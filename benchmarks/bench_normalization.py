"""Measurement noise with and without the tension-coefficient normalization (prints a table).

Per seed (turbulence and noise on, default plant), one kite flies alternately at two setpoints that differ by
``--dA`` deg in A_phi, each held for one experiment (10 s settle, 1 settle lap, 4 laps). From the same laps:
the lap-mean tension raw and normalized (``C_T w_nominal^2``), the 4-lap experiment means, and the forward
difference dT/dA_phi of consecutive experiments. Std over all seeds and pairs; the deterministic plant gives
the true values.

Usage: ``python benchmarks/bench_normalization.py [--seeds 4] [--pairs 3] [--dA 4] [--anemometer-correlation 0.95]``
"""
from __future__ import annotations

import argparse
import math
import time
from dataclasses import replace

import numpy as np

from kite_rto.rto.experiment import ExperimentSpec, PlantFlight
from kite_rto.rto.oracle import plant_performance
from kite_rto.kite.plant import PlantConfig

W_NOM = 8.0


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--seeds", type=int, default=4)
    ap.add_argument("--pairs", type=int, default=3)
    ap.add_argument("--dA", type=float, default=4.0, help="A_phi difference, deg")
    ap.add_argument("--laps", type=int, default=4)
    ap.add_argument("--anemometer-correlation", type=float, default=None,
                    help="plant anemometer gust correlation (default: PlantConfig's, 1)")
    args = ap.parse_args(argv)
    config = PlantConfig()
    if args.anemometer_correlation is not None:
        config = replace(config, turbulence=replace(config.turbulence,
                                                    anemometer_correlation=args.anemometer_correlation))
    ca = np.radians([30.0, 44.0, 7.0])
    cb = ca + np.radians([0.0, args.dA, 0.0])
    spec = ExperimentSpec(n_laps=args.laps, normalize=False)
    t0 = time.perf_counter()
    lap = {"raw": [], "norm": []}
    exp = {"raw": [], "norm": []}
    grad = {"raw": [], "norm": []}
    for seed in range(args.seeds):
        fl = PlantFlight(config, seed, spec)
        for _ in range(args.pairs):
            vals = []
            for c in (ca, cb):
                out = fl.fly(c)
                raw = np.array([x.mean_tension for x in out.laps]) / 1e3
                norm = np.array([x.tension_coefficient for x in out.laps]) * W_NOM ** 2 / 1e3
                vals.append({"raw": raw, "norm": norm})
            for k in ("raw", "norm"):
                lap[k] += list(vals[0][k] - np.mean(vals[0][k]) + 0.0)   # centred per experiment
                exp[k].append(np.mean(vals[0][k]))
                grad[k].append((np.mean(vals[1][k]) - np.mean(vals[0][k])) / args.dA)
    ta, _ = plant_performance(None, ca)
    tb, _ = plant_performance(None, cb)
    true_grad = (tb - ta) / args.dA
    print(f"bench_normalization: {args.seeds} seeds x {args.pairs} pairs, c_a = (30, 44, 7) deg, "
          f"dA_phi = {args.dA:g} deg, {args.laps} laps/experiment, anemometer correlation "
          f"{config.turbulence.anemometer_correlation:g}, {time.perf_counter() - t0:.0f} s wall")
    print(f"deterministic plant: T(c_a) = {ta:.1f} kN, forward-difference dT/dA_phi = {true_grad:.2f} kN/deg")
    head = f"{'quantity':38} {'raw':>10} {'normalized':>11} {'ratio':>6}"
    print(head)
    print("-" * len(head))
    rows = [("std of 4-lap experiment mean, kN", np.std(exp["raw"], ddof=1), np.std(exp["norm"], ddof=1)),
            ("bias of experiment mean vs determ., kN", np.mean(exp["raw"]) - ta, np.mean(exp["norm"]) - ta),
            ("std of dT/dA_phi, kN/deg", np.std(grad["raw"], ddof=1), np.std(grad["norm"], ddof=1)),
            ("mean of dT/dA_phi, kN/deg", np.mean(grad["raw"]), np.mean(grad["norm"])),
            ("within-experiment lap scatter, kN", np.std(lap["raw"]) * math.sqrt(args.laps / (args.laps - 1)),
             np.std(lap["norm"]) * math.sqrt(args.laps / (args.laps - 1)))]
    for name, r, n in rows:
        ratio = f"{n / r:6.2f}" if "std" in name or "scatter" in name else ""
        print(f"{name:38} {r:10.2f} {n:11.2f} {ratio:>6}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
