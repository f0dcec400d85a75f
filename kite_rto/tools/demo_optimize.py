"""The main job's ``optimize`` mode: plant + controller + optimizer as three processes, then the report."""
from __future__ import annotations

import math
import re
import time
from pathlib import Path

import rclpy

from ..gma import HistoryStore
from ..rto.experiment import default_wind_source
from ..rto.settings import KiteRTOSettings
from .demo_graph import (lifecycle, plant_params, recorder_summary, ros_init, spin_until, start_recorder,
                         warn_if_domain_busy)
from .graph import GraphRun, NodeProcess
from .progress import OptimizeProgress
from .recorder import Recorder
from .rto_report import write_report

__all__ = ["optimize"]

_PROGRESS = re.compile(r"\[optimizer\]: (experiment|iteration|done|resumed|refusing|failed)(.*)")


def optimize(args, env, out: Path, progress) -> int:
    """Run the GMA graph with the demo's ``args`` in ``env``, showing ``progress``; write the report to ``out``;
    return the exit code (130 when interrupted)."""
    db = out / "rto.sqlite"
    if not args.resume:          # a new run: the old database goes, with SQLite's side files (write-ahead log)
        for path in (db, db.with_name(db.name + "-wal"), db.with_name(db.name + "-shm")):
            path.unlink(missing_ok=True)
    print(f"kite_rto demo: GMA on the simulated kite, {args.iterations} iterations, lockstep, seed {args.seed}, "
          f"ROS_DOMAIN_ID={env['ROS_DOMAIN_ID']} (node output in {out / 'nodes.log'}; Ctrl-C stops cleanly, "
          "--resume continues)", flush=True)
    ros_init(args.namespace)
    rec = Recorder()
    warn_if_domain_busy(rec, env)
    log = open(out / "nodes.log", "a" if args.resume else "w")
    procs = []
    wall0 = time.monotonic()
    code = 1
    tracker = OptimizeProgress(args.iterations, KiteRTOSettings().experiments_per_iteration())
    with GraphRun(procs, rec, log, progress) as run:
        extra = start_recorder(args, log, env, rec, procs)
        opt = NodeProcess("optimizer", {"db": str(db), "n_iter": args.iterations, "exit_when_done": True,
                                        "wind_source": default_wind_source(args.wind_model), "autostart": False},
                          log=log, env=env, namespace=args.namespace)
        procs.append(opt)
        print("  starting the optimizer (builds the model's NLPs, ~10-30 s) ...", flush=True)
        # A lifecycle node started unconfigured: the demo drives it, as `kite_ctl configure` / `activate` would
        # (a resumed run that was paused goes on: activate resumes it).
        lifecycle(rec, "configure")
        lifecycle(rec, "activate")
        if not spin_until(lambda: rec.setpoints or not opt.alive(), rec, 300):
            raise RuntimeError("the optimizer published no setpoints within 300 s")
        if not opt.alive():
            raise RuntimeError(f"the optimizer exited with code {opt.proc.returncode}; see {out / 'nodes.log'}")
        # Synchronized with the optimizer: the graph flies the same sequence as the pure runner (run_rto).
        ctrl = NodeProcess("controller", {"sync_optimizer": True}, log=log, env=env,
                            namespace=args.namespace)
        procs.append(ctrl)
        spin_until(lambda: any("new setpoints" in ln for ln in ctrl.lines) or not ctrl.alive(), rec, 120)
        plant = NodeProcess("plant", plant_params(args, 3 + extra),    # controller, optimizer, demo (+ recorder, viz)
                            log=log, env=env,
                            namespace=args.namespace)
        procs.append(plant)
        shown = 0
        fly0 = None
        while opt.alive() and plant.alive() and ctrl.alive():
            rclpy.spin_once(rec, timeout_sec=0.1)
            if fly0 is None and rec.samples:
                fly0 = time.monotonic()
            for line in opt.lines[shown:]:
                m = _PROGRESS.search(line)
                if m:
                    t = rec.sim_time
                    rate = t / max(time.monotonic() - (fly0 or wall0), 1e-9)
                    progress.event(f"  [t = {t:6.0f} s sim, {rate:4.1f}x real time] {m.group(1)}{m.group(2)}")
            shown = len(opt.lines)
            if fly0 is not None and time.monotonic() - fly0 > 0.5:
                progress.update(tracker.text(rec.status, rec.sim_time, time.monotonic() - fly0))
        end = time.monotonic() + 30.0
        while opt.alive() and time.monotonic() < end:
            rclpy.spin_once(rec, timeout_sec=0.1)
        code = opt.proc.returncode if opt.proc.poll() is not None else 1
        if code != 0:
            print(f"the optimizer exited with code {code}; see {out / 'nodes.log'}")
    interrupted = run.interrupted
    if interrupted:
        code = 130
        print(f"\ninterrupted: every node stopped. The optimizer's database {db} keeps every finished experiment; "
              f"--resume continues the run", flush=True)
    recorder_summary(procs)
    wall = time.monotonic() - wall0
    history = HistoryStore(db).load() if db.exists() else None
    if history is None or not history.iterations:
        print("no completed iteration to report")
        return code or 1
    sim = rec.sim_time if rec.samples else math.nan
    print(f"\n{'partial report: ' if interrupted else ''}flew {sim:.0f} s of simulated time in {wall:.0f} s wall "
          f"({sim / wall:.1f}x real time)")
    if interrupted:
        print(f"(measured values only; the full report, judged on the deterministic plant: "
              f"python -m kite_rto.tools.rto_report --db {db} --out {out})")
    write_report(history, out, samples=rec.arrays() if rec.samples else None, laps=rec.laps, judge=not interrupted,
                 extra={"wall_s": wall, "sim_s": sim, "seed": args.seed, "turbulence": not args.no_turbulence,
                        "interrupted": interrupted})
    return code
