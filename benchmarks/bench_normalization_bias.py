"""How the observer-normalized cost bends the plant's cost: normalized over raw tension on the deterministic plant.

On a plant without turbulence and noise the wind is its mean profile, so a normalization that only removed
turbulence would give the same ratio ``normalized / raw`` at every setpoint. This flies a grid of shape points
(theta_0 deg x A_phi deg x aspect) on a campaign scenario's deterministic plant, one 4-lap experiment each (the
GMA experiment spec, ``wind_source="observer"``), and prints the raw mean tension, the observer-normalized one and
their ratio. A ratio that changes across the grid is a bias of the measured cost's gradient: ``d ratio`` times
the raw tension, in kN per box width. ``--observer-shear`` gives the observer the plant's exponent instead of
the model's (knowledge no user has; it separates the exponent mismatch from the rest); ``--wind-source
observer_profile`` measures :class:`~kite_rto.rto.wind_source.ProfileObserverWind` (the exponent learned in flight).

Usage: ``python benchmarks/bench_normalization_bias.py [--scenario default] [--observer-shear 0.20] [--laps 4]
[--wind-source observer_profile]``
"""
from __future__ import annotations

import argparse
import time
from dataclasses import replace

import numpy as np

from kite_rto.campaign.scenarios import scenario
from kite_rto.flight.shape import setpoints_from_shape
from kite_rto.kite.params import KiteParams
from kite_rto.rto.experiment import ExperimentEvaluator, PlantFlight
from kite_rto.rto.settings import KiteRTOSettings

THETA_0 = (30.0, 35.0)
A_PHI = (46.0, 54.0, 62.0)
ASPECT = (0.16, 0.19, 0.22)


def main(argv=None) -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--scenario", default="default", help="campaign scenario whose deterministic plant flies")
    ap.add_argument("--observer-shear", type=float, default=None,
                    help="shear exponent the observer brings the wind to z_ref with (default: the model's)")
    ap.add_argument("--laps", type=int, default=4)
    ap.add_argument("--wind-source", default="observer", choices=("observer", "observer_profile"))
    a = ap.parse_args(argv)
    sc = scenario(a.scenario)
    model = KiteParams() if a.observer_shear is None else replace(KiteParams(), shear=a.observer_shear)
    spec = replace(KiteRTOSettings().experiment, h_min=sc.h_min, n_laps=a.laps, wind_source=a.wind_source)
    flight = PlantFlight(sc.plant.without_disturbances(), 0, spec)
    flight.evaluator = ExperimentEvaluator(spec, model_params=model)
    t0 = time.perf_counter()
    print(f"scenario {sc.name}, deterministic plant, wind source {a.wind_source}, observer shear {model.shear:.3f}, "
          f"{a.laps} laps per point")
    print("| theta_0 deg | A_phi deg | " + " | ".join(f"aspect {x}: raw kN / normalized kN / ratio" for x in ASPECT)
          + " | ratio change over the aspect range |")
    print("|---|---|" + "---|" * (len(ASPECT) + 1))
    ratios = {}
    for th in THETA_0:
        for ap_ in A_PHI:
            cells = []
            for asp in ASPECT:
                out = flight.fly(setpoints_from_shape(np.array([np.radians(th), np.radians(ap_), asp])))
                ratios[th, ap_, asp] = r = out.tension_kn / out.mean_tension_kn
                cells.append(f"{out.mean_tension_kn:.1f} / {out.tension_kn:.1f} / {r:.4f}")
            change = 100.0 * (ratios[th, ap_, ASPECT[-1]] / ratios[th, ap_, ASPECT[0]] - 1.0)
            print(f"| {th:.0f} | {ap_:.0f} | " + " | ".join(cells) + f" | {change:+.2f} % |")
    learned = getattr(flight.evaluator.wind, "shear", None)
    if a.wind_source == "observer_profile":
        print(f"learned shear exponent at the end: {learned:.4f} (plant {sc.plant.params.shear:.3f})")
    v = np.array(list(ratios.values()))
    print(f"ratio over the grid: {v.min():.4f} - {v.max():.4f} ({100 * (v.max() / v.min() - 1):.2f} %); "
          f"{time.perf_counter() - t0:.0f} s wall")


if __name__ == "__main__":
    main()
