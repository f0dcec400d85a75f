"""Main job: fly the kite graph as separate node processes in lockstep simulated time, then report.

``optimize`` (default): plant, controller and optimizer (GMA) as three processes; progress per experiment and
iteration; ends with the per-iteration table, the optimality gap against the oracle, ``report.png`` and
``summary.json`` in ``--out``.
``fly``: plant + controller at the default setpoints; tracking quality, mean tension per lap and a plot of the
flown path over the reference on the N-W plane (``path.png``).
"""
from __future__ import annotations

import argparse
import json
import math
import sys
import time
from pathlib import Path

from .graph import NodeProcess, isolated_ros_env


def parse_args(argv=None):
    ap = argparse.ArgumentParser(prog="kite_rto demo", description=__doc__,
                                 formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--duration", type=float, default=300.0, help="simulated seconds (default 300)")
    ap.add_argument("--seed", type=int, default=0, help="turbulence/noise seed (default 0)")
    ap.add_argument("--no-turbulence", action="store_true", help="steady wind, no measurement noise")
    ap.add_argument("--out", default="runs/demo", help="output folder (default runs/demo)")
    ap.add_argument("--mode", choices=("optimize", "fly"), default="optimize", help="default: optimize")
    ap.add_argument("--iterations", type=int, default=10, help="optimize: GMA iterations (default 10)")
    ap.add_argument("--resume", action="store_true", help="optimize: continue the run in --out/rto.sqlite")
    return ap.parse_args(argv)


def fly(args, env, out: Path) -> dict:
    import rclpy

    from .recorder import Recorder

    rclpy.init()
    rec = Recorder()
    plant_params = {"duration": args.duration, "seed": args.seed, "wait_subscribers": 2}  # controller, recorder
    if args.no_turbulence:
        plant_params.update(turbulence=False, anemometer_noise=0.0, noise_angle_deg=0.0, noise_rate=0.0, noise_tension=0.0)
    log = open(out / "nodes.log", "w")
    ctrl = NodeProcess("controller", {}, log=log, env=env)
    wall0 = time.monotonic()
    while rec.count_publishers("/kite/steering") == 0 and time.monotonic() - wall0 < 60:
        rclpy.spin_once(rec, timeout_sec=0.1)
    plant = NodeProcess("plant", plant_params, log=log, env=env)
    next_report, code = 30.0, 1
    try:
        while plant.alive():
            rclpy.spin_once(rec, timeout_sec=0.05)
            if rec.samples and rec.samples[-1][0] >= next_report:
                t = rec.samples[-1][0]
                rate = t / (time.monotonic() - wall0)
                eta = (args.duration - t) / max(rate, 1e-9)
                last = rec.laps[-1] if rec.laps else None
                lap = (f"  lap {int(last['lap'])}: {last['mean_tension'] / 1e3:.0f} kN, "
                       f"RMS {last['rms_cross_track_deg']:.2f} deg") if last else ""
                print(f"  t = {t:6.0f} / {args.duration:.0f} s  ({rate:4.1f}x real time, ETA {eta:4.0f} s){lap}",
                      flush=True)
                next_report += 30.0
        deadline = time.monotonic() + 5.0
        while time.monotonic() < deadline:
            rclpy.spin_once(rec, timeout_sec=0.05)
        code = plant.proc.returncode
    finally:
        plant.stop()
        ctrl.stop()
        log.close()
        rec.destroy_node()
        rclpy.try_shutdown()
    return {"wall": time.monotonic() - wall0, "recorder": rec, "plant_exit": code}


def report(args, res, out: Path) -> int:
    import numpy as np

    from ..core.params import KiteParams
    from ..core.path import DEFAULT_SETPOINTS, FigureEightPath
    from .plots import plot_paths

    rec = res["recorder"]
    if not rec.samples:
        print("no samples received", file=sys.stderr)
        return 1
    t, theta, phi = rec.arrays()
    laps = rec.laps
    print(f"\nsimulated {t[-1]:.0f} s in {res['wall']:.0f} s wall ({t[-1] / res['wall']:.1f}x real time); "
          f"{len(laps)} complete laps")
    print(f"\n{'lap':>4} {'time s':>7} {'tension kN':>11} {'min alt m':>10} {'RMS xtrack deg':>15}")
    for lap in laps:
        print(f"{int(lap['lap']):>4} {lap['lap_time']:>7.1f} {lap['mean_tension'] / 1e3:>11.0f} "
              f"{lap['min_altitude']:>10.0f} {lap['rms_cross_track_deg']:>15.3f}")
    settled = laps[1:] if len(laps) > 1 else laps
    summary = {"setpoints_deg": DEFAULT_SETPOINTS.degrees(), "duration_s": float(t[-1]), "laps": len(laps),
               "wall_s": res["wall"], "seed": args.seed, "turbulence": not args.no_turbulence}
    if settled:
        summary.update(
            mean_tension_kN=float(np.mean([lap["mean_tension"] for lap in settled]) / 1e3),
            rms_cross_track_deg=float(np.sqrt(np.mean([lap["rms_cross_track_deg"] ** 2 for lap in settled]))),
            min_altitude_m=float(min(lap["min_altitude"] for lap in settled)))
        print(f"\nafter the first lap: mean tension {summary['mean_tension_kN']:.0f} kN, RMS cross-track "
              f"{summary['rms_cross_track_deg']:.3f} deg, min altitude {summary['min_altitude_m']:.0f} m")
    path = FigureEightPath(DEFAULT_SETPOINTS)
    s = np.linspace(0, 2 * math.pi, 361)
    keep = t >= t[-1] - 60.0
    plot_paths(out / "path.png", [{"theta": theta[keep], "phi": phi[keep], "ref": path.point(s),
                                   "label": "last 60 s, c = ({:.0f}, {:.0f}, {:.0f}) deg".format(
                                       *DEFAULT_SETPOINTS.degrees())}],
               KiteParams().r, DEFAULT_SETPOINTS.theta_0)
    (out / "summary.json").write_text(json.dumps(summary, indent=1))
    print(f"saved {out / 'path.png'} and {out / 'summary.json'}")
    return 0 if res["plant_exit"] == 0 and settled else 1


def main(argv=None) -> int:
    args = parse_args(argv)
    env = isolated_ros_env()
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    if args.mode == "optimize":
        from .demo_optimize import optimize
        return optimize(args, env, out)
    print(f"kite_rto demo: plant + controller, lockstep, {args.duration:.0f} s simulated, seed {args.seed}, "
          f"ROS_DOMAIN_ID={env['ROS_DOMAIN_ID']} (node output in {out / 'nodes.log'})", flush=True)
    try:
        res = fly(args, env, out)
    except KeyboardInterrupt:
        print("\ninterrupted: nodes stopped")
        return 130
    return report(args, res, out)


if __name__ == "__main__":
    sys.exit(main())
