"""The lockstep handshake of controller and optimizer: what the controller flies until the optimizer's next decision.

The optimizer decides only where an experiment ends (every 60-300 s of flight), not at every sample. A
:class:`Plan` is what it hands the controller at such a decision: the setpoints in force, the count of its setpoint
messages, and the :class:`Mode` that says where the next decision can be due:

- ``EXPERIMENT``: at the end of the experiment that starts at the plan's sample,
  :class:`~kite_rto.rto.experiment_end.ExperimentEnd` of ``(t, phi, crash count)`` with the plan's ``n_laps``,
  ``settle_time``, ``settle_laps`` and ``max_duration``;
- ``EACH``: at every sample (before the first experiment, while the optimizer is paused or holds its setpoints
  because its database cannot be written, after a plant restart);
- ``FREE``: never (the run has ended).

Both sides run a :class:`PlanClock` on the same samples: the controller waits at a sample only where its clock
says a decision is due (or where it would run more than :data:`MAX_LEAD` samples ahead of the optimizer), the
optimizer sends its next plan stamped with that sample. The docs: docs/interface.md *Lockstep with the optimizer*.
"""
from __future__ import annotations

import enum
import math
from dataclasses import dataclass, replace

from ..rto.experiment_end import ExperimentEnd

__all__ = ["Mode", "Plan", "PlanClock", "PlanSender", "PLAN_NAMES", "MAX_LEAD", "PROGRESS_EVERY", "JOIN_LEAD_NS"]

MAX_LEAD = 500
"""Samples the controller may answer beyond the last sample the optimizer reported as processed (10 s at 50 Hz):
the optimizer's subscriptions keep 1000 samples, so it never loses one however far behind it falls."""
JOIN_LEAD_NS = 20_000_000_000
"""How far (ns: 20 s) one topic's readings may run ahead of another's in the optimizer's join of a backlog: two
MAX_LEAD at 50 Hz; a reading stamped further ahead is future junk."""
PROGRESS_EVERY = 100
"""The optimizer reports its progress (a /rto/sync message with the plan in force) at least every this many
samples it processes."""
PLAN_NAMES = ["theta_0", "A_phi", "A_theta", "updates", "plan", "mode", "n_laps", "settle_time", "settle_laps",
              "max_duration"]
"""Names of a /rto/sync message's values: setpoints rad, setpoint-message count, plan number, :class:`Mode`, then
the experiment's end rule (laps, s, laps, s; zeros unless the mode is ``EXPERIMENT``)."""


class Mode(enum.IntEnum):
    """Where the next decision can be due (the module docstring)."""

    EACH = 0
    EXPERIMENT = 1
    FREE = 2


@dataclass(frozen=True)
class Plan:
    """What the controller flies from the sample of the message that carries it until the next decision.

    Attributes:
        c: setpoints (theta_0, A_phi, A_theta), rad.
        updates: the optimizer's count of setpoint messages (a change applies ``c`` again, as a repeat does).
        number: the plan's number, one more for each new plan of a run (the same number: the same plan).
        mode: :class:`Mode`.
        n_laps, settle_time, settle_laps, max_duration: the end rule of an ``EXPERIMENT`` plan (laps, s, laps, s).
    """

    c: tuple
    updates: int
    number: int
    mode: Mode = Mode.EACH
    n_laps: int = 0
    settle_time: float = 0.0
    settle_laps: int = 0
    max_duration: float = 0.0

    def values(self) -> list:
        """The message values, in :data:`PLAN_NAMES` order."""
        return [*map(float, self.c), float(self.updates), float(self.number), float(self.mode), float(self.n_laps),
                float(self.settle_time), float(self.settle_laps), float(self.max_duration)]

    @classmethod
    def from_values(cls, names, values) -> "Plan":
        """The plan of a message; raises ``ValueError`` naming what is wrong."""
        names, vals = list(names), [float(v) for v in values]
        if names != PLAN_NAMES or len(vals) != len(PLAN_NAMES):
            raise ValueError(f"names {names!r} with {len(vals)} values: expected names {PLAN_NAMES} with "
                             f"{len(PLAN_NAMES)} values")
        if not all(map(math.isfinite, vals)):
            raise ValueError(f"values {vals!r}: expected finite numbers")
        c, (updates, number, mode, n_laps, settle_time, settle_laps, max_duration) = tuple(vals[:3]), vals[3:]
        counts = {"updates": updates, "plan": number, "n_laps": n_laps, "settle_laps": settle_laps}
        bad = [f"{k} = {v!r}" for k, v in counts.items() if v < 0 or v != int(v)]
        if bad:
            raise ValueError(f"{', '.join(bad)}: expected whole numbers >= 0")
        if mode not in tuple(Mode):
            raise ValueError(f"mode = {mode!r}: expected one of {', '.join(f'{int(m)} ({m.name})' for m in Mode)}")
        plan = cls(c, int(updates), int(number), Mode(int(mode)), int(n_laps), settle_time, int(settle_laps),
                   max_duration)
        if plan.mode is Mode.EXPERIMENT and (plan.n_laps < 1 or settle_time < 0 or max_duration <= 0):
            raise ValueError(f"an experiment plan with n_laps = {plan.n_laps}, settle_time = {settle_time!r} s, "
                             f"max_duration = {max_duration!r} s: expected n_laps >= 1, settle_time >= 0, "
                             "max_duration > 0")
        return plan


class PlanClock:
    """Says at which samples a decision of the optimizer is due under the plan in force (the module docstring).

    :meth:`begin` at the sample that brought a plan, then :meth:`due` with every later sample, in order, once each.
    Before the first plan every sample is due.
    """

    def __init__(self):
        self.plan: Plan | None = None
        self._end = None

    @property
    def mode(self) -> Mode:
        return Mode.EACH if self.plan is None else self.plan.mode

    def begin(self, plan: Plan | None, t: float) -> None:
        """The plan in force from the sample at time ``t`` s on (None: none, every sample due)."""
        self.plan = plan
        self._end = None
        if plan is not None and plan.mode is Mode.EXPERIMENT:
            self._end = ExperimentEnd(t, plan.n_laps, plan.settle_time, plan.settle_laps, plan.max_duration)

    def due(self, t: float, phi: float, crashes: int) -> bool:
        """The next sample (t s, phi rad, the plant's crash count): True if a decision is due at it (an
        experiment plan's end, and every sample after it until the next plan)."""
        mode = self.mode
        if mode is not Mode.EXPERIMENT:
            return mode is Mode.EACH
        end = self._end
        return end.update(t, phi, crashes) is not None or end.ended is not None


class PlanSender:
    """The optimizer's side: the plan in force, its :class:`PlanClock`, and which /rto/sync message follows a
    processed sample (the module docstring)."""

    def __init__(self):
        self.clock = PlanClock()
        self.plan: Plan | None = None     # the plan last sent
        self._since = 0                   # samples processed since the last message

    def due(self, t: float, phi: float, crashes: int) -> bool:
        """The next processed sample (t s, phi rad, crash count): True if a decision is due at it."""
        return self.clock.due(t, phi, crashes)

    def restart(self) -> None:
        """The plant restarted: every sample is due until the next plan (as on the controller's side)."""
        self.clock.begin(None, math.nan)

    def after(self, t: float, due: bool, c, updates: int, mode: Mode, end: tuple = ()) -> Plan | None:
        """After a processed sample at ``t`` s: the plan to send stamped with it, or None (nothing to send).

        ``due``: :meth:`due` said so, or an experiment started at this sample; ``c`` (rad, None before any setpoints)
        and ``updates``: the setpoints in force and the count of setpoint messages; ``mode`` and ``end`` =
        ``(n_laps, settle_time, settle_laps, max_duration)`` of an experiment starting at this sample: the next
        plan, used only where a decision is due. Elsewhere the plan in force is reported every
        :data:`PROGRESS_EVERY` samples."""
        self._since += 1
        if c is None:
            return None
        if due:
            old = self.plan
            number = 0 if old is None else old.number
            plan = Plan(tuple(float(v) for v in c), int(updates), number, mode, *end)
            if old is None or mode is Mode.EXPERIMENT or plan != old:
                plan = replace(plan, number=number + 1)
            self.plan = plan
            self.clock.begin(plan, t)
        elif self.plan is None or self._since < PROGRESS_EVERY:
            return None
        self._since = 0
        return self.plan
