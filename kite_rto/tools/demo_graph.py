"""What both modes of the main job share around the node processes: rclpy for the in-process observer, the
plant's parameters, the optional recorder process, and spinning the observer while waiting.

Imported only once a run starts (it imports rclpy), never for ``--help``.
"""
from __future__ import annotations

import sys
import time
from pathlib import Path

import rclpy
from rclpy.signals import SignalHandlerOptions

from ..nodes.topics import STATE
from .graph import NodeProcess

__all__ = ["ros_init", "plant_params", "start_recorder", "recorder_summary", "spin_until"]


def ros_init() -> None:
    """rclpy without its signal handlers: Ctrl-C raises KeyboardInterrupt here, and the demo stops the nodes."""
    rclpy.init(signal_handler_options=SignalHandlerOptions.NO)


def plant_params(args, wait_subscribers: int, **params) -> dict:
    """The plant node's parameters for a demo run: ``params``, the seed, the /kite/state subscribers to wait for
    and, with ``--no-turbulence``, steady wind and no measurement noise."""
    params.update(seed=args.seed, wait_subscribers=wait_subscribers, wind_model=args.wind_model)
    if args.no_turbulence:
        params.update(turbulence=False, anemometer_noise=0.0, noise_angle_deg=0.0, noise_rate=0.0,
                      noise_tension=0.0)
    return params


def spin_until(pred, node, timeout: float, period: float = 0.05) -> bool:
    """Spin ``node`` (``period`` s at a time) until ``pred()`` is true or ``timeout`` wall s passed; return
    ``pred()``."""
    end = time.monotonic() + timeout
    while time.monotonic() < end:
        if pred():
            return True
        rclpy.spin_once(node, timeout_sec=period)
    return pred()


def start_recorder(args, log, env, rec, procs) -> int:
    """With ``--record``: start kite_record as a process and wait until it listens; return the number of extra
    /kite/state subscribers the plant must wait for (0 or 1)."""
    if not args.record:
        return 0
    Path(args.record).resolve().parent.mkdir(parents=True, exist_ok=True)
    before = rec.count_subscribers(STATE)
    recorder = NodeProcess("record", log=log, env=env,
                           cmd=[sys.executable, "-m", "kite_rto.tools.record", "--out", str(args.record)])
    procs.append(recorder)
    spin_until(lambda: rec.count_subscribers(STATE) > before or not recorder.alive(), rec, 60.0, period=0.1)
    if not recorder.alive():
        raise RuntimeError(f"the recorder exited (code {recorder.proc.returncode}): "
                           + " | ".join(recorder.lines[-3:]))
    print(f"  recording every topic to {args.record}", flush=True)
    return 1


def recorder_summary(procs) -> None:
    """Print what the recorder process said it wrote (or that it said nothing)."""
    for p in procs:
        if p.name == "record":
            said = [ln for ln in p.lines if "wrote" in ln]
            print(f"  {said[-1].strip()}" if said else f"  the recorder said nothing; see nodes.log (exit code "
                  f"{p.proc.returncode})", flush=True)
