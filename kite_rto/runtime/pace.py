"""Pacing of the real-time plant: the rate it can hold, measured from its own lag.

The real-time plant steps every ``dt / rate`` wall seconds and flies the last steering command it accepted
(zero-order hold). Two measurements say that a requested ``rate_factor`` cannot be held:

- **command lag**: the command answering sample k arrives when the plant is already at sample k + lag. The loop
  then flies with ``lag * dt`` simulated seconds of delay on top of the kite's dead time, and the lag grows in
  proportion to the rate (the wall-clock round trip is set by the machine). Without this pacer, ``rate_factor``
  100 on the project's busy 2-core machine ran at about 41x and the kite crashed 7 and 8 times in two runs of 20 s
  wall (``benchmarks/bench_rate.py``); the pure closed loop with a constant extra lag of up to 25
  samples flew 120 s on 2 seeds without a crash, its lowest altitude dropping beyond 10 samples;
- **schedule**: the plant itself steps fewer samples per wall second than the rate asks for (stepping and
  publishing take longer than ``dt / rate``).

:class:`RealtimePacer` turns them into an effective rate. The lag decides: when the median lag of a window of
commands is above ``max_lag`` the rate is lowered at once (aiming at 0.6 of it), and so it is when the controller
answers fewer than half of a window's samples (it drops samples it cannot keep up with: at ``rate_factor`` 100,
without this second rule, the controller logged lost samples from the start, the pacer took no lag decision for
4 s and the kite crashed twice); it is raised again by ``speed_up`` after ``hold_time`` wall seconds without
either, never above the requested rate. It never goes below ``min(rate_factor, 1)``: a sped-up simulation is a
convenience that can be slowed down, but real time is the stand-in for a real kite, which does not wait for a slow
controller; there the plant only warns. The schedule is reported, not acted on: a plant that steps slower than
asked already runs as fast as the machine lets it, and lowering its timer to the rate it achieved would only
ratchet the rate down (on a busy machine a timer always achieves a little less than its rate); what makes a
too-fast loop unsafe is the lag, and that is measured.
Pure (no ROS): the plant node passes wall times and lags in.
"""
from __future__ import annotations

import math
from dataclasses import dataclass

__all__ = ["PaceSettings", "PaceChange", "RealtimePacer"]


@dataclass(frozen=True)
class PaceSettings:
    """Settings of :class:`RealtimePacer`.

    max_lag: samples; median lag of the commands of a lag window above which the rate is too high (the pure
    closed loop flies without a crash up to 25 samples of constant extra lag; beyond 10 its lowest altitude drops).
    lag_window: samples per lag window (1 s simulated at dt = 0.02 s: at high rates a decision every few wall ms).
    min_commands: commands a lag window needs for its median to count.
    min_answered: share of a lag window's samples that must be answered when any is: a controller that answers
    fewer (it drops samples it cannot keep up with) is as much a sign of a too-high rate as a large lag.
    schedule_window: wall s per schedule window (long, so that a busy machine's hiccup is not taken for a rate the
    plant cannot hold).
    behind: achieved / effective rate below which the plant itself cannot keep pace.
    hold_time: wall s of holding well before the rate is raised again.
    speed_up: factor by which it is raised.
    """

    max_lag: float = 10.0
    lag_window: int = 50
    min_commands: int = 10
    min_answered: float = 0.5
    schedule_window: float = 2.0
    behind: float = 0.8
    hold_time: float = 2.0
    speed_up: float = 1.25

    def __post_init__(self):
        checks = {"max_lag": self.max_lag >= 1, "lag_window": self.lag_window >= 1,
                  "min_commands": self.min_commands >= 1, "min_answered": 0 < self.min_answered <= 1,
                  "schedule_window": self.schedule_window > 0,
                  "behind": 0 < self.behind < 1, "hold_time": self.hold_time >= 0, "speed_up": self.speed_up > 1}
        for name, ok in checks.items():
            if not ok:
                raise ValueError(f"PaceSettings.{name} = {getattr(self, name)!r}: out of range")


@dataclass(frozen=True)
class PaceChange:
    """A decision of the pacer, for the plant's log.

    rate: new effective rate, sim s per wall s; previous: the one before; requested: the rate_factor asked for;
    lag: median command lag of the lag window that decided, samples (None: not a lag decision); answered: share of
    that window's samples that were answered, when too few were (else None); achieved: sim s per wall s the plant
    stepped in the schedule window that decided (None: not a schedule decision). When the rate is
    already at ``min(requested, 1)`` and still too high, ``rate == previous`` (the plant warns, nothing changes).
    """

    rate: float
    previous: float
    requested: float
    lag: float | None = None
    achieved: float | None = None
    answered: float | None = None

    @property
    def slower(self) -> bool:
        """A too-high rate was measured (the rate was lowered, or is at its floor); else it was raised."""
        return self.lag is not None or self.achieved is not None or self.answered is not None

    def reason(self, dt: float) -> str:
        """What was measured, in words (``dt``: the sample time, s)."""
        if self.lag is not None:
            return (f"steering commands arrive {self.lag:.0f} samples ({self.lag * dt:.2f} s simulated) after their "
                    "sample")
        if self.answered is not None:
            return f"the controller answered only {100 * self.answered:.0f} % of the samples"
        if self.achieved is not None:
            return f"the plant steps at only {self.achieved:.1f}x"
        return "held well"

    def message(self, dt: float, first: bool) -> str:
        """The plant's log line: ``first`` for the one warning about a rate it cannot hold."""
        if first:
            if self.rate < self.previous:
                what = (f"slowing down to {self.rate:.1f}x (it adapts to what the machine holds; a lower rate_factor "
                        "avoids this)")
            elif self.achieved is None:
                what = f"already at {self.rate:g}x, the lowest it slows down to: the kite flies with that lag"
            else:
                what = "it runs as fast as it can (a lower rate_factor avoids this)"
            return f"cannot hold rate_factor {self.requested:g}: {self.reason(dt)}; {what}"
        if not self.slower and self.rate == self.requested:
            return f"real time: back at rate_factor {self.requested:g} ({self.reason(dt)})"
        return f"real time: {self.rate:.1f}x of rate_factor {self.requested:g} ({self.reason(dt)})"


class RealtimePacer:
    """The effective real-time rate of the plant (see the module docstring).

    Call :meth:`command` for every steering command whose stamp is a sample the plant published (accepted, or
    rejected as stale: both tell the lag), :meth:`step` after every step; it returns a :class:`PaceChange` when the
    rate changes (or is too high at its floor), else None. :meth:`request` sets a new requested rate.
    """

    def __init__(self, dt: float, requested: float, now: float, settings: PaceSettings | None = None):
        if not (dt > 0 and requested > 0):
            raise ValueError(f"RealtimePacer: dt = {dt!r} s and requested rate = {requested!r}: expected both > 0")
        self.dt = dt
        self.settings = settings or PaceSettings()
        self.request(requested, now)

    @property
    def floor(self) -> float:
        """The lowest effective rate: min(requested, 1)."""
        return min(self.requested, 1.0)

    def request(self, rate: float, now: float) -> None:
        """A new requested rate (``rate_factor`` changed at runtime): start from it again."""
        self.requested = self.rate = float(rate)
        self._held_since = self._t0 = now
        self._steps = self._lag_steps = 0
        self._lags: list = []

    def command(self, lag_samples: float) -> None:
        """A command answering the sample ``lag_samples`` samples before the current one arrived."""
        self._lags.append(lag_samples)

    def step(self, now: float) -> PaceChange | None:
        """One step done at wall time ``now`` (s, monotonic): close a full window and decide."""
        s = self.settings
        self._steps += 1
        self._lag_steps += 1
        change = None
        if self._lag_steps >= s.lag_window:
            lags = sorted(self._lags)
            self._lag_steps, self._lags = 0, []
            share = len(lags) / s.lag_window
            if len(lags) >= s.min_commands and lags[len(lags) // 2] > s.max_lag:
                lag = lags[len(lags) // 2]
                change = self._lower(self.rate * max(0.25, min(0.8, 0.6 * s.max_lag / lag)), now, lag=lag)
            elif 0 < share < s.min_answered:
                change = self._lower(self.rate * max(0.25, min(0.8, 0.8 * share)), now, answered=share)
        wall = now - self._t0
        if change is None and wall >= s.schedule_window:
            achieved = self._steps * self.dt / wall
            self._t0, self._steps = now, 0
            if achieved < s.behind * self.rate:
                change = PaceChange(self.rate, self.rate, self.requested, achieved=achieved)
        if change is None and self.rate < self.requested and now - self._held_since >= s.hold_time:
            change = PaceChange(min(self.requested, self.rate * s.speed_up), self.rate, self.requested)
            self.rate = change.rate
            self._held_since = now
        return change

    def _lower(self, rate: float, now: float, **measured) -> PaceChange:
        self._held_since = now
        change = PaceChange(max(self.floor, min(self.rate, rate)), self.rate, self.requested, **measured)
        self.rate = change.rate
        return change
