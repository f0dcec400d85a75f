"""Optimizer synchronization of the controller's steering loop (``sync_optimizer:=true``, lockstep).

Sample k is answered once the optimizer's /rto/sync message for it is in (the setpoints in force, applied first
when its count of setpoint messages changed: the pure runner's order). Once a sync message has arrived, every
sample waits for its own, however long the optimizer takes (a restarted optimizer picks the loop up again): the
answer never depends on wall time or on what the graph shows. Only a controller that has never heard from an
optimizer answers unsynchronized, once no publisher of /rto/sync has been in the graph for :data:`SYNC_ABSENT` s
(no optimizer at all), and from then on at once until a sync message arrives; /rto/setpoints then applies at the
sample boundary as without synchronization.

:class:`OptimizerSync` is the half of :class:`~.steering_loop.SteeringLoop` that does this; it uses the loop's
``_steer``, ``_apply_setpoints``, ``_take_setpoints``, ``_stamp_near``, ``reject``, ``log``, ``_clock``,
``_sync_sources``, ``timeline`` and ``controller``.
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
    """Holds each sample for the optimizer's sync message (see the module docstring); a mixin of SteeringLoop."""

    def _init_sync(self, sync: bool) -> None:
        self.sync = sync
        self._syncs = {}                  # sync entries by stamp (ns): (setpoints rad, updates)
        self._sync_held = None            # (stamp, measurement, position, wall time): waits for its sync
        self._sync_lost = False           # no optimizer: answer at once until a sync message arrives again
        self._sync_updates = None         # `updates` of the last applied sync
        self._sync_seen = -math.inf       # wall time an optimizer was last seen in the graph while a sample waited

    def synchronized(self) -> bool:
        """True while samples wait for the optimizer's sync message."""
        return self.sync and not self._sync_lost

    def _wait_for_sync(self, stamp: int) -> bool:
        """True to hold the sample stamped ``stamp`` for its sync; applies the sync message if it is in."""
        entry = self._syncs.pop(stamp, None)
        if self._syncs:
            for s in [s for s in self._syncs if s < stamp]:
                del self._syncs[s]
        if entry is not None:
            self._apply_sync(*entry)
            return False
        return not self._sync_lost

    def _apply_sync(self, c, updates: float) -> None:
        if updates != self._sync_updates or c != self.controller.setpoints.as_array().tolist():
            self._sync_updates = updates
            self._apply_setpoints(c)

    def sync_message(self, stamp: int, names, values) -> None:
        """The optimizer has processed the sample ``stamp``: ``values`` are :data:`SYNC_NAMES`."""
        vals = [float(x) for x in values]
        if list(names) != SYNC_NAMES or len(vals) != 4 or not all(map(math.isfinite, vals)):
            self.reject("sync", f"rejected sync message {(list(names), vals)!r}: expected names {SYNC_NAMES} "
                                "with 4 finite values")
            return
        if not self._stamp_near("sync", stamp):
            return
        if self._sync_lost:
            self._sync_lost = False
            self.log.info("/rto/sync is back: answering each sample after the optimizer again")
        held = self._sync_held
        if held is not None and held[0] == stamp:
            self._sync_held = None
            self._apply_sync(vals[:3], vals[3])
            self._steer(*held[:3])
        elif self.timeline.last is None or stamp > self.timeline.last:
            keep(self._syncs, stamp, (vals[:3], vals[3]))

    def watchdog(self) -> None:
        """Call periodically (the node: every 0.05 s): releases a held sample when there is no optimizer at all."""
        held = self._sync_held
        if held is None:
            return
        now = self._clock()
        if self._sync_updates is not None or self._sync_sources() > 0:
            self._sync_seen = now
            if now - held[3] > SYNC_WAIT_LOG:
                self.log.info(f"sample at {held[0] * 1e-9:.2f} s: waiting {now - held[3]:.0f} s for the optimizer's "
                              "/rto/sync", throttle_duration_sec=SYNC_WAIT_LOG)
        elif now - max(held[3], self._sync_seen) > SYNC_ABSENT:
            self._release_unsynced(f"no optimizer in the graph for {SYNC_ABSENT:g} s")

    def _release_unsynced(self, why: str) -> None:
        """Answer the held sample with the latest setpoints; answer at once until a sync message is back."""
        stamp, m, pos, _ = self._sync_held
        self._sync_held = None
        self._sync_lost = True
        self.log.warning(f"sample at {stamp * 1e-9:.2f} s: {why}; steering unsynchronized until the "
                         "optimizer's /rto/sync is back")
        self._take_setpoints()
        self._steer(stamp, m, pos)
