"""Are an experiment's standard errors right? Repeated experiments at one point against their own error bars.

GMA's noise-matched modifier filter and its pessimistic cost weigh each gradient estimate by the standard errors
its experiments report (``ExperimentOutcome.cost_std``: the lap-to-lap standard deviation over sqrt(n_laps)).
If slow eddies made laps of one experiment alike, that figure would understate the error of the experiment's
mean and the filter would trust single experiments too much. This flies ``--repeats`` experiments one after the
other at one point of each scenario's campaign settings (the 3-D field, its wind source, ``--laps`` laps) and
compares the scatter of their means with the standard errors they report, for the cost (kN) and the altitude
constraint (m). ``ratio`` > 1: the reported standard error understates the real one. ``lag-1`` is the
correlation of consecutive experiments' means (0: independent experiments).

The point is ``--point`` in box-normalized shape coordinates (default ``0 0.6 0.9``: theta_0 at its lower
bound, near most scenarios' optimum).

Usage: ``python benchmarks/bench_noise.py [--scenarios default,shear_turbulent] [--seeds 2] [--repeats 40]
[--laps 4] [--point 0 0.6 0.9]``
"""
from __future__ import annotations

import argparse
import time
from dataclasses import replace

import numpy as np

from kite_rto.campaign.methods import scenario_settings
from kite_rto.campaign.scenarios import select_scenarios
from kite_rto.rto.experiment import PlantFlight
from kite_rto.rto.settings import KiteRTOSettings


def measure(sc, seed: int, repeats: int, laps: int, point) -> dict:
    """Fly ``repeats`` experiments of ``laps`` laps at ``point`` (box units) of scenario ``sc``, plant ``seed``."""
    s = scenario_settings(KiteRTOSettings(), sc)
    flight = PlantFlight(sc.plant, seed, replace(s.experiment, n_laps=laps))
    outs = [flight.fly(s.box.from_unit(point)) for _ in range(repeats)]
    cost = np.array([o.cost for o in outs])
    alt = np.array([o.constraint for o in outs])
    rep_cost = float(np.sqrt(np.mean([o.cost_std ** 2 for o in outs])))
    rep_alt = float(np.sqrt(np.mean([o.constraint_std ** 2 for o in outs])))
    return {"cost_scatter": float(cost.std(ddof=1)), "cost_reported": rep_cost,
            "cost_ratio": float(cost.std(ddof=1)) / rep_cost, "lag1": float(np.corrcoef(cost[:-1], cost[1:])[0, 1]),
            "alt_scatter": float(alt.std(ddof=1)), "alt_reported": rep_alt,
            "alt_ratio": float(alt.std(ddof=1)) / rep_alt, "mean_kn": float(-cost.mean())}


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--scenarios", default="default,shear_turbulent", help="campaign scenarios (names, tuning, all)")
    ap.add_argument("--seeds", type=int, default=2)
    ap.add_argument("--first-seed", type=int, default=0)
    ap.add_argument("--repeats", type=int, default=40, help="experiments per scenario and seed (>= 3)")
    ap.add_argument("--laps", type=int, default=4, help="laps per experiment")
    ap.add_argument("--point", type=float, nargs=3, default=(0.0, 0.6, 0.9), help="box-normalized shape point")
    a = ap.parse_args(argv)
    if a.repeats < 3:
        ap.error(f"--repeats {a.repeats}: expected at least 3")
    print(f"# {a.repeats} experiments of {a.laps} laps at box point {list(a.point)} per scenario and seed")
    print("| scenario | seed | mean kN | cost scatter kN | reported kN | ratio | lag-1 | altitude scatter m "
          "| reported m | ratio | wall s |")
    print("|---|---|---|---|---|---|---|---|---|---|---|")
    ratios = []
    for sc in select_scenarios(a.scenarios):
        for seed in range(a.first_seed, a.first_seed + a.seeds):
            t0 = time.perf_counter()
            m = measure(sc, seed, a.repeats, a.laps, a.point)
            ratios.append(m["cost_ratio"])
            print(f"| {sc.name} | {seed} | {m['mean_kn']:.1f} | {m['cost_scatter']:.2f} | {m['cost_reported']:.2f} "
                  f"| {m['cost_ratio']:.2f} | {m['lag1']:+.2f} | {m['alt_scatter']:.2f} | {m['alt_reported']:.2f} "
                  f"| {m['alt_ratio']:.2f} | {time.perf_counter() - t0:.0f} |", flush=True)
    print(f"\ncost: scatter over reported standard error {min(ratios):.2f}-{max(ratios):.2f}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
