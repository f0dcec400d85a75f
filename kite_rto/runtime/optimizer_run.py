"""The optimizer node's logic without ROS: plant readings joined into samples, the GMA session, persistence, status.

:class:`OptimizerRun` takes the plant's readings (stamps in integer ns) and crash counts as plain values, drives
:class:`~kite_rto.rto.session.RTOSession` (the same per-sample logic as the pure runner), writes every finished
experiment and iteration to a :class:`~kite_rto.gma.HistoryStore`, and reports through callbacks:
``send_setpoints(c)`` (checked setpoints, rad), ``sync(stamp_ns)`` after each processed sample, ``status()`` when
the status changed, ``finished()`` once ``n_iter`` iterations are done, ``storage_lost()`` when the database stayed
unwritable for ``storage_timeout`` s. :class:`kite_rto.nodes.optimizer_node` turns these into messages.

Nothing is lost when storage fails. What GMA holds in memory and the store lacks is written in one transaction (a
run's start; finished experiments; the experiment that completes an iteration together with that iteration's
record and the next requests) before any setpoint that follows from it is published. When that write fails, the
run keeps everything in memory, holds the setpoints in force (the plant flies them; their measurements are not
used), and tries again at the next sample (at most every :data:`RETRY_PERIOD` s) and on :meth:`OptimizerRun.tick`;
once stored, the held experiment starts from that sample. After ``storage_timeout`` s of failed writes it gives up
(``storage_lost``). What is stored is compared with memory by request id and iteration number, so an iteration
that GMA completes again on resume (its last experiment stored, its record not) is written too.

Operator (the node's lifecycle, docs/interface.md *Pausing and overriding the optimizer*): :meth:`OptimizerRun.pause`
holds the setpoints in force and discards the experiment in progress (samples are still synchronized, nothing is
measured); :meth:`OptimizerRun.manual_setpoints` (only while paused) checks setpoints against the box and the turn
limit, stores them with the open iteration re-planned at them and publishes them; :meth:`OptimizerRun.resume`
flies the open iteration's next experiment from the next sample on (the discarded one again, or the manual point's
nominal experiment).
"""
from __future__ import annotations

import math
import time

import numpy as np

from ..flight.path import SetpointError, validate_setpoints
from ..flight.shape import setpoints_from_shape, shape_from_setpoints
from .sample_join import RejectLog, SampleJoin, reading_error, state_values
from ..gma import StoreError
from ..kite.params import KiteParams
from .operator_log import MANUAL

__all__ = ["OptimizerRun", "RETRY_PERIOD", "shape_degrees", "vector_text"]

RETRY_PERIOD = 0.5
"""Wall seconds between two tries of a failed write (at the next sample after it, or at the next tick)."""


def shape_degrees(x) -> str:
    """Setpoints in degrees of GMA's shape coordinates ``x``."""
    return "(" + ", ".join(f"{math.degrees(v):.2f}" for v in setpoints_from_shape(x)) + ") deg"


def _degrees(c) -> str:
    """Setpoints ``c`` (rad) in degrees."""
    return "(" + ", ".join(f"{math.degrees(v):.2f}" for v in c) + ") deg"


def vector_text(v) -> str:
    """A vector in 4 significant digits, as the status shows it."""
    return "[" + ", ".join(f"{x:.4g}" for x in np.asarray(v, dtype=float).ravel()) + "]"


class OptimizerRun:
    """GMA on the flying kite, one plant reading at a time; ``logger`` has ``info``/``warning``/``error``.

    ``run_meta``: run data written with a new run's start (e.g. the settings it was created with);
    ``storage_timeout``: wall seconds of failed writes after which the run gives up (``storage_lost()``);
    ``clock``: wall time in s (monotonic), for the retry period and the timeout.
    """

    def __init__(self, gma, session, store, box, *, n_iter: int, logger, send_setpoints, sync, status, finished,
                 storage_lost=lambda: None, storage_timeout: float = 60.0, run_meta: dict | None = None,
                 clock=time.monotonic):
        self.gma, self.session, self.store, self.box = gma, session, store, box
        self.n_iter = n_iter
        self.log = logger
        self._send, self._sync, self._status, self._finished = send_setpoints, sync, status, finished
        self._storage_lost, self.storage_timeout, self._clock = storage_lost, float(storage_timeout), clock
        self.reject = RejectLog(logger)
        self.join = SampleJoin()
        self._stored_ids, self._stored_ks = store.stored_keys()   # what the store holds, not what memory holds
        self._start_stored = store.has_run()
        self._run_meta = dict(run_meta or {})
        self._scan_exp = self._scan_rec = 0     # everything before these indices of the history is stored
        self._failing_since = None              # clock time of the first failed write of what is unstored
        self._last_try = -math.inf
        self.storage_error = ""                 # the last write error while something is unstored
        self._held = False                      # the session moved on while its records were unstored
        self._held_new = None                   # ... and asked for these setpoints (rad), applied once stored
        self.c_published = None             # setpoints of the last message sent (rad)
        self.updates = 0                    # setpoint messages sent by this process
        self._crashes_seen = 0              # last crash count of the current plant
        self._crash_offset = 0              # counts of plants that restarted (their count starts at 0 again)
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
        sample arrives."""
        if self._failing_since is not None and not self.done:
            self._store()

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
        if n < self._crashes_seen:
            self._crash_offset += self._crashes_seen
        self._crashes_seen = n
        self.join.crashes = self._crash_offset + n

    def _part(self, stamp: int, part: str, value) -> None:
        if part == "state" and stamp == self.join.last:
            self._sync(stamp)        # the plant re-published a processed sample (its answer is late): sync it again
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
        self.on_sample(m)
        self._sync(m.stamp)

    def on_sample(self, m) -> None:
        if self.done:
            return
        if not self.active:                 # paused: the held setpoints fly, nothing is measured
            if self._failing_since is not None:
                self._store()
            self.session.evaluator.update(m)        # an inactive evaluator only follows the wind
            return
        if self._failing_since is not None and not self._store():
            return                          # records unstored: the held setpoints fly, nothing is measured
        if self._held:                      # stored at last: what the session asked for starts now
            self._held = False
            self._started = True
            self.phase = "experiment"
            self._advance(self._held_new, m.t, restart=True)
            return
        if not self._started:
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
        held = "nothing yet" if self.c_published is None else _degrees(self.c_published)
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
        self.manual_note = f"accepted {_degrees(c_new)}"
        if not self.done:
            self.phase = f"paused: holding {_degrees(c_new)} (manual)"
        self.log.info(f"manual setpoints {_degrees(c_new)} stored and published; on resume GMA continues from them "
                      f"(experiment {requests[0].request_id})")
        self._status()
        return ""

    def _manual_error(self, c) -> str:
        if self.active:
            return "the optimizer is active: deactivate (pause) it first"
        if self.done:
            return f"the run has ended ({self.phase})"
        if self._failing_since is not None or self._held:
            return f"the database cannot be written ({self.storage_error})"
        try:
            c = np.asarray(c, dtype=float)
            if c.shape != (3,):
                raise SetpointError(f"setpoints = {c.tolist()}: expected 3 values (theta_0, A_phi, A_theta) rad")
            validate_setpoints(c, self.box, KiteParams())
        except (SetpointError, ValueError, TypeError) as err:
            return str(err)
        x, lb, ub = shape_from_setpoints(c), self.gma.problem.c_lb, self.gma.problem.c_ub
        for name, v, lo, hi, deg in zip(("theta_0", "A_phi", "aspect"), x, lb, ub, (True, True, False)):
            if not lo <= v <= hi:
                f = (lambda a: f"{math.degrees(a):.4g} deg") if deg else (lambda a: f"{a:.4g}")
                return (f"setpoints {_degrees(c)}: shape coordinate {name} = {f(v)}: outside the optimizer's box "
                        f"[{f(lo)}, {f(hi)}]")
        return ""

    # ------------------------------------------------------------------ storage
    def _unstored(self) -> tuple[list, list]:
        exps = [(q, r) for q, r in self.gma.history.experiments[self._scan_exp:]
                if q.request_id not in self._stored_ids]
        recs = [rec for rec in self.gma.records[self._scan_rec:] if rec.k not in self._stored_ks]
        return exps, recs

    def _store(self) -> bool:
        """Write what memory holds and the store lacks, in one transaction; True once nothing is unstored.

        After a failure the write is tried again at most every :data:`RETRY_PERIOD` s; once ``storage_timeout`` s
        have passed since the first failure, a failed try ends the run (:meth:`_give_up`)."""
        exps, recs = self._unstored()
        if not exps and not recs and self._start_stored:
            self._scan_exp, self._scan_rec = len(self.gma.history.experiments), len(self.gma.records)
            return True
        now = self._clock()
        if self._failing_since is not None and now - self._last_try < RETRY_PERIOD:
            return False
        self._last_try = now
        h = self.gma.history
        meta = None if self._start_stored else {**h.meta, **self._run_meta, "c0": h.c0}
        try:
            self.store.save_progress(exps, recs, h.pending if recs or meta else None, meta)
        except StoreError as err:
            self._write_failed(str(err), now, len(exps), len(recs))
            return False
        self._start_stored = True
        self._stored_ids.update(q.request_id for q, _ in exps)
        self._stored_ks.update(rec.k for rec in recs)
        self._scan_exp, self._scan_rec = len(h.experiments), len(self.gma.records)
        for req, res in exps:
            self.log.info(f"experiment {req.request_id}: tension {-res.cost:.1f} kN, "
                          f"g = {res.constraints[0]:+.1f} m, c = {shape_degrees(req.c)}")
        for rec in recs:
            self.log.info(f"iteration {rec.k}: c_k = {shape_degrees(rec.c_k)} -> c_next = "
                          f"{shape_degrees(rec.c_next)} ({rec.decision})")
            self._status()
        if self._failing_since is not None:
            self.log.info(f"stored in {self.store.path} after {now - self._failing_since:.1f} s of failed writes; "
                          "going on from the held setpoints")
            self._failing_since, self.storage_error = None, ""
            self.phase = "experiment" if self._started else "waiting for the plant"
            self._status()
        return True

    def _write_failed(self, err: str, now: float, n_exp: int, n_rec: int) -> None:
        self.storage_error = err
        if self._failing_since is None:
            self._failing_since = now
            self.phase = "holding: cannot write the database"
            self.log.error(f"{err}. Holding the setpoints in force and keeping {n_exp} experiment(s) and {n_rec} "
                           f"iteration(s) in memory; trying again every {RETRY_PERIOD:g} s for up to "
                           f"{self.storage_timeout:g} s (storage_timeout)")
            self._status()
        if now - self._failing_since >= self.storage_timeout:
            self._give_up(err, n_exp, n_rec)

    def _give_up(self, err: str, n_exp: int, n_rec: int) -> None:
        self.done = True
        self.phase = f"failed: cannot write {self.store.path} for {self.storage_timeout:g} s"
        self.log.error(f"{self.phase} ({err}): stopping. Everything stored so far is complete; {n_exp} finished "
                       f"experiment(s) and {n_rec} iteration(s) were not stored and will be measured and computed "
                       "again. Free the disk and restart the optimizer on the same database to resume")
        self._status()
        self._storage_lost()

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

    def status_values(self) -> dict:
        """The status as key -> value (str or number): iteration, phase, the current experiment, the last record."""
        req = self.session.request
        kv = {"iteration": len(self.gma.records), "phase": self.phase,
              "experiments_done": len(self.gma.history.experiments)}
        if self.manual_note:
            kv["manual_setpoints"] = self.manual_note
        if self.storage_error:
            kv["storage_error"] = self.storage_error
        if req is not None:
            kv.update(experiment=req.request_id, purpose=req.purpose, setpoints_deg=shape_degrees(req.c),
                      experiment_t_start=f"{self.session.evaluator.t_start:.2f}")
        if self.gma.records:
            r = self.gma.records[-1]
            kv.update(measured_cost_kN=f"{r.cost:.2f}", measured_constraint_m=f"{r.constraints[0]:.2f}",
                      grad_cost=vector_text(r.grad_cost), grad_constraint=vector_text(r.jac_constraints.ravel()),
                      eps=vector_text(r.eps), lambda_=vector_text(r.lam), mu=vector_text(r.mu.ravel()),
                      c_star_deg=shape_degrees(r.c_star), c_next_deg=shape_degrees(r.c_next),
                      decision=r.decision)
        return {k.rstrip("_"): v for k, v in kv.items()}
