"""Optimizer synchronization of the controller's steering loop (``sync_optimizer:=true``, lockstep).

The optimizer's /rto/sync messages carry :class:`~.plan.Plan` s (:mod:`~.plan`): the setpoints in force and where
the optimizer's next decision can be due. The controller answers every sample at once except:

- where its :class:`~.plan.PlanClock` says a decision is due: the sample waits for the optimizer's message about
  it (a new plan stamped with it is applied first, the pure runner's order; a message about a later sample says
  nothing was decided at it);
- where it would run more than :data:`~.plan.MAX_LEAD` samples ahead of the last sample the optimizer reported
  (its messages report progress at least every :data:`~.plan.PROGRESS_EVERY` samples).

So in lockstep the three processes fly exactly the pure runner's sequence, and the optimizer works on the samples
while the controller and the plant fly on. Once a message has arrived, every such sample waits however long the
optimizer takes (a restarted optimizer picks the loop up again): the answer never depends on wall time or on what
the graph shows. Only a controller that has never heard from an optimizer answers unsynchronized, once no
publisher of /rto/sync has been in the graph for :data:`SYNC_ABSENT` s (no optimizer at all), and from then on at
once until a message arrives; /rto/setpoints then applies at the sample boundary as without synchronization.

A plan that arrives for a sample already answered (the two sides disagreed on where a decision is due, which the
shared rule excludes unless messages were lost) is applied from the next sample on, with a warning.

:class:`OptimizerSync` is this state and its decisions, owned by :class:`~.steering_loop.SteeringLoop`. It never
steers: each method that ends a wait returns the held sample, and the loop answers it.
"""
from __future__ import annotations

import math
from collections import deque

from .plan import MAX_LEAD, PLAN_NAMES, Plan, PlanClock

__all__ = ["OptimizerSync", "SYNC_ABSENT", "SYNC_WAIT_LOG", "SYNC_NAMES", "keep"]

SYNC_ABSENT = 1.0
"""Wall s a sample waits, before any /rto/sync has arrived, while no optimizer is in the graph."""
SYNC_WAIT_LOG = 10.0
"""Wall s between the log lines of a sample that waits for a slow optimizer."""
SYNC_NAMES = PLAN_NAMES
"""Names of a /rto/sync message (:data:`~.plan.PLAN_NAMES`)."""
KEEP = 64
"""Anemometer readings and plans kept ahead of their samples."""


def keep(entries: dict, stamp: int, value) -> None:
    """Store ``value`` at ``stamp``, forgetting the oldest entry when :data:`KEEP` are held."""
    if len(entries) >= KEEP:
        del entries[next(iter(entries))]
    entries[stamp] = value


class OptimizerSync:
    """Holds the samples at which the optimizer's decision is due (see the module docstring).

    ``enabled``: synchronization asked for (``sync_optimizer``); ``log`` has ``info``/``warning``; ``reject(what,
    why)`` reports a bad message; ``clock()`` is the wall time; ``sync_sources()`` counts the publishers of /rto/sync.
    A held sample is ``(stamp, measurement, position, wall time held)``.
    """

    def __init__(self, enabled: bool, *, log, reject, clock, sync_sources):
        self.enabled = enabled
        self.log, self.reject, self._clock, self._sync_sources = log, reject, clock, sync_sources
        self.held = None                  # (stamp, measurement, position, wall time): waits for the optimizer
        self.plans = PlanClock()
        self.reported = None              # the last sample (stamp, ns) the optimizer reported as processed
        self._plans = {}                  # new plans by stamp (ns), for samples still to come
        self._ahead = deque()             # (stamp, t, phi, crashes) answered after `reported`
        self._sample = None               # the same of the sample being decided
        self._hold_due = False            # the held sample waits for a decision, not only for the optimizer's pace
        self._lost = False                # no optimizer: answer at once until a sync message arrives again
        self._updates = None              # `updates` of the last applied plan
        self._seen = -math.inf            # wall time an optimizer was last seen in the graph while a sample waited

    def synchronized(self) -> bool:
        """True while samples wait for the optimizer's decisions."""
        return self.enabled and not self._lost

    def decide(self, stamp: int, t: float, phi: float, crashes: int):
        """The next sample (stamp ns, t s, phi rad, crash count), once: ``(wait, plan)``. ``plan``: a new plan
        already in for it (apply it, then answer); ``wait``: hold the sample (:meth:`hold`) until a message."""
        self._sample = (stamp, t, phi, crashes)
        due = self.plans.due(t, phi, crashes)
        plan = self._plans.pop(stamp, None)
        for s in [s for s in self._plans if s < stamp]:
            del self._plans[s]
        if plan is not None:
            self.plans.begin(plan, t)
            return False, plan
        if self.reported is not None and self.reported >= stamp:
            return False, None                  # the optimizer processed it and decided nothing
        self._hold_due = due
        return due or len(self._ahead) >= MAX_LEAD, None

    def answered(self, stamp: int) -> None:
        """The loop answered the sample ``stamp`` (the one last decided)."""
        if self._sample is not None and self._sample[0] == stamp and \
                (self.reported is None or stamp > self.reported):
            self._ahead.append(self._sample)

    def hold(self, stamp: int, m, pos) -> bool:
        """Hold the sample until the optimizer's message about it: False (answer it now) once no optimizer is
        known."""
        if self._lost:
            return False
        self.held = (stamp, m, pos, self._clock())
        return True

    def changes(self, c, updates: float, flown) -> bool:
        """True if the plan's setpoints ``c`` must be applied: the optimizer's count of setpoint messages changed,
        or ``c`` differs from the setpoints ``flown`` (lists, rad)."""
        if updates != self._updates or c != flown:
            self._updates = updates
            return True
        return False

    def parse(self, names, values) -> Plan | None:
        """A /rto/sync message's :class:`~.plan.Plan`, or None (rejected) if it is malformed."""
        try:
            return Plan.from_values(names, values)
        except (ValueError, TypeError) as err:
            self.reject("sync", f"rejected sync message {(list(names), list(values))!r}: {err}")
            return None

    def plausible(self, stamp: int, timeline) -> bool:
        """A message stamped ``stamp`` (ns) can be about a sample of the ``timeline``
        (:class:`~.sample_join.Timeline`): not beyond its gap ahead of the last answered sample, nor behind the
        oldest sample the optimizer has not reported yet (it may be :data:`~.plan.MAX_LEAD` samples behind). If
        not, the message is rejected (False)."""
        last, gap = timeline.last, timeline.max_gap_ns
        oldest = None if last is None else self._ahead[0][0] if self._ahead else last
        if last is None or oldest - gap <= stamp <= last + gap:
            return True
        self.reject("sync stamp", f"rejected sync message stamped {stamp * 1e-9:.3f} s at sim time "
                                  f"{last * 1e-9:.3f} s: stale or future")
        return False

    def arrived(self, stamp: int, plan: Plan, last: int | None):
        """The optimizer has processed the sample ``stamp`` (``plan`` in force from it; the loop's last answered
        sample: ``last``): ``(held, apply)``, the held sample to answer now (or None) and a plan whose setpoints
        the loop applies first (or None)."""
        if self._lost:
            self._lost = False
            self.log.info("/rto/sync is back: answering samples after the optimizer again")
        new = self.plans.plan is None or plan.number != self.plans.plan.number
        self.reported = stamp if self.reported is None else max(self.reported, stamp)
        while self._ahead and self._ahead[0][0] <= self.reported:
            self._ahead.popleft()
        held, apply = self.held, None
        if new:
            if held is not None and held[0] == stamp:
                apply = plan
                self.plans.begin(plan, held[1].t)
            elif last is None or stamp > last:
                keep(self._plans, stamp, plan)
            else:
                apply = self._late(stamp, plan)
        if held is not None and (stamp >= held[0] or (not self._hold_due and len(self._ahead) < MAX_LEAD)):
            self.held = None
            return held, apply
        return None, apply

    def _late(self, stamp: int, plan: Plan) -> Plan:
        """A new plan for a sample already answered: in force from the next sample, its clock caught up."""
        self.log.warning(f"the optimizer's plan {plan.number} for the sample at {stamp * 1e-9:.2f} s arrived after "
                         "that sample was answered: applied from the next sample on (the flight no longer follows "
                         "the pure runner exactly)")
        self.plans.begin(plan, stamp * 1e-9)
        for s, t, phi, crashes in self._ahead:
            if s > stamp:
                self.plans.due(t, phi, crashes)
        return plan

    def restart(self) -> None:
        """The plant restarted: no plan until the optimizer's next one (every sample waits for it)."""
        self.plans.begin(None, math.nan)
        self._plans.clear()
        self._ahead.clear()
        self.reported = None

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
