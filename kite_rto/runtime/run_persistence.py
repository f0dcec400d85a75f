"""The optimizer run's persistence: what GMA holds in memory and the store lacks, written in one transaction, tried
again after a failure, given up after ``storage_timeout`` s (:class:`RunPersistence`, owned by
:class:`~kite_rto.runtime.optimizer_run.OptimizerRun`, which decides what the run does meanwhile).

One write holds everything unstored: a run's start (its ``c0``, run data and first requests), finished
experiments, the iterations they completed with the next requests. What is stored is compared with memory by
request id and iteration number, so an iteration that GMA completes again on resume (its last experiment stored,
its record not) is written too. After a failure the write is tried again at most every :data:`RETRY_PERIOD` s;
once ``storage_timeout`` s have passed since the first failure, a failed try gives up.

Run data that comes during the run (:meth:`RunPersistence.add_meta`: the run's description once the plant has said
what it is) is written at the next :meth:`RunPersistence.write`: with the records when some are unstored, else
alone. A failed write of run data alone keeps it in memory and is tried again (at most every :data:`RETRY_PERIOD`
s, and with the next records); the run goes on meanwhile: it holds nothing it would publish.
"""
from __future__ import annotations

import math
import time
from dataclasses import dataclass, field

from ..gma import StoreError

__all__ = ["RETRY_PERIOD", "RunPersistence", "Written"]

RETRY_PERIOD = 0.5
"""Wall seconds between two tries of a failed write (at the next sample after it, or at the next tick)."""


@dataclass
class Written:
    """What one :meth:`RunPersistence.write` did.

    Attributes:
        stored: nothing of the run is unstored (what follows from it may be published).
        experiments: the ``(request, result)`` pairs this write stored.
        records: the iteration records this write stored.
        change: ``"failing"`` (the first failed write), ``"recovered"`` (stored after failed writes), ``"gave up"``
            (``storage_timeout`` s of failed writes) or ``""``.
    """

    stored: bool
    experiments: list = field(default_factory=list)
    records: list = field(default_factory=list)
    change: str = ""


class RunPersistence:
    """Writes what ``gma`` holds in memory and ``store`` (a :class:`~kite_rto.gma.HistoryStore`) lacks.

    ``run_meta``: run data written with a new run's start (e.g. the settings it was created with);
    ``storage_timeout``: wall seconds of failed writes after which it gives up;
    ``clock``: wall time in s (monotonic), for the retry period and the timeout.
    """

    def __init__(self, gma, store, logger, *, run_meta: dict | None = None, storage_timeout: float = 60.0,
                 clock=time.monotonic):
        self.gma, self.store, self.log = gma, store, logger
        self.storage_timeout, self._clock = float(storage_timeout), clock
        self._stored_ids, self._stored_ks = store.stored_keys()   # what the store holds, not what memory holds
        self._start_stored = store.has_run()
        self._run_meta = dict(run_meta or {})
        self._scan_exp = self._scan_rec = 0     # everything before these indices of the history is stored
        self.failing_since = None               # clock time of the first failed write of what is unstored
        self._last_try = -math.inf
        self.error = ""                         # the last write error while something is unstored
        self.gave_up = False
        self._meta = {}                         # run data to write (add_meta)
        self._meta_try = -math.inf
        self._meta_error = ""                   # the last failed write of run data alone

    @property
    def failing(self) -> bool:
        """A write of what is unstored has failed and not succeeded since."""
        return self.failing_since is not None

    @property
    def meta_waiting(self) -> bool:
        """Run data is waiting to be written (and the persistence has not given up)."""
        return bool(self._meta) and not self.gave_up

    def add_meta(self, meta: dict) -> None:
        """Write run data ``meta`` (key -> JSON value; a key written again replaces its value) at the next
        :meth:`write`."""
        self._meta.update(meta)

    def unstored(self) -> tuple[list, list]:
        """The finished experiments and iteration records that memory holds and the store lacks."""
        exps = [(q, r) for q, r in self.gma.history.experiments[self._scan_exp:]
                if q.request_id not in self._stored_ids]
        recs = [rec for rec in self.gma.records[self._scan_rec:] if rec.k not in self._stored_ks]
        return exps, recs

    def write(self) -> Written:
        """Write what memory holds and the store lacks, in one transaction (see the module docstring)."""
        if self.gave_up:
            return Written(False)
        exps, recs = self.unstored()
        h = self.gma.history
        if not exps and not recs and self._start_stored:
            self._scan_exp, self._scan_rec = len(h.experiments), len(self.gma.records)
            if self._meta:
                self._write_meta()
            return Written(True)
        now = self._clock()
        if self.failing and now - self._last_try < RETRY_PERIOD:
            return Written(False)
        self._last_try = now
        meta = dict(self._meta) if self._start_stored else {**h.meta, **self._run_meta, "c0": h.c0, **self._meta}
        try:
            self.store.save_progress(exps, recs, h.pending if recs or not self._start_stored else None, meta or None)
        except StoreError as err:
            return self._failed(str(err), now, len(exps), len(recs))
        self._meta_stored()
        self._start_stored = True
        self._stored_ids.update(q.request_id for q, _ in exps)
        self._stored_ks.update(rec.k for rec in recs)
        self._scan_exp, self._scan_rec = len(h.experiments), len(self.gma.records)
        change = ""
        if self.failing:
            self.log.info(f"stored in {self.store.path} after {now - self.failing_since:.1f} s of failed writes; "
                          "going on from the held setpoints")
            self.failing_since, self.error, change = None, "", "recovered"
        return Written(True, exps, recs, change)

    def _write_meta(self) -> None:
        """Write the waiting run data alone (after a failure at most every RETRY_PERIOD s); a failure keeps it for
        the next write."""
        now = self._clock()
        if self._meta_error and now - self._meta_try < RETRY_PERIOD:
            return
        self._meta_try = now
        try:
            self.store.save_progress(meta=dict(self._meta))
        except StoreError as err:
            if not self._meta_error:
                self.log.error(f"{err}: run data ({', '.join(sorted(self._meta))}) kept in memory; trying again every "
                               f"{RETRY_PERIOD:g} s and with the next records (the run goes on)")
            self._meta_error = str(err)
            return
        self._meta_stored()

    def _meta_stored(self) -> None:
        """The waiting run data was written (alone or with records)."""
        if self._meta_error:
            self.log.info(f"run data ({', '.join(sorted(self._meta))}) stored in {self.store.path} after failed "
                          "writes")
        self._meta, self._meta_error = {}, ""

    def _failed(self, err: str, now: float, n_exp: int, n_rec: int) -> Written:
        self.error = err
        change = ""
        if self.failing_since is None:
            self.failing_since, change = now, "failing"
            self.log.error(f"{err}. Holding the setpoints in force and keeping {n_exp} experiment(s) and {n_rec} "
                           f"iteration(s) in memory; trying again every {RETRY_PERIOD:g} s for up to "
                           f"{self.storage_timeout:g} s (storage_timeout)")
        if now - self.failing_since >= self.storage_timeout:
            self.gave_up, change = True, "gave up"
            self.log.error(f"{self.give_up_phase} ({err}): stopping. Everything stored so far is complete; {n_exp} "
                           f"finished experiment(s) and {n_rec} iteration(s) were not stored and will be measured "
                           "and computed again. Free the disk and restart the optimizer on the same database to "
                           "resume")
        return Written(False, change=change)

    @property
    def give_up_phase(self) -> str:
        """The run's phase once this gave up."""
        return f"failed: cannot write {self.store.path} for {self.storage_timeout:g} s"
