"""The campaign at a glance (:func:`plot_campaign`): per scenario, every run's judged % of the oracle against the
flight time at which each iterate became available (matplotlib, file backend)."""
from __future__ import annotations

import math

from ..rto.judge import ALTITUDE_TOLERANCE_M, REACH_PERCENT, altitude_floor

__all__ = ["plot_campaign"]

_COLORS = {"model-only": "0.55", "nelder-mead": "tab:orange", "fd-ascent": "tab:green", "bayes-opt": "tab:purple"}


def plot_campaign(filename, rows) -> None:
    """Save one panel per scenario of ``rows`` (:class:`~kite_rto.campaign.results.RunResult`): step lines of
    judged % of the oracle over flight time (s) per run, coloured by method, the target (99 %) dashed, iterates
    judged below the altitude floor (h_min - 2 m; :mod:`kite_rto.rto.judge`) or crashed marked with a red x."""
    # Not on import: choosing the Agg backend is a global change that only drawing a file should make.
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    scenarios = list(dict.fromkeys(r.scenario for r in rows))
    methods = list(dict.fromkeys(r.method for r in rows))
    gma_colors = iter(["tab:blue", "tab:red", "tab:cyan", "tab:olive", "tab:brown", "tab:pink"])
    colors = {m: _COLORS.get(m) or next(gma_colors, "k") for m in methods}
    ncols = min(4, len(scenarios))
    nrows = math.ceil(len(scenarios) / ncols)
    fig, axes = plt.subplots(nrows, ncols, figsize=(max(4.2 * ncols, 8.0), 3.2 * nrows), squeeze=False, sharey=True)
    low = min([p for r in rows for p in r.percent] + [REACH_PERCENT])
    for ax, sc in zip(axes.flat, scenarios):
        for r in (r for r in rows if r.scenario == sc):
            t = list(r.times_s) + [max(r.flight_time_s, r.times_s[-1])]
            p = list(r.percent) + [r.percent[-1]]
            ax.step(t, p, where="post", color=colors[r.method], lw=1.0, alpha=0.8)
            low_i = [i for i, z in enumerate(r.altitude) if z is None or z < altitude_floor(r.h_min)]
            ax.plot([r.times_s[i] for i in low_i], [r.percent[i] for i in low_i], "x", color="red", ms=5)
        tuning = next(r.tuning for r in rows if r.scenario == sc)
        ax.axhline(REACH_PERCENT, color="k", ls="--", lw=0.8)
        ax.set_title(f"{sc}{' (tuning)' if tuning else ''}", fontsize=9)
        ax.set_ylim(max(low - 1.0, 50.0), 101.0)
        ax.grid(alpha=0.3)
    for ax in axes.flat[len(scenarios):]:
        ax.set_visible(False)
    for ax in axes[-1]:
        ax.set_xlabel("flight time s")
    for ax in axes[:, 0]:
        ax.set_ylabel("% of oracle (judged)")
    handles = [plt.Line2D([], [], color=colors[m], label=m) for m in methods]
    handles.append(plt.Line2D([], [], ls="", marker="x", color="red",
                              label=f"below h_min - {ALTITUDE_TOLERANCE_M:g} m"))
    fig.legend(handles=handles, loc="lower center", ncol=len(handles), fontsize=8, frameon=False)
    fig.tight_layout(rect=(0, 0.05, 1, 1))
    fig.savefig(filename, dpi=110)
    plt.close(fig)
