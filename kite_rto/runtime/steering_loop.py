"""The controller node's per-sample logic without ROS: join, timeline, plant restart, setpoints, optimizer sync.

:class:`SteeringLoop` takes the plant's readings (stamps in integer ns), setpoint and ``/rto/sync`` messages as
plain values and answers each /kite/state sample through ``answer(stamp_ns, delta)``. Wall time comes from
``clock``, the graph from publisher counts, so tests drive it deterministically.

Join: a /kite/state sample is answered once the anemometer reading of its stamp is in (DDS does not order across
topics); if that reading is lost, the next sample releases the waiting one with the previous reading. Timeline:
the :class:`~.sample_join.Timeline` rule shared with :class:`~.sample_join.SampleJoin`. A restart candidate is
answered by a fresh controller, kept if the restart is confirmed; the flying controller never sees it. While
/kite/state has several publishers (a second plant on the domain) a sample off the timeline is ignored as long as
the timeline served is alive (:class:`~.sources.ServedPlant`): the controller keeps the kite it flies. Bad
readings, or readings stamped far from the last sample, are rejected with throttled warnings.

Setpoints (unsynchronized): each /rto/setpoints message is checked cheaply and kept; the latest is applied at the
next sample (:class:`~.setpoint_inbox.SetpointInbox`: a flood costs at most one change per sample; setpoints that change faster
than the path can follow are warned about, :mod:`~.setpoint_rate`); at start-up
the loop waits for them before it steers (:class:`~.setpoint_inbox.StartupWait`). The reference path is published
after the answer, at most every :data:`PATH_PERIOD` s.

Synchronization (``sync=True``): the loop owns an :class:`~.optimizer_sync.OptimizerSync`, which follows the
optimizer's plans (:mod:`~.plan`: it holds a sample only where a decision is due, or where the loop would run too
far ahead of the optimizer) and says when a held sample is to be answered; the loop applies a new plan's setpoints
and answers.
"""
from __future__ import annotations

import math
import time
from types import SimpleNamespace

from ..flight.controller import PathController
from ..flight.laps import LapDetector
from ..flight.path import Setpoints, SetpointError
from ..kite.model import shared_model
from .optimizer_sync import SYNC_ABSENT, SYNC_NAMES, OptimizerSync, keep
from .sample_join import CrashCount, Place, RejectLog, Timeline, reading_error, state_values
from .setpoint_inbox import SETPOINTS_GRACE, SETPOINTS_WAIT, SetpointInbox, StartupWait, fmt_setpoints
from .sources import PLANT_QUIET, ServedPlant

__all__ = ["SteeringLoop", "fmt_setpoints", "SYNC_ABSENT", "SETPOINTS_GRACE", "SETPOINTS_WAIT", "SYNC_NAMES",
           "PLANT_QUIET", "PATH_PERIOD"]

PATH_PERIOD = 0.5
"""Wall s between two publications of the reference path (the latest setpoints are published, after the answer)."""


def _measurement(stamp: int, pos, vel, wind: float) -> SimpleNamespace:
    """What :meth:`PathController.command` reads: time s, angles rad, rates rad/s, reference wind m/s."""
    return SimpleNamespace(t=stamp * 1e-9, theta=pos[0], phi=pos[1], psi=pos[2], theta_dot=vel[0], phi_dot=vel[1],
                           psi_dot=vel[2], wind_ref=wind)


class SteeringLoop:
    """Answers plant samples with steering commands; follows setpoints and, optionally, the optimizer's sync.

    ``answer(stamp_ns, delta)`` sends a command, ``lap(stamp_ns, lap)`` a finished lap, ``path()`` publishes
    the reference path of the flown setpoints (after a change, at most every :data:`PATH_PERIOD` s); ``logger``
    has ``info``/``warning`` (extra keyword arguments such as ``throttle_duration_sec`` are passed on). The graph:
    ``setpoint_sources()``, ``sync_sources()``, ``state_sources()`` count the publishers of /rto/setpoints,
    /rto/sync and /kite/state; ``setpoint_publishers()`` lists those of /rto/setpoints and ``setpoint_matched()``
    counts the writers the subscription is matched with (only asked when ``setpoint_source``, the one node whose
    setpoints apply, is set: :class:`~.setpoint_inbox.SetpointInbox`).
    The parts it owns: ``optimizer_sync`` (:class:`~.optimizer_sync.OptimizerSync`; ``sync``: synchronization asked
    for), ``inbox``, ``startup`` (the wait for the first setpoints), ``served`` (the plant served), ``timeline``.
    Raises :class:`SetpointError` for initial setpoints ``c0`` outside ``settings.box``.
    """

    def __init__(self, params, settings, c0: Setpoints, *, answer, lap, path, logger, sync: bool = False,
                 setpoint_sources=lambda: 0, sync_sources=lambda: 0, state_sources=lambda: 1,
                 setpoint_source: str | None = None, setpoint_publishers=lambda: [], setpoint_matched=lambda: 0,
                 clock=time.monotonic):
        self.params, self.settings = params, settings
        self.controller = PathController(shared_model(), params, c0, settings)
        self.laps = LapDetector()
        self._answer, self._lap, self._path, self.log = answer, lap, path, logger
        self._clock = clock
        self.reject = RejectLog(logger, clock=clock)
        self.served = ServedPlant(state_sources, clock, self.reject)
        self.optimizer_sync = OptimizerSync(sync, log=logger, reject=self.reject, clock=clock,
                                            sync_sources=sync_sources)
        self.inbox = SetpointInbox(settings.box, logger, self.reject, clock, setpoint_source, setpoint_publishers,
                                   setpoint_matched)
        self._path_due, self._path_at = False, -math.inf
        self.timeline = Timeline()
        self._wind, self._tension, self._altitude = params.w_ref, math.nan, math.nan
        self._last_delta = 0.0
        self.crashes = CrashCount()       # the plant's crash count (the optimizer's plans end experiments on it)
        self._winds = {}                  # anemometer readings by stamp (ns), until their sample is answered
        self._pending = None              # (stamp, position, velocity) waiting for its wind reading
        self._jump = None                 # the same for a stale or future sample (plant restart or junk)
        self._restart = None              # (fresh controller, its answer) for a restart candidate
        self.startup = StartupWait(setpoint_sources, logger, clock)

    @property
    def sync(self) -> bool:
        """Synchronization with the optimizer asked for (``sync_optimizer``)."""
        return self.optimizer_sync.enabled

    def synchronized(self) -> bool:
        """True while samples wait for the optimizer's sync message."""
        return self.optimizer_sync.synchronized()

    # -------------------------------------------------------------- measurements
    def wind_reading(self, stamp: int, v: float) -> None:
        """An anemometer reading (m/s): releases the state sample of its stamp if that one waits for it."""
        if self._bad("wind", v):
            return
        keep(self._winds, stamp, v)
        for held in (self._pending, self._jump):
            if held is not None and held[0] == stamp:
                self._process(held)
                return

    def crash_count(self, n: int) -> None:
        """The plant's crash count (/kite/crashes)."""
        self.crashes.update(n)

    def tension_reading(self, stamp: int, v: float) -> None:
        """A line tension (N), for the lap statistics."""
        if not self._bad("tension", v) and self._stamp_near("tension", stamp):
            self._tension = v

    def position_reading(self, stamp: int, p) -> None:
        """``p``: (x, y, z) in m; the altitude z feeds the lap statistics."""
        if not self._bad("position", p) and self._stamp_near("position", stamp):
            self._altitude = p[2]

    def _bad(self, part: str, value) -> bool:
        why = reading_error(part, value)
        if why is not None:
            self.reject(part, why)
        return why is not None

    def _stamp_near(self, what: str, stamp: int) -> bool:
        if self.timeline.near(stamp):
            return True
        self.reject(f"{what} stamp", f"rejected {what} message stamped {stamp * 1e-9:.3f} s at sim time "
                                     f"{self.timeline.last * 1e-9:.3f} s: stale or future")
        return False

    def state_sample(self, stamp: int, names, position, velocity) -> None:
        """A /kite/state sample (names, positions rad, velocities rad/s): answered now or once its parts are in."""
        try:
            pos, vel = state_values(names, position, velocity)
        except ValueError as err:
            self.reject("state", f"rejected state message: {err}")
            return
        if stamp == self.timeline.last or self.timeline.on(stamp):
            self.served.heard()                      # the timeline served is alive
        if not self.synchronized():
            self._take_setpoints()                  # the sample boundary: the latest setpoints message, if any
        self.inbox.tick(self.controller.setpoints)
        if not self.startup.over and self.startup.waiting(self.controller.setpoints):
            return
        waiting = self.optimizer_sync.held
        if waiting is not None:
            if stamp == waiting[0]:
                return                              # re-published while the optimizer works on it
            if waiting[0] < stamp <= waiting[0] + self.timeline.max_gap_ns:
                self._answer_unsynced(self.optimizer_sync.release("the next sample arrived first"))
        held = (stamp, pos, vel)
        last = self.timeline.last
        off = stamp != last and not self.timeline.on(stamp)
        if off and self.served.other(stamp, last):
            return
        if self._jump is not None:
            self._reject_jump()
        if off:
            if stamp in self._winds:
                self._process(held)                 # complete: the plant restarted or samples were lost
            else:
                self._jump = held                   # wait for its anemometer reading
            return
        if self._pending is not None and self._pending[0] < stamp:
            self._process(self._pending)            # its anemometer reading was lost
        if stamp == last or stamp in self._winds:
            self._process(held)
        else:
            self._pending = held

    def _reject_jump(self) -> None:
        stamp = self._jump[0]
        self._jump = None
        self.reject("state stamp", f"rejected state message stamped {stamp * 1e-9:.3f} s at sim time "
                                   f"{self.timeline.last * 1e-9:.3f} s: stale or future, and no anemometer reading "
                                   "with that stamp (not a plant restart)")

    def _process(self, held) -> None:
        if held is self._pending:
            self._pending = None
        elif held is self._jump:
            self._jump = None
        stamp, pos, vel = held
        if stamp == self.timeline.last:
            self._answer(stamp, self._last_delta)       # re-published sample: same answer
            return
        wind = self._winds.pop(stamp, None)
        if not self._place(stamp, pos, vel, wind):
            return
        if wind is not None:
            self._wind = wind
        if self._winds:
            self._drop_winds(stamp)
        m = _measurement(stamp, pos, vel, self._wind)
        if self.sync:
            wait, plan = self.optimizer_sync.decide(stamp, m.t, pos[1], self.crashes.total)
            if plan is not None:
                self._apply_plan(plan)
            elif wait and self.optimizer_sync.hold(stamp, m, pos):
                return                              # until the optimizer's /rto/sync (sync_message) or the watchdog
        self._steer(stamp, m, pos)

    def _steer(self, stamp: int, m, pos) -> None:
        """Answer the sample ``m`` (stamp in ns) with a steering command and update the lap statistics."""
        delta = self.controller.command(m)
        self.timeline.last, self._last_delta = stamp, delta
        self._answer(stamp, delta)
        if self.sync:
            self.optimizer_sync.answered(stamp)
        self.inbox.flown(stamp)
        if self._path_due:
            self.publish_path_if_due()
        lap = self.laps.update(m.t, pos[0], pos[1], self._tension, self._altitude,
                               self.controller.status.cross_track, m.wind_ref)
        if lap is not None:
            self._lap(stamp, lap)

    def _place(self, stamp: int, pos, vel, wind) -> bool:
        """Place a complete sample on the timeline: True to fly on with it (see the module docstring)."""
        last = self.timeline.last
        place, dropped, confirmed = self.timeline.place(stamp)
        if dropped is not None:
            self.reject("state stamp", f"rejected state sample stamped {dropped * 1e-9:.3f} s at sim time "
                                       f"{last * 1e-9:.3f} s: stale or future, and the timeline went on "
                                       "(not a plant restart)")
        if place is Place.NEXT:
            self._restart = None
            return True
        if place in (Place.RESTART, Place.JUMP):
            back = place is Place.RESTART
            self.log.warning(f"sim time jumped {'back' if back else 'forward'} ({last * 1e-9:.2f} s -> "
                             f"{confirmed * 1e-9:.2f} s): " + ("plant restarted, re-synchronizing" if back
                                                              else "samples were lost"))
            if back:
                self.controller = self._restart[0]
                self.laps.reset()
                self.optimizer_sync.restart()
            self._restart = self._pending = None
            return True
        if place is Place.REPEATED:                     # the candidate re-published: the same answer
            if self._restart is not None:
                self._answer(stamp, self._restart[1])
            return False
        self._restart = None
        if stamp < last:
            fresh = PathController(shared_model(), self.params, self.controller.setpoints, self.settings)
            delta = fresh.command(_measurement(stamp, pos, vel, self._wind if wind is None else wind))
            self._restart = (fresh, delta)
            self._answer(stamp, delta)
        return False

    def _drop_winds(self, stamp: int) -> None:
        """Forget readings older than the answered sample; reject those far from it (stale or future junk)."""
        winds, gap = self._winds, self.timeline.max_gap_ns
        for s in list(winds):
            if s < stamp or s > stamp + gap:
                v = winds.pop(s)
                if abs(s - stamp) > gap:
                    self.reject("wind stamp", f"rejected wind message {v!r} stamped {s * 1e-9:.3f} s at sim "
                                              f"time {stamp * 1e-9:.3f} s: stale or future (no state sample has "
                                              "that stamp)")

    # ---------------------------------------------------------------------- sync
    def sync_message(self, stamp: int, names, values) -> None:
        """The optimizer has processed the sample ``stamp``: ``values`` are :data:`SYNC_NAMES` (its plan from it)."""
        plan = self.optimizer_sync.parse(names, values)
        if plan is None or not self.optimizer_sync.plausible(stamp, self.timeline):
            return
        held, apply = self.optimizer_sync.arrived(stamp, plan, self.timeline.last)
        if apply is not None:
            self._apply_plan(apply)
        if held is not None:
            self._steer(*held[:3])

    def watchdog(self) -> None:
        """Call periodically (the node: every 0.05 s): releases a held sample when there is no optimizer at all."""
        held = self.optimizer_sync.overdue()
        if held is not None:
            self._answer_unsynced(held)

    def _apply_plan(self, plan) -> None:
        c = list(plan.c)
        if self.optimizer_sync.changes(c, plan.updates, self.controller.setpoints.as_array().tolist()):
            self._apply_setpoints(c)

    def _answer_unsynced(self, held) -> None:
        """Answer a sample released from its wait for the optimizer, with the latest setpoints."""
        self._take_setpoints()
        self._steer(*held[:3])

    # ----------------------------------------------------------------- setpoints
    def setpoints_message(self, names, values) -> None:
        """New setpoints (``names`` theta_0, A_phi, A_theta in any order, ``values`` rad): checked cheaply and
        kept; the latest is applied at the next sample (unsynchronized) or on the optimizer's sync message."""
        c = self.inbox.put(names, values)
        if c is not None and self.synchronized() and not self.startup.over:
            self.log.info(f"new setpoints {fmt_setpoints(Setpoints.from_array(c))} received; synchronized with the "
                          "optimizer: setpoints apply at the sample of its /rto/sync")
            self.startup.over = True

    def _take_setpoints(self) -> None:
        """The sample boundary: fly the latest setpoints message received since the last one, if any."""
        c = self.inbox.take()
        if c is None:
            return
        if self.timeline.last is not None and c == self.controller.setpoints.as_array().tolist():
            self.startup.over = True           # flying them already
        elif self._apply_setpoints(c):
            self.startup.over = True

    def publish_path_if_due(self) -> None:
        """Publish the reference path if the setpoints changed since it was last published and PATH_PERIOD s have
        passed (the node calls it now and then too, so the last change is published when samples stop)."""
        now = self._clock()
        if self._path_due and now - self._path_at >= PATH_PERIOD:
            self._path_due, self._path_at = False, now
            self._path()

    def housekeeping(self) -> None:
        """Call now and then (the node: every 0.5 s wall): the path and the setpoint summary when samples stop."""
        self.publish_path_if_due()
        self.inbox.tick(self.controller.setpoints)

    def _apply_setpoints(self, c) -> bool:
        """Fly the setpoints ``c`` (rad): at once before the first sample, else blended; False if refused."""
        try:
            if self.timeline.last is None:      # nothing flown yet: start on the new path, no blend
                self.controller = PathController(shared_model(), self.params, c, self.settings)
                accepted = self.controller.setpoints
            else:
                accepted = self.controller.set_setpoints(c)
        except SetpointError as err:
            self.reject("setpoints value", f"rejected setpoints: {err}; keeping "
                                           f"{fmt_setpoints(self.controller.setpoints)}")
            return False
        self.laps.reset()
        self.inbox.applied_change(accepted)
        self._path_due = True
        return True
