"""Frozen settings dataclasses to plain JSON values and back (:func:`to_plain`, :func:`from_plain`).

Nested dataclasses become dicts (``None`` stays ``None``), tuples and arrays lists, infinite floats the strings
``"inf"`` / ``"-inf"`` (strict JSON has no infinity). :func:`from_plain` rebuilds the dataclasses from the field
annotations, so every level runs its own validation; an unknown key raises ``ValueError`` naming it.
"""
from __future__ import annotations

import math
import types
import typing
from dataclasses import fields, is_dataclass

import numpy as np

__all__ = ["to_plain", "from_plain"]


def to_plain(value):
    """``value`` as plain JSON data (see the module docstring)."""
    if is_dataclass(value) and not isinstance(value, type):
        return {f.name: to_plain(getattr(value, f.name)) for f in fields(value) if f.init}
    if isinstance(value, dict):
        return {str(k): to_plain(v) for k, v in value.items()}
    if isinstance(value, (list, tuple, np.ndarray)):
        return [to_plain(v) for v in (value.tolist() if isinstance(value, np.ndarray) else value)]
    if isinstance(value, (bool, np.bool_)):
        return bool(value)
    if isinstance(value, (int, np.integer)):
        return int(value)
    if isinstance(value, (float, np.floating)):
        v = float(value)
        return ("inf" if v > 0 else "-inf") if math.isinf(v) else v
    return value


def _numbers(value):
    """Lists back to tuples, ``"inf"`` back to floats (for fields that are not dataclasses)."""
    if isinstance(value, list):
        return tuple(_numbers(v) for v in value)
    if value in ("inf", "-inf"):
        return float(value)
    return value


def _dataclass_in(hint):
    """The dataclass type a field annotation names (alone or in ``X | None``), else ``None``."""
    if is_dataclass(hint):
        return hint
    if isinstance(hint, types.UnionType) or typing.get_origin(hint) is typing.Union:
        found = [a for a in typing.get_args(hint) if is_dataclass(a)]
        return found[0] if len(found) == 1 else None
    return None


def from_plain(cls, data):
    """The dataclass ``cls`` rebuilt from :func:`to_plain`'s output ``data``."""
    if not isinstance(data, dict):
        raise ValueError(f"{cls.__name__}: expected a dict of its fields, got {data!r}")
    hints = typing.get_type_hints(cls)
    known = {f.name for f in fields(cls) if f.init}
    unknown = sorted(set(data) - known)
    if unknown:
        raise ValueError(f"{cls.__name__}: unknown fields {unknown} (known: {sorted(known)}); written by another "
                         "version of kite_rto?")
    kwargs = {}
    for name, value in data.items():
        sub = _dataclass_in(hints[name])
        if value is None:
            kwargs[name] = None
        elif sub is not None:
            kwargs[name] = from_plain(sub, value)
        elif isinstance(value, dict):
            kwargs[name] = dict(value)
        else:
            kwargs[name] = _numbers(value)
    return cls(**kwargs)
