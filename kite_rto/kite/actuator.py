"""The steering actuator: a dead-time line of whole samples followed by a rate limit.

Written once and used twice: by the plant (the real actuator) and by the path controller's dead-time predictor
(its own copy of the actuator, fed the commands it sent, to know what the kite will apply in the coming samples).
"""
from __future__ import annotations

from collections import deque

__all__ = ["Actuator", "step_toward"]


def step_toward(value: float, target: float, max_change: float) -> float:
    """``value`` moved towards ``target`` by at most ``max_change`` (> 0); a NaN target gives NaN."""
    change = target - value
    if change < -max_change:
        change = -max_change
    elif change > max_change:
        change = max_change
    return value + change


class Actuator:
    """Dead time then rate limit, one :meth:`push` per sample.

    Args:
        dead_time: s, rounded to whole samples of ``dt``.
        rate_limit: largest change of the applied value, 1/s (> 0).
        dt: sample time, s.

    Attributes:
        applied: the value applied now (after dead time and rate limit).
        max_change: largest change per sample, ``rate_limit * dt``.
        n_delay: dead time in samples.
    """

    def __init__(self, dead_time: float, rate_limit: float, dt: float):
        self.n_delay = round(dead_time / dt)
        self.max_change = rate_limit * dt
        self._line = deque([0.0] * self.n_delay)     # commands sent, not yet applied, oldest first
        self.applied = 0.0

    def push(self, command: float) -> float:
        """Send ``command`` and advance one sample; returns the new applied value."""
        line = self._line
        if line:
            line.append(command)
            command = line.popleft()
        mc = self.max_change                    # inlined step_toward(): this runs every sample
        change = command - self.applied
        if change < -mc:
            change = -mc
        elif change > mc:
            change = mc
        self.applied = a = self.applied + change
        return a

    def pending(self):
        """The applied values of the next ``n_delay`` samples if no new command arrived in between: the
        commands already in the line, through the rate limit (the actuator itself is not changed)."""
        a, mc = self.applied, self.max_change
        for u in self._line:
            change = u - a                      # inlined step_toward(a, u, mc): runs n_delay times per sample
            if change < -mc:
                change = -mc
            elif change > mc:
                change = mc
            a = a + change
            yield a

    def reset(self) -> None:
        """Empty the line (all zero) and apply 0."""
        self._line = deque([0.0] * self.n_delay)
        self.applied = 0.0
