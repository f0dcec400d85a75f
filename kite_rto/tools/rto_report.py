"""Report of a GMA run on the kite, from the optimizer's SQLite history (and, if given, the flown samples).

Every iterate c_k is judged the way the oracle is judged: re-flown on the deterministic plant (turbulence and
noise off, long averaging), so that noise cannot flatter the result. Command line:
``python -m kite_rto.tools.rto_report --db runs/demo/rto.sqlite --out runs/demo``.
"""
from __future__ import annotations

import argparse
import json
import math
import sys
from pathlib import Path

import numpy as np

from ..core.oracle import find_oracle, plant_performance
from ..core.path import FigureEightPath, Setpoints, ShapeBox, setpoints_from_shape
from ..core.plant import PlantConfig
from ..gma import HistoryStore

__all__ = ["judge_iterates", "write_report", "main"]


def _deg(c) -> str:
    return "/".join(f"{math.degrees(x):.2f}" for x in c)


def judge_iterates(history, config: PlantConfig, oracle, h_min: float = 100.0) -> list[dict]:
    """One row per iterate c_0 .. c_K (GMA's shape coordinates, judged as setpoints): measured values (if any)
    and the deterministic-plant judgement."""
    iterates = [setpoints_from_shape(history.c0)] + [setpoints_from_shape(r.c_next) for r in history.iterations]
    rows = []
    for k, c in enumerate(iterates):
        t_kn, z = plant_performance(config, c)
        rec = history.iterations[k] if k < len(history.iterations) else None
        rows.append({"k": k, "c_deg": np.degrees(c).round(3).tolist(), "judged_tension_kN": t_kn,
                     "judged_min_altitude_m": z, "percent_of_oracle": 100.0 * t_kn / oracle.tension_kn,
                     "feasible": bool(z >= h_min - 2.0),
                     "measured_tension_kN": None if rec is None else -rec.cost,
                     "measured_g_m": None if rec is None else float(rec.constraints[0]),
                     "decision": None if rec is None else rec.decision})
    return rows


def write_report(history, out: Path, config: PlantConfig | None = None, box: ShapeBox | None = None,
                 samples=None, laps=None, extra: dict | None = None) -> dict:
    """Print the per-iteration table, save figures and ``summary.json`` in ``out``; return the summary."""
    config = config or PlantConfig()
    box = box or ShapeBox()
    print("\ncomputing the oracle (direct optimization of the deterministic plant; cached in runs/) ...", flush=True)
    oracle = find_oracle(config, box)
    rows = judge_iterates(history, config, oracle)
    print(f"\noracle: c = {_deg(oracle.c)} deg, {oracle.tension_kn:.1f} kN, min altitude {oracle.min_altitude:.1f} m "
          f"({oracle.evaluations} evaluations)")
    print(f"\n{'k':>3} {'c_k (theta_0/A_phi/A_theta deg)':>32} {'measured kN':>12} {'judged kN':>10} "
          f"{'% oracle':>9} {'min alt m':>10}  decision")
    for r in rows:
        meas = "" if r["measured_tension_kN"] is None else f"{r['measured_tension_kN']:.1f}"
        print(f"{r['k']:>3} {'/'.join(f'{v:.2f}' for v in r['c_deg']):>32} {meas:>12} {r['judged_tension_kN']:>10.1f} "
              f"{r['percent_of_oracle']:>9.2f} {r['judged_min_altitude_m']:>10.1f}  {r['decision'] or ''}")
    reach = next((r["k"] for r in rows if r["percent_of_oracle"] >= 99.0 and r["feasible"]), None)
    best = max(rows, key=lambda r: r["judged_tension_kN"] if r["feasible"] else -1)
    summary = {"oracle": {"c_deg": oracle.c_deg, "tension_kN": oracle.tension_kn,
                          "min_altitude_m": oracle.min_altitude},
               "model_only": rows[0], "final": rows[-1], "iterations": len(rows) - 1,
               "first_iteration_at_99_percent": reach, "best_feasible": best,
               "gap_model_only_percent": 100.0 - rows[0]["percent_of_oracle"],
               "gap_final_percent": 100.0 - rows[-1]["percent_of_oracle"],
               "experiments": len(history.experiments), "rows": rows, **(extra or {})}
    print(f"\nmodel-only optimum (k = 0): {rows[0]['percent_of_oracle']:.2f} % of the oracle "
          f"(gap {summary['gap_model_only_percent']:.2f} %); final iterate: {rows[-1]['percent_of_oracle']:.2f} % "
          f"(gap {summary['gap_final_percent']:.2f} %); >= 99 % first at iteration: {reach}")
    out.mkdir(parents=True, exist_ok=True)
    (out / "summary.json").write_text(json.dumps(summary, indent=1, default=float))
    _figures(history, rows, oracle, out, samples, laps)
    print(f"saved {out / 'report.png'} and {out / 'summary.json'}")
    return summary


def _figures(history, rows, oracle, out: Path, samples, laps) -> None:
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    from .plots import nw_coordinates

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
        if samples is not None and k in nominal:
            t1 = nominal[k][1].extra.get("t_end")
            t, theta, phi = samples
            sel = (t >= t1 - 20.0) & (t <= t1)
            if sel.any():
                w, n = nw_coordinates(theta[sel], phi[sel], 400.0, theta_bar)
                ax.plot(w, n, color=col, lw=1.0, label=f"k = {k}")
    ax.set_title("flown paths (solid, last 20 s of each nominal experiment) and references (dashed)")
    ax.set_xlabel("W (m)")
    ax.set_ylabel("N (m)")
    ax.set_aspect("equal")
    ax.legend(fontsize=7, ncol=2)
    ax = axes[0, 1]
    if laps:
        ax.plot([lap["t_end"] for lap in laps], [lap["mean_tension"] / 1e3 for lap in laps], ".", ms=4,
                label="lap mean tension (measured, turbulent)")
        ax.plot([lap["t_end"] for lap in laps], [lap["tension_coefficient"] * 64.0 / 1e3 for lap in laps], ".",
                ms=4, label="normalized to w_ref = 8 m/s")
    ax.axhline(oracle.tension_kn, color="k", lw=1, label=f"oracle {oracle.tension_kn:.0f} kN (deterministic)")
    ax.set_xlabel("simulated time (s)")
    ax.set_ylabel("kN")
    ax.set_title("mean tension per lap")
    ax.legend(fontsize=7)
    ax = axes[1, 0]
    c_deg = np.array([r["c_deg"] for r in rows])
    for i, name in enumerate(("theta_0", "A_phi", "A_theta")):
        ax.plot(c_deg[:, i], "o-", label=name)
    for i, v in enumerate(oracle.c_deg):
        ax.axhline(v, color=f"C{i}", ls=":", lw=1)
    ax.set_xlabel("iteration k")
    ax.set_ylabel("deg")
    ax.set_title("setpoints (dotted: oracle)")
    ax.legend(fontsize=7)
    ax = axes[1, 1]
    ax.plot([r["percent_of_oracle"] for r in rows], "o-", label="judged tension, % of oracle")
    ax.axhline(99.0, color="k", ls=":", lw=1)
    ax2 = ax.twinx()
    ax2.plot([r["judged_min_altitude_m"] for r in rows], "s--", color="C3", label="judged min altitude (m)")
    ax2.axhline(100.0, color="C3", ls=":", lw=1)
    ax.set_xlabel("iteration k")
    ax.set_title("judged on the deterministic plant: tension (left), min altitude (right)")
    ax.legend(fontsize=7, loc="lower right")
    ax2.legend(fontsize=7, loc="upper right")
    fig.tight_layout()
    fig.savefig(out / "report.png", dpi=100)
    plt.close(fig)


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(prog="kite_rto report", description=__doc__)
    ap.add_argument("--db", required=True, help="optimizer SQLite database")
    ap.add_argument("--out", default="runs/report", help="output folder")
    args = ap.parse_args(argv)
    if not Path(args.db).exists():
        print(f"no database at {args.db}", file=sys.stderr)
        return 2
    history = HistoryStore(args.db).load()
    if history is None:
        print(f"{args.db} holds no run", file=sys.stderr)
        return 2
    write_report(history, Path(args.out))
    return 0


if __name__ == "__main__":
    sys.exit(main())
