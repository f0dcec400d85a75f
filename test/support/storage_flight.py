"""A pure stand-in for one optimizer process, for the storage fault tests: the real :class:`OptimizerRun`, GMA,
session and SQLite store on a file, with the lap measurement replaced by an analytic plant and the wall clock by a
counter, so that a whole GMA run with its database writes takes a second and is deterministic.

Each flight checks, at every setpoint message, that memory holds nothing the database lacks (else the message is
counted in ``unsafe``, as is one that fails the box and turn check), and at every finished experiment that the
plant flew that experiment's setpoints from its start on (else ``mismeasured``).
"""
from __future__ import annotations

import math
from types import SimpleNamespace

import numpy as np

from kite_rto.flight.path import SetpointError, validate_setpoints
from kite_rto.gma import HistoryStore
from kite_rto.kite.params import KiteParams
from kite_rto.rto.builder import make_gma
from kite_rto.rto.experiment import ExperimentOutcome, ExperimentSpec
from kite_rto.rto.experiment_end import ExperimentEnd
from kite_rto.rto.run import RUN_KEY
from kite_rto.runtime.optimizer_run import OptimizerRun
from kite_rto.runtime.run_db import SETTINGS_KEY, open_run_database
from kite_rto.rto.session import RTOSession
from kite_rto.rto.settings import KiteRTOSettings

DT = 0.1            # s of simulated time per sample
WALL = 0.1          # s of (fake) wall time per sample
DURATION = 1.0      # s: every experiment lasts this long
TICK = 10           # samples between two OptimizerRun.tick() (the node's 1 Hz timer)
SETTINGS = KiteRTOSettings()


def plant(c) -> tuple[float, float]:
    """A smooth deterministic 'kite': cost (kN, minus tension) and altitude constraint (m) of setpoints c (rad)."""
    t0, a_phi, a_theta = c
    tension = 8.0 - 20.0 * (t0 - 0.55) ** 2 - 6.0 * (a_phi - 0.9) ** 2 - 80.0 * (a_theta - 0.15) ** 2
    return -tension, -5.0 + 10.0 * (0.6 - t0)


def sample(t: float) -> SimpleNamespace:
    """A joined sample at ``t`` s as :meth:`OptimizerRun.on_sample` takes it (flying no lap, no crash)."""
    return SimpleNamespace(t=t, phi=0.0, crashes=0, stamp=round(t * 1e9))


class Log:
    """A logger that keeps (level, text) lines (throttling arguments ignored)."""

    def __init__(self):
        self.lines = []

    def info(self, text, **_):
        self.lines.append(("info", text))

    def warning(self, text, **_):
        self.lines.append(("warning", text))

    def error(self, text, **_):
        self.lines.append(("error", text))

    def text(self, level=None) -> str:
        return "\n".join(t for lv, t in self.lines if level in (None, lv))


class Evaluator:
    """Stands in for ExperimentEvaluator: an experiment ends DURATION s after its start (the samples fly no lap, so
    the shared end rule times it out there, as the optimizer's plans expect), measured by ``plant``."""

    n_laps, max_duration = 1, DURATION

    def __init__(self, flight):
        self.flight = flight
        self.c = None
        self.t_start = math.nan
        self.active = False
        self.wind_estimate = math.nan
        self.end = None

    def start(self, t, c=None, n_laps=None):
        self.c, self.t_start, self.active = np.array(c, dtype=float), float(t), True
        self.end = ExperimentEnd(self.t_start, self.n_laps, 0.0, 0, self.max_duration)

    def update(self, m):
        if not self.active or self.end.update(m.t, m.phi, m.crashes) is None:
            return None
        self.active = False
        self.flight.check_window(self.c, self.t_start)
        cost, g = plant(self.c)
        return ExperimentOutcome(c=self.c, cost=cost, constraint=g, cost_std=math.nan, constraint_std=math.nan,
                                 n_laps=1, mean_tension_kn=-cost, min_altitude=50.0, crashed=False, timed_out=False,
                                 valid=True, t_start=self.t_start, t_end=float(m.t))


class Flight:
    """One optimizer process on the database ``db`` (see the module docstring)."""

    def __init__(self, db, fault=None, n_iter: int = 2, timeout: float = 5.0, settings: dict | None = None,
                 description=None):
        """``description``: the run's RunDescription, written with its start as the optimizer node does (None: no
        description)."""
        settings = {"n_laps": 1} if settings is None else settings
        run_meta = {SETTINGS_KEY: settings, **({RUN_KEY: description.to_dict()} if description is not None else {})}
        self.store, history, _ = open_run_database(db, settings, True, fault=fault)
        self.gma = make_gma(SETTINGS, history=history)
        session = RTOSession(self.gma, ExperimentSpec(n_laps=1, settle_laps=0))
        session.evaluator = Evaluator(self)
        self.clock, self.t = 0.0, 0.0
        self.flying, self.sent_t, self.sent = None, -math.inf, []
        self.unsafe = self.mismeasured = 0
        self.storage_lost = self.finished = False
        self.log = Log()
        self.run = OptimizerRun(self.gma, session, self.store, SETTINGS.box.setpoint_box(), n_iter=n_iter,
                                logger=self.log, send_setpoints=self.send, processed=lambda stamp, plan: None,
                                status=lambda: None, finished=self._finished, storage_lost=self._lost,
                                storage_timeout=timeout, run_meta=run_meta, description=description,
                                clock=lambda: self.clock)

    def _finished(self):
        self.finished = True

    def _lost(self):
        self.storage_lost = True

    def send(self, c):
        ids, ks = self.store.stored_keys()
        if ({q.request_id for q, _ in self.gma.history.experiments} - ids
                or {r.k for r in self.gma.records} - ks or not self.store.has_run()):
            self.unsafe += 1                        # published while memory held something the file lacks
        try:
            validate_setpoints(np.asarray(c), SETTINGS.box.setpoint_box(), KiteParams())
        except SetpointError:
            self.unsafe += 1
        self.flying, self.sent_t = np.array(c, dtype=float), self.t
        self.sent.append(np.array(c, dtype=float))

    def check_window(self, c, t_start):
        if self.flying is None or not np.array_equal(self.flying, c) or self.sent_t > t_start:
            self.mismeasured += 1

    def fly(self, max_samples: int = 2000, kill_after: int | None = None) -> "Flight":
        """Begin, then one sample every DT until the run is done (or ``kill_after`` samples: a SIGKILL, the store
        left as it is)."""
        self.run.begin()
        for n in range(max_samples):
            if self.run.done or n == kill_after:
                break
            self.clock += WALL
            self.run.on_sample(sample(self.t))
            if n % TICK == 0:
                self.run.tick()
            self.t += DT
        if kill_after is None:
            self.store.close()
        return self


def compare(db, reference) -> dict:
    """Records lost, duplicated and extra in ``db`` against the ``reference`` History, and the largest setpoint
    difference of the experiments (rad, shape coordinates)."""
    store = HistoryStore(db)
    try:
        h = store.load()
        rows = store._reader().execute("SELECT request_id FROM experiments").fetchall()
        ks = store._reader().execute("SELECT k FROM iterations").fetchall()
    finally:
        store.close()
    ids = [r for (r,) in rows]
    ref_ids = [q.request_id for q, _ in reference.experiments]
    ref_ks = {r.k for r in reference.iterations}
    lost = len(set(ref_ids) - set(ids)) + len(ref_ks - {k for (k,) in ks})
    duplicated = len(ids) - len(set(ids)) + len(ks) - len(set(ks))
    extra = len(set(ids) - set(ref_ids)) + len({k for (k,) in ks} - ref_ks)
    same_order = [q.request_id for q, _ in h.experiments] == ref_ids
    dc = (float(np.max(np.abs(np.array([q.c for q, _ in h.experiments]) - [q.c for q, _ in reference.experiments])))
          if same_order else math.inf)
    return {"lost": lost, "duplicated": duplicated, "extra": extra, "same_order": same_order, "dc": dc,
            "experiments": len(ids), "iterations": len(ks)}
