"""Main job: fly the kite graph as separate node processes in lockstep simulated time, then report.

``optimize`` (default): plant, controller and optimizer (GMA) as three processes; progress per experiment and
iteration; ends with the per-iteration table, the optimality gap against the oracle, ``report.png`` and
``summary.json`` in ``--out``.
``fly``: plant + controller at the default setpoints; tracking quality, mean tension per lap and a plot of the
flown path over the reference on the N-W plane (``path.png``).

A progress line shows simulated time, iteration k/N and the ETA (updated in place on a terminal). ``--record
FILE.mcap`` records every topic (kite_record as a 4th process). Ctrl-C (or SIGTERM) stops every node, writes a
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
from .graph import NodeProcess, close_graph, isolated_ros_env, stopped_by_signal


def parse_args(argv=None):
    ap = argparse.ArgumentParser(prog="kite_rto demo", description=__doc__,
                                 formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--duration", type=float, default=300.0, help="fly: simulated seconds (default 300)")
    ap.add_argument("--seed", type=int, default=0, help="turbulence/noise seed (default 0)")
    ap.add_argument("--no-turbulence", action="store_true", help="steady wind, no measurement noise")
    ap.add_argument("--out", default="runs/demo", help="output folder (default runs/demo)")
    ap.add_argument("--mode", choices=("optimize", "fly"), default="optimize", help="default: optimize")
    ap.add_argument("--iterations", type=int, default=10, help="optimize: GMA iterations (default 10)")
    ap.add_argument("--resume", action="store_true", help="optimize: continue the run in --out/rto.sqlite")
    ap.add_argument("--record", metavar="FILE.mcap",
                    help="also record every topic of the run to this MCAP file (kite_record as a 4th process)")
    ap.add_argument("--progress", type=float, default=10.0, metavar="S",
                    help="wall seconds between progress lines when the output is not a terminal (default 10; "
                         "on a terminal the progress line is updated in place)")
    return ap.parse_args(argv)


class Progress:
    """The live progress line: rewritten in place on a terminal, printed every ``every`` wall s otherwise.

    :meth:`event` prints a permanent line (the live line is cleared first and redrawn on the next update).
    """

    def __init__(self, every: float = 10.0, stream=None):
        self.stream = stream or sys.stdout
        self.tty = self.stream.isatty()
        self.every = every if not self.tty else 0.5
        self._last = -math.inf
        self._shown = False

    def update(self, text: str, force: bool = False) -> None:
        now = time.monotonic()
        if not force and now - self._last < self.every:
            return
        self._last = now
        if self.tty:
            self.stream.write("\r" + text + "\x1b[K")
            self._shown = True
        else:
            self.stream.write(text + "\n")
        self.stream.flush()

    def event(self, text: str) -> None:
        self.clear()
        self.stream.write(text + "\n")
        self.stream.flush()

    def clear(self) -> None:
        if self._shown:
            self.stream.write("\r\x1b[K")
            self.stream.flush()
            self._shown = False


def eta_text(seconds) -> str:
    """``ETA 1 min 05 s`` / ``ETA 42 s`` / ``ETA ?``."""
    if seconds is None or not math.isfinite(seconds) or seconds < 0:
        return "ETA ?"
    seconds = round(seconds)
    return f"ETA {seconds // 60} min {seconds % 60:02d} s" if seconds >= 60 else f"ETA {seconds} s"


def ros_init() -> None:
    """rclpy without its signal handlers: Ctrl-C raises KeyboardInterrupt here, and the demo stops the nodes."""
    import rclpy
    from rclpy.signals import SignalHandlerOptions
    rclpy.init(signal_handler_options=SignalHandlerOptions.NO)


def start_recorder(args, log, env, rec, procs) -> int:
    """With ``--record``: start kite_record as a process and wait until it listens; return the number of extra
    /kite/state subscribers the plant must wait for (0 or 1)."""
    if not args.record:
        return 0
    import rclpy

    from ..nodes.topics import STATE
    Path(args.record).resolve().parent.mkdir(parents=True, exist_ok=True)
    before = rec.count_subscribers(STATE)
    recorder = NodeProcess("record", log=log, env=env,
                           cmd=[sys.executable, "-m", "kite_rto.tools.record", "--out", str(args.record)])
    procs.append(recorder)
    end = time.monotonic() + 60.0
    while rec.count_subscribers(STATE) <= before and recorder.alive() and time.monotonic() < end:
        rclpy.spin_once(rec, timeout_sec=0.1)
    if not recorder.alive():
        raise RuntimeError(f"the recorder exited (code {recorder.proc.returncode}): "
                           + " | ".join(recorder.lines[-3:]))
    print(f"  recording every topic to {args.record}", flush=True)
    return 1


def recorder_summary(procs) -> None:
    for p in procs:
        if p.name == "record":
            said = [ln for ln in p.lines if "wrote" in ln]
            print(f"  {said[-1].strip()}" if said else f"  the recorder said nothing; see nodes.log (exit code "
                  f"{p.proc.returncode})", flush=True)


def fly(args, env, out: Path, progress: Progress) -> dict:
    import rclpy

    from .recorder import Recorder

    ros_init()
    rec = Recorder()
    procs = []
    log = open(out / "nodes.log", "w")
    wall0 = time.monotonic()
    code, interrupted = 1, False
    try:
        extra = start_recorder(args, log, env, rec, procs)
        plant_params = {"duration": args.duration, "seed": args.seed, "wait_subscribers": 2 + extra}
        if args.no_turbulence:
            plant_params.update(turbulence=False, anemometer_noise=0.0, noise_angle_deg=0.0, noise_rate=0.0,
                                noise_tension=0.0)
        ctrl = NodeProcess("controller", {}, log=log, env=env)
        procs.append(ctrl)
        while rec.count_publishers("/kite/steering") == 0 and ctrl.alive() and time.monotonic() - wall0 < 60:
            rclpy.spin_once(rec, timeout_sec=0.1)
        plant = NodeProcess("plant", plant_params, log=log, env=env)
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
    except (KeyboardInterrupt, RuntimeError) as exc:
        if not stopped_by_signal(exc):
            raise
        interrupted, code = True, 130
    finally:
        progress.clear()
        close_graph(procs, rec, log)
    if interrupted:
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
