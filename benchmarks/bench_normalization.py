"""Measurement noise of the experiment cost, raw and normalized by each wind measurement (prints a table).

Per seed (turbulence and noise on, default plant; the 3-D field wind by default), one kite flies alternately at
two setpoints that differ by ``--dA`` deg in A_phi, each held for one experiment (10 s settle, 1 settle lap,
4 laps). From the same laps: the 4-lap experiment mean of the lap tension, raw and normalized as a tension
coefficient scaled to the nominal wind, ``mean T / mean(w^2) * w_nominal^2``, with ``w`` (at z_ref) taken from

* (a) ``anemometer``: the ground anemometer at z_ref, as the optimizer does today (``LapStats``);
* (b) ``anemo+lag``: the anemometer shifted by the transport lag ``mean kite x / U(mean kite z)``, U from the
  anemometer's mean and the model's shear (per seed, over the whole flight);
* (c) ``observer``: :class:`~kite_rto.kite.wind_estimate.WindObserver`, the wind at the kite from its measured
  motion (glide-ratio free), brought to z_ref with the model's shear;
* (c') ``tension``: the wind that makes the model's tension equal the measured one
  (:func:`~kite_rto.kite.wind_estimate.tension_wind`, model E), for comparison;

and the forward difference dT/dA_phi of consecutive experiments. Std over all seeds and pairs; the
deterministic plant gives the true values (its wind is the mean profile, so the truth is the same for every
normalization).

Usage: ``python benchmarks/bench_normalization.py [--seeds 4] [--pairs 3] [--dA 4] [--wind-model field]
[--anemometer-correlation 0.95]``
"""
from __future__ import annotations

import argparse
import math
import time
from dataclasses import replace

import numpy as np

from kite_rto.kite.model import shared_model
from kite_rto.kite.params import KiteParams
from kite_rto.kite.plant import WIND_MODELS, PlantConfig
from kite_rto.kite.wind_estimate import WindObserver, WindObserverSettings, tension_wind
from kite_rto.rto.experiment import ExperimentSpec, PlantFlight
from kite_rto.rto.oracle import plant_performance

W_NOM = 8.0
METHODS = ("raw", "anemometer", "anemo+lag", "observer", "tension")


class RecordingPlant:
    """A plant that records, per sample, t, tension, anemometer, kite x and z, and the two kite wind estimates."""

    def __init__(self, plant, model_params: KiteParams, observer: WindObserverSettings):
        self.plant, self.params, self.dt = plant, model_params, plant.dt
        self.observer = WindObserver(model_params, plant.dt, observer)
        self.rows: list = []

    @property
    def t(self) -> float:
        return self.plant.t

    def measure(self):
        return self.plant.measure()

    def step(self, delta: float):
        m = self.plant.step(delta)
        observed = self.observer.observe(m)
        z = m.position[2]
        w_tension = tension_wind(shared_model(), self.params, m.theta, m.phi, m.tension)
        ref = (self.params.z_ref / max(z, 0.5)) ** self.params.shear      # wind at the kite -> at z_ref
        self.rows.append((m.t, m.tension, m.wind_ref, m.position[0], z, observed, w_tension * ref))
        return m


def lap_values(rec: np.ndarray, laps, lag: float) -> dict:
    """Per lap: raw mean tension and tension coefficients x w_nominal^2 (kN) for every method."""
    t, tension, anemo = rec[:, 0], rec[:, 1], rec[:, 2]
    out = {k: [] for k in METHODS}
    for lap in laps:
        sel = (t >= lap.t_start) & (t < lap.t_end)
        mean_t = np.mean(tension[sel])
        shifted = np.interp(t[sel] - lag, t, anemo)
        wind_sq = {"anemo+lag": np.mean(shifted ** 2), "observer": np.mean(rec[sel, 5] ** 2),
                   "tension": np.mean(rec[sel, 6] ** 2)}
        out["raw"].append(lap.mean_tension / 1e3)
        out["anemometer"].append(lap.tension_coefficient * W_NOM ** 2 / 1e3)
        for k, v in wind_sq.items():
            out[k].append(mean_t / v * W_NOM ** 2 / 1e3)
    return {k: np.array(v) for k, v in out.items()}


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--seeds", type=int, default=4)
    ap.add_argument("--pairs", type=int, default=3)
    ap.add_argument("--dA", type=float, default=4.0, help="A_phi difference, deg")
    ap.add_argument("--laps", type=int, default=4)
    ap.add_argument("--wind-model", choices=WIND_MODELS, default="field")
    ap.add_argument("--observer-tau", type=float, default=WindObserverSettings().time_constant,
                    help="time constant of the wind observer, s")
    ap.add_argument("--anemometer-correlation", type=float, default=None,
                    help="uniform wind only: anemometer gust correlation (default: PlantConfig's, 1)")
    args = ap.parse_args(argv)
    config = replace(PlantConfig(), wind_model=args.wind_model)
    if args.anemometer_correlation is not None:
        config = replace(config, turbulence=replace(config.turbulence,
                                                    anemometer_correlation=args.anemometer_correlation))
    model_params = KiteParams()
    ca = np.radians([30.0, 44.0, 7.0])
    cb = ca + np.radians([0.0, args.dA, 0.0])
    spec = ExperimentSpec(n_laps=args.laps, normalize=False)
    t0 = time.perf_counter()
    lap = {k: [] for k in METHODS}
    exp = {k: [] for k in METHODS}
    grad = {k: [] for k in METHODS}
    lags = []
    for seed in range(args.seeds):
        fl = PlantFlight(config, seed, spec, c0=ca)
        fl.plant = recorder = RecordingPlant(fl.plant, model_params,
                                             WindObserverSettings(time_constant=args.observer_tau))
        outcomes = [(fl.fly(ca), fl.fly(cb)) for _ in range(args.pairs)]
        rec = np.array(recorder.rows)
        u_kite = np.mean(rec[:, 2]) * (np.mean(rec[:, 4]) / model_params.z_ref) ** model_params.shear
        lag = float(np.mean(rec[:, 3]) / u_kite)
        lags.append(lag)
        for out_a, out_b in outcomes:
            va, vb = lap_values(rec, out_a.laps, lag), lap_values(rec, out_b.laps, lag)
            for k in METHODS:
                lap[k] += list(va[k] - np.mean(va[k]))           # centred per experiment
                exp[k].append(np.mean(va[k]))
                grad[k].append((np.mean(vb[k]) - np.mean(va[k])) / args.dA)
    ta, _ = plant_performance(None, ca)
    tb, _ = plant_performance(None, cb)
    true_grad = (tb - ta) / args.dA
    wind = (f"3-D field (IEC class {config.wind_field.turbulence_class})" if args.wind_model == "field" else
            f"uniform gust, anemometer correlation {config.turbulence.anemometer_correlation:g}")
    print(f"bench_normalization: {args.seeds} seeds x {args.pairs} pairs, c_a = (30, 44, 7) deg, "
          f"dA_phi = {args.dA:g} deg, {args.laps} laps/experiment, wind: {wind}; transport lag "
          f"{np.mean(lags):.1f} s; observer tau {args.observer_tau:g} s; {time.perf_counter() - t0:.0f} s wall")
    print(f"deterministic plant: T(c_a) = {ta:.1f} kN, forward-difference dT/dA_phi = {true_grad:.2f} kN/deg")
    head = f"{'quantity':40} " + " ".join(f"{k:>10}" for k in METHODS)
    print(head)
    print("-" * len(head))
    rows = [("std of 4-lap experiment mean, kN", [np.std(exp[k], ddof=1) for k in METHODS]),
            ("bias of experiment mean vs determ., kN", [np.mean(exp[k]) - ta for k in METHODS]),
            ("std of dT/dA_phi, kN/deg", [np.std(grad[k], ddof=1) for k in METHODS]),
            ("mean of dT/dA_phi, kN/deg", [np.mean(grad[k]) for k in METHODS]),
            ("within-experiment lap scatter, kN",
             [np.std(lap[k]) * math.sqrt(args.laps / (args.laps - 1)) for k in METHODS])]
    for name, vals in rows:
        print(f"{name:40} " + " ".join(f"{v:10.2f}" for v in vals))
    print(f"{'ratio of std to raw (experiment mean)':40} " + " ".join(
        f"{np.std(exp[k], ddof=1) / np.std(exp['raw'], ddof=1):10.2f}" for k in METHODS))
    print(f"{'ratio of std to raw (gradient)':40} " + " ".join(
        f"{np.std(grad[k], ddof=1) / np.std(grad['raw'], ddof=1):10.2f}" for k in METHODS))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
