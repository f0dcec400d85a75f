"""Log times of a recording on simulated time, read straight from the CDR bytes (nothing is deserialized).

Used by ``kite_record`` and ``kite_foxglove``. The rule (``--log-time sim``, the default):

* a message with a header (every stamped project type, and ``visualization_msgs/MarkerArray`` by its first
  marker's header) is logged at its header stamp: the simulated time of the sample it belongs to;
* ``/clock`` at the time it carries;
* a message without a header (``/kite/crashes``, ``/kite/plant_config``, ``/rto/run``), an empty marker array, a
  stamp of 0 on a topic that is not stamped per sample (not set: the latched ``/kite/reference_path``; on the
  per-sample topics and ``/kite/markers`` 0 is sample 0) or a wall-clock stamp (a node run without
  ``use_sim_time``: more than :data:`WALL_STAMP_GAP` s ahead of the simulated clock) is logged at the latest
  ``/clock`` heard (0 before the first).

``--log-time wall`` keeps the wall receive time (as ``ros2 bag record`` without ``--use-sim-time``).

Each sample is recorded once: on the per-sample topics (:data:`PER_SAMPLE`) a message whose stamp equals the previous
one of its topic is a re-publication of the same sample (the lockstep plant re-publishes a sample until it is
answered, the controller and optimizer answer each copy) and is skipped. A stamp lower than the previous one (a
restarted plant) is recorded.

Samples that never arrived are counted (:class:`SampleGaps`): a recorder starved of CPU for longer than its
publishers' history (1000 samples, 20 s of flight in lockstep) loses a block of samples, and the recording says so
instead of looking complete.
"""
from __future__ import annotations

import struct

from ..nodes import topics as T

__all__ = ["PER_SAMPLE", "SAMPLE_STAMPED", "WALL_STAMP_GAP", "LOG_TIME_MODES", "cdr_stamp", "SimLogTime", "SampleGaps"]

PER_SAMPLE = frozenset({T.CLOCK, T.STATE, T.POSITION, T.TENSION, T.WIND, T.WIND_ESTIMATE, T.STEERING, T.SYNC})
"""Topics with one message per sample, stamped with the sample's time: duplicates are skipped."""

SAMPLE_STAMPED = PER_SAMPLE | {T.MARKERS}
"""Topics whose stamp is always a sample's time, so that a stamp of 0 is sample 0 (not "not set")."""

WALL_STAMP_GAP = 1e6
"""s: a stamp this far ahead of the simulated clock is a wall-clock stamp (simulated runs start at 0; wall stamps
are more than 1.7e9 s since 1970)."""

LOG_TIME_MODES = ("sim", "wall")

_HEADER_FIRST = 4          # the encapsulation header (4 bytes), then the first field: Header.stamp or Clock.clock
_ARRAY_FIRST = 8           # ... a sequence length (uint32), then the first element's header


def cdr_stamp(data: bytes, offset: int) -> int | None:
    """The ``builtin_interfaces/Time`` at byte ``offset`` of a CDR message (after its 4-byte encapsulation
    header), in ns; None if the message is too short. Little- and big-endian encapsulations are read."""
    if len(data) < offset + 8:
        return None
    sec, nsec = struct.unpack_from("<iI" if data[1] & 1 else ">iI", data, offset)
    return sec * 1_000_000_000 + nsec


def _stamp_offset(type_name: str) -> int | None:
    if type_name in ("std_msgs/msg/UInt32", "std_msgs/msg/String"):
        return None
    if type_name == "visualization_msgs/msg/MarkerArray":
        return _ARRAY_FIRST
    return _HEADER_FIRST               # Clock and every stamped type: the Time is the first field


class SimLogTime:
    """Log time and duplicate check of each received message (see the module doc).

    Args:
        types: topic -> message type name (``pkg/msg/Type``) of the recorded topics.
        mode: ``sim`` or ``wall``.
    """

    def __init__(self, types: dict, mode: str = "sim"):
        if mode not in LOG_TIME_MODES:
            raise ValueError(f"log time mode {mode!r}: expected one of {', '.join(LOG_TIME_MODES)}")
        self.mode = mode
        self._offset = {}
        for topic, name in types.items():
            off = _stamp_offset(name)
            if off == _ARRAY_FIRST:
                self._offset[topic] = ("array", off)
            elif off is not None:
                self._offset[topic] = ("header", off)
        self.clock_ns = 0
        self._last: dict = {}
        self.duplicates: dict = {}
        self.gaps = SampleGaps()
        self.replaced = 0               # messages logged at the latest /clock instead of their stamp

    def last_stamp(self, topic: str) -> int | None:
        """The stamp (ns) of the last sample recorded on the per-sample ``topic`` (None before the first)."""
        return self._last.get(topic)

    def log_time(self, topic: str, data: bytes, wall_ns: int) -> int | None:
        """The log time (ns) of ``data`` received on ``topic`` at ``wall_ns``, or None for a duplicate sample."""
        kind = self._offset.get(topic)
        stamp = None
        if kind is not None:
            if kind[0] == "array" and (len(data) < 8 or struct.unpack_from("<I" if data[1] & 1 else ">I", data,
                                                                             4)[0] == 0):
                stamp = None
            else:
                stamp = cdr_stamp(data, kind[1])
        if topic in PER_SAMPLE and stamp is not None:
            last = self._last.get(topic)
            if last == stamp:
                self.duplicates[topic] = self.duplicates.get(topic, 0) + 1
                return None
            self.gaps.add(topic, last, stamp)
            self._last[topic] = stamp
        if topic == T.CLOCK and stamp is not None:
            self.clock_ns = stamp
        if self.mode == "wall":
            return wall_ns
        if stamp is None or stamp < 0 or (stamp == 0 and topic not in SAMPLE_STAMPED) \
                or stamp > self.clock_ns + WALL_STAMP_GAP * 1e9:
            if stamp is not None and stamp != 0:
                self.replaced += 1
            return self.clock_ns
        return stamp


class SampleGaps:
    """Samples missing inside the recorded span of each per-sample topic, from the steps between its stamps.

    The sample period of a topic is its smallest step; a step of n periods (rounded) means n - 1 samples missed.
    Only the distinct steps are kept (with their count and the first place each occurred), so a long recording costs
    a few entries. A step back (a restarted plant) starts a new span. Samples after the last one received (a plant
    that exits right after publishing) are not seen.
    """

    def __init__(self):
        self._steps: dict = {}          # topic -> {step ns: [count, first stamp before the step]}

    def add(self, topic: str, previous: int | None, stamp: int) -> None:
        """Note the step from ``previous`` to ``stamp`` (ns) on ``topic`` (nothing before its first sample)."""
        if previous is None or stamp <= previous:
            return
        entry = self._steps.setdefault(topic, {}).setdefault(stamp - previous, [0, previous])
        entry[0] += 1

    def period_ns(self, topic: str) -> int | None:
        """The topic's sample period (its smallest step, ns), None before its second sample."""
        steps = self._steps.get(topic)
        return min(steps) if steps else None

    def missing(self, topic: str) -> int:
        """Samples of ``topic`` missing between the first and the last received."""
        period = self.period_ns(topic)
        if period is None:
            return 0
        return sum(n * (round(step / period) - 1) for step, (n, _) in self._steps[topic].items())

    def largest(self, topic: str) -> tuple[int, int] | None:
        """(last stamp before, first stamp after) of the topic's longest gap (ns), None without a gap."""
        if not self.missing(topic):
            return None
        step = max(self._steps[topic])
        start = self._steps[topic][step][1]
        return start, start + step

    def report(self) -> dict:
        """Topic -> (missing samples, largest gap) for every topic that misses some."""
        return {t: (n, self.largest(t)) for t in sorted(self._steps) if (n := self.missing(t))}

    @staticmethod
    def summary(report: dict, name=lambda t: t) -> str:
        """One line from a :meth:`report`: ``no sample missing`` or, per topic, the count and the largest gap in s."""
        if not report:
            return "no sample missing"
        return "samples missing: " + ", ".join(
            f"{name(t)} {n} (largest gap {a / 1e9:g} .. {b / 1e9:g} s)" for t, (n, (a, b)) in report.items())
