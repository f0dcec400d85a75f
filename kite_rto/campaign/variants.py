"""GMA variants for a campaign from text (:func:`parse_variant`) or from a Python object (:func:`load_variants`).

A variant is a name and a :class:`~kite_rto.rto.settings.KiteRTOSettings`. On the command line it is written
``NAME=FIELD=VALUE[,FIELD=VALUE...]``: dotted fields of the settings dataclasses changed from their defaults, values
as Python literals (a bare word is a string), e.g. ``undo2=gma.undo.sigma=2.0``, ``noundo=gma.undo=None`` or
``laps6=experiment.n_laps=6,gma.backoff=4.0``. A field of a GMA mechanism that is off switches it on with its
defaults first (``gma.undo.sigma=1.5`` when ``gma.undo`` is ``None``). ``load_variants("package.module:NAME")`` imports a mapping of names
to settings (or a callable returning one).
"""
from __future__ import annotations

import ast
import dataclasses
import importlib

from ..gma import MECHANISMS, GMASettings
from ..rto.settings import KiteRTOSettings

__all__ = ["parse_variant", "settings_with", "load_variants"]


def settings_with(settings, changes: dict):
    """A copy of the dataclass ``settings`` with dotted ``changes`` (``{"gma.backoff": 4.0}``) applied; the
    dataclass's own validation runs on every changed level."""
    out = settings
    nested: dict = {}
    for path, value in changes.items():
        head, _, rest = path.partition(".")
        names = [f.name for f in dataclasses.fields(out)]
        if head not in names:
            raise ValueError(f"variant field {path!r}: {type(out).__name__} has no field {head!r} "
                             f"(expected one of {', '.join(names)})")
        if rest:
            nested.setdefault(head, {})[rest] = value
        else:
            out = dataclasses.replace(out, **{head: value})
    for head, sub in nested.items():
        inner = getattr(out, head)
        if inner is None and isinstance(out, GMASettings) and head in MECHANISMS:
            inner = MECHANISMS[head]()          # a mechanism that is off: on, with its defaults, then changed
        if not dataclasses.is_dataclass(inner):
            raise ValueError(f"variant field {head}.{next(iter(sub))}: {head} = {inner!r} is not a dataclass")
        out = dataclasses.replace(out, **{head: settings_with(inner, sub)})
    return out


def _literal(text: str):
    try:
        return ast.literal_eval(text)
    except (ValueError, SyntaxError):
        return text


def _split(spec: str) -> list:
    """``spec`` split at the commas outside brackets (``fd_step=(0.3, 0.3, 0.3),n_directions=1``)."""
    items, depth, start = [], 0, 0
    for i, ch in enumerate(spec):
        depth += (ch in "([{") - (ch in ")]}")
        if ch == "," and depth == 0:
            items.append(spec[start:i])
            start = i + 1
    return [s.strip() for s in items + [spec[start:]] if s.strip()]


def parse_variant(text: str, base: KiteRTOSettings | None = None) -> tuple:
    """``(name, KiteRTOSettings)`` from ``NAME=FIELD=VALUE[,FIELD=VALUE...]`` (``NAME`` alone: ``base``)."""
    name, _, spec = text.partition("=")
    if not name:
        raise ValueError(f"variant {text!r}: expected NAME=FIELD=VALUE[,FIELD=VALUE...]")
    changes = {}
    for item in _split(spec):
        field, eq, value = item.partition("=")
        if not eq or not field:
            raise ValueError(f"variant {text!r}: {item!r} is not FIELD=VALUE")
        changes[field.strip()] = _literal(value.strip())
    return name, settings_with(base or KiteRTOSettings(), changes)


def load_variants(ref: str) -> dict:
    """The mapping name -> :class:`KiteRTOSettings` at ``"package.module:NAME"`` (a mapping, or a callable
    returning one)."""
    module, _, attr = ref.partition(":")
    if not module or not attr:
        raise ValueError(f"variants {ref!r}: expected package.module:NAME")
    obj = getattr(importlib.import_module(module), attr)
    variants = dict(obj() if callable(obj) else obj)
    for name, s in variants.items():
        if not isinstance(s, KiteRTOSettings):
            raise ValueError(f"variants {ref!r}: {name!r} = {s!r}: expected a KiteRTOSettings")
    return variants
