"""SQLite history store: lossless round trip, and a run killed mid-iteration resumes without repeating work."""
import numpy as np

from kite_rto.gma import run_offline
from kite_rto.gma.store import HistoryStore

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
