"""The optimizer's database at start-up: open it, and refuse a file the run would damage or mix with another run.

:func:`open_run_database` opens the :class:`~kite_rto.gma.HistoryStore` and decides, before anything is written:

- a damaged or foreign file: refused (the file is left as it was);
- a file that holds a run while ``resume`` is false: refused (a new run's records would land among the old ones);
- a file that holds a run made with other settings (the values under :data:`SETTINGS_KEY` in its meta, stored when
  the run was created): refused, naming every differing setting with its stored and its current value;
- otherwise: the store, and the history to resume (None for a new run).

Every refusal is a :class:`RunDatabaseError` whose message names the file and says what to do.
"""
from __future__ import annotations

import json
import sqlite3

from ..gma import History, HistoryStore, StoreError

__all__ = ["RunDatabaseError", "SETTINGS_KEY", "open_run_database", "settings_differences"]

SETTINGS_KEY = "optimizer_parameters"
"""Meta key of the settings a run was created with (name -> value), compared on every resume."""


class RunDatabaseError(ValueError):
    """The database cannot be used for this run (the message names the file, the reason and what to do)."""


def settings_differences(stored: dict, now: dict) -> list[str]:
    """``"name = <stored> (stored) vs <now> (now)"`` for each setting whose value differs or is on one side only."""
    def plain(v):
        return json.loads(json.dumps(v))
    out = []
    for name in sorted(set(stored) | set(now)):
        old, new = stored.get(name, "<not stored>"), now.get(name, "<not set>")
        if plain(old) != plain(new):
            out.append(f"{name} = {old!r} (stored) vs {new!r} (now)")
    return out


def open_run_database(path, settings: dict, resume: bool, fault=None) -> tuple[HistoryStore, History | None, str]:
    """Open ``path`` for a run with ``settings`` (name -> JSON value); return (store, history to resume or None,
    a note for the log or ""). Raises :class:`RunDatabaseError` (nothing written) when the file must not be used."""
    try:
        store = HistoryStore(path, fault=fault)
    except StoreError as err:
        raise RunDatabaseError(str(err)) from None
    try:
        history = store.load()
    except (sqlite3.DatabaseError, ValueError, KeyError, TypeError) as err:
        store.close()
        raise RunDatabaseError(str(StoreError.damaged(str(path), err))) from None
    if history is None:
        return store, None, ""
    where = (f"database {path} holds a run ({len(history.experiments)} experiments, {len(history.iterations)} "
             "iterations)")
    advice = (f"to start a new run, move it aside (mv {path} {path}.old) or give another file (db:=...). It was "
              "not modified")
    if not resume:
        store.close()
        raise RunDatabaseError(f"{where} and resume is false: a new run would mix its records with that run's. "
                               f"Resume it with resume:=true, or {advice}")
    stored = history.meta.get(SETTINGS_KEY)
    if stored is None:
        note = (f"{where} made by an older version, without its settings: resuming it without checking that they "
                "match")
    else:
        diffs = settings_differences(stored, settings)
        if diffs:
            store.close()
            raise RunDatabaseError(f"{where} made with other settings: {'; '.join(diffs)}. Resuming would mix two "
                                   f"runs: start with the stored values to resume it, or {advice}")
        note = ""
    return store, history, note
