"""Input hygiene for the nodes that read the plant: plausibility limits, throttled rejection warnings, and the
join of the plant's per-sample messages (state, tension, position, wind) by stamp into one measurement.

DDS orders messages per topic, not across topics; the optimizer needs all four readings of a sample. A sample is
released when its four parts are in; parts of older samples that never completed are dropped.

Stamps: the plant stamps every message of a sample with the sample's simulation time, and time only moves forward
while the plant runs. A complete sample (every part with the same stamp) stamped before the last one, or more than
:data:`MAX_STAMP_GAP_NS` after it, is off the timeline: a restarted plant (sim time jumped back), lost samples, or
stale/future junk. It is held as a candidate and only accepted when the next complete sample continues it (a later
stamp within the gap); if the old timeline goes on instead, it was junk and is reported. A lone part whose stamp
matches no complete sample is never used; if it is far from the timeline it is reported as stale or future too
(:attr:`SampleJoin.discarded`). The rule is :class:`Timeline`, the one the controller's
:class:`~kite_rto.runtime.steering_loop.SteeringLoop` follows too.
"""
from __future__ import annotations

import enum
import math
import time
from types import SimpleNamespace
from typing import NamedTuple

__all__ = ["SampleJoin", "CrashCount", "Timeline", "Place", "Placement", "RejectLog", "state_values", "reading_error",
           "MAX_STAMP_GAP_NS", "ANGLE_MAX", "PSI_MAX", "RATE_MAX", "TENSION_MAX", "POSITION_MAX", "WIND_MAX"]

PARTS = ("state", "tension", "position", "wind")

MAX_STAMP_GAP_NS = 1_000_000_000
"""A stamp more than this (1 s of simulation time) away from the last sample is stale or future."""

# Plausibility limits of the measurements (anything outside is a bad message, not a kite):
ANGLE_MAX = math.pi          # |theta|, |phi|, rad
PSI_MAX = 1000.0             # |psi|, rad (psi is not wrapped: it may wind up over loops)
RATE_MAX = 1.0e4             # |theta_dot|, |phi_dot|, |psi_dot|, rad/s (a crash dive reaches 120-270 rad/s)
TENSION_MAX = 1e7            # line tension, N (the default kite pulls about 6e5 N)
POSITION_MAX = 1e4           # |x|, |y|, |z|, m (tether 400 m by default)
WIND_MAX = 100.0             # anemometer, m/s (in [0, WIND_MAX))
STATE_NAMES = ["theta", "phi", "psi"]


def state_values(names, position, velocity) -> tuple[list, list]:
    """``(position, velocity)`` of a /kite/state message as floats; raises ``ValueError`` saying what is wrong."""
    names = list(names)
    if names != STATE_NAMES:
        raise ValueError(f"names {names!r}: expected {STATE_NAMES}")
    pos, vel = [float(v) for v in position], [float(v) for v in velocity]
    if len(pos) != 3 or len(vel) != 3:
        raise ValueError(f"{len(pos)} positions and {len(vel)} velocities: expected 3 of each")
    if not all(map(math.isfinite, pos + vel)):
        raise ValueError(f"position {pos!r}, velocity {vel!r}: expected finite numbers")
    if abs(pos[0]) > ANGLE_MAX or abs(pos[1]) > ANGLE_MAX or abs(pos[2]) > PSI_MAX:
        raise ValueError(f"position {pos!r}: expected |theta|, |phi| <= pi rad and |psi| <= {PSI_MAX:g} rad")
    if max(map(abs, vel)) > RATE_MAX:
        raise ValueError(f"velocity {vel!r}: expected rates within +-{RATE_MAX:g} rad/s")
    return pos, vel


def reading_error(part: str, value) -> str | None:
    """Why a ``tension`` (N), ``position`` ((x, y, z) m) or ``wind`` (m/s) reading is rejected, or None if plausible."""
    if part == "tension":
        if not (math.isfinite(value) and 0.0 <= value <= TENSION_MAX):
            return f"rejected tension message {value!r}: expected a finite force in [0, {TENSION_MAX:g}] N"
    elif part == "position":
        if not all(math.isfinite(x) and abs(x) <= POSITION_MAX for x in value):
            return f"rejected position message {list(value)!r}: expected finite coordinates within " \
                   f"+-{POSITION_MAX:g} m"
    elif part == "wind":
        if not (math.isfinite(value) and 0.0 <= value < WIND_MAX):
            return f"rejected wind message {value!r}: expected a finite speed in [0, {WIND_MAX:g}) m/s"
    else:
        raise ValueError(f"reading_error: unknown part {part!r}")
    return None


class RejectLog:
    """Throttled warnings about rejected input, throttled per ``key`` (e.g. the topic).

    The first rejection of a key is logged at once; later ones at most once per ``period`` wall seconds, saying
    how many were rejected without a warning in between. :attr:`counts` holds all rejections per key.
    """

    def __init__(self, logger, period: float = 2.0, clock=time.monotonic):
        self._logger = logger
        self.period = period
        self._clock = clock
        self._last: dict = {}
        self._quiet: dict = {}
        self.counts: dict = {}

    def __call__(self, key: str, text: str) -> None:
        self.counts[key] = self.counts.get(key, 0) + 1
        now = self._clock()
        last = self._last.get(key)
        if last is not None and now - last < self.period:
            self._quiet[key] = self._quiet.get(key, 0) + 1
            return
        self._last[key] = now
        n = self._quiet.pop(key, 0)
        self._logger.warning(text + (f" [{n} more rejected since the last warning]" if n else ""))


class Place(enum.Enum):
    """Where a complete sample falls relative to the timeline (see :meth:`Timeline.place`)."""

    NEXT = "next"                  # on the timeline (or the first sample): fly on
    RESTART = "restart"            # continues the candidate, which lay before the last sample: plant restarted
    JUMP = "jump"                  # continues the candidate, which lay far after the last sample: samples lost
    CANDIDATE = "candidate"        # off the timeline: held as the candidate of a new timeline
    REPEATED = "repeated"          # the candidate again (re-published)


class Placement(NamedTuple):
    """:meth:`Timeline.place`'s answer: the place, a candidate dropped as junk, the candidate confirmed (ns)."""

    place: Place
    dropped: int | None = None
    confirmed: int | None = None


class Timeline:
    """The restart rule, one for every node that reads the plant: where a complete sample's stamp (ns) falls.

    A sample stamped after :attr:`last` by at most ``max_gap_ns`` is the next one. Any other stamp is off the
    timeline: it becomes the :attr:`candidate` of a new timeline, confirmed only when the next complete sample
    continues it (a later stamp within ``max_gap_ns``); if the old timeline goes on instead, the candidate is
    dropped as junk. The caller moves :attr:`last` when it has used a sample.
    """

    def __init__(self, max_gap_ns: int = MAX_STAMP_GAP_NS):
        self.max_gap_ns = max_gap_ns
        self.last: int | None = None          # stamp of the last sample used, None before the first
        self.candidate: int | None = None     # stamp of a complete sample off the timeline, not yet continued

    def reset(self) -> None:
        """Forget the timeline."""
        self.last = self.candidate = None

    def on(self, stamp: int) -> bool:
        """True if ``stamp`` is the first or follows :attr:`last` within the gap."""
        return self.last is None or self.last < stamp <= self.last + self.max_gap_ns

    def near(self, stamp: int) -> bool:
        """True if ``stamp`` lies within the gap of :attr:`last` (either side), or nothing was used yet."""
        return self.last is None or abs(stamp - self.last) <= self.max_gap_ns

    def place(self, stamp: int) -> Placement:
        """Classify the complete sample ``stamp`` and update :attr:`candidate` (never :attr:`last`)."""
        cand = self.candidate
        if self.on(stamp):
            self.candidate = None
            return Placement(Place.NEXT, dropped=cand)
        if cand is not None and cand < stamp <= cand + self.max_gap_ns:
            self.candidate = None
            return Placement(Place.RESTART if stamp < self.last else Place.JUMP, confirmed=cand)
        if cand == stamp:
            return Placement(Place.REPEATED)
        self.candidate = stamp
        return Placement(Place.CANDIDATE, dropped=cand)


class CrashCount:
    """The plant's crash count (/kite/crashes) over plant restarts: a restarted plant counts from 0 again, which is
    neither a crash nor one undone. :attr:`total` is what a sample's ``crashes`` reads."""

    def __init__(self):
        self.total = 0
        self._seen = 0                    # the last count of the current plant
        self._offset = 0                  # counts of plants that restarted

    def update(self, n: int) -> int:
        """A count ``n`` published by the plant; returns :attr:`total`."""
        if n < self._seen:
            self._offset += self._seen
        self._seen = n
        self.total = self._offset + n
        return self.total


class SampleJoin:
    """Collects parts keyed by stamp (ns); :meth:`add` returns the completed measurement or None.

    Parts: ``state`` = (theta, phi, psi) rad, optionally followed by their rates rad/s (NaN when absent),
    ``tension`` N, ``position`` (x, y, z) m, ``wind`` m/s (the anemometer).

    The measurement has ``jumped_back = True`` when the timeline restarted before the previous sample (the plant
    restarted; the measurement is the second sample of the new timeline, the first one was the candidate).
    Parts and complete samples that can no longer be used and lie more than ``max_gap_ns`` behind the timeline or
    ``lead_ns`` ahead of it (default ``max_gap_ns``; a reader that takes a backlog of several topics may see one
    topic that far ahead of another) are appended to :attr:`discarded` as ``(stamp, parts)`` (stale or future junk;
    the caller reports and clears it); parts of a sample that lost one message are dropped silently.
    """

    def __init__(self, max_pending: int = 50, max_gap_ns: int = MAX_STAMP_GAP_NS, lead_ns: int | None = None):
        self._pending: dict[int, dict] = {}
        self.timeline = Timeline(max_gap_ns)
        self.max_pending = max_pending
        self.max_gap_ns = max_gap_ns
        self.lead_ns = max_gap_ns if lead_ns is None else lead_ns
        self.crashes = 0
        self.discarded: list[tuple[int, tuple]] = []

    @property
    def last(self) -> int:
        """Stamp (ns) of the last complete sample, -1 before the first."""
        return -1 if self.timeline.last is None else self.timeline.last

    def reset(self) -> None:
        """Forget everything."""
        self._pending.clear()
        self.timeline.reset()

    def add(self, stamp: int, part: str, value) -> SimpleNamespace | None:
        if stamp == self.timeline.last:
            return None                           # duplicate (lockstep re-publish)
        pending = self._pending
        entry = pending.get(stamp)
        if entry is None:
            if len(pending) >= self.max_pending:  # evict the oldest entry (first inserted): junk floods go first
                old = next(iter(pending))
                self.discarded.append((old, tuple(pending.pop(old))))
            entry = pending[stamp] = {}
        entry[part] = value
        if len(entry) < len(PARTS):
            return None
        del pending[stamp]
        place, dropped, _ = self.timeline.place(stamp)
        if dropped is not None:
            self.discarded.append((dropped, PARTS))
        if place in (Place.CANDIDATE, Place.REPEATED):
            return None
        jumped_back = place is Place.RESTART
        if pending:
            gap, lead = self.max_gap_ns, self.lead_ns
            for s in list(pending):
                if jumped_back:                   # the old timeline: gone with the old plant
                    del pending[s]
                elif s < stamp or s > stamp + lead:
                    parts = tuple(pending.pop(s))
                    if s < stamp - gap or s > stamp + lead:
                        self.discarded.append((s, parts))
        self.timeline.last = stamp
        state, tension, position, wind = (entry[p] for p in PARTS)
        theta, phi, psi = state[:3]
        theta_dot, phi_dot, psi_dot = state[3:6] if len(state) >= 6 else (math.nan,) * 3
        return SimpleNamespace(t=stamp * 1e-9, theta=theta, phi=phi, psi=psi, theta_dot=theta_dot, phi_dot=phi_dot,
                               psi_dot=psi_dot, tension=tension, position=position, wind_ref=wind,
                               crashes=self.crashes, stamp=stamp, jumped_back=jumped_back)
