"""The optimizer node's logic without ROS: plant readings joined into samples, the GMA session, persistence, status.

:class:`OptimizerRun` takes the plant's readings (stamps in integer ns) and crash counts as plain values, drives
:class:`~kite_rto.rto.session.RTOSession` (the same per-sample logic as the pure runner), writes every finished
experiment and iteration to a :class:`~kite_rto.gma.HistoryStore`, and reports through callbacks:
``send_setpoints(c)`` (checked setpoints, rad), ``sync(stamp_ns)`` after each processed sample, ``status()`` when
the status changed, ``finished()`` once ``n_iter`` iterations are done. :class:`kite_rto.nodes.optimizer_node`
turns these into messages.
"""
from __future__ import annotations

import math

import numpy as np

from ..flight.path import SetpointError, validate_setpoints
from ..flight.shape import setpoints_from_shape
from ..flight.sample_join import RejectLog, SampleJoin, reading_error, state_values
from ..kite.params import KiteParams

__all__ = ["OptimizerRun", "shape_degrees", "vector_text"]


def shape_degrees(x) -> str:
    """Setpoints in degrees of GMA's shape coordinates ``x``."""
    return "(" + ", ".join(f"{math.degrees(v):.2f}" for v in setpoints_from_shape(x)) + ") deg"


def vector_text(v) -> str:
    """A vector in 4 significant digits, as the status shows it."""
    return "[" + ", ".join(f"{x:.4g}" for x in np.asarray(v, dtype=float).ravel()) + "]"


class OptimizerRun:
    """GMA on the flying kite, one plant reading at a time; ``logger`` has ``info``/``warning``/``error``."""

    def __init__(self, gma, session, store, box, *, n_iter: int, logger, send_setpoints, sync, status, finished):
        self.gma, self.session, self.store, self.box = gma, session, store, box
        self.n_iter = n_iter
        self.log = logger
        self._send, self._sync, self._status, self._finished = send_setpoints, sync, status, finished
        self.reject = RejectLog(logger)
        self.join = SampleJoin()
        self._saved_exp = len(gma.history.experiments)
        self._saved_rec = len(gma.records)
        self.c_published = None             # setpoints of the last message sent (rad)
        self.updates = 0                    # setpoint messages sent by this process
        self._crashes_seen = 0              # last crash count of the current plant
        self._crash_offset = 0              # counts of plants that restarted (their count starts at 0 again)
        self._started = False
        self.done = False
        self.phase = "waiting for the plant"

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
        if not self._started:
            self._started = True
            if self.session.request is None:
                self.setpoints(self.session.start(m.t))
            else:                                   # plant restart: same request, measured again
                self.session.evaluator.start(m.t, self.session.c)
            self.phase = "experiment"
            return
        request, repeats = self.session.request, self.session.repeats
        new = self.session.on_measurement(m)
        if self.session.request is request and self.session.repeats > repeats:
            self.log.warning(f"experiment {request.request_id} invalid (kite crashed or no lap) at "
                             f"t = {m.t:.2f} s: its data is discarded, repeating it "
                             f"({self.session.repeats}/{self.session.max_repeats})")
        self._persist()
        if self.session.stopped:
            self.phase = f"failed: {self.session.message}"
            self.log.error(self.phase)
            self.done = True
        elif self.n_iter and len(self.gma.records) >= self.n_iter:
            self.finish()
        elif new is not None:
            self.setpoints(new)

    def _persist(self) -> None:
        exps = self.gma.history.experiments
        for req, res in exps[self._saved_exp:]:
            self.store.save_experiment(req, res)
            self.log.info(f"experiment {req.request_id}: tension {-res.cost:.1f} kN, "
                          f"g = {res.constraints[0]:+.1f} m, c = {shape_degrees(req.c)}")
        self._saved_exp = len(exps)
        for rec in self.gma.records[self._saved_rec:]:
            self.store.save_iteration(rec, self.gma.history.pending)
            self.log.info(f"iteration {rec.k}: c_k = {shape_degrees(rec.c_k)} -> c_next = "
                          f"{shape_degrees(rec.c_next)} ({rec.decision})")
            self._status()
        self._saved_rec = len(self.gma.records)

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
