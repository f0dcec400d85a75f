"""The oracle's cache: where it goes (explicit argument, KITE_RTO_CACHE, the platform's user cache directory)."""
import json
import os

import numpy as np
from platformdirs import user_cache_dir

import kite_rto
from kite_rto.rto import oracle
from kite_rto.rto.oracle import CACHE_ENV, find_oracle, oracle_cache_dir


def _closed_form(config, c, spec):
    """A stand-in plant: tension peaks at the box centre in setpoints, altitude always feasible."""
    return 600.0 - 1e3 * float(np.sum((np.asarray(c) - 0.5) ** 2)), 120.0


def test_cache_dir_order(monkeypatch, tmp_path):
    monkeypatch.delenv(CACHE_ENV, raising=False)
    assert oracle_cache_dir() == user_cache_dir("kite_rto")
    monkeypatch.setenv(CACHE_ENV, str(tmp_path / "env"))
    assert oracle_cache_dir() == str(tmp_path / "env")
    assert oracle_cache_dir(tmp_path / "arg") == str(tmp_path / "arg")


def test_oracle_is_cached_where_kite_rto_cache_points(monkeypatch, tmp_path):
    cache = tmp_path / "cache"
    monkeypatch.setenv(CACHE_ENV, str(cache))
    monkeypatch.setattr(oracle, "plant_performance", _closed_form)
    package_dir = os.path.dirname(os.path.dirname(os.path.abspath(kite_rto.__file__)))
    before = set(os.listdir(package_dir))
    res = find_oracle(h_min=100.0, grid=2, starts=1, maxfev=5)
    files = os.listdir(cache)
    assert files == [f"oracle_{res.key}.json"]
    assert json.loads((cache / files[0]).read_text())["tension_kn"] == res.tension_kn
    assert set(os.listdir(package_dir)) == before          # nothing written beside the package

    def fly(*args):
        raise AssertionError("a cached oracle must not fly the plant again")
    monkeypatch.setattr(oracle, "plant_performance", fly)
    assert find_oracle(h_min=100.0, grid=2, starts=1, maxfev=5) == res


def test_no_cache_writes_nothing(monkeypatch, tmp_path):
    monkeypatch.setenv(CACHE_ENV, str(tmp_path / "cache"))
    monkeypatch.setattr(oracle, "plant_performance", _closed_form)
    find_oracle(h_min=100.0, grid=2, starts=1, maxfev=5, cache=False)
    assert not (tmp_path / "cache").exists()


def test_a_damaged_entry_is_recomputed_and_replaced_whole(monkeypatch, tmp_path):
    monkeypatch.setattr(oracle, "plant_performance", _closed_form)
    res = find_oracle(h_min=100.0, grid=2, starts=1, maxfev=5, cache_dir=tmp_path)
    path = tmp_path / f"oracle_{res.key}.json"
    path.write_text('{"c": [0.1, ')                     # what a reader saw of a non-atomic write cut short
    assert find_oracle(h_min=100.0, grid=2, starts=1, maxfev=5, cache_dir=tmp_path) == res
    assert json.loads(path.read_text())["tension_kn"] == res.tension_kn
    assert os.listdir(tmp_path) == [path.name]          # no temporary file left beside it
