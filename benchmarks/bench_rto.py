"""GMA on the turbulent kite versus baselines, judged on the deterministic plant (prints a table).

GMA starts at the model-only optimum on the default plant (turbulence and noise on). Every iterate c_k is
re-flown on the deterministic plant (turbulence and noise off); the target is >= 99 % of the oracle's mean
tension (``kite_rto.core.oracle.find_oracle``, cached under runs/) with min altitude >= h_min - 2 m. The
baselines (model-only, model-free finite-difference ascent, Nelder-Mead on the plant) get the same plant
seed, the same experiment spec and the same flight time as GMA used for that seed.

Usage: ``python benchmarks/bench_rto.py [--seeds 3] [--iters 10] [--quick] [--no-baselines]``
(``--quick``: 2 seeds, 5 iterations).
"""
from __future__ import annotations

import argparse
import math
import time

import numpy as np

from kite_rto.core.baselines import finite_difference_ascent, model_only, nelder_mead_plant, time_to_target
from kite_rto.core.kite_rto import KiteRTOSettings, model_only_optimum, run_kite_rto
from kite_rto.core.oracle import find_oracle, plant_performance
from kite_rto.core.plant import PlantConfig


def _deg(c):
    return "/".join(f"{v:.1f}" for v in np.degrees(c))


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--seeds", type=int, default=3)
    ap.add_argument("--iters", type=int, default=10)
    ap.add_argument("--quick", action="store_true")
    ap.add_argument("--no-baselines", action="store_true")
    args = ap.parse_args(argv)
    if args.quick:
        args.seeds, args.iters = min(args.seeds, 2), min(args.iters, 5)
    t_wall = time.perf_counter()
    config = PlantConfig()
    settings = KiteRTOSettings()
    oracle = find_oracle(config, settings.box)
    target = 0.99 * oracle.tension_kn
    c0, t_model, _ = model_only_optimum(settings.box)
    t0, z0 = plant_performance(config, c0)
    print(f"bench_rto: {args.seeds} seeds x {args.iters} GMA iterations, plant default (turbulence on), "
          f"experiment {settings.experiment.n_laps} laps + 1 settle lap, gradient {settings.gradient} "
          f"fd_step {settings.fd_step}")
    print(f"oracle (deterministic plant): c = {_deg(oracle.c)} deg, {oracle.tension_kn:.1f} kN, "
          f"min alt {oracle.min_altitude:.1f} m ({oracle.evaluations} evaluations); target 99 % = {target:.1f} kN")
    print(f"model-only optimum: c = {_deg(c0)} deg, model says {t_model:.1f} kN; plant gives {t0:.1f} kN, "
          f"min alt {z0:.1f} m: gap {100 * (1 - t0 / oracle.tension_kn):.1f} % below the oracle")
    head = (f"{'method':12} {'seed':>4} {'reach k':>7} {'t reach s':>9} {'final c deg':>16} {'T_det kN':>8} "
            f"{'% orac':>6} {'alt m':>6} {'exps':>4} {'flight s':>8} {'crash':>5}")
    print(head)
    print("-" * len(head))
    summary = {}
    for seed in range(args.seeds):
        res = run_kite_rto(config, seed, args.iters, settings)
        k, t = time_to_target(res.iterates, res.iterate_times, config, target)
        tf, zf = plant_performance(config, res.iterates[-1])
        summary.setdefault("GMA", []).append((k, t, tf))
        print(f"{'GMA':12} {seed:4d} {str(k):>7} {t:9.0f} {_deg(res.iterates[-1]):>16} {tf:8.1f} "
              f"{100 * tf / oracle.tension_kn:6.1f} {zf:6.1f} {len(res.experiments):4d} {res.flight_time:8.0f} "
              f"{res.crashes:5d}", flush=True)
        if args.no_baselines:
            continue
        budget = res.flight_time
        for run in (model_only(c0, budget),
                    finite_difference_ascent(config, seed, c0, budget, settings.experiment, settings.box),
                    nelder_mead_plant(config, seed, c0, budget, settings.experiment, settings.box)):
            k, t = time_to_target(run.candidates, run.times, config, target)
            tf, zf = plant_performance(config, run.candidates[-1])
            summary.setdefault(run.name, []).append((k, t, tf))
            print(f"{run.name:12} {seed:4d} {str(k):>7} {t:9.0f} {_deg(run.candidates[-1]):>16} {tf:8.1f} "
                  f"{100 * tf / oracle.tension_kn:6.1f} {zf:6.1f} {run.experiments:4d} {run.flight_time:8.0f} "
                  f"{'':>5}", flush=True)
    print("-" * len(head))
    print(f"{'method':12} {'reached':>8} {'median t reach s':>16} {'final % oracle: mean (min..max)':>32}")
    for name, rows in summary.items():
        reached = [t for _, t, _ in rows if math.isfinite(t)]
        pct = np.array([100 * tf / oracle.tension_kn for _, _, tf in rows])
        med = f"{np.median(reached):.0f}" if reached else "never"
        print(f"{name:12} {len(reached):>4}/{len(rows):<3} {med:>16} "
              f"{pct.mean():20.1f} ({pct.min():.1f}..{pct.max():.1f})")
    print(f"wall time {time.perf_counter() - t_wall:.0f} s")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
