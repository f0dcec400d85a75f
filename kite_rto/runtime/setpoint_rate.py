"""How fast the setpoints change: a warning when /rto/setpoints changes faster than the path can follow.

The controller follows a setpoint change by blending to the new figure-eight over ``blend_time`` (10 s by
default); a lap takes about 20 s, and the optimizer changes the setpoints once per experiment (``settle_time``
plus ``settle_laps + n_laps`` laps: at least a lap, about two minutes with its defaults). Setpoints that change
more than :data:`RATE_LIMIT` times within :data:`RATE_WINDOW` s of flight (more than once per 10 s on average, a
new path before the last one was blended in) cannot be flown: each change restarts the blend and the lap
statistics. They come from a wrong or rogue publisher, and :class:`SetpointRate` warns about them.

Counting: a change is a valid message whose values differ from those of the previous valid message (a republished
identical value is not a change), counted on arrival whether or not it is applied. Time is flight time: the stamp of
the latest sample the loop answered (simulated s; wall s when the plant runs in real time), so the verdict is the
same however fast the simulation runs; a flight time that goes back (a plant restart) starts the count anew.

Warning: a change opens an interval; at the first sample at least :data:`RATE_PERIOD` s of flight after its
opening, and :data:`RATE_PERIOD` wall s after the last warning, the interval closes, with one warning if one of
its changes made the last :data:`RATE_WINDOW` s of flight hold more than :data:`RATE_LIMIT`. The warning gives the
number of changes in the interval and their rate per second of flight, and names the publishers of /rto/setpoints
seen in the graph while the changes arrived (a look at most every :data:`LOOK_PERIOD` wall s, at a sample after a
change; the publisher may have left by the time the interval closes). DDS gives an rclpy callback no per-message
sender (see :mod:`.sources`): with one publisher the changes are its own, with several the warning names them all.
"""
from __future__ import annotations

import math
import time
from collections import deque

from .sources import UNKNOWN_NODE, describe

__all__ = ["SetpointRate", "RATE_WINDOW", "RATE_LIMIT", "RATE_PERIOD", "LOOK_PERIOD"]

RATE_WINDOW = 60.0
"""s of flight over which setpoint changes are counted."""
RATE_LIMIT = 6
"""Setpoint changes within :data:`RATE_WINDOW` s of flight that can still be flown (one per 10 s: the default
``blend_time``); more are warned about."""
RATE_PERIOD = 10.0
"""s of flight, and wall s, between two warnings about the rate of setpoint changes (the length of an interval)."""
LOOK_PERIOD = 0.5
"""Wall s between two looks at the graph for the publishers of changing setpoints (a look costs about 0.1 ms)."""


class SetpointRate:
    """Counts setpoint changes per second of flight and warns, once per interval, when they cannot be flown.

    ``logger`` has ``warning``; ``publishers()`` lists the publishers of /rto/setpoints
    (:class:`~.sources.Publisher`), asked while the setpoints change (at most every :data:`LOOK_PERIOD` wall s);
    ``source``: the controller's ``setpoint_source`` (fully qualified) or None; ``clock`` gives wall seconds.
    :meth:`message` takes each valid message (cheap), :meth:`flight` the flight time of each answered sample.
    :attr:`warnings` counts the warnings.
    """

    def __init__(self, logger, publishers=lambda: [], source: str | None = None, clock=time.monotonic,
                 window: float = RATE_WINDOW, limit: int = RATE_LIMIT, period: float = RATE_PERIOD):
        self.log, self._publishers, self.source, self._clock = logger, publishers, source, clock
        self.window, self.limit, self.period = window, limit, period
        self._prev = None                   # values of the previous valid message
        self._t = None                      # flight time of the latest answered sample, s (None: no flight yet)
        self._changes = deque()             # [flight time, changes] of the last window, oldest first
        self._in_window = 0                 # changes in _changes
        self._opened = None                 # flight time the current interval opened (None: no interval)
        self._in_interval = 0               # changes in the current interval
        self._peak = 0                      # the most changes the window held at a change of the interval
        self._warned_at = -math.inf         # wall time of the last warning
        self._seen = {}                     # gid -> Publisher seen in the graph during the current interval
        self._unseen = False                # changes since the last look at the graph
        self._looked_at = -math.inf         # wall time of that look
        self.changes = self.warnings = 0    # totals since start-up

    def message(self, values) -> None:
        """A valid setpoint message (its values, in a fixed order): counted if they differ from the previous."""
        if values == self._prev:
            return
        self._prev = list(values)
        self.changes += 1
        self._unseen = True
        self._in_window += 1
        self._in_interval += 1
        if self._changes and self._changes[-1][0] == self._t:
            self._changes[-1][1] += 1
        else:
            self._changes.append([self._t, 1])
        if self._opened is None:
            self._opened = self._t
        self._peak = max(self._peak, self._in_window)

    def flight(self, t: float) -> None:
        """A sample stamped ``t`` (s of flight) was answered: the window moves on; an interval may close."""
        if self._t is not None and t < self._t:              # the flight time went back: a new flight
            self._changes.clear()
            self._in_window = self._in_interval = self._peak = 0
            self._opened, self._seen = None, {}
        elif self._t is None:                                 # changes before the first sample: at this one
            for entry in self._changes:
                entry[0] = t
            if self._in_interval:
                self._opened = t
        self._t = t
        while self._changes and self._changes[0][0] <= t - self.window:
            self._in_window -= self._changes.popleft()[1]
        if self._opened is None:
            return
        now = self._clock()
        if self._unseen and now - self._looked_at >= LOOK_PERIOD:
            self._look(now)
        if t - self._opened < self.period or now - self._warned_at < self.period:
            return                                            # the interval stays open until a warning may come
        n, peak, span = self._in_interval, self._peak, t - self._opened
        self._opened, self._in_interval, self._peak = None, 0, 0
        if n and peak > self.limit:
            if self._unseen:
                self._look(now)
            self._warned_at = now
            self.warnings += 1
            self.log.warning(self._text(n, span, t, peak))
        self._seen = {}

    def _look(self, now: float) -> None:
        """Note the publishers in the graph (a name learnt later replaces :data:`~.sources.UNKNOWN_NODE`)."""
        self._unseen, self._looked_at = False, now
        for p in self._publishers():
            if p.gid not in self._seen or p.node != UNKNOWN_NODE:
                self._seen[p.gid] = p

    def _text(self, n: int, span: float, t: float, peak: int) -> str:
        pubs = list(self._seen.values())
        if not pubs:
            who = "a publisher not seen in the graph"
        elif len(pubs) == 1:
            who = describe(pubs)
        else:
            who = f"one of {describe(pubs)} (a message does not tell its sender)"
        hint = (f"setpoint_source is {self.source}: only its setpoints apply, none while another node publishes"
                if self.source else "parameter setpoint_source (e.g. /optimizer) restricts /rto/setpoints to "
                                    "one node")
        return (f"setpoints change faster than the path can follow: {who} changed /rto/setpoints {n} times in "
                f"{span:.1f} s of flight up to t = {t:.1f} s ({n / span:.1f} changes per s of flight; "
                f"up to {peak} within {self.window:g} s of flight, expected at most {self.limit}: a change "
                f"blends in over blend_time and a lap takes about 20 s); a wrong or rogue publisher? {hint}")
