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
from types import SimpleNamespace

import numpy as np

from ..rto.oracle import find_oracle, plant_performance
from ..flight.path import FigureEightPath, Setpoints, ShapeBox, setpoints_from_shape, shape_from_setpoints
from ..kite.plant import PlantConfig
from ..gma import HistoryStore

__all__ = ["judge_iterates", "write_report", "flight_report", "read_mcap", "history_from_mcap", "main"]


def _deg(c) -> str:
    return "/".join(f"{math.degrees(x):.2f}" for x in c)


def judge_iterates(history, config: PlantConfig, oracle, h_min: float = 100.0) -> list[dict]:
    """One row per iterate c_0 .. c_K (GMA's shape coordinates, judged as setpoints): measured values (if any)
    and the deterministic-plant judgement (``oracle`` None: no judgement, the judged fields are None)."""
    iterates = [setpoints_from_shape(history.c0)] + [setpoints_from_shape(r.c_next) for r in history.iterations]
    rows = []
    for k, c in enumerate(iterates):
        t_kn, z = plant_performance(config, c) if oracle is not None else (None, None)
        rec = history.iterations[k] if k < len(history.iterations) else None
        rows.append({"k": k, "c_deg": np.degrees(c).round(3).tolist(), "judged_tension_kN": t_kn,
                     "judged_min_altitude_m": z,
                     "percent_of_oracle": None if t_kn is None else 100.0 * t_kn / oracle.tension_kn,
                     "feasible": None if z is None else bool(z >= h_min - 2.0),
                     "measured_tension_kN": None if rec is None else -rec.cost,
                     "measured_g_m": None if rec is None else float(rec.constraints[0]),
                     "decision": None if rec is None else rec.decision})
    return rows


def write_report(history, out: Path, config: PlantConfig | None = None, box: ShapeBox | None = None,
                 samples=None, laps=None, extra: dict | None = None, judge: bool = True) -> dict:
    """Print the per-iteration table, save figures and ``summary.json`` in ``out``; return the summary.

    ``judge=False``: no oracle and no deterministic-plant judgement (measured values only).
    """
    config = config or PlantConfig()
    box = box or ShapeBox()
    oracle = None
    if judge:
        print("\ncomputing the oracle (direct optimization of the deterministic plant; cached in runs/) ...",
              flush=True)
        oracle = find_oracle(config, box)
        print(f"\noracle: c = {_deg(oracle.c)} deg, {oracle.tension_kn:.1f} kN, min altitude "
              f"{oracle.min_altitude:.1f} m ({oracle.evaluations} evaluations)")
    rows = judge_iterates(history, config, oracle)
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
        reach = next((r["k"] for r in rows if r["percent_of_oracle"] >= 99.0 and r["feasible"]), None)
        summary.update(
            oracle={"c_deg": oracle.c_deg, "tension_kN": oracle.tension_kn, "min_altitude_m": oracle.min_altitude},
            first_iteration_at_99_percent=reach,
            best_feasible=max(rows, key=lambda r: r["judged_tension_kN"] if r["feasible"] else -1),
            gap_model_only_percent=100.0 - rows[0]["percent_of_oracle"],
            gap_final_percent=100.0 - rows[-1]["percent_of_oracle"])
        print(f"\nmodel-only optimum (k = 0): {rows[0]['percent_of_oracle']:.2f} % of the oracle "
              f"(gap {summary['gap_model_only_percent']:.2f} %); final iterate: {rows[-1]['percent_of_oracle']:.2f} % "
              f"(gap {summary['gap_final_percent']:.2f} %); >= 99 % first at iteration: {reach}")
    else:
        print("\n(not judged on the deterministic plant: measured values only)")
    summary.update(extra or {})
    out.mkdir(parents=True, exist_ok=True)
    (out / "summary.json").write_text(json.dumps(summary, indent=1, default=float))
    _figures(history, rows, oracle, out, samples, laps)
    print(f"saved {out / 'report.png'} and {out / 'summary.json'}")
    return summary


def _legend(ax, **kw) -> None:
    if ax.get_legend_handles_labels()[0]:
        ax.legend(**kw)


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
    ax.set_xlabel("simulated time (s)")
    ax.set_ylabel("kN")
    ax.set_title("mean tension per lap")
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
        ax.axhline(99.0, color="k", ls=":", lw=1)
        ax2 = ax.twinx()
        ax2.plot([r["judged_min_altitude_m"] for r in rows], "s--", color="C3", label="judged min altitude (m)")
        ax2.axhline(100.0, color="C3", ls=":", lw=1)
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


def flight_report(samples, laps, out: Path, reference=None, label: str = "", extra: dict | None = None) -> dict:
    """Report of a flight without GMA: lap table, summary (after the first lap) and the flown path of the last
    60 s over ``reference`` = (theta, phi) arrays (rad) on the N-W plane (``path.png``); return the summary."""
    from ..kite.params import KiteParams
    from .plots import plot_paths

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


# ----------------------------------------------------------------------------------------- MCAP recordings
def read_mcap(path) -> SimpleNamespace:
    """The data of a recording that the reports use.

    Returns ``samples`` = (t, theta, phi) arrays from /kite/state (stamps, s), ``laps`` (dicts of the
    /kite/laps fields plus ``t_end``), ``setpoints`` = list of (sim t, c rad) from /rto/setpoints (sim t = stamp of
    the last sample recorded before it), ``status`` = list of (sim t, key/values) of the optimizer's /rto/status,
    ``reference`` = (theta, phi) of the last /kite/reference_path (or None), ``crashes`` and ``topics`` (counts).
    """
    from mcap.reader import make_reader
    from rclpy.serialization import deserialize_message
    from sensor_msgs.msg import JointState

    from ..nodes.interface import stamp_to_ns
    from ..nodes import topics as T
    from .record import TOPICS

    wanted = [T.STATE, T.LAPS, T.SETPOINTS, T.STATUS, T.REFERENCE_PATH, T.CRASHES]
    t, theta, phi = [], [], []
    data = SimpleNamespace(laps=[], setpoints=[], status=[], reference=None, crashes=0, topics={})
    with open(path, "rb") as f:
        reader = make_reader(f)
        summary = reader.get_summary()
        if summary is not None:
            data.topics = {ch.topic: summary.statistics.channel_message_counts.get(cid, 0)
                           for cid, ch in summary.channels.items()} if summary.statistics else {}
        for _schema, channel, message in reader.iter_messages(topics=wanted, log_time_order=True):
            topic = channel.topic
            if topic == T.STATE:
                state = deserialize_message(message.data, JointState)
                ns, pos = stamp_to_ns(state.header.stamp), state.position
                if not t or ns * 1e-9 > t[-1]:
                    t.append(ns * 1e-9)
                    theta.append(pos[0])
                    phi.append(pos[1])
                continue
            msg = deserialize_message(message.data, TOPICS[topic][0])
            now = t[-1] if t else 0.0
            if topic == T.LAPS:
                lap = dict(zip(msg.name, msg.position))
                lap["t_end"] = stamp_to_ns(msg.header.stamp) * 1e-9
                data.laps.append(lap)
            elif topic == T.SETPOINTS:
                values = dict(zip(msg.name, msg.position))
                data.setpoints.append((now, np.array([values.get(n, math.nan) for n in Setpoints.names()])))
            elif topic == T.STATUS:
                for st in msg.status:
                    if st.name == "kite_rto/optimizer":
                        data.status.append((now, {kv.key: kv.value for kv in st.values}))
            elif topic == T.REFERENCE_PATH and msg.poses:
                p = np.array([[q.pose.position.x, q.pose.position.y, q.pose.position.z] for q in msg.poses])
                data.reference = (np.arctan2(np.hypot(p[:, 1], p[:, 2]), p[:, 0]), np.arctan2(p[:, 1], p[:, 2]))
            elif topic == T.CRASHES:
                data.crashes = max(data.crashes, int(msg.data))
    data.samples = (np.array(t), np.array(theta), np.array(phi))
    return data


def _parse_deg(text: str):
    """``"(30.00, 42.00, 6.50) deg"`` -> array in rad (None if it does not parse)."""
    try:
        return np.radians([float(x) for x in text.replace("deg", "").strip().strip("()").split(",")])
    except (AttributeError, ValueError):
        return None


def history_from_mcap(data: SimpleNamespace):
    """Rebuild what the report needs of the optimizer's history from a recording's /rto/status and
    /rto/setpoints: c_0 (the first setpoints), per finished iteration the measured cost and constraint, c_{k+1}
    (0.01 deg resolution, as published) and the decision, and the experiments that finished while recording (id,
    purpose, iteration, sim-time end = start of the next one). None if the recording has no finished iteration."""
    iterations = {}
    experiments = []                                     # [id, purpose, iteration, t_start]
    done = []                                            # experiments_done of each status
    for _, kv in data.status:
        try:
            done.append(int(kv.get("experiments_done", "")))
        except ValueError:
            pass
        try:
            n = int(kv.get("iteration", 0))
        except ValueError:
            continue
        c_next = _parse_deg(kv.get("c_next_deg"))
        if n >= 1 and n not in iterations and c_next is not None:
            try:
                cost = float(kv["measured_cost_kN"])
                g = float(kv["measured_constraint_m"])
            except (KeyError, ValueError):
                cost, g = math.nan, math.nan
            iterations[n] = SimpleNamespace(k=n - 1, c_next=shape_from_setpoints(c_next), cost=cost,
                                            constraints=np.array([g]),
                                            decision=kv.get("decision", ""))
        exp = kv.get("experiment")
        if exp and (not experiments or experiments[-1][0] != exp):
            try:
                t_start = float(kv.get("experiment_t_start", "nan"))
            except ValueError:
                t_start = math.nan
            try:
                it = int(exp.split("-")[0].lstrip("k"))
            except ValueError:
                it = -1
            experiments.append([exp, kv.get("purpose", ""), it, t_start])
    if not iterations:
        return None
    if data.setpoints:
        c0 = data.setpoints[0][1]
    else:
        c0 = next((_parse_deg(kv.get("setpoints_deg")) for _, kv in data.status
                   if kv.get("experiment", "").startswith("k0-")), None)
    if c0 is None:
        return None
    t_last = float(data.samples[0][-1]) if len(data.samples[0]) else math.nan
    finished = done[-1] - done[0] if done else len(experiments) - 1    # the first one seen was running then
    exps = []
    for i, (exp_id, purpose, it, _t0) in enumerate(experiments[:max(finished, 0)]):
        t_end = experiments[i + 1][3] if i + 1 < len(experiments) else t_last
        exps.append((SimpleNamespace(request_id=exp_id, purpose=purpose, iteration=it),
                     SimpleNamespace(extra={"t_end": None if math.isnan(t_end) else t_end})))
    ordered = [iterations[n] for n in sorted(iterations)]
    # in GMA's shape coordinates, like an optimizer's History (the recording has setpoints)
    return SimpleNamespace(c0=shape_from_setpoints(np.asarray(c0, dtype=float)), iterations=ordered,
                           experiments=exps)


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
        except Exception as exc:  # noqa: BLE001 - a damaged or foreign file: say so, no traceback
            from mcap.exceptions import McapError
            if isinstance(exc, (McapError, KeyError, ValueError, EOFError)):
                print(f"cannot read {args.mcap} as a kite_rto MCAP recording: {exc}", file=sys.stderr)
                return 2
            raise
    history = HistoryStore(args.db).load()
    if history is None:
        print(f"{args.db} holds no run", file=sys.stderr)
        return 2
    write_report(history, Path(args.out), judge=not args.no_judge)
    return 0


if __name__ == "__main__":
    sys.exit(main())
