"""The controller's /rto/setpoints inbox: what arrives costs the steering loop a bounded amount, whatever the rate.

:meth:`SetpointInbox.put` (the subscription callback) only checks a message cheaply (names, three finite values
inside the box: a few µs) and keeps it as the latest; the trackability check (about a millisecond) and the switch
to the new path happen once per sample, on the latest message only, when :class:`~.steering_loop.SteeringLoop`
calls :meth:`take` at the sample boundary. A flood of N messages between two samples thus costs N cheap checks
and at most one change. Logging is bounded too: a change is logged as ``new setpoints ...`` unless one was logged
less than :data:`SUMMARY_PERIOD` s ago; beyond that, one summary line per period says
``N setpoint messages in the last X s, applied M``.

Source restriction (``source``, the controller's ``setpoint_source``): a message cannot be attributed to its
sender, so while any other node publishes /rto/setpoints, and for :data:`~.sources.SOURCE_QUIET` s after, every
message is ignored (throttled warning naming those nodes; the rule is :class:`~.sources.SourceGuard`), and
:attr:`refresh` asks the node to subscribe again once the configured source is alone, to get its latched
setpoints.

Rate: every checked message also goes to :attr:`SetpointInbox.rate` (:class:`~.setpoint_rate.SetpointRate`), which
warns when the setpoints change faster than the path can follow, naming the publishers; the loop tells it the
flight time of each answered sample (:meth:`SetpointInbox.flown`).
"""
from __future__ import annotations

import math
import time

from ..flight.path import Setpoints, SetpointError, setpoints_in_box
from .setpoint_rate import SetpointRate
from .sources import SourceGuard

__all__ = ["SetpointInbox", "StartupWait", "SUMMARY_PERIOD", "SETPOINTS_GRACE", "SETPOINTS_WAIT", "fmt_setpoints"]

SUMMARY_PERIOD = 5.0
"""Wall s: at most one ``new setpoints`` line per period; a summary line per period while more arrive."""
SETPOINTS_GRACE, SETPOINTS_WAIT = 1.0, 3.0
"""Wall s after start-up during which the controller waits for /rto/setpoints before steering (see
:meth:`StartupWait.waiting`): always for the first, while an optimizer is known for the second."""
_NAMES = Setpoints.names()
_SORTED = sorted(_NAMES)


def fmt_setpoints(c: Setpoints) -> str:
    """Setpoints in degrees, as the controller logs them."""
    return "theta_0 {:.1f} deg, A_phi {:.1f} deg, A_theta {:.1f} deg".format(*c.degrees())


class SetpointInbox:
    """The latest checked /rto/setpoints message, its counts and its logging (see the module docstring).

    ``box``: the accepted :class:`~kite_rto.flight.path.SetpointBox`; ``reject(key, text)``: throttled warnings
    (RejectLog); ``logger`` has ``info``/``warning``; ``clock``: wall s; ``source``: the only node whose setpoints
    apply (fully qualified, e.g. ``/optimizer``), None for any; ``publishers()``: the current publishers of
    /rto/setpoints (:class:`~.sources.Publisher` list), asked when ``source`` is set (:attr:`guard`) and when the
    setpoints change too fast (:attr:`rate`), and ``matched()`` the number the subscription is matched with, asked
    only when ``source`` is set.
    """

    def __init__(self, box, logger, reject, clock=time.monotonic, source: str | None = None,
                 publishers=lambda: [], matched=lambda: 0, period: float = SUMMARY_PERIOD):
        self.box, self.log, self.reject, self._clock = box, logger, reject, clock
        self.source, self.period = source, period
        self.guard = None if source is None else SourceGuard(source, publishers, matched, clock)
        self.rate = SetpointRate(logger, publishers, source, clock)
        self._latest = None                 # latest checked message (rad, theta_0, A_phi, A_theta), not yet taken
        self._latest_at = -math.inf         # its arrival, wall s (only with a source restriction)
        self._held = 0                      # checked messages since the last take
        self.received = self.applied = self.ignored = 0          # totals since start-up
        self._rx = self._app = self._quiet = 0                   # counts in the current summary window
        self._since = clock()
        self._line_at = -math.inf           # wall time of the last "new setpoints" or summary line
        self._ignored_at = -math.inf
        self.refresh = False                # ignored messages since the source was last alone: subscribe again

    def put(self, names, values) -> list | None:
        """A /rto/setpoints message (``names`` theta_0, A_phi, A_theta in any order, ``values`` rad): checked
        cheaply and kept as the latest; returns it as a list in that order, or None (rejected, with a warning)."""
        self.received += 1
        self._rx += 1
        names = list(names)
        if sorted(names) != _SORTED or len(values) != 3:
            self.reject("setpoints", f"rejected setpoints message {(names, list(values))!r}: expected names "
                                     "theta_0, A_phi, A_theta with 3 values (rad)")
            return None
        by_name = dict(zip(names, values))
        c = [float(by_name[n]) for n in _NAMES]
        try:
            setpoints_in_box(c, self.box)
        except SetpointError as err:
            self.reject("setpoints value", f"rejected setpoints: {err}; keeping the setpoints in force")
            return None
        self._latest = c
        self._held += 1
        self.rate.message(c)
        if self.guard is not None:
            self._latest_at = self.guard.arrived()
        return c

    def take(self) -> list | None:
        """The sample boundary: the latest message since the last call (None if none, or ignored: source)."""
        c, self._latest = self._latest, None
        held, self._held = self._held, 0
        if c is None or self.guard is None:
            return c
        why = self.guard.refused(self._latest_at)
        if why is None:
            return c
        self.ignored += held
        self.refresh = True
        now = self._clock()
        if now - self._ignored_at >= self.period:
            self._ignored_at = now
            self.log.warning(f"ignoring /rto/setpoints: {why} ({self.ignored} messages ignored so far)")
        return None

    def flown(self, stamp: int) -> None:
        """The loop answered the sample stamped ``stamp`` (ns of flight): the rate of changes moves on."""
        self.rate.flight(stamp * 1e-9)

    def applied_change(self, c: Setpoints) -> None:
        """The loop now flies ``c``: logged at once unless a line was logged less than a period ago."""
        self.applied += 1
        self._app += 1
        now = self._clock()
        if now - self._line_at >= self.period:
            self._line_at = now
            self.log.info(f"new setpoints {fmt_setpoints(c)}")
        else:
            self._quiet += 1

    def tick(self, flying: Setpoints) -> None:
        """Call once per sample (and now and then): closes the summary window after a period; logs the summary if
        a change in it was not logged, or more messages arrived than changes were applied (beyond one)."""
        now = self._clock()
        if now - self._since < self.period:
            return
        if self._quiet or self._rx > self._app + 1:      # more than the changes logged one by one
            self._line_at = now
            self.log.info(f"{self._rx} setpoint messages in the last {now - self._since:.1f} s, applied {self._app}"
                          + (f", ignored {self.ignored} in all" if self.ignored else "")
                          + f"; flying {fmt_setpoints(flying)}")
        self._since, self._rx, self._app, self._quiet = now, 0, 0, 0


class StartupWait:
    """The controller's wait for the optimizer's setpoints at start-up, before it steers.

    A controller started into a running loop (e.g. restarted after a crash) would otherwise steer the kite towards
    its initial setpoints until the latched setpoints arrive. ``setpoint_sources()`` counts the publishers of
    /rto/setpoints; ``logger`` has ``info``/``warning``; ``clock`` gives wall seconds. :attr:`over` is True once
    setpoints were accepted (the loop sets it) or the wait ended.
    """

    def __init__(self, setpoint_sources, logger, clock):
        self._setpoint_sources, self.log, self._clock = setpoint_sources, logger, clock
        self.over = False
        self._t_up = clock()

    def waiting(self, flying: Setpoints) -> bool:
        """True (do not steer yet) while the optimizer's setpoints may still be on their way: while a setpoint
        publisher is known, or for the first SETPOINTS_GRACE s after start-up (discovery), at most SETPOINTS_WAIT s;
        without an optimizer the loop then flies ``flying``, its initial setpoints."""
        age = self._clock() - self._t_up
        if age < SETPOINTS_WAIT and (age < SETPOINTS_GRACE or self._setpoint_sources() > 0):
            self.log.info("waiting for the setpoints on /rto/setpoints before steering", throttle_duration_sec=2.0)
            return True
        if self._setpoint_sources() > 0:
            self.log.warning(f"no valid setpoints on /rto/setpoints within {SETPOINTS_WAIT:g} s: flying "
                             f"{fmt_setpoints(flying)}")
        self.over = True                       # stop waiting (and asking the graph)
        return False
