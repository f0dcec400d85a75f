"""A test hook for :class:`~kite_rto.gma.store.HistoryStore`: writes that fail like a full disk.

:class:`DiskFull` raises SQLite's own disk-full error (``sqlite3.OperationalError("database or disk is full")``,
what SQLITE_FULL gives) inside the write transaction, after its statements ran and just before it commits, so the
transaction is rolled back by SQLite exactly as on a real full disk. ``test/gma/test_gma_store.py`` also fills a real
database to its page limit (``PRAGMA max_page_count``) to show that SQLite's own SQLITE_FULL ends the same way.
"""
from __future__ import annotations

import sqlite3
from dataclasses import dataclass

__all__ = ["DiskFull", "WRITE_KINDS"]

WRITE_KINDS = ("start", "experiment", "iteration", "event", "any")
"""``start``: a run's first write (its c0, settings and first requests), or any other write of requests or run data;
``experiment``: finished experiments only; ``iteration``: a write that holds an iteration record (with the
experiment that completed it); ``event``: operator events only (lifecycle transitions); ``any``."""


@dataclass
class DiskFull:
    """From the ``nth`` write of ``kind`` on, every write fails, ``attempts`` times in all (None: for ever).

    Writes are counted per store (1-based); a write retried after a failure is the same write.
    """

    kind: str
    nth: int = 1
    attempts: int | None = None
    failed: int = 0
    _seen: int = 0
    _full: bool = False

    def __post_init__(self):
        if self.kind not in WRITE_KINDS:
            raise ValueError(f"DiskFull.kind = {self.kind!r}: expected one of {', '.join(WRITE_KINDS)}")
        if self.nth < 1 or (self.attempts is not None and self.attempts < 1):
            raise ValueError(f"DiskFull: nth = {self.nth}, attempts = {self.attempts}: expected integers >= 1")

    @classmethod
    def parse(cls, spec: str) -> "DiskFull":
        """``KIND:N[:ATTEMPTS]``, e.g. ``iteration:1`` (the first iteration write and every later write fail) or
        ``experiment:2:3`` (the second experiment-only write fails 3 times, then the disk has room again)."""
        parts = spec.strip().split(":")
        try:
            if not 1 <= len(parts) <= 3:
                raise ValueError
            return cls(parts[0], int(parts[1]) if len(parts) > 1 else 1,
                       int(parts[2]) if len(parts) > 2 else None)
        except ValueError as err:
            raise ValueError(f"disk-full spec {spec!r}: expected KIND:N[:ATTEMPTS], KIND one of "
                             f"{', '.join(WRITE_KINDS)}, N and ATTEMPTS integers >= 1"
                             + (f" ({err})" if str(err) else "")) from None

    def before_commit(self, kind: str) -> None:
        """Called inside each write transaction; raises SQLite's disk-full error when the disk is 'full'."""
        if not self._full:
            if self.kind not in (kind, "any"):
                return
            self._seen += 1
            if self._seen < self.nth:
                return
            self._full = True
        if self.attempts is not None and self.failed >= self.attempts:
            return
        self.failed += 1
        raise sqlite3.OperationalError("database or disk is full")
