"""The lockstep plant waits for lossless recorders (:class:`RecorderGate`): a recording of a simulated flight need
not lose a sample, since in lockstep the simulation has all the time in the world.

A recorder started with ``kite_record --lossless`` acknowledges on ``/kite/recorded`` the simulated time up to which
it has written every sample of the plant's topics (``std_msgs/Header``: ``stamp`` that time, ``frame_id`` the
recorder's node). A lockstep plant does not publish a sample more than :data:`WINDOW_SAMPLES` ahead of any such
recorder it has heard, so the recorder's queues (deeper than the window) never overflow, however busy the machine
or however long the recorder is stopped. A recorder that leaves the graph is no longer waited for; one that stays in
the graph but does not catch up within ``timeout`` wall seconds (stopped, or starved) is left behind with a warning,
and waited for again once it has caught up: the loop goes on, and the recording's own gap report says where it is
incomplete. The real-time plant never waits.
"""
from __future__ import annotations

__all__ = ["RecorderGate", "WINDOW_SAMPLES"]

WINDOW_SAMPLES = 250
"""Samples a lockstep plant may publish ahead of a lossless recorder's acknowledgement: well below the plant's
publisher history and the recorder's queues (1000 samples each), well above the recorder's acknowledgement step."""


class RecorderGate:
    """Whether the plant may publish its next sample (see the module docstring).

    Args:
        window_ns: how far (ns of simulated time) a sample may be ahead of a recorder's acknowledgement.
        timeout: wall seconds a lagging recorder in the graph is waited for before the loop goes on without it.
        clock: wall time, s (monotonic).
        log: has ``info`` and ``warning``.
        recorders: the names of the nodes that publish acknowledgements now (the graph).
    """

    def __init__(self, window_ns: int, timeout: float, *, clock, log, recorders):
        self.window_ns, self.timeout = int(window_ns), float(timeout)
        self._clock, self.log, self._recorders = clock, log, recorders
        self.acked: dict = {}               # recorder -> simulated time (ns) written through
        self.left_behind: set = set()       # recorders the loop went on without (until they catch up)
        self._waiting_since = None          # wall time the current wait began
        self.waits = 0                      # times the plant had to wait

    def ack(self, recorder: str, stamp: int, current: int) -> None:
        """``recorder`` has written every sample through ``stamp`` (ns); ``current``: the plant's latest sample."""
        self.acked[recorder] = max(stamp, self.acked.get(recorder, stamp))
        if recorder in self.left_behind and current - stamp <= self.window_ns:
            self.left_behind.discard(recorder)
            self.log.info(f"lossless recorder {recorder} caught up: waited for again")

    def may_publish(self, stamp: int) -> bool:
        """True if the sample stamped ``stamp`` (ns) may be published: no recorder waited for lags more than the
        window behind it (recorders that left the graph forgotten; after ``timeout`` s the laggards left behind)."""
        lagging = [r for r, s in self.acked.items() if r not in self.left_behind and stamp - s > self.window_ns]
        if not lagging:
            self._waiting_since = None
            return True
        present = set(self._recorders())
        for r in [r for r in lagging if r not in present]:
            del self.acked[r]
            self.log.info(f"lossless recorder {r} left the graph: not waited for any more")
        lagging = [r for r in lagging if r in present]
        if not lagging:
            self._waiting_since = None
            return True
        now = self._clock()
        if self._waiting_since is None:
            self._waiting_since = now
            self.waits += 1
        if now - self._waiting_since < self.timeout:
            return False
        for r in lagging:
            self.left_behind.add(r)
            self.log.warning(f"lossless recorder {r} has written only through {self.acked[r] * 1e-9:.2f} s of "
                             f"simulated time after {self.timeout:g} s of waiting at {stamp * 1e-9:.2f} s: going on "
                             "without it (its file will say which samples it misses)")
        self._waiting_since = None
        return True
