"""The optimizer node's logic without ROS: plant readings joined into samples, the GMA session, persistence, status.

:class:`OptimizerRun` takes the plant's readings (stamps in integer ns) and crash counts as plain values, drives
:class:`~kite_rto.rto.session.RTOSession` (the same per-sample logic as the pure runner), writes every finished
experiment and iteration to a :class:`~kite_rto.gma.HistoryStore`, and reports through callbacks:
``send_setpoints(c)`` (checked setpoints, rad), ``processed(stamp_ns, plan)`` after each processed sample (``plan``:
the :class:`~kite_rto.runtime.plan.Plan` to send on /rto/sync stamped with it, or None), ``status()`` when
the status changed, ``finished()`` once ``n_iter`` iterations are done, ``storage_lost()`` when the database stayed
unwritable for ``storage_timeout`` s. :class:`kite_rto.nodes.optimizer_node` turns these into messages.

The run's description (:class:`~kite_rto.rto.run.RunDescription`) is stored again with the plant's configuration
when the plant publishes it (:meth:`OptimizerRun.plant_config`; run data, which a failed write does not hold).

Nothing is lost when storage fails. What GMA holds in memory and the store lacks is written in one transaction (a
run's start; finished experiments; the experiment that completes an iteration together with that iteration's
record and the next requests; :class:`~kite_rto.runtime.run_persistence.RunPersistence`) before any setpoint that
follows from it is published. When that write fails, the run keeps everything in memory, holds the setpoints in
force (the plant flies them; their measurements are not used), and tries again at the next sample (at most every
:data:`~kite_rto.runtime.run_persistence.RETRY_PERIOD` s) and on :meth:`OptimizerRun.tick`; once stored, the held
experiment starts from that sample. After ``storage_timeout`` s of failed writes it gives up (``storage_lost``).

Operator (the node's lifecycle, docs/interface.md *Pausing and overriding the optimizer*): :meth:`OptimizerRun.pause`
holds the setpoints in force and discards the experiment in progress (samples are still synchronized, nothing is
measured); :meth:`OptimizerRun.manual_setpoints` (only while paused) checks setpoints against the box and the turn
limit, stores them with the open iteration re-planned at them and publishes them; :meth:`OptimizerRun.resume`
flies the open iteration's next experiment from the next sample where a decision is due (:mod:`~.plan`; the
discarded one again, or the manual point's nominal experiment).
"""
from __future__ import annotations

import time
from dataclasses import replace

import numpy as np

from ..flight.path import SetpointError, validate_setpoints
from ..flight.shape import setpoints_from_shape, shape_from_setpoints
from ..gma import StoreError
from ..kite.params import KiteParams
from ..rto.run import RUN_KEY
from .operator_log import MANUAL, setpoints_error
from .run_description import plant_from_json
from .plan import JOIN_LEAD_NS, MAX_LEAD, Mode, PlanSender
from .run_persistence import RunPersistence
from .run_status import degrees, shape_degrees
from .sample_join import CrashCount, RejectLog, SampleJoin, reading_error, state_values

__all__ = ["OptimizerRun"]


class OptimizerRun:
    """GMA on the flying kite, one plant reading at a time; ``logger`` has ``info``/``warning``/``error``.

    ``run_meta``: run data written with a new run's start (e.g. the settings it was created with, its description);
    ``description``: the run's :class:`~kite_rto.rto.run.RunDescription` (None: :meth:`plant_config` refuses);
    ``storage_timeout``: wall seconds of failed writes after which the run gives up (``storage_lost()``);
    ``clock``: wall time in s (monotonic), for the retry period and the timeout.
    """

    def __init__(self, gma, session, store, box, *, n_iter: int, logger, send_setpoints, processed, status, finished,
                 storage_lost=lambda: None, storage_timeout: float = 60.0, run_meta: dict | None = None,
                 description=None, clock=time.monotonic):
        self.gma, self.session, self.store, self.box = gma, session, store, box
        self.n_iter = n_iter
        self.log = logger
        self._send, self._processed, self._status, self._finished = send_setpoints, processed, status, finished
        self.plans = PlanSender()           # the plan the controller flies, and where a decision is due
        self._storage_lost = storage_lost
        self.description = description
        self.persist = RunPersistence(gma, store, logger, run_meta=run_meta, storage_timeout=storage_timeout,
                                      clock=clock)
        self.reject = RejectLog(logger)
        self.join = SampleJoin(max_pending=2 * MAX_LEAD, lead_ns=JOIN_LEAD_NS)   # a backlog's topics out of step
        self._held = False                      # the session moved on while its records were unstored
        self._held_new = None                   # ... and asked for these setpoints (rad), applied once stored
        self.c_published = None             # setpoints of the last message sent (rad)
        self.updates = 0                    # setpoint messages sent by this process
        self._crashes = CrashCount()
        self._started = False
        self.done = False
        self.phase = "waiting for the plant"
        self.active = True                  # False while paused (the node inactive): setpoints held
        self._moved = False                 # an operator moved the open iteration while paused
        self.manual_note = ""               # the last manual setpoints: accepted or why refused

    def begin(self) -> None:
        """Store what memory holds and the store lacks (a new run's start; an iteration GMA completed again on
        resume), then publish the first experiment's setpoints; while that write fails nothing is published (the
        first sample after it succeeds starts the run)."""
        if self._store():
            self.setpoints(setpoints_from_shape(self.gma.next_request().c))

    def tick(self) -> None:
        """Wall-clock timer (the node: 1 Hz): retry a failed write and check ``storage_timeout`` even when no
        sample arrives; write waiting run data (also once the run has ended)."""
        if (self.persist.failing and not self.done) or self.persist.meta_waiting:
            self._store()

    def plant_config(self, text: str):
        """The plant's configuration, ``text`` = JSON as the plant publishes it: the run's description with it is
        stored (at once, or with a later write while the database cannot be written) and returned. None when the
        description already names that plant, or when ``text`` is not a plant configuration (rejected: a throttled
        warning naming what is wrong; the run goes on)."""
        old = self.description
        if old is None:
            raise ValueError("OptimizerRun.plant_config: this run keeps no description (made with description=None)")
        try:
            plant = plant_from_json(text)
        except ValueError as err:
            return self.reject("plant_config", f"rejected plant configuration {err}")
        if plant == old.plant:
            return None
        self.description = replace(old, plant=plant)
        self.persist.add_meta({RUN_KEY: self.description.to_dict()})
        self._store()
        if old.plant is None:
            self.log.info("the run's description now names the plant's configuration")
        else:
            self.log.warning("the plant's configuration changed during the run (a plant restarted with other "
                             "parameters?): the run's description now names the new one")
        return self.description

    # ------------------------------------------------------------ measurements
    def state_reading(self, stamp: int, names, position, velocity) -> None:
        try:
            pos, vel = state_values(names, position, velocity)
        except ValueError as err:
            return self.reject("state", f"rejected state message: {err}")
        self._part(stamp, "state", (*pos, *vel))

    def reading(self, stamp: int, part: str, value) -> None:
        """A ``tension`` (N), ``position`` ((x, y, z) m) or ``wind`` (m/s) reading of the sample ``stamp``."""
        why = reading_error(part, value)
        if why is not None:
            return self.reject(part, why)
        self._part(stamp, part, value)

    def crashes(self, n: int) -> None:
        """The plant's crash count (a restarted plant counts from 0 again: not a crash, not un-crashed)."""
        self.join.crashes = self._crashes.update(n)

    def _part(self, stamp: int, part: str, value) -> None:
        if part == "state" and stamp == self.join.last:
            self._processed(stamp, self.plans.plan)   # re-published (its answer is late): report it again
            return
        m = self.join.add(stamp, part, value)
        if self.join.discarded:
            s, parts = self.join.discarded[-1]
            self.reject("stamp", f"discarded {len(self.join.discarded)} sample(s) off the timeline, the last "
                                 f"stamped {s * 1e-9:.3f} s ({', '.join(parts)}) at sim time "
                                 f"{self.join.last * 1e-9:.3f} s: stale or future stamps")
            self.join.discarded.clear()
        if m is None:
            return
        if m.jumped_back:
            self.log.warning(f"sim time jumped back to {m.t:.2f} s: plant restarted, the current "
                             "experiment starts again")
            self._started = False
            self.plans.restart()
        self.on_sample(m)

    def on_sample(self, m) -> None:
        """One joined sample: measured and decided on where a decision is due, then reported."""
        due = self.plans.due(m.t, m.phi, m.crashes)
        self._fly(m, due)
        ev = self.session.evaluator
        started = self.active and not self.done and ev.active and ev.t_start == m.t
        mode = Mode.FREE if self.done else Mode.EXPERIMENT if started and not self._held else Mode.EACH
        sp = self.session.spec
        end = (ev.n_laps, sp.settle_time, sp.settle_laps, ev.max_duration) if mode is Mode.EXPERIMENT else ()
        self._processed(m.stamp, self.plans.after(m.t, due or started, self.c_published, self.updates, mode, end))

    def _fly(self, m, due: bool) -> None:
        """The run's part of a sample: nothing starts or ends where no decision is ``due``."""
        if self.done:
            return
        if not self.active:                 # paused: the held setpoints fly, nothing is measured
            if self.persist.failing:
                self._store()
            self.session.evaluator.update(m)        # an inactive evaluator only follows the wind
            return
        if self.persist.failing and not self._store():
            return                          # records unstored: the held setpoints fly, nothing is measured
        if self._held:                      # stored at last: what the session asked for starts now
            self._held = False
            self._started = True
            self.phase = "experiment"
            self._advance(self._held_new, m.t, restart=True)
            return
        if not self._started:
            if not due:
                return                              # resumed: the next experiment starts where a decision is due
            self._started = True
            if self.session.request is None:
                self.setpoints(self.session.start(m.t))
            else:                                   # plant restart: same request, measured again
                self.session.restart(m.t)
            self.phase = "experiment"
            return
        request, repeats = self.session.request, self.session.repeats
        new = self.session.on_measurement(m)
        if self.session.request is request and self.session.repeats > repeats:
            self.log.warning(f"experiment {request.request_id} invalid (kite crashed or no lap) at "
                             f"t = {m.t:.2f} s: its data is discarded, repeating it "
                             f"({self.session.repeats}/{self.session.max_repeats})")
        if not self._store():
            self._held, self._held_new = True, new
            return
        self._advance(new, m.t)

    def _advance(self, new, t: float, restart: bool = False) -> None:
        """Go on after a sample whose records are stored: stop, finish, or apply the ``new`` setpoints (rad); with
        ``restart`` the session's experiment (started while they were held) starts again at ``t`` s."""
        if self.session.stopped:
            self.phase = f"failed: {self.session.message}"
            self.log.error(self.phase)
            self.done = True
        elif self.n_iter and len(self.gma.records) >= self.n_iter:
            self.finish()
        elif new is not None:
            self.setpoints(new)
            if restart and not self.done:
                self.session.restart(t)

    # ----------------------------------------------------------------- operator
    def pause(self) -> None:
        """Hold the setpoints in force; the experiment in progress is discarded (flown again after :meth:`resume`)."""
        if not self.active:
            return
        self.active = False
        self.session.evaluator.active = False
        if not self._held:
            self._started = False
        held = "nothing yet" if self.c_published is None else degrees(self.c_published)
        if not self.done:
            self.phase = f"paused: holding {held}"
        req = self.session.request
        self.log.info(f"paused: holding {held}; " + ("the run has ended" if self.done else
                                                     "the experiment in progress is discarded" if req is None else
                                                     f"the experiment in progress ({req.request_id}) is discarded"))
        self._status()

    def resume(self) -> None:
        """Go on from the next sample: the discarded experiment again, or the manual point's first experiment."""
        if self.active:
            return
        self.active = True
        if self._moved:
            self._moved = False
            self.session.request = None     # the next sample starts GMA's next request (the manual point's)
        if not self.done:
            self.phase = "resuming: the next sample starts the experiment"
        self.log.info(f"resumed: the next sample starts experiment {self.gma.next_request().request_id}"
                      if not self.done else "resumed: the run has ended, holding its last setpoints")
        self._status()

    def manual_setpoints(self, c, t: float | None = None) -> str:
        """An operator's setpoints ``c`` = (theta_0, A_phi, A_theta) rad while paused, at sim time ``t`` s.

        Checked like GMA's own (the safe box, the turn limit, the optimizer's shape box); accepted ones are stored
        with the open iteration re-planned at them (GMA continues from them: they become ``c_k``), in one
        transaction, then published. Returns "" when accepted, else the reason (nothing changed)."""
        why = self._manual_error(c)
        if why:
            self.manual_note = f"refused: {why}"
            return why
        x = shape_from_setpoints(np.asarray(c, dtype=float))
        try:
            requests = self.gma.plan_at(x)
        except ValueError as err:
            self.manual_note = f"refused: {err}"
            return str(err)
        c_new = [float(v) for v in setpoints_from_shape(x)]
        try:
            self.store.save_progress(pending=requests, events=[(MANUAL, {
                "c": c_new, "x": [float(v) for v in x], "requests": [q.request_id for q in requests], "t": t})])
        except StoreError as err:
            self.manual_note = f"refused: not stored: {err}"
            return f"not stored: {err}"
        self.gma.replace_plan(requests)
        self._moved = True
        self.setpoints(c_new)
        self.manual_note = f"accepted {degrees(c_new)}"
        if not self.done:
            self.phase = f"paused: holding {degrees(c_new)} (manual)"
        self.log.info(f"manual setpoints {degrees(c_new)} stored and published; on resume GMA continues from them "
                      f"(experiment {requests[0].request_id})")
        self._status()
        return ""

    def _manual_error(self, c) -> str:
        if self.active:
            return "the optimizer is active: deactivate (pause) it first"
        if self.done:
            return f"the run has ended ({self.phase})"
        if self.persist.failing or self._held:
            return f"the database cannot be written ({self.persist.error})"
        return setpoints_error(c, self.box, self.gma.problem.c_lb, self.gma.problem.c_ub)

    # ------------------------------------------------------------------ storage
    def _store(self) -> bool:
        """Write what memory holds and the store lacks (:meth:`RunPersistence.write`); True once nothing is
        unstored. Logs what was stored; while writes fail the run holds (phase), after ``storage_timeout`` s it
        ends (``storage_lost``)."""
        w = self.persist.write()
        for req, res in w.experiments:
            self.log.info(f"experiment {req.request_id}: tension {-res.cost:.1f} kN, "
                          f"g = {res.constraints[0]:+.1f} m, c = {shape_degrees(req.c)}")
        for rec in w.records:
            self.log.info(f"iteration {rec.k}: c_k = {shape_degrees(rec.c_k)} -> c_next = "
                          f"{shape_degrees(rec.c_next)} ({rec.decision})")
            self._status()
        if w.change == "failing":
            self.phase = "holding: cannot write the database"
            self._status()
        elif w.change == "recovered":
            self.phase = "experiment" if self._started else "waiting for the plant"
            self._status()
        elif w.change == "gave up":
            self.done = True
            self.phase = self.persist.give_up_phase
            self._status()
            self._storage_lost()
        return w.stored

    def finish(self) -> None:
        rec = self.gma.records[-1]
        self.setpoints(setpoints_from_shape(rec.c_next))
        self.done = True
        self.phase = "done"
        self._status()
        self.log.info(f"done: {len(self.gma.records)} iterations; holding c = {shape_degrees(rec.c_next)}")
        self._finished()

    # ----------------------------------------------------------------- output
    def setpoints(self, c) -> None:
        """Send setpoints ``c`` (rad) after checking them against the safe box and the turn limit."""
        try:
            validate_setpoints(np.asarray(c, dtype=float), self.box, KiteParams())
        except SetpointError as err:
            self.log.error(f"refusing to publish unsafe setpoints: {err}")
            self.session.stop(f"unsafe setpoints requested: {err}")
            self.done = True
            return
        self.c_published = [float(x) for x in c]
        self._send(self.c_published)
        self.updates += 1
