"""Join the plant's per-sample messages (state, tension, position, wind) by stamp into one measurement.

DDS orders messages per topic, not across topics; the optimizer needs all four readings of a sample. A sample is
released when its four parts are in; parts of older samples that never completed are dropped.
"""
from __future__ import annotations

from types import SimpleNamespace

__all__ = ["SampleJoin"]

PARTS = ("state", "tension", "position", "wind")


class SampleJoin:
    """Collects parts keyed by stamp (ns); :meth:`add` returns the completed measurement or None."""

    def __init__(self, max_pending: int = 50):
        self._pending: dict[int, dict] = {}
        self._last = -1
        self.max_pending = max_pending
        self.crashes = 0

    def reset(self) -> None:
        """Forget everything (after a plant restart: sim time jumped back)."""
        self._pending.clear()
        self._last = -1

    def add(self, stamp: int, part: str, value) -> SimpleNamespace | None:
        if stamp <= self._last:
            return None                           # duplicate (lockstep re-publish) or stale
        entry = self._pending.setdefault(stamp, {})
        entry[part] = value
        if len(entry) < len(PARTS):
            if len(self._pending) > self.max_pending:
                del self._pending[min(self._pending)]
            return None
        del self._pending[stamp]
        for old in [s for s in self._pending if s < stamp]:
            del self._pending[old]
        self._last = stamp
        (theta, phi, psi), tension, position, wind = (entry[p] for p in PARTS)
        return SimpleNamespace(t=stamp * 1e-9, theta=theta, phi=phi, psi=psi, tension=tension, position=position,
                               wind_ref=wind, crashes=self.crashes, stamp=stamp)
