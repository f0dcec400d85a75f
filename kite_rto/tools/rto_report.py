"""Report of a GMA run on the kite, from the optimizer's SQLite history or from an MCAP recording of the run.

Every iterate c_k is judged the way the oracle is judged: re-flown on the deterministic plant (turbulence and
noise off, long averaging), so that noise cannot flatter the result (``--no-judge`` skips that: measured values
only, seconds instead of minutes when the oracle is not cached yet). Command line::

    python -m kite_rto.tools.rto_report --db runs/demo/rto.sqlite --out runs/report
    python -m kite_rto.tools.rto_report --mcap run.mcap --out runs/report [--no-judge]

From a recording (``kite_record`` or ``demo --record``) the iterations come from ``/rto/status`` and
``/rto/setpoints``, the flown paths from ``/kite/state`` and the tension per lap from ``/kite/laps``; a recording
without an optimizer (``demo --mode fly``) gives the flight report: lap table and flown path (``path.png``).
"""
from __future__ import annotations

import argparse
import json
import math
import sys
from pathlib import Path

import numpy as np
from mcap.exceptions import McapError

from ..flight.shape import ShapeBox, setpoints_from_shape
from ..gma import HistoryStore, StoreError
from ..kite.params import KiteParams
from ..kite.plant import PlantConfig
from ..rto.experiment import ExperimentSpec
from ..rto.judge import judge_flight, judge_point
from ..rto.oracle import find_oracle
from ..rto.run import RUN_KEY, RunDescription
from .mcap_history import history_from_mcap, read_mcap
from .plots import plot_paths
from .report_figure import report_figure

__all__ = ["judge_iterates", "yield_line", "run_of", "write_report", "flight_report", "report_from_mcap", "main"]


def _deg(c) -> str:
    return "/".join(f"{math.degrees(x):.2f}" for x in c)


def judge_iterates(history, config: PlantConfig, h_min: float, oracle) -> list[dict]:
    """One row per iterate c_0 .. c_K (GMA's shape coordinates, judged as setpoints): measured values (if any)
    and the judgement (:func:`~kite_rto.rto.judge.judge_point`) on ``config``'s deterministic plant against
    ``oracle`` and the floor of ``h_min`` (m) (``oracle`` None: no judgement, the judged fields are None)."""
    iterates = [setpoints_from_shape(history.c0)] + [setpoints_from_shape(r.c_next) for r in history.iterations]
    rows = []
    for k, c in enumerate(iterates):
        j = judge_point(config, h_min, oracle.tension_kn, c) if oracle is not None else None
        rec = history.iterations[k] if k < len(history.iterations) else None
        rows.append({"k": k, "c_deg": np.degrees(c).round(3).tolist(),
                     "judged_tension_kN": None if j is None else j.tension_kn,
                     "judged_min_altitude_m": None if j is None else j.min_altitude,
                     "percent_of_oracle": None if j is None else j.percent,
                     "feasible": None if j is None else j.above_floor,
                     "reached": None if j is None else j.reached,
                     "measured_tension_kN": None if rec is None else -rec.cost,
                     "measured_g_m": None if rec is None else float(rec.constraints[0]),
                     "decision": None if rec is None else rec.decision})
    return rows


def yield_line(flight) -> str:
    """The report's line about the yield of the whole flight (a :class:`~kite_rto.rto.flight_yield.FlightYield`)."""
    parts = ", ".join(f"{k} {t:.0f} s at {p:.2f} %" for k, (t, p) in flight.by_purpose.items())
    return (f"yield of the whole flight (learning included): {flight.percent:.2f} % of the oracle's energy over "
            f"{flight.flight_time:.0f} s ({parts}); below the floor: {flight.below_floor_s:.0f} s")


def run_of(history) -> RunDescription | None:
    """The :class:`~kite_rto.rto.run.RunDescription` stored with ``history`` (None when it holds none)."""
    data = history.meta.get(RUN_KEY)
    return None if data is None else RunDescription.from_dict(data)


def write_report(history, out: Path, run: RunDescription | None = None, samples=None, laps=None,
                 extra: dict | None = None, judge: bool = True) -> dict:
    """Print the per-iteration table, save figures and ``summary.json`` in ``out``; return the summary.

    ``run``: the run's description (default: the one stored with ``history``): its plant, box and h_min are what
    the oracle and the judge use. A run whose plant is not known is not judged (measured values only), nor with
    ``judge=False``.
    """
    run = run or run_of(history)
    if judge and (run is None or run.plant is None):
        print(f"\nnot judged: the run's {'description' if run is None else 'plant'} is not stored with it (a real "
              "plant, or a file written by another version)", flush=True)
        judge = False
    config, box = (run.plant, run.settings.box) if run is not None else (None, ShapeBox())
    h_min = run.h_min if run is not None else ExperimentSpec().h_min
    oracle = flight = None
    if judge:
        print("\ncomputing the oracle (direct optimization of the deterministic plant; cached in $KITE_RTO_CACHE or "
              "the user cache directory) ...",
              flush=True)
        oracle = find_oracle(config, box, h_min=h_min)
        print(f"\noracle: c = {_deg(oracle.c)} deg, {oracle.tension_kn:.1f} kN, min altitude "
              f"{oracle.min_altitude:.1f} m ({oracle.evaluations} evaluations)")
    rows = judge_iterates(history, config, h_min, oracle)
    print(f"\n{'k':>3} {'c_k (theta_0/A_phi/A_theta deg)':>32} {'measured kN':>12} {'judged kN':>10} "
          f"{'% oracle':>9} {'min alt m':>10}  decision")

    def num(v, fmt):
        return "" if v is None else format(v, fmt)
    for r in rows:
        print(f"{r['k']:>3} {'/'.join(f'{v:.2f}' for v in r['c_deg']):>32} {num(r['measured_tension_kN'], '.1f'):>12} "
              f"{num(r['judged_tension_kN'], '.1f'):>10} {num(r['percent_of_oracle'], '.2f'):>9} "
              f"{num(r['judged_min_altitude_m'], '.1f'):>10}  {r['decision'] or ''}")
    summary = {"model_only": rows[0], "final": rows[-1], "iterations": len(rows) - 1,
               "experiments": len(history.experiments), "judged": oracle is not None, "rows": rows}
    if oracle is not None:
        reach = next((r["k"] for r in rows if r["reached"]), None)
        summary.update(
            oracle={"c_deg": oracle.c_deg, "tension_kN": oracle.tension_kn, "min_altitude_m": oracle.min_altitude},
            first_iteration_at_99_percent=reach,
            best_feasible=max(rows, key=lambda r: r["judged_tension_kN"] if r["feasible"] else -1),
            gap_model_only_percent=100.0 - rows[0]["percent_of_oracle"],
            gap_final_percent=100.0 - rows[-1]["percent_of_oracle"])
        print(f"\nmodel-only optimum (k = 0): {rows[0]['percent_of_oracle']:.2f} % of the oracle "
              f"(gap {summary['gap_model_only_percent']:.2f} %); final iterate: {rows[-1]['percent_of_oracle']:.2f} % "
              f"(gap {summary['gap_final_percent']:.2f} %); >= 99 % first at iteration: {reach}")
        if history.experiments:
            flight = judge_flight(config, h_min, oracle.tension_kn, history)
            summary["flight_yield"] = flight.summary()
            print(yield_line(flight))
    else:
        print("\n(not judged on the deterministic plant: measured values only)")
    summary.update(extra or {})
    out.mkdir(parents=True, exist_ok=True)
    (out / "summary.json").write_text(json.dumps(summary, indent=1, default=float))
    report_figure(history, rows, oracle, out, samples, laps, h_min, flight)
    print(f"saved {out / 'report.png'} and {out / 'summary.json'}")
    return summary


def flight_report(samples, laps, out: Path, reference=None, label: str = "", extra: dict | None = None) -> dict:
    """Report of a flight without GMA: lap table, summary (after the first lap) and the flown path of the last
    60 s over ``reference`` = (theta, phi) arrays (rad) on the N-W plane (``path.png``); return the summary."""
    t, theta, phi = samples
    print(f"\n{'lap':>4} {'time s':>7} {'tension kN':>11} {'min alt m':>10} {'RMS xtrack deg':>15}")
    for lap in laps:
        print(f"{int(lap['lap']):>4} {lap['lap_time']:>7.1f} {lap['mean_tension'] / 1e3:>11.0f} "
              f"{lap['min_altitude']:>10.0f} {lap['rms_cross_track_deg']:>15.3f}")
    settled = laps[1:] if len(laps) > 1 else laps
    summary = {"duration_s": float(t[-1]) if len(t) else 0.0, "laps": len(laps), **(extra or {})}
    if settled:
        summary.update(
            mean_tension_kN=float(np.mean([lap["mean_tension"] for lap in settled]) / 1e3),
            rms_cross_track_deg=float(np.sqrt(np.mean([lap["rms_cross_track_deg"] ** 2 for lap in settled]))),
            min_altitude_m=float(min(lap["min_altitude"] for lap in settled)))
        print(f"\nafter the first lap: mean tension {summary['mean_tension_kN']:.0f} kN, RMS cross-track "
              f"{summary['rms_cross_track_deg']:.3f} deg, min altitude {summary['min_altitude_m']:.0f} m")
    out.mkdir(parents=True, exist_ok=True)
    saved = []
    if len(t):
        keep = t >= t[-1] - 60.0
        theta_bar = float(np.mean(reference[0])) if reference is not None else float(np.mean(theta[keep]))
        plot_paths(out / "path.png", [{"theta": theta[keep], "phi": phi[keep], "ref": reference,
                                       "label": label or "last 60 s"}], KiteParams().r, theta_bar)
        saved.append(str(out / "path.png"))
    (out / "summary.json").write_text(json.dumps(summary, indent=1, default=float))
    saved.append(str(out / "summary.json"))
    print(f"saved {' and '.join(saved)}")
    return summary


def report_from_mcap(path, out: Path, judge: bool = True) -> int:
    """The GMA report (or, without an optimizer in the recording, the flight report) of a recording."""
    data = read_mcap(path)
    n = len(data.samples[0])
    print(f"{path}: {sum(data.topics.values())} messages on {sum(1 for v in data.topics.values() if v)} topics; "
          f"{n} samples"
          + (f" ({data.samples[0][0]:.1f} .. {data.samples[0][-1]:.1f} s sim)" if n else "")
          + f", {len(data.laps)} laps, {len(data.status)} optimizer status messages, crashes: {data.crashes}")
    history = history_from_mcap(data)
    extra = {"source": str(path), "crashes": data.crashes}
    if history is not None:
        write_report(history, out, samples=data.samples if n else None, laps=data.laps, judge=judge,
                     extra={**extra, "sim_s": float(data.samples[0][-1]) if n else None})
        return 0
    if data.status:
        print("the optimizer finished no iteration in this recording: flight report only")
    if not n and not data.laps:
        print(f"{path} holds no /kite/state or /kite/laps message: nothing to report", file=sys.stderr)
        return 1
    flight_report(data.samples, data.laps, out, data.reference, "last 60 s (reference as recorded)", extra)
    return 0


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(prog="kite_rto report", description=__doc__,
                                 formatter_class=argparse.RawDescriptionHelpFormatter)
    src = ap.add_mutually_exclusive_group(required=True)
    src.add_argument("--db", help="optimizer SQLite database")
    src.add_argument("--mcap", help="MCAP recording of a run (kite_record, demo --record)")
    ap.add_argument("--out", default="runs/report", help="output folder")
    ap.add_argument("--no-judge", action="store_true",
                    help="skip the oracle and the deterministic-plant judgement of each iterate")
    args = ap.parse_args(argv)
    source = args.db or args.mcap
    if not Path(source).exists():
        print(f"no {'database' if args.db else 'recording'} at {source}", file=sys.stderr)
        return 2
    if args.mcap:
        try:
            return report_from_mcap(args.mcap, Path(args.out), judge=not args.no_judge)
        except (McapError, KeyError, ValueError, EOFError) as exc:   # a damaged or foreign file: say so
            print(f"cannot read {args.mcap} as a kite_rto MCAP recording: {exc}", file=sys.stderr)
            return 2
    try:
        history = HistoryStore(args.db).load()
    except StoreError as exc:                                           # damaged or foreign: say so
        print(exc, file=sys.stderr)
        return 2
    if history is None:
        print(f"{args.db} holds no run", file=sys.stderr)
        return 2
    write_report(history, Path(args.out), judge=not args.no_judge)
    return 0


if __name__ == "__main__":
    sys.exit(main())
