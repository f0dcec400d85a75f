"""Run keyed, dependent tasks on Dask; every finished result is cached on disk once and never run again.

A :class:`Task` names a function, its arguments and the keys of the tasks whose results follow those arguments.
:func:`execute` reads the stored results that exist from a :class:`ResultCache`, submits only what is missing
(and the unstored tasks those need) to a ``distributed.Client``, and writes each result as it arrives, from the
client, one JSON file per key, atomically. What a dead worker was running the scheduler runs again elsewhere; a
task that raises is retried ``retries`` times; the client writes a key at most once. Nothing here knows kites:
the tests drive it with closed-form tasks.
"""
from __future__ import annotations

import json
import os
import re
import tempfile
from dataclasses import dataclass, field
from typing import Callable

__all__ = ["Task", "ResultCache", "Execution", "pending", "execute"]

_KEY = re.compile(r"^[A-Za-z0-9][A-Za-z0-9._-]*$")


@dataclass(frozen=True)
class Task:
    """One unit of work.

    Attributes:
        key: unique, deterministic name of the result (letters, digits, ``._-``; the cache file's name).
        fn: called on a worker as ``fn(*args, *results of deps)``; returns a JSON-serializable value.
        args: leading arguments (picklable).
        deps: keys of earlier tasks whose results are appended to ``args``, in this order.
        store: True: the result is cached on disk and the task never runs again; False: it runs whenever a
            task that needs it runs (for results cached elsewhere, e.g. the oracle's own cache).
    """

    key: str
    fn: Callable
    args: tuple = ()
    deps: tuple = ()
    store: bool = True

    def __post_init__(self):
        if not isinstance(self.key, str) or not _KEY.match(self.key):
            raise ValueError(f"Task.key = {self.key!r}: expected letters, digits, '.', '_' or '-', not starting "
                             "with a separator")


class ResultCache:
    """A directory of finished results, ``<key>.json`` each, holding ``{"key": key, "value": value}``."""

    def __init__(self, directory: str | os.PathLike):
        self.directory = os.fspath(directory)

    def path(self, key: str) -> str:
        return os.path.join(self.directory, f"{key}.json")

    def get(self, key: str) -> tuple:
        """``(True, value)`` if ``key`` is cached, else ``(False, None)`` (an unreadable file counts as absent)."""
        try:
            with open(self.path(key)) as f:
                entry = json.load(f)
        except (OSError, ValueError):
            return False, None
        if not isinstance(entry, dict) or entry.get("key") != key or "value" not in entry:
            return False, None
        return True, entry["value"]

    def put(self, key: str, value) -> object:
        """Write ``value`` for ``key`` (temporary file, then :func:`os.replace`); return it as read back from
        JSON, so fresh and cached results look the same. NaN and infinity are refused (use None)."""
        text = json.dumps({"key": key, "value": value}, allow_nan=False, sort_keys=True)
        os.makedirs(self.directory, exist_ok=True)
        fd, tmp = tempfile.mkstemp(dir=self.directory, prefix=f".{key}-", suffix=".tmp")
        try:
            with os.fdopen(fd, "w") as f:
                f.write(text)
            os.replace(tmp, self.path(key))
        except BaseException:
            os.unlink(tmp)
            raise
        return json.loads(text)["value"]


@dataclass
class Execution:
    """What :func:`execute` did.

    Attributes:
        results: key -> value of every stored task that finished (read from the cache or computed now).
        submitted: keys submitted to Dask, in submission order (empty when everything was cached).
        cached: stored keys read from the cache.
        failed: key -> error text of tasks that failed after their retries (or whose dependency failed).
        transient: key -> value of the unstored tasks that ran (not cached; e.g. for a log).
    """

    results: dict = field(default_factory=dict)
    submitted: list = field(default_factory=list)
    cached: list = field(default_factory=list)
    failed: dict = field(default_factory=dict)
    transient: dict = field(default_factory=dict)


def _check(tasks) -> dict:
    by_key = {}
    for t in tasks:
        if t.key in by_key:
            raise ValueError(f"task key {t.key!r} appears twice")
        for d in t.deps:
            if d not in by_key:
                raise ValueError(f"task {t.key!r} depends on {d!r}: expected the key of an earlier task")
        by_key[t.key] = t
    return by_key


def pending(tasks, cache: ResultCache) -> tuple:
    """``(to_run, cached)``: the tasks that must run, in the given order (stored tasks missing from ``cache`` and
    the unstored tasks they need), and key -> value of the stored tasks found in ``cache``."""
    by_key = _check(tasks)
    cached, needed = {}, set()
    for t in tasks:
        if t.store:
            found, value = cache.get(t.key)
            if found:
                cached[t.key] = value
            else:
                needed.add(t.key)
    for t in reversed(tasks):                     # dependencies come earlier: one backward pass is transitive
        if t.key in needed:
            needed.update(d for d in t.deps if d not in cached)
    return [by_key[t.key] for t in tasks if t.key in needed], cached


def execute(tasks, cache: ResultCache, client=None, retries: int = 2, progress: bool = True) -> Execution:
    """Run ``tasks`` (dependencies first) on ``client`` (a ``distributed.Client``; may be None when everything
    is cached) and return the :class:`Execution`. The progress bar (tqdm, on stderr) counts the submitted tasks
    that finished, out of all submitted, and shows how many failed beside it (``failed=N``): a bar that ends short
    of its total says that tasks failed."""
    from distributed import as_completed
    from tqdm import tqdm
    to_run, cached = pending(tasks, cache)
    run = Execution(results=dict(cached), cached=list(cached))
    if not to_run:
        return run
    if client is None:
        raise ValueError(f"execute: {len(to_run)} tasks to run but no Dask client given")
    futures, owner = {}, {}
    for t in to_run:
        inputs = [futures[d] if d in futures else cached[d] for d in t.deps]
        fut = client.submit(t.fn, *t.args, *inputs, key=t.key, retries=retries, pure=False)
        futures[t.key], owner[fut.key] = fut, t
        run.submitted.append(t.key)
    with tqdm(total=len(futures), desc="tasks finished", unit="task", disable=not progress,
              dynamic_ncols=True) as bar:
        bar.set_postfix(failed=0)
        for fut in as_completed(list(futures.values())):
            t = owner[fut.key]
            if t.key in run.results or t.key in run.failed or t.key in run.transient:
                continue                          # a future is reported once; guard against a repeat anyway
            try:
                value = fut.result()
            except Exception as exc:              # noqa: BLE001 - the task's own error, reported per key
                run.failed[t.key] = f"{type(exc).__name__}: {exc}"
                bar.set_postfix(failed=len(run.failed))
                continue
            if t.store:
                run.results[t.key] = cache.put(t.key, value)
            else:
                run.transient[t.key] = value
            bar.update(1)
    return run
