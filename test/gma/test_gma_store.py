"""SQLite history store: lossless round trip, a run killed mid-iteration resumes without repeating work, writes are
atomic and durable, a failed write stores nothing and can be tried again, a damaged file is refused untouched."""
import hashlib
import os
import sqlite3

import numpy as np
import pytest

from kite_rto.gma import StoreError, run_offline
from kite_rto.gma.store import HistoryStore
from kite_rto.runtime.store_fault import DiskFull

from test_gma_history import Plant, make


def drive(gma, plant, store, n_experiments):
    """Run ``n_experiments`` experiments through the request/submit interface, persisting each one."""
    store.save_meta({**gma.history.meta, "c0": gma.history.c0})
    store.save_pending(gma.history.pending)
    for _ in range(n_experiments):
        req = gma.next_request()
        res = plant(req.c)
        res.request_id = req.request_id
        rec = gma.submit(res)
        store.save_experiment(req, res)
        if rec is not None:
            store.save_iteration(rec, gma.history.pending)


def test_store_round_trip(tmp_path):
    gma = make()
    store = HistoryStore(tmp_path / "rto.sqlite")
    drive(gma, Plant(), store, 10)
    assert store.load().to_dict() == gma.history.to_dict()
    assert store.counts()["experiments"] == 10


def test_resume_from_database_after_a_kill(tmp_path):
    reference = make()
    run_offline(reference, Plant(), 5)

    db = tmp_path / "rto.sqlite"
    first, plant1 = make(), Plant()
    store = HistoryStore(db)
    drive(first, plant1, store, 7)          # stops in the middle of an iteration (3 experiments per iteration)
    store.close()
    del first                               # "killed"

    store = HistoryStore(db)
    history = store.load()
    assert len(history.experiments) == 7
    resumed, plant2 = make(history), Plant()
    done = {q.request_id for q, _ in history.experiments}
    assert resumed.next_request().request_id not in done
    n_left = len(reference.history.experiments) - 7
    drive(resumed, plant2, store, n_left)
    assert len(plant1.log) + len(plant2.log) == len(reference.history.experiments)   # nothing repeated
    np.testing.assert_allclose(resumed.c, reference.c, atol=1e-7)
    assert store.counts() == {"experiments": len(reference.history.experiments), "iterations": 5}


def test_empty_database_loads_none():
    assert HistoryStore(":memory:").load() is None


# ------------------------------------------------------------------------------ durability and failed writes
def digest(path) -> str:
    return hashlib.sha256(open(path, "rb").read()).hexdigest()


def first_iteration(gma, plant):
    """Run GMA to its first completed iteration; return the finished (request, result) pairs and the record."""
    pairs = []
    while True:
        req = gma.next_request()
        res = plant(req.c)
        res.request_id = req.request_id
        rec = gma.submit(res)
        pairs.append((req, res))
        if rec is not None:
            return pairs, rec


def test_store_is_wal_with_full_sync(tmp_path):
    store = HistoryStore(tmp_path / "rto.sqlite")
    gma = make()
    store.save_history(gma.history)
    db = store._writer()
    assert db.execute("PRAGMA journal_mode").fetchone() == ("wal",)
    assert db.execute("PRAGMA synchronous").fetchone() == (2,)          # FULL


def test_completing_experiment_and_its_iteration_are_one_transaction(tmp_path):
    """A failed write of the experiment that completes an iteration stores neither it nor the record nor the next
    requests; the same write succeeds once the disk has room, and a repeated write changes nothing."""
    gma = make()
    store = HistoryStore(tmp_path / "rto.sqlite", fault=DiskFull("iteration", 1, attempts=1))
    store.save_history(gma.history)
    pairs, rec = first_iteration(gma, Plant())
    store.save_progress(pairs[:-1])
    before = store.load().to_dict()
    with pytest.raises(StoreError, match=rf"cannot write {tmp_path / 'rto.sqlite'}: database or disk is full"):
        store.save_progress(pairs[-1:], [rec], gma.history.pending)
    assert store.load().to_dict() == before                         # nothing of the record set
    store.save_progress(pairs[-1:], [rec], gma.history.pending)      # "disk freed": the same write again
    store.save_progress(pairs[-1:], [rec], gma.history.pending)      # repeated: no duplicate
    assert store.load().to_dict() == gma.history.to_dict()
    assert store.counts() == {"experiments": len(pairs), "iterations": 1}


def test_real_sqlite_disk_full_rolls_back(tmp_path):
    """SQLite's own SQLITE_FULL (the file may not grow: max_page_count) ends like the test hook: StoreError naming
    the file and the cause, nothing written, and the store usable again (a new connection, the limit gone)."""
    gma = make()
    path = tmp_path / "rto.sqlite"
    store = HistoryStore(path)
    store.save_history(gma.history)
    pairs, rec = first_iteration(gma, Plant())
    db = store._writer()
    pages = db.execute("PRAGMA page_count").fetchone()[0]
    assert db.execute(f"PRAGMA max_page_count = {pages}").fetchone() == (pages,)
    pairs[-1][1].extra = {"padding": "x" * 40000}           # needs new pages: the file must grow
    with pytest.raises(StoreError, match=rf"cannot write {path}: database or disk is full"):
        store.save_progress(pairs, [rec], gma.history.pending)
    assert store.counts() == {"experiments": 0, "iterations": 0}
    store.save_progress(pairs, [rec], gma.history.pending)
    assert store.counts() == {"experiments": len(pairs), "iterations": 1}


def test_conflicting_record_is_refused_not_dropped(tmp_path):
    gma = make()
    store = HistoryStore(tmp_path / "rto.sqlite")
    store.save_history(gma.history)
    pairs, rec = first_iteration(gma, Plant())
    store.save_progress(pairs[:1])
    req, res = pairs[0]
    res.cost += 1.0
    with pytest.raises(StoreError, match=f"experiment {req.request_id} is stored there with other data"):
        store.save_progress([(req, res)])


def _damaged(tmp_path, kind):
    path = tmp_path / "rto.sqlite"
    if kind == "random bytes":
        path.write_bytes(np.random.default_rng(1).bytes(16384))
    elif kind == "foreign":
        db = sqlite3.connect(path)
        db.execute("CREATE TABLE t (x)")
        db.commit()
        db.close()
    else:                                           # a valid history cut to half its size
        store = HistoryStore(path)
        drive(make(), Plant(), store, 10)
        store.close()
        data = path.read_bytes()
        path.write_bytes(data[: len(data) // 2])
    return path


@pytest.mark.parametrize("kind, cause", [("random bytes", "file is not a database"),
                                         ("truncated", "malformed"),
                                         ("foreign", "not a GMA history")])
def test_damaged_file_is_refused_untouched(tmp_path, kind, cause):
    path = _damaged(tmp_path, kind)
    files, before = sorted(os.listdir(tmp_path)), digest(path)
    with pytest.raises(StoreError) as err:
        HistoryStore(path)
    text = str(err.value)
    assert str(path) in text and cause in text and "Move it aside" in text and "not modified" in text, text
    assert digest(path) == before and sorted(os.listdir(tmp_path)) == files


def test_reading_a_history_does_not_modify_it(tmp_path):
    path = tmp_path / "rto.sqlite"
    store = HistoryStore(path)
    drive(make(), Plant(), store, 5)
    store.close()
    before = digest(path)
    store = HistoryStore(path)
    assert store.load() is not None and store.counts()["experiments"] == 5 and store.has_run()
    store.close()
    assert digest(path) == before


def test_disk_full_spec():
    assert DiskFull.parse("iteration:2:3") == DiskFull("iteration", 2, 3)
    assert DiskFull.parse("experiment") == DiskFull("experiment", 1, None)
    for bad in ("disk", "iteration:0", "iteration:x", "experiment:1:0", "a:1:2:3"):
        with pytest.raises(ValueError, match="KIND:N"):
            DiskFull.parse(bad)
    f = DiskFull("experiment", 2, attempts=2)
    f.before_commit("iteration")
    f.before_commit("experiment")                      # the 1st experiment write: fine
    for _ in range(2):
        with pytest.raises(sqlite3.OperationalError, match="database or disk is full"):
            f.before_commit("experiment")
    f.before_commit("iteration")                       # room again
