"""Validation of settings values: every error names the owner, the field, the value and what was expected."""
from __future__ import annotations

import math
from typing import Sequence

import numpy as np

__all__ = ["Scalar", "check_range", "check_bool", "check_int", "check_choice", "per_setpoint"]

Scalar = float | Sequence[float]
"""A number, or one number per setpoint (or per constraint), length checked when GMA is built."""


def check_range(owner: str, name: str, value, low=None, high=None, *, low_open=False, high_open=False,
                inf_ok=False) -> None:
    """Raise ``ValueError`` naming ``owner.name``, the value and the range unless every entry of ``value`` is in
    range (``low``/``high`` ``None``: unbounded; ``inf_ok``: ``inf`` is allowed)."""
    try:
        entries = np.atleast_1d(np.asarray(value, dtype=float)).ravel()
    except (TypeError, ValueError):
        entries = None
    lo = "(" if low_open else "["
    hi = ")" if high_open else "]"
    expected = f"{lo}{'-inf' if low is None else low}, {'inf' if high is None else high}{hi}"
    if entries is None or entries.size == 0 or isinstance(value, bool):
        raise ValueError(f"{owner}.{name}={value!r}: expected a number or a non-empty sequence in {expected}")
    for v in entries:
        bad = math.isnan(v) or (math.isinf(v) and not inf_ok)
        if low is not None and (v < low or (low_open and v == low)):
            bad = True
        if high is not None and (v > high or (high_open and v == high)):
            bad = True
        if bad:
            raise ValueError(f"{owner}.{name}={value!r}: expected every value in {expected}")


def check_bool(owner: str, name: str, value) -> None:
    """Raise ``ValueError`` naming the field and value unless ``value`` is True or False."""
    if not isinstance(value, bool):
        raise ValueError(f"{owner}.{name}={value!r}: expected True or False")


def check_int(owner: str, name: str, value, low: int) -> None:
    """Raise ``ValueError`` naming the field and value unless ``value`` is an integer ``>= low`` (not a bool)."""
    if isinstance(value, bool) or not isinstance(value, int) or value < low:
        raise ValueError(f"{owner}.{name}={value!r}: expected an integer >= {low}")


def check_choice(owner: str, name: str, value, choices: tuple) -> None:
    """Raise ``ValueError`` naming the field and value unless ``value`` is one of ``choices``."""
    if value not in choices:
        raise ValueError(f"{owner}.{name}={value!r}: expected one of {', '.join(repr(c) for c in choices)}")


def per_setpoint(name: str, value, n: int) -> np.ndarray:
    """Broadcast a scalar-or-sequence setting to shape ``(n,)``; ``ValueError`` naming ``name`` on a length
    mismatch."""
    arr = np.atleast_1d(np.asarray(value, dtype=float)).ravel()
    if arr.size == 1:
        return np.full(n, float(arr[0]))
    if arr.size != n:
        raise ValueError(f"{name}={value!r}: expected a scalar or {n} values, got {arr.size}")
    return arr.copy()
