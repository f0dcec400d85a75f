"""The main job's progress lines: the live line (in place on a terminal), the ETA text and the GMA run's progress.

Pure formatting and timing: no ROS, so the lines are unit-tested without a graph (``test/tools/test_demo_cli.py``).
"""
from __future__ import annotations

import math
import sys
import time

__all__ = ["Progress", "OptimizeProgress", "eta_text"]


def eta_text(seconds) -> str:
    """``ETA 1 min 05 s`` / ``ETA 42 s`` / ``ETA ?`` for a remaining wall time in s (None or not finite: unknown)."""
    if seconds is None or not math.isfinite(seconds) or seconds < 0:
        return "ETA ?"
    seconds = round(seconds)
    return f"ETA {seconds // 60} min {seconds % 60:02d} s" if seconds >= 60 else f"ETA {seconds} s"


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


class OptimizeProgress:
    """Progress of the GMA run from the optimizer's /rto/status: iteration k/N, experiment, ETA.

    The ETA extrapolates the wall time per finished experiment of this run (experiments of earlier runs, when
    resuming, do not count) to the experiments still to do; before the first one finishes it is unknown.
    """

    def __init__(self, n_iter: int, per_iteration: int):
        self.n_iter = n_iter
        self.per_iteration = per_iteration
        self.done0 = None
        self.t0 = None

    def text(self, status: dict, sim_t: float, wall_flying: float) -> str:
        """The progress line for the last /rto/status key/values, simulated time ``sim_t`` (s) and the wall time
        since the first sample ``wall_flying`` (s)."""
        try:
            k = int(status.get("iteration", 0))
            done = int(status.get("experiments_done", 0))
        except ValueError:
            k, done = 0, 0
        if self.done0 is None and status:
            self.done0, self.t0 = done, wall_flying
        total = self.n_iter * self.per_iteration
        in_iter = done - k * self.per_iteration
        if k >= self.n_iter:
            return f"  t = {sim_t:6.0f} s sim, all {self.n_iter} iterations done, finishing"
        eta = None
        if self.done0 is not None and done > self.done0:
            per_exp = (wall_flying - self.t0) / (done - self.done0)
            eta = per_exp * max(total - done, 0)
        rate = sim_t / max(wall_flying, 1e-9)
        exp = status.get("experiment", "")
        return (f"  t = {sim_t:6.0f} s sim ({rate:4.1f}x real time), "
                f"iteration {min(k + 1, self.n_iter)}/{self.n_iter}, "
                f"experiment {min(max(in_iter, 0) + 1, self.per_iteration)}/{self.per_iteration}"
                + (f" ({exp})" if exp else "") + f", {100.0 * done / max(total, 1):3.0f} % done, {eta_text(eta)}")
