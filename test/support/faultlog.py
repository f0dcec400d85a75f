"""Rows of the fault-injection table (``scripts/faults.sh`` -> ``python -m kite_rto.testing.fault_table DIR``).

Each fault test records one row per fault it injects: what the fault is, how it was injected, the measured
outcome, experiments lost and unsafe setpoints (both must be 0), and whether the test's checks passed. When
``KITE_RTO_FAULT_LOG`` names a directory, the row is appended as one JSON line to ``<dir>/<test>.jsonl``;
otherwise nothing is written (the test still runs and asserts).

Use it as a context manager, so that a failing check still leaves a row with ``passed: false``::

    with fault_row(request, "bad wind message", "NaN, -1, 1e3 on /kite/wind") as row:
        ...inject, measure...
        row.outcome = f"{n} rejected, {w} warnings; loop kept running"
        row.experiments_lost = 0          # measured, or None when no optimizer runs
        row.unsafe_setpoints = unsafe     # measured
        assert ...

or call :func:`write_row` directly with the same fields.
"""
from __future__ import annotations

import json
import os
import re
from pathlib import Path

__all__ = ["ENV", "FIELDS", "write_row", "fault_row", "FaultRow"]

ENV = "KITE_RTO_FAULT_LOG"
FIELDS = ("fault", "injection", "outcome", "experiments_lost", "unsafe_setpoints", "passed")


def _test_name(request_or_name) -> str:
    name = getattr(getattr(request_or_name, "node", None), "nodeid", None) or str(request_or_name)
    return re.sub(r"[^A-Za-z0-9_.-]+", "_", name).strip("_") or "fault"


def write_row(test, fault: str, injection: str, outcome: str, experiments_lost, unsafe_setpoints,
              passed: bool) -> dict:
    """Append one row to ``$KITE_RTO_FAULT_LOG/<test>.jsonl`` (if the variable is set); return the row.

    ``test`` is pytest's ``request`` (its node id names the file) or a string.
    """
    row = {"fault": fault, "injection": injection, "outcome": outcome, "experiments_lost": experiments_lost,
           "unsafe_setpoints": unsafe_setpoints, "passed": bool(passed)}
    folder = os.environ.get(ENV)
    if folder:
        path = Path(folder) / f"{_test_name(test)}.jsonl"
        path.parent.mkdir(parents=True, exist_ok=True)
        with open(path, "a", encoding="utf-8") as f:
            f.write(json.dumps(row) + "\n")
    return row


class FaultRow:
    """One row being measured; written when the ``with`` block ends (``passed`` = no exception escaped)."""

    def __init__(self, test, fault: str, injection: str):
        self.test, self.fault, self.injection = test, fault, injection
        self.outcome = ""
        self.experiments_lost = None
        self.unsafe_setpoints = None
        self.row = None

    def __enter__(self) -> "FaultRow":
        return self

    def __exit__(self, exc_type, exc, tb) -> bool:
        outcome = self.outcome
        if exc_type is not None:
            first = str(exc).strip().splitlines()[0][:200] if str(exc).strip() else exc_type.__name__
            outcome = (outcome + "; " if outcome else "") + f"FAILED: {first}"
        self.row = write_row(self.test, self.fault, self.injection, outcome, self.experiments_lost,
                             self.unsafe_setpoints, exc_type is None)
        return False


def fault_row(test, fault: str, injection: str) -> FaultRow:
    """A :class:`FaultRow` context manager (see the module docstring)."""
    return FaultRow(test, fault, injection)
