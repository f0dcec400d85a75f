"""Measurement noise and scale of the experiment cost, raw and normalized by each wind source (prints a table).

Per seed (turbulence and noise on, default plant; the 3-D field wind by default), one kite flies alternately at
two setpoints ``c_a`` and ``c_b``, each held for one experiment (10 s settle, 1 settle lap, 4 laps). From the
same laps: the 4-lap experiment mean of the lap tension, raw and normalized as a tension coefficient scaled to a
reference wind, ``mean T / mean(w^2) * w_scale^2``, with ``w`` (at z_ref) and ``w_scale`` from each wind source
of :mod:`kite_rto.rto.wind_source`, run online exactly as the experiment cost runs them:

* ``anemometer``: the ground anemometer at z_ref (``LapStats``, what ``wind_source="anemometer"`` averages);
* ``anemo_lag``: the anemometer delayed by the transport lag (``"anemometer_lagged"``);
* ``obs_nominal``: the wind observer at the kite, brought to z_ref with the model's shear, scaled to the nominal
  wind (``ObserverWind(calibrate=False)``);
* ``observer``: the same scaled to the nominal wind times the run's calibration mean observer / mean
  anemometer (``"observer"``);
* ``tension``: the wind that makes the model's tension equal the measured one
  (:func:`~kite_rto.kite.wind_estimate.tension_wind`, model E), for comparison;

and the difference of consecutive experiments T(c_b) - T(c_a). Std over all seeds and pairs; the deterministic
plant gives the true values (its wind is the mean profile, so the truth is the same for every normalization).
``scale`` is the mean measured difference over the true one: the factor by which the normalized cost stretches
the plant's cost differences (1 = unbiased gradient scale), with its standard error.

Default ``c_a = (30, 44, 7)`` deg and ``c_b`` = ``c_a`` + ``--dA`` deg in A_phi (a gradient step); ``--cb`` gives
another ``c_b`` (e.g. the model-only optimum, ~150 kN below: a large difference that measures the scale).

Usage: ``python benchmarks/bench_normalization.py [--seeds 4] [--first-seed 0] [--pairs 3] [--dA 4]
[--cb 22 15 4] [--wind-model field] [--anemometer-correlation 0.95]``
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
from kite_rto.kite.wind_estimate import WindObserverSettings, tension_wind
from kite_rto.rto.experiment import ExperimentSpec, PlantFlight
from kite_rto.rto.oracle import plant_performance
from kite_rto.rto.wind_source import Anemometer, LaggedAnemometer, ObserverWind

W_NOM = 8.0
METHODS = ("raw", "anemometer", "anemo_lag", "obs_nominal", "obs_cal_an", "obs_run", "tension")


class RecordingPlant:
    """A plant that feeds every measurement to the wind sources and records, per sample, t, tension, and for
    every method the wind at z_ref and the scale wind."""

    def __init__(self, plant, model_params: KiteParams, observer: WindObserverSettings):
        self.plant, self.params, self.dt = plant, model_params, plant.dt
        self.sources = {"anemometer": Anemometer(W_NOM), "anemo_lag": LaggedAnemometer(W_NOM, model_params),
                        "obs_nominal": ObserverWind(W_NOM, model_params, observer, "none"),
                        "obs_cal_an": ObserverWind(W_NOM, model_params, observer, "anemometer"),
                        "obs_run": ObserverWind(W_NOM, model_params, observer, "observer")}
        self.rows: list = []

    @property
    def t(self) -> float:
        return self.plant.t

    def measure(self):
        return self.plant.measure()

    def step(self, delta: float):
        m = self.plant.step(delta)
        row = [m.t, m.tension, m.position[0]]
        for src in self.sources.values():
            row += [src.update(m), src.scale()]
        z = m.position[2]
        w_tension = tension_wind(shared_model(), self.params, m.theta, m.phi, m.tension)
        ref = (self.params.z_ref / max(z, 0.5)) ** self.params.shear      # wind at the kite -> at z_ref
        row += [w_tension * ref, W_NOM]
        self.rows.append(row)
        return m


def lap_values(rec: np.ndarray, laps) -> dict:
    """Per lap: raw mean tension and tension coefficients x w_scale^2 (kN) for every method (the anemometer's
    from ``LapStats``, the others from the samples of the lap, scaled by the scale wind at the lap's end)."""
    t, tension = rec[:, 0], rec[:, 1]
    out = {k: [] for k in METHODS}
    for lap in laps:
        sel = (t >= lap.t_start) & (t < lap.t_end)
        last = np.flatnonzero(sel)[-1]
        out["raw"].append(lap.mean_tension / 1e3)
        out["anemometer"].append(lap.tension_coefficient * W_NOM ** 2 / 1e3)
        for j, k in enumerate(METHODS[2:]):
            w, scale = rec[sel, 3 + 2 * (j + 1)], rec[last, 4 + 2 * (j + 1)]
            out[k].append(np.mean(tension[sel]) / np.mean(w ** 2) * scale ** 2 / 1e3)
    return {k: np.array(v) for k, v in out.items()}


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--seeds", type=int, default=4)
    ap.add_argument("--first-seed", type=int, default=0, help="seeds first-seed .. first-seed + seeds - 1")
    ap.add_argument("--pairs", type=int, default=3)
    ap.add_argument("--dA", type=float, default=4.0, help="A_phi difference of c_b from c_a, deg")
    ap.add_argument("--cb", type=float, nargs=3, default=None, metavar=("THETA_0", "A_PHI", "A_THETA"),
                    help="c_b in deg (instead of c_a + dA in A_phi)")
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
    cb = np.radians(args.cb) if args.cb else ca + np.radians([0.0, args.dA, 0.0])
    spec = ExperimentSpec(n_laps=args.laps, wind_source="anemometer")
    t0 = time.perf_counter()
    lap = {k: [] for k in METHODS}
    exp = {k: [] for k in METHODS}
    diff = {k: [] for k in METHODS}
    lags = []
    seeds = range(args.first_seed, args.first_seed + args.seeds)
    for seed in seeds:
        fl = PlantFlight(config, seed, spec, c0=ca)
        fl.plant = recorder = RecordingPlant(fl.plant, model_params,
                                             WindObserverSettings(time_constant=args.observer_tau))
        outcomes = [(fl.fly(ca), fl.fly(cb)) for _ in range(args.pairs)]
        rec = np.array(recorder.rows)
        lags.append(recorder.sources["anemo_lag"].lag)
        for out_a, out_b in outcomes:
            va, vb = lap_values(rec, out_a.laps), lap_values(rec, out_b.laps)
            for k in METHODS:
                lap[k] += list(va[k] - np.mean(va[k]))           # centred per experiment
                exp[k].append(np.mean(va[k]))
                diff[k].append(np.mean(vb[k]) - np.mean(va[k]))
    ta, _ = plant_performance(None, ca)
    tb, _ = plant_performance(None, cb)
    true_diff = tb - ta
    wind = (f"3-D field (IEC class {config.wind_field.turbulence_class})" if args.wind_model == "field" else
            f"uniform gust, anemometer correlation {config.turbulence.anemometer_correlation:g}")
    deg = lambda c: "(" + ", ".join(f"{v:g}" for v in np.round(np.degrees(c), 2)) + ")"  # noqa: E731
    print(f"bench_normalization: seeds {seeds.start}..{seeds.stop - 1} x {args.pairs} pairs, c_a = {deg(ca)} deg, "
          f"c_b = {deg(cb)} deg, {args.laps} laps/experiment, wind: {wind}; transport lag at the end "
          f"{np.mean(lags):.1f} s (mean over seeds); observer tau {args.observer_tau:g} s; "
          f"{time.perf_counter() - t0:.0f} s wall")
    print(f"deterministic plant: T(c_a) = {ta:.1f} kN, T(c_b) - T(c_a) = {true_diff:.2f} kN")
    head = f"{'quantity':40} " + " ".join(f"{k:>11}" for k in METHODS)
    print(head)
    print("-" * len(head))
    n = len(diff["raw"])
    rows = [("std of 4-lap experiment mean, kN", [np.std(exp[k], ddof=1) for k in METHODS]),
            ("bias of experiment mean vs determ., kN", [np.mean(exp[k]) - ta for k in METHODS]),
            ("std of T(c_b) - T(c_a), kN", [np.std(diff[k], ddof=1) for k in METHODS]),
            ("mean of T(c_b) - T(c_a), kN", [np.mean(diff[k]) for k in METHODS]),
            ("scale = mean difference / true", [np.mean(diff[k]) / true_diff for k in METHODS]),
            ("  its standard error", [np.std(diff[k], ddof=1) / math.sqrt(n) / abs(true_diff) for k in METHODS]),
            ("within-experiment lap scatter, kN",
             [np.std(lap[k]) * math.sqrt(args.laps / (args.laps - 1)) for k in METHODS])]
    for name, vals in rows:
        print(f"{name:40} " + " ".join(f"{v:11.2f}" for v in vals))
    print(f"{'ratio of std to raw (experiment mean)':40} " + " ".join(
        f"{np.std(exp[k], ddof=1) / np.std(exp['raw'], ddof=1):11.2f}" for k in METHODS))
    print(f"{'ratio of std to raw (difference)':40} " + " ".join(
        f"{np.std(diff[k], ddof=1) / np.std(diff['raw'], ddof=1):11.2f}" for k in METHODS))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
