"""Optimizer synchronization of the controller's steering loop (``sync_optimizer:=true``, lockstep).

Sample k is answered once the optimizer's /rto/sync message for it is in (the setpoints in force, applied first
when its count of setpoint messages changed: the pure runner's order). Once a sync message has arrived, every
sample waits for its own, however long the optimizer takes (a restarted optimizer picks the loop up again): the
answer never depends on wall time or on what the graph shows. Only a controller that has never heard from an
optimizer answers unsynchronized, once no publisher of /rto/sync has been in the graph for :data:`SYNC_ABSENT` s
(no optimizer at all), and from then on at once until a sync message arrives; /rto/setpoints then applies at the
sample boundary as without synchronization.

:class:`OptimizerSync` is this state and its decisions, owned by :class:`~.steering_loop.SteeringLoop`: which
sample is held, which sync entries wait for their samples, whether an optimizer is known. It never steers: each
method that ends a wait returns the held sample, and the loop answers it.
"""
from __future__ import annotations

import math

__all__ = ["OptimizerSync", "SYNC_ABSENT", "SYNC_WAIT_LOG", "SYNC_NAMES", "keep"]

SYNC_ABSENT = 1.0
"""Wall s a sample waits, before any /rto/sync has arrived, while no optimizer is in the graph."""
SYNC_WAIT_LOG = 10.0
"""Wall s between the log lines of a sample that waits for a slow optimizer."""
SYNC_NAMES = ["theta_0", "A_phi", "A_theta", "updates"]
"""Names of a /rto/sync message: the setpoints in force (rad) and the optimizer's setpoint-message count."""
KEEP = 64
"""Anemometer readings and sync entries kept ahead of their samples."""


def keep(entries: dict, stamp: int, value) -> None:
    """Store ``value`` at ``stamp``, forgetting the oldest entry when :data:`KEEP` are held."""
    if len(entries) >= KEEP:
        del entries[next(iter(entries))]
    entries[stamp] = value


class OptimizerSync:
    """Holds each sample for the optimizer's sync message (see the module docstring).

    ``enabled``: synchronization asked for (``sync_optimizer``); ``log`` has ``info``/``warning``; ``reject(what,
    why)`` reports a bad message; ``clock()`` is the wall time; ``sync_sources()`` counts the publishers of /rto/sync.
    A held sample is ``(stamp, measurement, position, wall time held)``.
    """

    def __init__(self, enabled: bool, *, log, reject, clock, sync_sources):
        self.enabled = enabled
        self.log, self.reject, self._clock, self._sync_sources = log, reject, clock, sync_sources
        self.held = None                  # (stamp, measurement, position, wall time): waits for its sync
        self._syncs = {}                  # sync entries by stamp (ns): (setpoints rad, updates)
        self._lost = False                # no optimizer: answer at once until a sync message arrives again
        self._updates = None              # `updates` of the last applied sync
        self._seen = -math.inf            # wall time an optimizer was last seen in the graph while a sample waited

    def synchronized(self) -> bool:
        """True while samples wait for the optimizer's sync message."""
        return self.enabled and not self._lost

    def entry(self, stamp: int):
        """The sync entry ``(setpoints, updates)`` of the sample ``stamp`` if it is in (None if not); older entries
        are forgotten."""
        entry = self._syncs.pop(stamp, None)
        if self._syncs:
            for s in [s for s in self._syncs if s < stamp]:
                del self._syncs[s]
        return entry

    def hold(self, stamp: int, m, pos) -> bool:
        """Hold the sample (its entry not in) until its sync message arrives: False (answer it now) once no
        optimizer is known."""
        if self._lost:
            return False
        self.held = (stamp, m, pos, self._clock())
        return True

    def changes(self, c, updates: float, flown) -> bool:
        """True if the synced setpoints ``c`` must be applied: the optimizer's count of setpoint messages changed,
        or ``c`` differs from the setpoints ``flown`` (lists, rad)."""
        if updates != self._updates or c != flown:
            self._updates = updates
            return True
        return False

    def parse(self, names, values):
        """A /rto/sync message's entry ``(setpoints, updates)``, or None (rejected) if it is malformed."""
        vals = [float(x) for x in values]
        if list(names) != SYNC_NAMES or len(vals) != 4 or not all(map(math.isfinite, vals)):
            self.reject("sync", f"rejected sync message {(list(names), vals)!r}: expected names {SYNC_NAMES} "
                                "with 4 finite values")
            return None
        return vals[:3], vals[3]

    def arrived(self, stamp: int, entry, last: int | None):
        """The optimizer has processed the sample ``stamp`` (the loop's last answered sample: ``last``): the held
        sample if it is that one (the loop applies ``entry`` and answers it), else None (the entry is kept for a
        sample still to come)."""
        if self._lost:
            self._lost = False
            self.log.info("/rto/sync is back: answering each sample after the optimizer again")
        held = self.held
        if held is not None and held[0] == stamp:
            self.held = None
            return held
        if last is None or stamp > last:
            keep(self._syncs, stamp, entry)
        return None

    def overdue(self):
        """The held sample if it is to be answered unsynchronized because there is no optimizer at all (called
        periodically), else None."""
        held = self.held
        if held is None:
            return None
        now = self._clock()
        if self._updates is not None or self._sync_sources() > 0:
            self._seen = now
            if now - held[3] > SYNC_WAIT_LOG:
                self.log.info(f"sample at {held[0] * 1e-9:.2f} s: waiting {now - held[3]:.0f} s for the optimizer's "
                              "/rto/sync", throttle_duration_sec=SYNC_WAIT_LOG)
        elif now - max(held[3], self._seen) > SYNC_ABSENT:
            return self.release(f"no optimizer in the graph for {SYNC_ABSENT:g} s")
        return None

    def release(self, why: str):
        """Stop waiting for the held sample (returned: the loop answers it with the latest setpoints); answer at once
        until a sync message is back."""
        held = self.held
        self.held = None
        self._lost = True
        self.log.warning(f"sample at {held[0] * 1e-9:.2f} s: {why}; steering unsynchronized until the "
                         "optimizer's /rto/sync is back")
        return held
