"""Where kite_rto keeps what it computes once and reuses: the oracle, the optimizer's start-up numbers, the
turbulence boxes.

``$KITE_RTO_CACHE`` if set and non-empty, else the platform's user cache directory for kite_rto
(``platformdirs.user_cache_dir("kite_rto")``, e.g. ``~/.cache/kite_rto`` on Linux); never beside the installed
package. Each kind of entry has its own subfolder.
"""
from __future__ import annotations

import os

from platformdirs import user_cache_dir

__all__ = ["CACHE_ENV", "cache_dir"]

CACHE_ENV = "KITE_RTO_CACHE"
"""Environment variable naming the cache directory (overrides the platform's user cache directory)."""


def cache_dir(sub: str | None = None) -> str:
    """The cache directory (see the module docstring), or its subfolder ``sub``; created by the writers."""
    root = os.environ.get(CACHE_ENV) or user_cache_dir("kite_rto")
    return os.path.join(root, sub) if sub else root
