"""The code-version tag of campaign results (:func:`code_version`): part of every cache key, checked on workers.

A SHA-1 over the source of every module that decides a run's numbers (``kite``, ``flight``, ``gma``, ``rto``
with the judge ``rto/judge.py``, ``cache.py`` and the campaign's methods, tasks and result rows; the scenarios enter
the keys by value) and the versions of the numerical libraries they call. Any change to either gives new keys, so
no cached result of other code is reused; a worker whose tag differs from the client's refuses the task
(:func:`check_code_version`), so a cluster running other code cannot mix its numbers in.
"""
from __future__ import annotations

import hashlib
from functools import lru_cache
from importlib.metadata import PackageNotFoundError, version
from pathlib import Path

__all__ = ["code_version", "check_code_version", "library_versions"]

_PACKAGES = ("kite", "flight", "gma", "rto")
_MODULES = ("cache.py", "campaign/methods.py", "campaign/tasks.py", "campaign/results.py")
_LIBRARIES = ("numpy", "scipy", "casadi", "scikit-learn", "bayesian-optimization", "hipersim")


@lru_cache(maxsize=1)
def code_version() -> str:
    """12 hex digits identifying this kite_rto core and its numerical libraries."""
    root = Path(__file__).resolve().parent.parent
    h = hashlib.sha1()
    files = [root / m for m in _MODULES] + sorted(p for pkg in _PACKAGES for p in (root / pkg).rglob("*.py"))
    for p in files:
        h.update(p.relative_to(root).as_posix().encode() + b"\0" + p.read_bytes() + b"\0")
    for lib, v in library_versions().items():
        h.update(f"{lib}={v}\0".encode())
    return h.hexdigest()[:12]


def library_versions() -> dict:
    """Name -> installed version (``"absent"``) of the numerical libraries :func:`code_version` hashes."""
    out = {}
    for lib in _LIBRARIES:
        try:
            out[lib] = version(lib)
        except PackageNotFoundError:
            out[lib] = "absent"
    return out


def check_code_version(expected: str) -> None:
    """Raise RuntimeError if this process's :func:`code_version` is not ``expected`` (the client's)."""
    here = code_version()
    if here != expected:
        raise RuntimeError(f"this worker runs kite_rto code version {here}, the campaign expects {expected}: "
                           "install the same kite_rto and libraries on every worker as on the client")
