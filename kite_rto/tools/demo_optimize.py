"""The main job's ``optimize`` mode: plant + controller + optimizer as three processes, then the report."""
from __future__ import annotations

import re
import time
from pathlib import Path

from .graph import NodeProcess

_PROGRESS = re.compile(r"\[optimizer\]: (experiment|iteration|done|resumed|refusing|failed)(.*)")


def _wait(pred, rec, timeout: float) -> bool:
    import rclpy
    end = time.monotonic() + timeout
    while time.monotonic() < end:
        if pred():
            return True
        rclpy.spin_once(rec, timeout_sec=0.05)
    return pred()


def optimize(args, env, out: Path) -> int:
    import rclpy

    from ..gma import HistoryStore
    from .recorder import Recorder
    from .rto_report import write_report

    db = out / "rto.sqlite"
    if db.exists() and not args.resume:
        db.unlink()
    plant_params = {"seed": args.seed, "wait_subscribers": 3}    # controller, optimizer, recorder
    if args.no_turbulence:
        plant_params.update(turbulence=False, anemometer_noise=0.0, noise_angle_deg=0.0, noise_rate=0.0, noise_tension=0.0)
    print(f"kite_rto demo: GMA on the simulated kite, {args.iterations} iterations, lockstep, seed {args.seed}, "
          f"ROS_DOMAIN_ID={env['ROS_DOMAIN_ID']} (node output in {out / 'nodes.log'})", flush=True)
    rclpy.init()
    rec = Recorder()
    log = open(out / "nodes.log", "a" if args.resume else "w")
    procs = []
    wall0 = time.monotonic()
    code = 1
    try:
        opt = NodeProcess("optimizer", {"db": str(db), "n_iter": args.iterations, "exit_when_done": True},
                          log=log, env=env)
        procs.append(opt)
        print("  starting the optimizer (builds the model's NLPs, ~10-30 s) ...", flush=True)
        if not _wait(lambda: rec.setpoints or not opt.alive(), rec, 300):
            raise RuntimeError("the optimizer published no setpoints")
        ctrl = NodeProcess("controller", {}, log=log, env=env)
        procs.append(ctrl)
        _wait(lambda: any("new setpoints" in ln for ln in ctrl.lines) or not ctrl.alive(), rec, 120)
        plant = NodeProcess("plant", plant_params, log=log, env=env)
        procs.append(plant)
        shown = 0
        while opt.alive() and plant.alive() and ctrl.alive():
            rclpy.spin_once(rec, timeout_sec=0.1)
            for line in opt.lines[shown:]:
                m = _PROGRESS.search(line)
                if m:
                    t = rec.samples[-1][0] if rec.samples else 0.0
                    rate = t / max(time.monotonic() - wall0, 1e-9)
                    print(f"  [t = {t:6.0f} s sim, {rate:4.1f}x real time] {m.group(1)}{m.group(2)}", flush=True)
            shown = len(opt.lines)
        code = opt.proc.wait(timeout=30)
        if code != 0:
            print(f"the optimizer exited with code {code}; see {out / 'nodes.log'}")
    except KeyboardInterrupt:
        print("\ninterrupted: stopping the nodes (the optimizer's database keeps every finished experiment; "
              "--resume continues)")
        code = 130
    finally:
        for p in reversed(procs):
            p.stop()
        log.close()
        rec.destroy_node()
        rclpy.try_shutdown()
    wall = time.monotonic() - wall0
    history = HistoryStore(db).load() if db.exists() else None
    if history is None or not history.iterations:
        print("no completed iteration to report")
        return code or 1
    sim = rec.samples[-1][0] if rec.samples else float("nan")
    print(f"\nflew {sim:.0f} s of simulated time in {wall:.0f} s wall ({sim / wall:.1f}x real time)")
    write_report(history, out, samples=rec.arrays() if rec.samples else None, laps=rec.laps,
                 extra={"wall_s": wall, "sim_s": sim, "seed": args.seed, "turbulence": not args.no_turbulence})
    return code
