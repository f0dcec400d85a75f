"""Who publishes the controller's inputs: :class:`Publisher` (node name and endpoint GID, from the ROS graph),
:class:`SourceWatch`, which warns, throttled, while a topic that should have one publisher has several, and
:class:`SourceGuard`, which decides whether a /rto/setpoints message may be applied when the controller is
restricted to one source node (``setpoint_source``).

The node asks the graph (``get_publishers_info_by_topic``) and hands the lists in; nothing here talks ROS. A
second publisher of /kite/state or /clock is a second plant on the domain; of /rto/setpoints, a second setpoint
source (whose messages the controller cannot tell apart from the optimizer's: DDS gives no per-message sender to
an rclpy callback spun by the events executor, see docs/interface.md).
"""
from __future__ import annotations

import math
import re
import time
from typing import NamedTuple

from ..kite.params import ParameterError

__all__ = ["Publisher", "SourceWatch", "SourceGuard", "ServedPlant", "describe", "node_name", "parse_source",
           "WARN_PERIOD", "SOURCE_QUIET", "PLANT_QUIET", "UNKNOWN_NODE"]

WARN_PERIOD = 10.0
"""Wall s between repeated warnings about the same publishers of a topic (a new publisher is warned at once)."""
SOURCE_QUIET = 1.0
"""Wall s after another publisher of /rto/setpoints was last seen during which every setpoint message is still
ignored (its last messages may be delivered after the graph stopped listing it)."""
PLANT_QUIET = 2.0
"""Wall s: while /kite/state has several publishers, a sample off the timeline is another plant's (ignored) unless
the timeline served has been silent this long (its plant is gone: a restart)."""


class Publisher(NamedTuple):
    """A publisher of a topic: its node's fully qualified name (``/optimizer``) and its endpoint GID (hex)."""

    node: str
    gid: str

    def __str__(self) -> str:
        return f"{self.node} (gid {self.gid})"


UNKNOWN_NODE = "<node not known yet>"
"""How a publisher is named while the graph knows its DDS writer but not yet its node (rmw_fastrtps then reports
``_NODE_NAMESPACE_UNKNOWN_/_NODE_NAME_UNKNOWN_``)."""


def node_name(name: str, namespace: str = "/") -> str:
    """The fully qualified node name: ``/ns/name`` (``/name`` in the root namespace); :data:`UNKNOWN_NODE` while
    the graph does not know it yet."""
    if "_NODE_NAME_UNKNOWN_" in name or "_NODE_NAMESPACE_UNKNOWN_" in namespace:
        return UNKNOWN_NODE
    return f"{namespace.rstrip('/')}/{name.lstrip('/')}"


def parse_source(name: str, namespace: str = "/") -> str | None:
    """The controller's ``setpoint_source`` parameter: None for ``*`` (any publisher), else the fully qualified node
    name; a relative name is in the controller's ``namespace`` (``optimizer`` -> ``/optimizer``, or
    ``/kite2/optimizer`` for a controller in ``/kite2``). Raises :class:`ParameterError` for anything else."""
    if name == "*":
        return None
    if not re.fullmatch(r"/?[A-Za-z_][A-Za-z0-9_]*(/[A-Za-z_][A-Za-z0-9_]*)*", name):
        raise ParameterError(f"parameter setpoint_source = {name!r}: expected * or a node name such as /optimizer")
    return name if name.startswith("/") else node_name(name, namespace)


def describe(publishers) -> str:
    """``/plant (gid ...), /plant (gid ...)``: every publisher, the GID telling two nodes of one name apart."""
    return ", ".join(map(str, publishers)) or "none"


class SourceWatch:
    """Throttled warnings while a topic has more than one publisher.

    :meth:`update` takes a topic's current publishers: with two or more it warns naming them all, at once when the
    set changed (a publisher came or went, or the graph learnt a node's name) and then every :data:`WARN_PERIOD`
    wall s while it lasts; when the topic is back to one publisher it says so once. ``logger`` has ``info`` and ``warning``; ``clock`` gives wall seconds.
    """

    def __init__(self, logger, clock=time.monotonic, period: float = WARN_PERIOD):
        self.log, self._clock, self.period = logger, clock, period
        self._seen: dict[str, tuple] = {}           # topic -> (publishers warned about, wall time of the warning)
        self.warnings = 0

    def update(self, topic: str, publishers, meaning: str) -> None:
        """``publishers``: the topic's :class:`Publisher` list now; ``meaning``: what several of them mean."""
        pubs = frozenset(publishers)
        seen = self._seen.get(topic)
        if len(pubs) > 1:
            now = self._clock()
            if seen is None or seen[0] != pubs or now - seen[1] >= self.period:
                self._seen[topic] = (pubs, now)
                self.warnings += 1
                self.log.warning(f"{len(pubs)} publishers of {topic}: {describe(publishers)}: {meaning}")
        elif seen is not None:
            del self._seen[topic]
            self.log.info(f"{topic} has one publisher again: {describe(publishers)}")


class SourceGuard:
    """Only ``source``'s /rto/setpoints apply; a message cannot be attributed to its sender, so the guard goes by
    who else publishes.

    Another publisher is one the graph lists under another name (``publishers()``: :class:`Publisher` list, about
    0.1 ms), or a writer the subscription is matched with (``matched()``, a few µs) beyond the source's writers in
    the graph: DDS matches a writer before its first message is delivered, the graph may learn of it later. A
    message is applied only if no other publisher is seen when it is taken (the sample boundary), none was matched
    when it arrived, and none has been seen for :data:`SOURCE_QUIET` s before it arrived.
    """

    def __init__(self, source: str, publishers, matched, clock, quiet: float = SOURCE_QUIET):
        self.source, self._publishers, self._matched, self._clock, self.quiet = \
            source, publishers, matched, clock, quiet
        self._known = 1                     # writers of the source in the graph at the last look
        self._dirty_at = -math.inf          # wall time another publisher was last seen

    def arrived(self) -> float:
        """Call when a message arrives (cheap): its wall time; notes a matched writer the graph does not explain."""
        now = self._clock()
        if self._matched() > self._known:
            self._dirty_at = now
        return now

    def others(self) -> str | None:
        """The other publishers in words (a look at the graph), or None if the source is alone."""
        pubs = self._publishers()
        others = [p for p in pubs if p.node != self.source]
        self._known = len(pubs) - len(others)
        unknown = self._matched() - len(pubs)
        if not others and unknown <= 0:
            return None
        self._dirty_at = self._clock()
        return ", ".join([describe(others)] * bool(others) + [f"{unknown} not in the graph yet"] * (unknown > 0))

    def refused(self, arrived_at: float) -> str | None:
        """Why the message that arrived at ``arrived_at`` (wall s) may not apply, or None."""
        others = self.others()
        if others is not None:
            return f"nodes other than setpoint_source {self.source} publish it: {others}"
        if arrived_at - self._dirty_at < self.quiet:
            return f"another node published it less than {self.quiet:g} s before"
        return None

    def clean(self) -> bool:
        """True once the source has been alone for :data:`SOURCE_QUIET` s (subscribe again for its latched value)."""
        return self.others() is None and self._clock() - self._dirty_at >= self.quiet


class ServedPlant:
    """The plant the steering loop serves while /kite/state has several publishers (a second plant on the domain).

    ``state_sources()`` counts the publishers of /kite/state, ``clock()`` gives wall seconds, ``reject(key, text)``
    warns (throttled). The loop calls :meth:`heard` for each sample of the timeline it serves and asks
    :meth:`other` about a sample off that timeline.
    """

    def __init__(self, state_sources, clock, reject):
        self._state_sources, self._clock, self.reject = state_sources, clock, reject
        self._served_at = -math.inf       # wall time of the last sample of the timeline served

    def heard(self) -> None:
        """A sample of the timeline served arrived: that plant is alive."""
        self._served_at = self._clock()

    def other(self, stamp: int, last: int | None) -> bool:
        """True (ignore the sample, with a warning) for a sample off the timeline (``last``: its last stamp) while
        /kite/state has several publishers and the timeline served is alive (a sample of it within
        :data:`PLANT_QUIET` s): another plant's, not a restart."""
        if self._clock() - self._served_at >= PLANT_QUIET:
            return False
        n = self._state_sources()
        if n < 2:
            return False
        self.reject("other plant", f"rejected state message stamped {stamp * 1e-9:.3f} s at sim time "
                                   f"{last * 1e-9:.3f} s: stale or future, and {n} publishers of "
                                   "/kite/state while the kite served still flies (another plant on this domain?); "
                                   "serving that one")
        return True
