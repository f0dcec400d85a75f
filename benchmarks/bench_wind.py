"""Realism of the 3-D wind field (issue 13 item 2): what the kite and the anemometer see (prints tables).

Per seed, the default kite flies the default figure-eight under path control in the default field
(``PlantConfig(wind_model="field")``, IEC 61400-1 class B, Mann box) for ``--duration`` s (the first 60 s dropped).
From the samples:

* turbulence intensity at the kite: std over mean of the wind at the kite, the turbulence alone
  (``w - U(z)``, the mean profile at the kite's height removed) and in total (the lap's sweep through the
  sheared profile included), and at the anemometer;
* correlation of the anemometer with the kite's reference wind (the wind at the kite brought to z_ref through
  the profile: what a tension normalization needs) at zero lag and at the best lag in [0, 90] s, with that lag
  and the advection time ``mean kite x / U_hub``.

Coherence of the field's u component between two points separated across the wind (laterally, y; vertically,
z), estimated from the whole box (the box is periodic along the wind: one periodogram per line, cross-spectra
averaged over all line pairs of that separation between 100 and 300 m up and over a +-20 % frequency band; the
co-coherence ``Re S_xy / sqrt(S_xx S_yy)``, which is the coherence when the phase is zero, as in both models),
against the Mann model's own coherence (hipersim's spectral-tensor integral, the co-coherence, which may be
negative) and the IEC 61400-1 exponential coherence ``exp(-12 sqrt((f r / V_hub)^2 + (0.12 r / L_c)^2))``,
L_c = 340.2 m. Tolerances: |field - Mann| <= ``MODEL_TOLERANCE`` (the boxes realize their model) and
|field - IEC| <= ``COHERENCE_TOLERANCE`` at every listed frequency. The Mann model with IEC annex C parameters
meets the IEC exponential coherence for vertical separations; across the wind (y) its coherence is lower than the
exponential model's at low frequency and oscillates around zero higher up (a property of the model, shown by the
Mann column), so those rows do not meet the IEC tolerance; the benchmark says so rather than hiding it.

Usage: ``python benchmarks/bench_wind.py [--seeds 4] [--duration 1200]``
"""
from __future__ import annotations

import argparse
import time
from dataclasses import replace

import numpy as np

from kite_rto.flight.closed_loop import make_closed_loop
from kite_rto.flight.path import DEFAULT_SETPOINTS
from kite_rto.kite.plant import PlantConfig
from kite_rto.kite.wind_field import MannBox, iec_coherence

FREQUENCIES = (0.005, 0.01, 0.02, 0.05, 0.1)
SEPARATIONS = (("y", 32.0), ("y", 64.0), ("y", 144.0), ("z", 40.0), ("z", 100.0))
COHERENCE_TOLERANCE = 0.15
MODEL_TOLERANCE = 0.15
"""At 0.005 Hz the +-20 % band holds about two periodogram bins of the 18.7 min box: with four boxes the estimate
scatters by ~0.1; the higher frequencies agree to ~0.05."""
MAX_LAG = 90.0


def fly(config: PlantConfig, seed: int, duration: float, skip: float = 60.0) -> dict:
    """Closed-loop flight in the field: per-sample anemometer, kite reference wind and kite position."""
    plant, controller = make_closed_loop(DEFAULT_SETPOINTS, config, seed=seed)
    m = plant.measure()
    rows = []
    for _ in range(int(round(duration / plant.dt))):
        m = plant.step(controller.command(m))
        rows.append((m.t, m.wind_ref, plant.kite_wind, *m.position))
    a = np.array(rows)
    a = a[a[:, 0] >= skip]
    return {"t": a[:, 0], "anemometer": a[:, 1], "kite_ref": a[:, 2], "x": a[:, 3], "z": a[:, 5],
            "U_hub": plant.wind.mean_speed, "dt": plant.dt, "crashes": m.crashes}


def lagged_correlation(a: np.ndarray, b: np.ndarray, max_lag_samples: int) -> np.ndarray:
    """corr(a[t - L], b[t]) for L = 0 .. max_lag_samples (a leads b by L samples)."""
    n = len(a)
    return np.array([np.corrcoef(a[:n - k], b[k:])[0, 1] for k in range(max_lag_samples + 1)])


def box_coherence(box: MannBox, U_hub: float, axis: str, separation: float, freqs) -> np.ndarray:
    """Co-coherence Re(S_xy) / sqrt(S_xx S_yy) of u between points ``separation`` m apart along ``axis`` (y or z)."""
    s = box.settings
    u = box.u()
    dx, dy, dz = s.spacing
    step = int(round(separation / (dy if axis == "y" else dz)))
    k_lo, k_hi = int(np.ceil(100.0 / dz)), min(int(300.0 / dz), s.points[2] - 1)
    spec = np.fft.rfft(u, axis=0)                     # periodic along x: exact periodogram, no window
    f = np.fft.rfftfreq(s.points[0], d=dx / U_hub)
    if axis == "y":
        a, b = spec[:, :-step, k_lo:k_hi + 1], spec[:, step:, k_lo:k_hi + 1]
    else:
        a, b = spec[:, :, k_lo:k_hi + 1 - step], spec[:, :, k_lo + step:k_hi + 1]
    sxy = (a * np.conj(b)).reshape(len(f), -1).sum(axis=1)
    sxx = (np.abs(a) ** 2).reshape(len(f), -1).sum(axis=1)
    syy = (np.abs(b) ** 2).reshape(len(f), -1).sum(axis=1)
    out = []
    for fc in freqs:
        band = (f >= 0.8 * fc) & (f <= 1.2 * fc)
        out.append(sxy[band].sum().real / np.sqrt(sxx[band].sum() * syy[band].sum()))
    return np.array(out)


def mann_coherence(settings, U_hub: float, axis: str, separation: float, freqs) -> np.ndarray:
    """The Mann model's co-coherence of u at ``separation`` m along ``axis`` (hipersim's tensor integral)."""
    from hipersim.mann_turbulence import MannTurbulenceInput
    model = MannTurbulenceInput(1.0, settings.length_scale, settings.gamma, np.array(settings.points),
                                settings.spacing)
    dy, dz = (separation, 0.0) if axis == "y" else (0.0, separation)
    return model.coherence_integrated(dy, dz, k1=2 * np.pi * np.asarray(freqs) / U_hub)[1]


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--seeds", type=int, default=4)
    ap.add_argument("--duration", type=float, default=1200.0, help="flight per seed, s")
    args = ap.parse_args(argv)
    config = replace(PlantConfig(), wind_model="field")
    fs = config.wind_field
    t0 = time.perf_counter()
    print(f"bench_wind: {args.seeds} seeds x {args.duration:g} s, IEC 61400-1 class {fs.turbulence_class}, hub "
          f"{fs.hub_height:g} m, U_hub {fs.hub_wind(config.params):.2f} m/s, "
          f"sigma_1 {fs.sigma(config.params):.2f} m/s, "
          f"Mann L {fs.length_scale:g} m, Gamma {fs.gamma:g}, box {fs.points} x {fs.spacing} m")
    head = (f"{'seed':>4} {'TI kite turb':>12} {'TI kite total':>13} {'TI anemo':>9} {'corr lag 0':>10} "
            f"{'best corr':>9} {'best lag s':>10} {'x/U_hub s':>9} {'alpha-eps':>9} {'crashes':>7}")
    print(head)
    print("-" * len(head))
    U_hub = fs.hub_wind(config.params)
    rows, coh = [], {sep: [] for sep in SEPARATIONS}
    for seed in range(args.seeds):
        r = fly(config, seed, args.duration)
        p = config.params
        profile = (r["z"] / p.z_ref) ** p.shear
        w_kite = r["kite_ref"] * profile
        turb = w_kite - p.w_ref * profile
        lags = lagged_correlation(r["anemometer"], r["kite_ref"], int(MAX_LAG / r["dt"]))
        best = int(np.argmax(lags))
        box = MannBox(fs, fs.sigma(p), seed)
        row = (np.std(turb) / np.mean(w_kite), np.std(w_kite) / np.mean(w_kite),
               np.std(r["anemometer"]) / np.mean(r["anemometer"]), lags[0], lags[best], best * r["dt"],
               np.mean(r["x"]) / r["U_hub"], box.alpha_epsilon, r["crashes"])
        rows.append(row)
        print(f"{seed:4d} {row[0]:12.3f} {row[1]:13.3f} {row[2]:9.3f} {row[3]:10.3f} {row[4]:9.3f} {row[5]:10.1f} "
              f"{row[6]:9.1f} {row[7]:9.4f} {row[8]:7d}")
        for sep in SEPARATIONS:
            coh[sep].append(box_coherence(box, U_hub, sep[0], sep[1], FREQUENCIES))
    m = np.mean(np.array(rows, dtype=float), axis=0)
    print(f"{'mean':>4} {m[0]:12.3f} {m[1]:13.3f} {m[2]:9.3f} {m[3]:10.3f} {m[4]:9.3f} {m[5]:10.1f} {m[6]:9.1f} "
          f"{m[7]:9.4f}")
    print(f"\ncoherence of u: field (mean over {args.seeds} boxes) / Mann model / IEC exponential; tolerances "
          f"field-Mann +-{MODEL_TOLERANCE:g}, field-IEC +-{COHERENCE_TOLERANCE:g}")
    head = f"{'separation':>10} " + " ".join(f"{f'{f:g} Hz':>18}" for f in FREQUENCIES) + "  Mann  IEC"
    print(head)
    print("-" * len(head))
    model_ok = iec_ok = True
    for (axis, r), vals in coh.items():
        field = np.mean(vals, axis=0)
        mann = mann_coherence(fs, U_hub, axis, r, FREQUENCIES)
        iec = iec_coherence(np.array(FREQUENCIES), r, U_hub)
        ok_m = bool(np.all(np.abs(field - mann) <= MODEL_TOLERANCE))
        ok_i = bool(np.all(np.abs(field - iec) <= COHERENCE_TOLERANCE))
        model_ok &= ok_m
        iec_ok &= ok_i
        cells = " ".join(f"{fv:5.2f}/{mv:5.2f}/{iv:4.2f} " for fv, mv, iv in zip(field, mann, iec))
        print(f"{f'{axis} {r:g} m':>10} {cells} {'yes' if ok_m else 'NO':>5} {'yes' if ok_i else 'NO':>4}")
    print(f"field realizes the Mann model: {'yes' if model_ok else 'NO'}; field within IEC tolerance on every row: "
          f"{'yes' if iec_ok else 'NO'}; {time.perf_counter() - t0:.0f} s wall")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
