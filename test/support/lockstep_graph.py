"""The lockstep graph in one process, without DDS: a :class:`KitePlant` stepped on the controller's answers, the
controller's :class:`SteeringLoop` and the optimizer's :class:`OptimizerRun`, their messages handed over in
order per topic, the optimizer working ``behind`` the controller at a seeded random pace (its backlog of samples
processed a few at a time, or all of them while the controller waits).

What the DDS graph adds (processes, QoS, discovery) is left out, so the handshake itself can be checked against
the pure runner on every sample, quickly and deterministically.
"""
from __future__ import annotations

import random
from collections import deque
from dataclasses import replace

from kite_rto.flight.controller import ControllerSettings
from kite_rto.flight.path import DEFAULT_SETPOINTS, Setpoints
from kite_rto.kite.params import KiteParams
from kite_rto.kite.plant import KitePlant
from kite_rto.rto.builder import make_gma
from kite_rto.rto.session import RTOSession
from kite_rto.runtime.optimizer_run import OptimizerRun
from kite_rto.runtime.optimizer_sync import SYNC_NAMES
from kite_rto.runtime.run_db import open_run_database
from kite_rto.runtime.steering_loop import SteeringLoop

from storage_flight import Log

STATE_NAMES = ["theta", "phi", "psi"]


class LockstepGraph:
    """Plant, controller and optimizer of one run (``settings``: KiteRTOSettings) on the database ``db``.

    ``pace``: the most samples of its backlog the optimizer processes per plant step, drawn uniformly from 0 to
    ``pace`` (1: half a sample per step on average, so it falls behind until the controller waits for it; 0: it
    keeps up at once, as the per-sample handshake did); ``seed``: the plant's seed and the pace's.
    """

    def __init__(self, db, settings, plant_config, seed: int = 0, n_iter: int = 1, pace: int = 3):
        self.plant = KitePlant(plant_config, seed=seed)
        self.dt_ns = round(self.plant.dt * 1e9)
        self.rng, self.pace = random.Random(seed), pace
        self.log, self.opt_log = Log(), Log()
        self.now = 0.0
        self.answer = None
        self.syncs = deque()                   # /rto/sync messages on their way to the controller
        self.backlog = deque()                 # samples on their way to the optimizer
        self.sync_messages = 0
        self.max_backlog = 0                   # the most samples the optimizer was behind the controller
        cs = replace(ControllerSettings(), box=settings.box.setpoint_box())
        self.loop = SteeringLoop(KiteParams(), cs, DEFAULT_SETPOINTS, answer=self._answer, lap=lambda s, lap: None,
                                 path=lambda: None, logger=self.log, sync=True, setpoint_sources=lambda: 1,
                                 sync_sources=lambda: 1, clock=lambda: self.now)
        store, history, _ = open_run_database(db, {"lockstep": True}, True)
        self.gma = make_gma(settings, history=history)
        session = RTOSession(self.gma, settings.experiment, settings.max_repeats)
        self.run = OptimizerRun(self.gma, session, store, settings.box.setpoint_box(), n_iter=n_iter,
                                logger=self.opt_log, send_setpoints=self._setpoints, processed=self._processed,
                                status=lambda: None, finished=lambda: None, clock=lambda: self.now)

    def _answer(self, stamp: int, delta: float) -> None:
        self.answer = (stamp, delta)

    def _setpoints(self, c) -> None:
        self.loop.setpoints_message(Setpoints.names(), list(c))

    def _processed(self, stamp: int, plan) -> None:
        if plan is not None:
            self.sync_messages += 1
            self.syncs.append((stamp, plan.values()))

    def _optimizer_step(self) -> None:
        """The optimizer takes one sample of its backlog; its messages reach the controller."""
        stamp, m = self.backlog.popleft()
        self.run.crashes(m.crashes)
        self.run.state_reading(stamp, STATE_NAMES, [m.theta, m.phi, m.psi], [m.theta_dot, m.phi_dot, m.psi_dot])
        self.run.reading(stamp, "tension", m.tension)
        self.run.reading(stamp, "position", tuple(m.position))
        self.run.reading(stamp, "wind", m.wind_ref)
        while self.syncs:
            stamp, values = self.syncs.popleft()
            self.loop.sync_message(stamp, SYNC_NAMES, values)

    def fly(self, max_samples: int = 200_000) -> "LockstepGraph":
        """Fly until the optimizer is done (or ``max_samples``)."""
        self.run.begin()
        m = self.plant.measure()
        for _ in range(max_samples):
            if self.run.done:
                break
            stamp = self.plant.k * self.dt_ns
            self.backlog.append((stamp, m))
            self.max_backlog = max(self.max_backlog, len(self.backlog))
            self.loop.crash_count(m.crashes)
            self.loop.tension_reading(stamp, m.tension)
            self.loop.position_reading(stamp, tuple(m.position))
            self.loop.wind_reading(stamp, m.wind_ref)
            self.loop.state_sample(stamp, STATE_NAMES, [m.theta, m.phi, m.psi], [m.theta_dot, m.phi_dot, m.psi_dot])
            for _ in range(self.rng.randint(0, self.pace) if self.pace else len(self.backlog)):
                if self.backlog:
                    self._optimizer_step()
            while self.answer is None or self.answer[0] != stamp:
                if not self.backlog:
                    raise AssertionError(f"deadlock: the controller waits at {stamp * 1e-9:.2f} s and the optimizer "
                                         "has processed every sample")
                self._optimizer_step()
            m = self.plant.step(self.answer[1])
        return self
