"""Disk cache of the optimizer's start-up numbers: the model-only optimum and DMA's privileged directions.

Both take seconds of NLP solves (10.6 s for the directions in ``benchmarks/bench_ocp.py``) and depend only on the
model, the OCP settings, the box and the uncertainty, so a restarted optimizer reads them back instead. Entries are
JSON files named by a hash of the inputs' ``repr`` and of the source of every module that computes them (a code
change makes a new entry); they live in :func:`kite_rto.cache.cache_dir` ``("startup")`` (the user
cache directory, or ``$KITE_RTO_CACHE``). A missing, unreadable or foreign file is recomputed and rewritten.
"""
from __future__ import annotations

import hashlib
import json
import os
import tempfile
from pathlib import Path

import numpy as np

from ..gma import PrivilegedDirections
from ..cache import cache_dir

__all__ = ["cached", "directions_to_json", "directions_from_json", "source_digest"]

_SOURCES = ("kite/model.py", "kite/params.py", "flight/projection.py", "flight/shape.py", "rto/ocp.py",
            "rto/ocp_solve.py", "rto/directions.py", "rto/builder.py", "gma/directional.py", "gma/problem.py")
_DIGEST = None


def source_digest() -> str:
    """SHA-1 of the modules whose code decides the cached numbers."""
    global _DIGEST
    if _DIGEST is None:
        root = Path(__file__).resolve().parent.parent
        h = hashlib.sha1()
        for rel in _SOURCES:
            h.update((root / rel).read_bytes())
        _DIGEST = h.hexdigest()
    return _DIGEST


def _path(kind: str, key) -> Path:
    digest = hashlib.sha1(repr((key, source_digest())).encode()).hexdigest()[:16]
    return Path(cache_dir("startup")) / f"{kind}-{digest}.json"


def cached(kind: str, key, compute, to_json=lambda v: v, from_json=lambda v: v):
    """``compute()``'s value for ``key``, read from the disk cache when an entry exists, else computed and stored.

    ``to_json``/``from_json`` convert the value to and from what :func:`json.dump` writes. Writes are atomic
    (a temporary file renamed into place), so concurrent optimizers never read half a file.
    """
    path = _path(kind, key)
    try:
        with open(path) as f:
            entry = json.load(f)
        if entry.get("key") == repr(key):
            return from_json(entry["value"])
    except (OSError, ValueError, KeyError, TypeError):
        pass
    value = compute()
    try:
        path.parent.mkdir(parents=True, exist_ok=True)
        fd, tmp = tempfile.mkstemp(dir=path.parent, suffix=".tmp")
        with os.fdopen(fd, "w") as f:
            json.dump({"key": repr(key), "value": to_json(value)}, f)
        os.replace(tmp, path)
    except OSError:
        pass                      # a read-only or full cache directory only costs the next start-up the time
    return value


def directions_to_json(d: PrivilegedDirections) -> dict:
    """:class:`~kite_rto.gma.PrivilegedDirections` as plain lists."""
    return {"directions": d.directions.tolist(), "scaled": d.scaled.tolist(),
            "singular_values": d.singular_values.tolist(), "captured": float(d.captured),
            "sensitivity": d.sensitivity.tolist(), "gradient": d.gradient.tolist(), "fixed": d.fixed.tolist()}


def directions_from_json(v: dict) -> PrivilegedDirections:
    """The inverse of :func:`directions_to_json` (bit for bit: floats round-trip through JSON exactly)."""
    return PrivilegedDirections(directions=np.array(v["directions"]), scaled=np.array(v["scaled"]),
                                singular_values=np.array(v["singular_values"]), captured=v["captured"],
                                sensitivity=np.array(v["sensitivity"]), gradient=np.array(v["gradient"]),
                                fixed=np.array(v["fixed"], dtype=bool))
