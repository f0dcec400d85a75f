"""The figure of a GMA run's report (``report.png``): paths, tension per lap, setpoints, judged performance."""
from __future__ import annotations

import math
from pathlib import Path

import numpy as np

from ..flight.path import FigureEightPath, Setpoints
from ..rto.judge import REACH_PERCENT
from .plots import nw_coordinates

__all__ = ["report_figure"]


def _legend(ax, **kw) -> None:
    if ax.get_legend_handles_labels()[0]:
        ax.legend(**kw)


def report_figure(history, rows, oracle, out: Path, samples=None, laps=None, h_min: float | None = None,
                  flight=None) -> None:
    """Save ``out/report.png``: flown paths and references per iterate, tension per lap against the oracle,
    setpoints per iteration and the judged (or measured) performance per iteration.

    ``rows`` are :func:`~kite_rto.tools.rto_report.judge_iterates` rows, ``oracle`` an ``OracleResult`` or None,
    ``samples`` = (t, theta, phi) arrays (s, rad) of the flight or None, ``laps`` dicts of the /kite/laps fields,
    ``h_min`` the run's altitude floor (m; drawn when the rows are judged), ``flight`` the run's
    :class:`~kite_rto.rto.flight_yield.FlightYield` or None (drawn as the judged tension of the setpoints flown).
    """
    # Not on import: choosing the Agg backend is a global change that only drawing a file should make.
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, axes = plt.subplots(2, 2, figsize=(13, 8))
    ax = axes[0, 0]
    iterates = [np.radians(r["c_deg"]) for r in rows]
    theta_bar = float(np.mean([c[0] for c in iterates]))
    colors = plt.cm.viridis(np.linspace(0, 1, max(len(iterates), 2)))
    s = np.linspace(0, 2 * math.pi, 361)
    nominal = {q.iteration: (q, res) for q, res in history.experiments if q.purpose == "nominal"}
    for k, (c, col) in enumerate(zip(iterates, colors)):
        th, ph = FigureEightPath(Setpoints.from_array(c)).point(s)
        w, n = nw_coordinates(th, ph, 400.0, theta_bar)
        ax.plot(w, n, "--", color=col, lw=0.8)
        t1 = nominal[k][1].extra.get("t_end") if k in nominal else None
        if samples is not None and t1 is not None:
            t, theta, phi = samples
            sel = (t >= t1 - 20.0) & (t <= t1)
            if sel.any():
                w, n = nw_coordinates(theta[sel], phi[sel], 400.0, theta_bar)
                ax.plot(w, n, color=col, lw=1.0, label=f"k = {k}")
    ax.set_title("flown paths (solid, last 20 s of each nominal experiment) and references (dashed)")
    ax.set_xlabel("W (m)")
    ax.set_ylabel("N (m)")
    ax.set_aspect("equal")
    _legend(ax, fontsize=7, ncol=2)
    ax = axes[0, 1]
    if laps:
        ax.plot([lap["t_end"] for lap in laps], [lap["mean_tension"] / 1e3 for lap in laps], ".", ms=4,
                label="lap mean tension (measured, turbulent)")
        ax.plot([lap["t_end"] for lap in laps], [lap["tension_coefficient"] * 64.0 / 1e3 for lap in laps], ".",
                ms=4, label="normalized to w_ref = 8 m/s")
    if oracle is not None:
        ax.axhline(oracle.tension_kn, color="k", lw=1, label=f"oracle {oracle.tension_kn:.0f} kN (deterministic)")
    if flight is not None:
        t = [v for r in flight.segments for v in (r.segment.t_start, r.segment.t_end)]
        kn = [v for r in flight.segments for v in 2 * (r.energy / max(r.segment.duration, 1e-9),)]
        ax.plot(t, kn, color="C3", lw=1, label="judged tension of the setpoints flown (deterministic)")
    ax.set_xlabel("simulated time (s)")
    ax.set_ylabel("kN")
    ax.set_title("mean tension per lap" + ("" if flight is None else
                                           f"; yield of the whole flight {flight.percent:.2f} % of the oracle's"))
    _legend(ax, fontsize=7)
    ax = axes[1, 0]
    c_deg = np.array([r["c_deg"] for r in rows])
    for i, name in enumerate(("theta_0", "A_phi", "A_theta")):
        ax.plot(c_deg[:, i], "o-", label=name)
    for i, v in enumerate(oracle.c_deg if oracle is not None else ()):
        ax.axhline(v, color=f"C{i}", ls=":", lw=1)
    ax.set_xlabel("iteration k")
    ax.set_ylabel("deg")
    ax.set_title("setpoints (dotted: oracle)" if oracle is not None else "setpoints")
    ax.legend(fontsize=7)
    ax = axes[1, 1]
    if oracle is not None:
        ax.plot([r["percent_of_oracle"] for r in rows], "o-", label="judged tension, % of oracle")
        ax.axhline(REACH_PERCENT, color="k", ls=":", lw=1)
        ax2 = ax.twinx()
        ax2.plot([r["judged_min_altitude_m"] for r in rows], "s--", color="C3", label="judged min altitude (m)")
        if h_min is not None:
            ax2.axhline(h_min, color="C3", ls=":", lw=1)
        ax.set_title("judged on the deterministic plant: tension (left), min altitude (right)")
        ax2.legend(fontsize=7, loc="upper right")
    else:
        measured = [(r["k"], r["measured_tension_kN"]) for r in rows if r["measured_tension_kN"] is not None]
        if measured:
            ax.plot(*zip(*measured), "o-", label="measured tension at c_k (kN, normalized)")
        ax.set_title("measured per iteration (not judged on the deterministic plant)")
    ax.set_xlabel("iteration k")
    _legend(ax, fontsize=7, loc="lower right")
    fig.tight_layout()
    fig.savefig(out / "report.png", dpi=100)
    plt.close(fig)
