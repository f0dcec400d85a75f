"""Main job: fly the kite graph as separate node processes in lockstep simulated time, then report.

``optimize`` (default): plant, controller and optimizer (GMA) as three processes; progress per experiment and
iteration; ends with the per-iteration table, the optimality gap against the oracle, ``report.png`` and
``summary.json`` in ``--out``.
``fly``: plant + controller at the default setpoints; tracking quality, mean tension per lap and a plot of the
flown path over the reference on the N-W plane (``path.png``).

A progress line shows simulated time, iteration k/N and the ETA (updated in place on a terminal). ``--record
FILE.mcap`` records every topic on simulated time, with the 3-D scene (kite_record and kite_viz as extra
processes); ``--viz`` publishes the scene only. Ctrl-C (or SIGTERM) stops every node, writes a
partial report from what was flown (optimize: measured values only) and exits with code 130.
"""
from __future__ import annotations

import argparse
import math
import signal
import sys
import time
from pathlib import Path

from . import graph
from .graph import GraphRun, NodeProcess, isolated_ros_env, stopped_by_signal
from ..nodes.namespace import add_namespace_option
from .progress import Progress, eta_text

__all__ = ["parse_args", "fly", "report", "main"]

# rclpy, the observer node, the report (matplotlib, the oracle) and the optimize mode are imported inside the
# functions that run the graph: together about 1.5 s that `--help` and a mistyped option should not wait for.


def parse_args(argv=None):
    ap = argparse.ArgumentParser(prog="kite_rto demo", description=__doc__,
                                 formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--duration", type=float, default=300.0, help="fly: simulated seconds (default 300)")
    ap.add_argument("--seed", type=int, default=0, help="turbulence/noise seed (default 0)")
    ap.add_argument("--no-turbulence", action="store_true", help="steady wind, no measurement noise")
    ap.add_argument("--wind-model", choices=("field", "uniform"), default="field",
                    help="the plant's turbulence: field (3-D Mann box, the default) or uniform (one gust the "
                         "anemometer sees too); the optimizer normalizes by the matching wind source")
    ap.add_argument("--out", default="runs/demo", help="output folder (default runs/demo)")
    add_namespace_option(ap)
    ap.add_argument("--mode", choices=("optimize", "fly"), default="optimize", help="default: optimize")
    ap.add_argument("--iterations", type=int, default=10, help="optimize: GMA iterations (default 10)")
    ap.add_argument("--resume", action="store_true", help="optimize: continue the run in --out/rto.sqlite")
    ap.add_argument("--record", metavar="FILE.mcap",
                    help="also record every topic of the run to this MCAP file, log time = simulated time (kite_record "
                         "and kite_viz as extra processes)")
    ap.add_argument("--viz", action="store_true",
                    help="also publish the 3-D scene on /kite/markers for RViz2 or Foxglove (kite_viz as a process; "
                         "implied by --record)")
    ap.add_argument("--progress", type=float, default=10.0, metavar="S",
                    help="wall seconds between progress lines when the output is not a terminal (default 10; "
                         "on a terminal the progress line is updated in place)")
    return ap.parse_args(argv)


def fly(args, env, out: Path, progress: Progress) -> dict:
    import rclpy

    from ..nodes.topics import STEERING
    from .demo_graph import plant_params, recorder_summary, ros_init, spin_until, start_recorder, warn_if_domain_busy
    from .recorder import Recorder

    ros_init(args.namespace)
    rec = Recorder()
    warn_if_domain_busy(rec, env)
    procs = []
    log = open(out / "nodes.log", "w")
    wall0 = time.monotonic()
    code = 1
    with GraphRun(procs, rec, log, progress) as run:
        extra = start_recorder(args, log, env, rec, procs)
        ctrl = NodeProcess("controller", {}, log=log, env=env, namespace=args.namespace)
        procs.append(ctrl)
        spin_until(lambda: rec.count_publishers(STEERING) > 0 or not ctrl.alive(), rec,
                   60.0 - (time.monotonic() - wall0), period=0.1)
        plant = NodeProcess("plant", plant_params(args, 2 + extra, duration=args.duration), log=log, env=env,
                            namespace=args.namespace)
        procs.append(plant)
        fly0 = None
        while plant.alive():
            rclpy.spin_once(rec, timeout_sec=0.05)
            t = rec.sim_time
            if rec.samples and fly0 is None:
                fly0 = time.monotonic()
            if fly0 is not None and time.monotonic() - fly0 > 0.5:
                rate = t / max(time.monotonic() - fly0, 1e-9)
                last = rec.laps[-1] if rec.laps else None
                lap = (f", lap {int(last['lap'])}: {last['mean_tension'] / 1e3:.0f} kN, "
                       f"xtrack {last['rms_cross_track_deg']:.2f} deg") if last else ""
                progress.update(f"  t = {t:6.0f} / {args.duration:.0f} s sim ({100 * t / args.duration:3.0f} %, "
                                f"{rate:4.1f}x real time){lap}, "
                                f"{eta_text((args.duration - t) / rate if rate > 0 else None)}")
        deadline = time.monotonic() + 2.0
        while time.monotonic() < deadline:                  # the last lap message
            rclpy.spin_once(rec, timeout_sec=0.05)
        code = plant.proc.returncode
    interrupted = run.interrupted
    if interrupted:
        code = 130
        print(f"\ninterrupted: every node stopped (node output in {out / 'nodes.log'})", flush=True)
    recorder_summary(procs)
    return {"wall": time.monotonic() - wall0, "recorder": rec, "plant_exit": code, "interrupted": interrupted}


def report(args, res, out: Path) -> int:
    import numpy as np

    from ..flight.path import DEFAULT_SETPOINTS, FigureEightPath
    from .rto_report import flight_report

    rec = res["recorder"]
    if not rec.samples:
        print("no samples received", file=sys.stderr)
        return 130 if res["interrupted"] else 1
    t, theta, phi = rec.arrays()
    print(f"\n{'partial report: ' if res['interrupted'] else ''}simulated {t[-1]:.0f} s in {res['wall']:.0f} s "
          f"wall ({t[-1] / res['wall']:.1f}x real time); {len(rec.laps)} complete laps")
    ref = FigureEightPath(DEFAULT_SETPOINTS).point(np.linspace(0, 2 * math.pi, 361))
    summary = flight_report((t, theta, phi), rec.laps, out, ref,
                            "last 60 s, c = ({:.0f}, {:.0f}, {:.0f}) deg".format(*DEFAULT_SETPOINTS.degrees()),
                            {"setpoints_deg": DEFAULT_SETPOINTS.degrees(), "wall_s": res["wall"], "seed": args.seed,
                             "turbulence": not args.no_turbulence, "interrupted": res["interrupted"]})
    if res["interrupted"]:
        return 130
    return 0 if res["plant_exit"] == 0 and summary.get("mean_tension_kN") is not None else 1


def _terminate(signum, frame):
    graph.SIGNALLED = True
    raise KeyboardInterrupt


def main(argv=None) -> int:
    args = parse_args(argv)
    signal.signal(signal.SIGTERM, _terminate)         # a kill or a closing session: the same clean stop
    if signal.getsignal(signal.SIGINT) is signal.default_int_handler:   # not when the shell ignores it (cmd &)
        signal.signal(signal.SIGINT, _terminate)
    env = isolated_ros_env()
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    progress = Progress(args.progress)
    try:
        if args.mode == "optimize":
            from .demo_optimize import optimize
            return optimize(args, env, out, progress)
        print(f"kite_rto demo: plant + controller, lockstep, {args.duration:.0f} s simulated, seed {args.seed}, "
              f"ROS_DOMAIN_ID={env['ROS_DOMAIN_ID']} (node output in {out / 'nodes.log'})", flush=True)
        res = fly(args, env, out, progress)
        return report(args, res, out)
    except KeyboardInterrupt:                          # a further Ctrl-C while reporting: stop here
        progress.clear()
        print("\ninterrupted", flush=True)
        return 130
    except RuntimeError as exc:
        if stopped_by_signal(exc):
            progress.clear()
            print("\ninterrupted", flush=True)
            return 130
        print(f"kite_rto demo: {exc}", file=sys.stderr)
        return 1


if __name__ == "__main__":
    sys.exit(main())
