"""SQLite persistence of a GMA run: every finished experiment and iteration, written as it happens.

A restarted optimizer calls :meth:`HistoryStore.load` and passes the result to ``GMA(..., history=...)``: finished
experiments are never requested again.

Durability. The file is in SQLite's write-ahead-log mode (``journal_mode=WAL``) with ``synchronous=FULL``: every
write is one transaction, flushed to the disk (fsync of the log) before :meth:`HistoryStore.save_progress`
returns. A process killed at any moment, or a power cut, leaves the database at the last complete write.
(``synchronous=NORMAL`` with WAL would also survive a killed process but may lose the last writes on a power cut;
the optimizer writes a few records per minute, so the fsync costs nothing that matters.)

Atomicity. :meth:`HistoryStore.save_progress` writes a record set in one transaction: the experiment that completes
an iteration, that iteration's record and the next iteration's requests are stored together or not at all.

Failures. A damaged or foreign file is detected when the store is opened (:class:`StoreError`), without writing to
it: the file is read through a read-only connection, and the writing connection is opened at the first write. A
failed write (disk full, I/O error) raises :class:`StoreError` naming the file and SQLite's reason; nothing of the
record set is stored and the store stays usable: the same write may be tried again.
"""
from __future__ import annotations

import json
import os
import sqlite3
import time

from .records import ExperimentRequest, ExperimentResult, History, IterationRecord, _plain

__all__ = ["HistoryStore", "StoreError"]

_SCHEMA = """
CREATE TABLE IF NOT EXISTS meta (key TEXT PRIMARY KEY, value TEXT NOT NULL);
CREATE TABLE IF NOT EXISTS experiments (seq INTEGER PRIMARY KEY AUTOINCREMENT, request_id TEXT UNIQUE NOT NULL,
    iteration INTEGER NOT NULL, purpose TEXT NOT NULL, request TEXT NOT NULL, result TEXT NOT NULL,
    wall_time REAL NOT NULL);
CREATE TABLE IF NOT EXISTS iterations (k INTEGER PRIMARY KEY, record TEXT NOT NULL, wall_time REAL NOT NULL);
CREATE TABLE IF NOT EXISTS pending (k INTEGER PRIMARY KEY CHECK (k = 0), requests TEXT NOT NULL);
CREATE TABLE IF NOT EXISTS events (seq INTEGER PRIMARY KEY AUTOINCREMENT, kind TEXT NOT NULL, data TEXT NOT NULL,
    wall_time REAL NOT NULL);
"""
_TABLES = {"meta", "experiments", "iterations"}        # a history has at least these (older files lack pending,
                                                        # events: created at their first write)
_BUSY_TIMEOUT = 10.0                                    # s: wait for another connection's write to end


class StoreError(Exception):
    """The history file cannot be read (damaged, not a history) or written (disk full, I/O error); the message
    names the file and the cause."""

    @classmethod
    def damaged(cls, path: str, cause) -> "StoreError":
        """The error of a file that cannot be read as a history, with what to do about it."""
        return cls(f"database {path} cannot be read ({cause}). It was not modified. Move it aside "
                   f"(mv {path} {path}.damaged) and start again for a new run, or give another file")


def _json(v) -> str:
    return json.dumps(_plain(v), allow_nan=False)


class HistoryStore:
    """A GMA :class:`~kite_rto.gma.records.History` kept in an SQLite file.

    Args:
        path: database file (created at the first write if missing); ``":memory:"`` for tests.
        fault: test hook, an object with ``before_commit(kind)`` called inside every write transaction just before
            it commits (``kind``: ``"start"``, ``"experiment"`` or ``"iteration"``, see :meth:`save_progress`); an
            exception it raises rolls the transaction back like a real failure (e.g. an ``OSError`` of a full
            disk).

    Raises:
        StoreError: the file exists but is not a readable history (it is left as it was).
    """

    def __init__(self, path, *, fault=None):
        self.path = str(path)
        self.fault = fault
        self._db = None          # the writing connection, opened by the first write
        self._ro = None          # the reading connection until then
        if self.path == ":memory:":
            self._db = sqlite3.connect(self.path)
            self._db.executescript(_SCHEMA)
        else:
            self._check_readable()

    def close(self) -> None:
        for conn in (self._ro, self._db):
            if conn is not None:
                conn.close()
        self._ro = self._db = None

    # ------------------------------------------------------------------ open
    def _check_readable(self) -> None:
        """Open the file read-only and check it (``PRAGMA quick_check`` and the tables); StoreError if damaged."""
        p = self.path
        if not os.path.exists(p) or os.path.getsize(p) == 0:
            wal = p + "-wal"
            if os.path.exists(wal) and os.path.getsize(wal) > 0:
                raise StoreError(f"database {p}: a write-ahead log {wal} is there without its database. Move it "
                                 f"aside (mv {wal} {wal}.orphan) and start again, or give another file")
            return
        created = [s for s in ("-wal", "-shm") if not os.path.exists(p + s)]
        try:
            self._ro = self._open_read_only()
            tables = {r[0] for r in self._ro.execute("SELECT name FROM sqlite_master WHERE type = 'table'")}
        except sqlite3.DatabaseError as err:
            self._refuse_damaged(err, created)
        if tables and not _TABLES <= tables:
            self._refuse_damaged(f"not a GMA history: its tables are {sorted(tables)}, a history has "
                                 f"{sorted(_TABLES)}", created)

    def _open_read_only(self) -> sqlite3.Connection:
        uri = "file:" + os.path.abspath(self.path) + "?mode=ro"
        conn = sqlite3.connect(uri, uri=True, timeout=_BUSY_TIMEOUT)
        try:
            check = conn.execute("PRAGMA quick_check").fetchall()
        except sqlite3.OperationalError as err:
            if not getattr(err, "sqlite_errorname", "").startswith("SQLITE_READONLY"):
                conn.close()
                raise
            # a hot rollback journal (a file of an older version whose writer was killed mid-write): a writing
            # connection rolls the interrupted transaction back, as SQLite does whenever such a file is opened
            conn.close()
            sqlite3.connect(self.path, timeout=_BUSY_TIMEOUT).execute("SELECT 1 FROM sqlite_master").close()
            conn = sqlite3.connect(uri, uri=True, timeout=_BUSY_TIMEOUT)
            check = conn.execute("PRAGMA quick_check").fetchall()
        if check != [("ok",)]:
            conn.close()
            raise sqlite3.DatabaseError("; ".join(str(r[0]) for r in check[:3]))
        return conn

    def _refuse_damaged(self, cause, created) -> None:
        """Raise the StoreError of a damaged file after removing the empty side files our reading created."""
        if self._ro is not None:
            self._ro.close()
            self._ro = None
        for suffix in created:
            side = self.path + suffix
            if os.path.exists(side) and (suffix == "-shm" or os.path.getsize(side) == 0):
                try:
                    os.remove(side)
                except OSError:
                    pass
        raise StoreError.damaged(self.path, cause) from None

    def _writer(self) -> sqlite3.Connection:
        """The writing connection (WAL, synchronous FULL, the tables), opened on first use."""
        if self._db is None:
            db = sqlite3.connect(self.path, timeout=_BUSY_TIMEOUT)
            try:
                db.execute("PRAGMA journal_mode=WAL").fetchone()
                db.execute("PRAGMA synchronous=FULL")
                db.executescript(_SCHEMA)
            except sqlite3.Error:
                db.close()
                raise
            self._db = db
            if self._ro is not None:
                self._ro.close()
                self._ro = None
        return self._db

    def _reader(self) -> sqlite3.Connection | None:
        """A connection to read from, or None while the file does not exist."""
        if self._db is not None:
            return self._db
        if self._ro is None and os.path.exists(self.path) and os.path.getsize(self.path) > 0:
            self._ro = self._open_read_only()
        return self._ro

    # ------------------------------------------------------------------ write
    def save_progress(self, experiments=(), records=(), pending=None, meta: dict | None = None,
                      events=()) -> None:
        """Store finished experiments, completed iterations, the open iteration's requests and run data, all in ONE
        transaction: everything or, when it fails, nothing.

        Args:
            experiments: ``(ExperimentRequest, ExperimentResult)`` pairs, in submission order.
            records: :class:`IterationRecord` s.
            pending: the requests of the open iteration (None: unchanged).
            meta: free run data (problem, settings, ``c0``), key by key.
            events: ``(kind, data)`` pairs appended to the run's event log (operator actions: lifecycle
                transitions, manual setpoints; ``data`` a JSON-able dict), see :meth:`events`.

        An experiment or iteration already stored with the same content is skipped (a repeated write changes
        nothing); one stored with other content raises :class:`StoreError` (two runs in one file). A failed write
        (disk full, I/O error) raises :class:`StoreError` naming the file and the cause; the store stays usable.
        """
        kind = ("iteration" if records else "experiment" if experiments else
                "event" if events and pending is None and not meta else "start")
        try:
            db = self._writer()
            with db:
                if meta:
                    db.executemany("INSERT OR REPLACE INTO meta VALUES (?, ?)",
                                   [(k, _json(v)) for k, v in meta.items()])
                for req, res in experiments:
                    self._insert_experiment(db, req, res)
                for rec in records:
                    self._insert_iteration(db, rec)
                if pending is not None:
                    db.execute("INSERT OR REPLACE INTO pending VALUES (0, ?)",
                               (json.dumps([q.to_dict() for q in pending], allow_nan=False),))
                db.executemany("INSERT INTO events (kind, data, wall_time) VALUES (?, ?, ?)",
                               [(kind_, _json(data), time.time()) for kind_, data in events])
                if self.fault is not None:
                    self.fault.before_commit(kind)
        except sqlite3.Error as err:
            self._drop_writer()
            raise StoreError(f"cannot write {self.path}: {err}") from None

    def _drop_writer(self) -> None:
        """After a failed write: close the writing connection (the next write opens a fresh one)."""
        if self._db is not None and self.path != ":memory:":
            try:
                self._db.rollback()
                self._db.close()
            except sqlite3.Error:
                pass
            self._db = None

    def _insert_experiment(self, db, req: ExperimentRequest, res: ExperimentResult) -> None:
        q, r = json.dumps(req.to_dict(), allow_nan=False), json.dumps(res.to_dict(), allow_nan=False)
        cur = db.execute("INSERT OR IGNORE INTO experiments (request_id, iteration, purpose, request, result, "
                         "wall_time) VALUES (?, ?, ?, ?, ?, ?)",
                         (req.request_id, req.iteration, req.purpose, q, r, time.time()))
        if cur.rowcount == 0 and db.execute("SELECT request, result FROM experiments WHERE request_id = ?",
                                            (req.request_id,)).fetchone() != (q, r):
            raise StoreError(f"cannot write {self.path}: experiment {req.request_id} is stored there with other "
                             "data (a second run in the same file?)")

    def _insert_iteration(self, db, rec: IterationRecord) -> None:
        text = json.dumps(rec.to_dict(), allow_nan=False)
        cur = db.execute("INSERT OR IGNORE INTO iterations VALUES (?, ?, ?)", (rec.k, text, time.time()))
        if cur.rowcount == 0 and db.execute("SELECT record FROM iterations WHERE k = ?",
                                            (rec.k,)).fetchone() != (text,):
            raise StoreError(f"cannot write {self.path}: iteration {rec.k} is stored there with another record "
                             "(a second run in the same file?)")

    def save_meta(self, meta: dict) -> None:
        """Store free run data (problem, settings, c0 under key ``c0``)."""
        self.save_progress(meta=meta)

    def save_experiment(self, request: ExperimentRequest, result: ExperimentResult) -> None:
        """Store one finished experiment (a second write of the same experiment changes nothing)."""
        self.save_progress([(request, result)])

    def save_iteration(self, record: IterationRecord, pending: list[ExperimentRequest]) -> None:
        """Store a completed iteration and the requests of the next one, in one transaction."""
        self.save_progress(records=[record], pending=pending)

    def save_pending(self, pending: list[ExperimentRequest]) -> None:
        self.save_progress(pending=pending)

    def save_history(self, history: History, meta: dict | None = None) -> None:
        """Write everything of ``history`` (plus run data ``meta``) in one transaction (a run's start)."""
        self.save_progress(history.experiments, history.iterations, history.pending,
                           meta={**history.meta, **(meta or {}), "c0": history.c0})

    # ------------------------------------------------------------------- read
    def _tables(self, db) -> set:
        return {r[0] for r in db.execute("SELECT name FROM sqlite_master WHERE type = 'table'")}

    def load(self) -> History | None:
        """The stored history, or None for an empty database."""
        db = self._reader()
        if db is None or not _TABLES <= self._tables(db):
            return None
        meta = {k: json.loads(v) for k, v in db.execute("SELECT key, value FROM meta")}
        if "c0" not in meta:
            return None
        c0 = meta.pop("c0")
        exps = [{"request": json.loads(q), "result": json.loads(r)}
                for q, r in db.execute("SELECT request, result FROM experiments ORDER BY seq")]
        its = [json.loads(r) for (r,) in db.execute("SELECT record FROM iterations ORDER BY k")]
        row = db.execute("SELECT requests FROM pending").fetchone() if "pending" in self._tables(db) else None
        return History.from_dict({"c0": c0, "experiments": exps, "iterations": its,
                                  "pending": json.loads(row[0]) if row else [], "meta": meta})

    def events(self) -> list[tuple[str, dict, float]]:
        """The event log, oldest first: ``(kind, data, wall_time)`` (a file without the table: none)."""
        db = self._reader()
        if db is None or "events" not in self._tables(db):
            return []
        return [(k, json.loads(d), w) for k, d, w in db.execute("SELECT kind, data, wall_time FROM events ORDER BY seq")]

    def stored_keys(self) -> tuple[set, set]:
        """(request ids of the stored experiments, iteration numbers ``k`` of the stored records)."""
        db = self._reader()
        if db is None or not _TABLES <= self._tables(db):
            return set(), set()
        return ({r for (r,) in db.execute("SELECT request_id FROM experiments")},
                {k for (k,) in db.execute("SELECT k FROM iterations")})

    def has_run(self) -> bool:
        """True once a run's start (its ``c0``) is stored."""
        db = self._reader()
        return (db is not None and _TABLES <= self._tables(db)
                and db.execute("SELECT 1 FROM meta WHERE key = 'c0'").fetchone() is not None)

    def counts(self) -> dict:
        """Numbers of stored experiments and iterations."""
        keys = self.stored_keys()
        return {"experiments": len(keys[0]), "iterations": len(keys[1])}
