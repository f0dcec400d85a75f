"""SQLite persistence of a GMA run: every finished experiment and iteration, written as it happens.

A restarted optimizer calls :meth:`HistoryStore.load` and passes the result to ``GMA(..., history=...)``: finished
experiments are never requested again. Each write is one transaction, so a process killed at any moment leaves
the database at the last complete write.
"""
from __future__ import annotations

import json
import sqlite3
import time

from .records import ExperimentRequest, ExperimentResult, History, IterationRecord, _plain

__all__ = ["HistoryStore"]

_SCHEMA = """
CREATE TABLE IF NOT EXISTS meta (key TEXT PRIMARY KEY, value TEXT NOT NULL);
CREATE TABLE IF NOT EXISTS experiments (seq INTEGER PRIMARY KEY AUTOINCREMENT, request_id TEXT UNIQUE NOT NULL,
    iteration INTEGER NOT NULL, purpose TEXT NOT NULL, request TEXT NOT NULL, result TEXT NOT NULL,
    wall_time REAL NOT NULL);
CREATE TABLE IF NOT EXISTS iterations (k INTEGER PRIMARY KEY, record TEXT NOT NULL, wall_time REAL NOT NULL);
CREATE TABLE IF NOT EXISTS pending (k INTEGER PRIMARY KEY CHECK (k = 0), requests TEXT NOT NULL);
"""


class HistoryStore:
    """A GMA :class:`~kite_rto.gma.records.History` kept in an SQLite file.

    Args:
        path: database file (created if missing); ``":memory:"`` for tests.
    """

    def __init__(self, path):
        self.path = str(path)
        self._db = sqlite3.connect(self.path)
        self._db.executescript(_SCHEMA)
        self._db.commit()

    def close(self) -> None:
        self._db.close()

    # ------------------------------------------------------------------ write
    def save_meta(self, meta: dict) -> None:
        """Store free run data (problem, settings, c0 under key ``c0``)."""
        with self._db:
            self._db.executemany("INSERT OR REPLACE INTO meta VALUES (?, ?)",
                                 [(k, json.dumps(_plain(v), allow_nan=False)) for k, v in meta.items()])

    def save_experiment(self, request: ExperimentRequest, result: ExperimentResult) -> None:
        """Store one finished experiment (idempotent: a second write of the same id is ignored)."""
        with self._db:
            self._db.execute("INSERT OR IGNORE INTO experiments (request_id, iteration, purpose, request, result, "
                             "wall_time) VALUES (?, ?, ?, ?, ?, ?)",
                             (request.request_id, request.iteration, request.purpose,
                              json.dumps(request.to_dict(), allow_nan=False),
                              json.dumps(result.to_dict(), allow_nan=False), time.time()))

    def save_iteration(self, record: IterationRecord, pending: list[ExperimentRequest]) -> None:
        """Store a completed iteration and the requests of the next one, in one transaction."""
        with self._db:
            self._db.execute("INSERT OR REPLACE INTO iterations VALUES (?, ?, ?)",
                             (record.k, json.dumps(record.to_dict(), allow_nan=False), time.time()))
            self._save_pending(pending)

    def save_pending(self, pending: list[ExperimentRequest]) -> None:
        with self._db:
            self._save_pending(pending)

    def _save_pending(self, pending) -> None:
        self._db.execute("INSERT OR REPLACE INTO pending VALUES (0, ?)",
                         (json.dumps([q.to_dict() for q in pending], allow_nan=False),))

    def save_history(self, history: History) -> None:
        """Write everything of ``history`` (used once when a run starts from an existing History)."""
        self.save_meta({**history.meta, "c0": history.c0})
        for req, res in history.experiments:
            self.save_experiment(req, res)
        for rec in history.iterations:
            self.save_iteration(rec, history.pending)
        self.save_pending(history.pending)

    # ------------------------------------------------------------------- read
    def load(self) -> History | None:
        """The stored history, or None for an empty database."""
        meta = {k: json.loads(v) for k, v in self._db.execute("SELECT key, value FROM meta")}
        if "c0" not in meta:
            return None
        c0 = meta.pop("c0")
        exps = [{"request": json.loads(q), "result": json.loads(r)}
                for q, r in self._db.execute("SELECT request, result FROM experiments ORDER BY seq")]
        its = [json.loads(r) for (r,) in self._db.execute("SELECT record FROM iterations ORDER BY k")]
        row = self._db.execute("SELECT requests FROM pending").fetchone()
        return History.from_dict({"c0": c0, "experiments": exps, "iterations": its,
                                  "pending": json.loads(row[0]) if row else [], "meta": meta})

    def counts(self) -> dict:
        """Numbers of stored experiments and iterations."""
        n_e = self._db.execute("SELECT COUNT(*) FROM experiments").fetchone()[0]
        n_i = self._db.execute("SELECT COUNT(*) FROM iterations").fetchone()[0]
        return {"experiments": n_e, "iterations": n_i}
