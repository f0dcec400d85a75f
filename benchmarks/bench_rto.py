"""GMA on the turbulent kite versus baselines, judged on the deterministic plant (prints a table).

GMA starts at the model-only optimum on the plant of ``--scenario`` (``kite_rto/campaign/scenarios.py``, default
``default``; turbulence and noise on), with that scenario's h_min. Every iterate c_k is judged by
``kite_rto.rto.judge.judge``: re-flown on the scenario's deterministic plant (turbulence and noise off); the
target is >= 99 % of the oracle's mean tension (``kite_rto.rto.oracle.find_oracle`` on that plant and h_min, cached
in ``$KITE_RTO_CACHE`` or the user cache directory) with min altitude >= h_min - 2 m. The baselines (model-only,
model-free finite-difference ascent, Nelder-Mead and Bayesian optimization on the plant) get the same plant seed,
the same experiment spec and start point, and a flight-time budget of ``--budget`` times the flight time GMA needed
to reach 99 % on that seed (its whole flight time if it did not); a baseline stops as soon as a candidate
reaches 99 %. ``kite_campaign`` (docs/campaign.md) runs the same comparison over all scenarios on Dask. The summary
gives, per seed, the baseline's time to 99 % over GMA's (``>x`` when the baseline did not reach 99 % within its
budget: the ratio is then above ``x``).

The scenario's plant can be changed by the options: ``--wind-model`` (``uniform`` gust or the 3-D ``field``; default
the scenario's), ``--anemometer-correlation`` (uniform gust only); the experiment cost normalizes by
``--wind-source`` (default: the default source of that wind model, ``kite_rto.rto.experiment.DEFAULT_WIND_SOURCES``).
GMA and the baselines use the same experiment spec. The oracle is always the deterministic plant (turbulence and
noise off, which also makes the two wind models the same plant).

Usage: ``python benchmarks/bench_rto.py [--scenario default] [--seeds 5] [--iters 10] [--budget 4]
[--wind-model field] [--wind-source observer] [--anemometer-correlation 1.0] [--gradient directional]
[--n-directions 2] [--backoff 6] [--first-seed 0] [--quick] [--no-baselines]`` (``--quick``: 2 seeds, 5 iterations).
With the directional gradient it first prints DMA's privileged directions.
"""
from __future__ import annotations

import argparse
import math
import time
from dataclasses import replace
from functools import partial

import numpy as np

from kite_rto.campaign.methods import BASELINES, fly_baseline, fly_gma, scenario_settings, start_point
from kite_rto.campaign.scenarios import SCENARIOS, scenario
from kite_rto.rto.settings import KiteRTOSettings
from kite_rto.rto.builder import gma_directions
from kite_rto.rto.judge import REACH_FRACTION, judge, reaches
from kite_rto.rto.oracle import find_oracle, plant_performance
from kite_rto.rto.experiment import default_wind_source
from kite_rto.rto.wind_source import WIND_SOURCES
from kite_rto.kite.plant import WIND_MODELS


def _deg(c):
    return "/".join(f"{v:.1f}" for v in np.degrees(c))


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--scenario", default="default", choices=[s.name for s in SCENARIOS],
                    help="the plant variant and h_min (kite_rto/campaign/scenarios.py)")
    ap.add_argument("--seeds", type=int, default=5)
    ap.add_argument("--iters", type=int, default=10)
    ap.add_argument("--quick", action="store_true")
    ap.add_argument("--no-baselines", action="store_true")
    ap.add_argument("--budget", type=float, default=4.0, help="baseline flight time / GMA flight time")
    ap.add_argument("--wind-model", choices=WIND_MODELS, default=None,
                    help="the plant's wind: one uniform gust or the 3-D turbulence field (default: the scenario's)")
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
    sc = scenario(args.scenario)
    config = sc.plant if args.wind_model is None else replace(sc.plant, wind_model=args.wind_model)
    if args.anemometer_correlation is not None:
        config = replace(config, turbulence=replace(config.turbulence,
                                                    anemometer_correlation=args.anemometer_correlation))
    sc = replace(sc, plant=config)
    source = args.wind_source or default_wind_source(config.wind_model)
    settings = KiteRTOSettings(gradient=args.gradient, n_directions=args.n_directions)
    settings = replace(settings, experiment=replace(settings.experiment, wind_source=source)
                       ).with_gma(backoff=args.backoff)
    settings = scenario_settings(settings, sc)
    oracle = find_oracle(config, settings.box, h_min=sc.h_min)
    target = REACH_FRACTION * oracle.tension_kn
    c0 = start_point(settings)
    t0, z0 = plant_performance(config, c0)
    wind = (f"3-D field (IEC class {config.wind_field.turbulence_class})" if config.wind_model == "field" else
            f"uniform gust, anemometer correlation {config.turbulence.anemometer_correlation:g}")
    print(f"bench_rto: {args.seeds} seeds x {args.iters} GMA iterations, scenario {sc.name} ({sc.description}; "
          f"h_min {sc.h_min:g} m, turbulence on), wind {wind}, "
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
    print(f"model-only optimum: c = {_deg(c0)} deg; plant gives {t0:.1f} kN, "
          f"min alt {z0:.1f} m: gap {100 * (1 - t0 / oracle.tension_kn):.1f} % below the oracle")
    head = (f"{'method':12} {'seed':>4} {'reach k':>7} {'t reach s':>9} {'final c deg':>16} {'T_det kN':>8} "
            f"{'% orac':>6} {'alt m':>6} {'exps':>4} {'flight s':>8} {'crash':>5} {'held from k':>11}")
    print(head)
    print("-" * len(head))
    summary, budgets = {}, []

    def row(name, seed, flown):
        v = judge(sc.plant, sc.h_min, oracle.tension_kn, flown.iterates, flown.times)
        summary.setdefault(name, []).append((v.reach_index, v.reach_time, v.tension_kn[-1]))
        print(f"{name:12} {seed:4d} {str(v.reach_index):>7} {v.reach_time:9.0f} {_deg(flown.iterates[-1]):>16} "
              f"{v.tension_kn[-1]:8.1f} {v.percent[-1]:6.1f} {v.min_altitude[-1]:6.1f} {flown.experiments:4d} "
              f"{flown.flight_time:8.0f} {flown.crashes:5d} {str(v.held_from):>11}", flush=True)
        return v
    for seed in range(args.first_seed, args.first_seed + args.seeds):
        gma = fly_gma(sc, seed, args.iters, settings)
        v = row("GMA", seed, gma)
        if args.no_baselines:
            continue
        budget = args.budget * (v.reach_time if math.isfinite(v.reach_time) else gma.flight_time)
        budgets.append(budget)
        for method in BASELINES:
            row(method, seed, fly_baseline(method, sc, seed, settings, budget,
                                           stop=partial(reaches, sc.plant, sc.h_min, oracle.tension_kn)))
    print("-" * len(head))
    print(f"{'method':12} {'reached':>8} {'median t reach s':>16} {'final % oracle: mean (min..max)':>32} "
          f"{'t reach / GMA t reach per seed':>32}")
    gma_t = [t for _, t, _ in summary["GMA"]]
    for name, rows in summary.items():
        reached = [t for _, t, _ in rows if math.isfinite(t)]
        pct = np.array([100 * tf / oracle.tension_kn for _, _, tf in rows])
        med = f"{np.median(reached):.0f}" if reached else "never"
        ratios = []
        for i, ((_, t, _), tg) in enumerate(zip(rows, gma_t)):
            if not math.isfinite(tg):
                ratios.append("-")
            elif math.isfinite(t):
                ratios.append(f"{t / tg:.1f}")
            else:   # not reached within its budget: the ratio is above budget / GMA's time
                ratios.append(f">{budgets[i] / tg:.1f}")
        print(f"{name:12} {len(reached):>4}/{len(rows):<3} {med:>16} "
              f"{pct.mean():20.1f} ({pct.min():.1f}..{pct.max():.1f}) {' '.join(ratios):>32}")
    print(f"wall time {time.perf_counter() - t_wall:.0f} s")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
