"""GMA on the turbulent kite versus baselines, judged on the deterministic plant (prints a table).

GMA starts at the model-only optimum on the default plant (turbulence and noise on). Every iterate c_k is
re-flown on the deterministic plant (turbulence and noise off); the target is >= 99 % of the oracle's mean
tension (``kite_rto.rto.oracle.find_oracle``, cached in ``$KITE_RTO_CACHE`` or the user cache directory) with
min altitude >= h_min - 2 m. The
baselines (model-only, model-free finite-difference ascent, Nelder-Mead on the plant) get the same plant
seed and the same experiment spec, and a flight-time budget of ``--budget`` times the flight time GMA needed
to reach 99 % on that seed (its whole flight time if it did not); a baseline stops as soon as a candidate
reaches 99 %. The summary gives, per seed, the baseline's time to 99 % over GMA's (``>x`` when the baseline
did not reach 99 % within its budget: the ratio is then above ``x``).

The plant is built from the options: ``--wind-model`` (``uniform`` gust or the 3-D ``field``; default the
plant's default), ``--anemometer-correlation`` (uniform gust only); the experiment cost normalizes by
``--wind-source`` (default: the default source of that wind model, ``kite_rto.rto.experiment.DEFAULT_WIND_SOURCES``).
GMA and the baselines use the same experiment spec. The oracle is always the deterministic plant (turbulence and
noise off, which also makes the two wind models the same plant).

Usage: ``python benchmarks/bench_rto.py [--seeds 5] [--iters 10] [--budget 4] [--wind-model field]
[--wind-source observer] [--anemometer-correlation 1.0] [--gradient directional] [--n-directions 2] [--backoff 6]
[--first-seed 0] [--quick] [--no-baselines]`` (``--quick``: 2 seeds, 5 iterations).
With the directional gradient it first prints DMA's privileged directions.
"""
from __future__ import annotations

import argparse
import math
import time
from dataclasses import replace

import numpy as np

from kite_rto.rto.baselines import finite_difference_ascent, model_only, nelder_mead_plant, time_to_target
from kite_rto.rto.settings import KiteRTOSettings
from kite_rto.rto.builder import gma_directions, model_only_optimum
from kite_rto.rto.runner import run_rto
from kite_rto.rto.oracle import find_oracle, plant_performance
from kite_rto.rto.experiment import default_wind_source
from kite_rto.rto.wind_source import WIND_SOURCES
from kite_rto.kite.plant import DEFAULT_WIND_MODEL, WIND_MODELS, PlantConfig


def _deg(c):
    return "/".join(f"{v:.1f}" for v in np.degrees(c))


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--seeds", type=int, default=5)
    ap.add_argument("--iters", type=int, default=10)
    ap.add_argument("--quick", action="store_true")
    ap.add_argument("--no-baselines", action="store_true")
    ap.add_argument("--budget", type=float, default=4.0, help="baseline flight time / GMA flight time")
    ap.add_argument("--wind-model", choices=WIND_MODELS, default=DEFAULT_WIND_MODEL,
                    help="the plant's wind: one uniform gust or the 3-D turbulence field")
    ap.add_argument("--wind-source", choices=WIND_SOURCES, default=None,
                    help="wind the experiment cost normalizes by (default: the wind model's default source)")
    ap.add_argument("--anemometer-correlation", type=float, default=None,
                    help="uniform wind only: plant anemometer gust correlation (default: PlantConfig's)")
    ap.add_argument("--gradient", default=KiteRTOSettings().gradient,
                    choices=("directional", "forward", "central", "least_squares"), help="GMA's plant gradient")
    ap.add_argument("--n-directions", type=int, default=KiteRTOSettings().n_directions,
                    help="privileged directions (gradient directional)")
    ap.add_argument("--backoff", type=float, default=KiteRTOSettings().gma.backoff,
                    help="GMA's altitude back-off, m")
    ap.add_argument("--first-seed", type=int, default=0, help="seeds first-seed .. first-seed + seeds - 1")
    args = ap.parse_args(argv)
    if args.quick:
        args.seeds, args.iters = min(args.seeds, 2), min(args.iters, 5)
    t_wall = time.perf_counter()
    config = PlantConfig(wind_model=args.wind_model)
    if args.anemometer_correlation is not None:
        config = replace(config, turbulence=replace(config.turbulence,
                                                    anemometer_correlation=args.anemometer_correlation))
    source = args.wind_source or default_wind_source(args.wind_model)
    settings = KiteRTOSettings(gradient=args.gradient, n_directions=args.n_directions)
    settings = replace(settings, experiment=replace(settings.experiment, wind_source=source)
                       ).with_gma(backoff=args.backoff)
    oracle = find_oracle(config, settings.box)
    target = 0.99 * oracle.tension_kn
    opt = model_only_optimum(settings.box)
    c0, t_model = opt.c, opt.mean_tension_kn
    t0, z0 = plant_performance(config, c0)
    wind = (f"3-D field (IEC class {config.wind_field.turbulence_class})" if config.wind_model == "field" else
            f"uniform gust, anemometer correlation {config.turbulence.anemometer_correlation:g}")
    print(f"bench_rto: {args.seeds} seeds x {args.iters} GMA iterations, plant default (turbulence on), wind {wind}, "
          f"cost normalized by {source}, experiment {settings.experiment.n_laps} laps "
          f"+ 1 settle lap, gradient {settings.gradient} fd_step {settings.fd_step} "
          f"back-off {settings.gma.backoff:g} m; "
          f"baselines get {args.budget:g}x GMA's time to 99 %")
    if settings.gradient == "directional":
        d = gma_directions(settings)
        dirs = "; ".join("(" + ", ".join(f"{v:+.3f}" for v in col) + ")" for col in d.scaled.T)
        print(f"privileged directions (theta_0, A_phi, aspect in box widths): {dirs}; held at a robustly active "
              f"bound: {[n for n, f in zip(('theta_0', 'A_phi', 'aspect'), d.fixed) if f]}; singular values "
              f"{np.round(d.singular_values, 2).tolist()} kN per box width, captured {100 * d.captured:.1f} %")
    print(f"oracle (deterministic plant): c = {_deg(oracle.c)} deg, {oracle.tension_kn:.1f} kN, "
          f"min alt {oracle.min_altitude:.1f} m ({oracle.evaluations} evaluations); target 99 % = {target:.1f} kN")
    print(f"model-only optimum: c = {_deg(c0)} deg, model says {t_model:.1f} kN; plant gives {t0:.1f} kN, "
          f"min alt {z0:.1f} m: gap {100 * (1 - t0 / oracle.tension_kn):.1f} % below the oracle")
    head = (f"{'method':12} {'seed':>4} {'reach k':>7} {'t reach s':>9} {'final c deg':>16} {'T_det kN':>8} "
            f"{'% orac':>6} {'alt m':>6} {'exps':>4} {'flight s':>8} {'crash':>5} {'held from k':>11}")
    print(head)
    print("-" * len(head))
    summary, budgets = {}, []

    def reached(c) -> bool:
        tension, z = plant_performance(config, c)
        return tension >= target and z >= 100.0 - 2.0
    for seed in range(args.first_seed, args.first_seed + args.seeds):
        res = run_rto(config, seed, args.iters, settings)
        k, t = time_to_target(res.iterates, res.iterate_times, config, target)
        tf, zf = plant_performance(config, res.iterates[-1])
        ok = [reached(c) for c in res.iterates]
        held = next((j for j in range(len(ok)) if all(ok[j:])), None)   # >= 99 % at every iterate from here on
        summary.setdefault("GMA", []).append((k, t, tf))
        print(f"{'GMA':12} {seed:4d} {str(k):>7} {t:9.0f} {_deg(res.iterates[-1]):>16} {tf:8.1f} "
              f"{100 * tf / oracle.tension_kn:6.1f} {zf:6.1f} {len(res.experiments):4d} {res.flight_time:8.0f} "
              f"{res.crashes:5d} {str(held):>11}", flush=True)
        if args.no_baselines:
            continue
        budget = args.budget * (t if math.isfinite(t) else res.flight_time)
        budgets.append(budget)
        for run in (model_only(c0, budget),
                    finite_difference_ascent(config, seed, c0, budget, settings.experiment, settings.box,
                                             stop=reached),
                    nelder_mead_plant(config, seed, c0, budget, settings.experiment, settings.box, stop=reached)):
            k, t = time_to_target(run.candidates, run.times, config, target)
            tf, zf = plant_performance(config, run.candidates[-1])
            summary.setdefault(run.name, []).append((k, t, tf))
            print(f"{run.name:12} {seed:4d} {str(k):>7} {t:9.0f} {_deg(run.candidates[-1]):>16} {tf:8.1f} "
                  f"{100 * tf / oracle.tension_kn:6.1f} {zf:6.1f} {run.experiments:4d} {run.flight_time:8.0f} "
                  f"{'':>5}", flush=True)
    print("-" * len(head))
    print(f"{'method':12} {'reached':>8} {'median t reach s':>16} {'final % oracle: mean (min..max)':>32} "
          f"{'t reach / GMA t reach per seed':>32}")
    gma_t = [t for _, t, _ in summary["GMA"]]
    for name, rows in summary.items():
        reached = [t for _, t, _ in rows if math.isfinite(t)]
        pct = np.array([100 * tf / oracle.tension_kn for _, _, tf in rows])
        med = f"{np.median(reached):.0f}" if reached else "never"
        ratios = []
        for seed, ((_, t, _), tg) in enumerate(zip(rows, gma_t)):
            if not math.isfinite(tg):
                ratios.append("-")
            elif math.isfinite(t):
                ratios.append(f"{t / tg:.1f}")
            else:   # not reached within its budget: the ratio is above budget / GMA's time
                ratios.append(f">{budgets[seed] / tg:.1f}")
        print(f"{name:12} {len(reached):>4}/{len(rows):<3} {med:>16} "
              f"{pct.mean():20.1f} ({pct.min():.1f}..{pct.max():.1f}) {' '.join(ratios):>32}")
    print(f"wall time {time.perf_counter() - t_wall:.0f} s")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
