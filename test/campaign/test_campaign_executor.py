"""The campaign executor on closed-form tasks: the cache (a second run submits nothing), the same results from a
LocalCluster and from a scheduler plus two workers started as separate processes, and a worker killed with SIGKILL
mid-task that loses and duplicates nothing."""
import json
import os
import signal
import subprocess
import sys
import threading
import time
from pathlib import Path

import pytest
from distributed import Client, LocalCluster

from campaign_tasks import closed_form_tasks, expected, fail, held, square
from kite_rto.campaign.executor import ResultCache, Task, execute, pending
from kite_rto.tools import graph

ROOT = Path(__file__).resolve().parents[2]
DASK = str(Path(sys.executable).with_name("dask"))


def _cache_files(directory: Path) -> dict:
    return {p.name: p.read_bytes() for p in sorted(directory.iterdir())}


@pytest.fixture(scope="module")
def local_client():
    with LocalCluster(n_workers=2, threads_per_worker=1, processes=True, dashboard_address=None) as cluster, \
            Client(cluster) as client:
        yield client


def _start(cmd, log: Path):
    env = dict(os.environ, PYTHONPATH=os.pathsep.join([str(ROOT), str(ROOT / "test" / "support")]))
    return subprocess.Popen(cmd, env=env, stdout=open(log, "wb"), stderr=subprocess.STDOUT, start_new_session=True,
                            preexec_fn=graph._die_with_parent if graph._PRCTL is not None else None)


@pytest.fixture
def process_cluster(tmp_path):
    """A ``dask scheduler`` and two ``dask worker`` processes (one process, one thread each); yields the scheduler
    address. They die with the test process."""
    sched_file = tmp_path / "scheduler.json"
    procs = [_start([DASK, "scheduler", "--host", "127.0.0.1", "--port", "0", "--no-dashboard",
                     "--scheduler-file", str(sched_file)], tmp_path / "scheduler.log")]
    try:
        end = time.monotonic() + 60
        while not sched_file.exists() or not sched_file.read_text().strip():
            assert time.monotonic() < end and procs[0].poll() is None, (tmp_path / "scheduler.log").read_text()
            time.sleep(0.1)
        address = json.loads(sched_file.read_text())["address"]
        for i in range(2):
            procs.append(_start([DASK, "worker", address, "--nworkers", "1", "--nthreads", "1", "--no-dashboard",
                                 "--name", f"w{i}"], tmp_path / f"worker{i}.log"))
        yield address
    finally:
        for p in procs:
            if p.poll() is None:
                os.killpg(p.pid, signal.SIGTERM)
        for p in procs:
            try:
                p.wait(timeout=20)
            except subprocess.TimeoutExpired:
                os.killpg(p.pid, signal.SIGKILL)
                p.wait()


def test_only_missing_results_and_the_unstored_tasks_they_need_are_pending(tmp_path):
    tasks, cache = closed_form_tasks(), ResultCache(tmp_path)
    for key, value in expected().items():
        cache.put(key, value)
    os.remove(cache.path("off-1"))
    to_run, cached = pending(tasks, cache)
    assert [t.key for t in to_run] == ["total", "off-1"]
    assert set(cached) == set(expected()) - {"off-1"}
    with pytest.raises(ValueError, match="no Dask client"):
        execute(tasks, cache, client=None, progress=False)


def test_bad_task_sets_are_refused():
    with pytest.raises(ValueError, match="'a/b'"):
        Task("a/b", print)
    with pytest.raises(ValueError, match="depends on 'later'"):
        pending([Task("first", print, deps=("later",)), Task("later", print)], ResultCache("/nonexistent"))


def test_a_second_run_submits_nothing(tmp_path, local_client):
    cache = ResultCache(tmp_path / "cache")
    first = execute(closed_form_tasks(), cache, local_client, progress=False)
    assert not first.failed and first.results == expected()
    assert sorted(first.submitted) == sorted(["total"] + list(expected()))
    files = _cache_files(tmp_path / "cache")
    assert sorted(files) == sorted(f"{k}.json" for k in expected())
    second = execute(closed_form_tasks(), cache, client=None, progress=False)   # no client: nothing may run
    assert second.submitted == [] and sorted(second.cached) == sorted(expected())
    assert second.results == first.results
    assert _cache_files(tmp_path / "cache") == files


def test_a_task_that_raises_fails_with_its_dependents_and_the_bar_counts_only_what_finished(tmp_path, local_client,
                                                                                           capsys):
    tasks = [Task("sq-0", square, (0,)), Task("sq-1", square, (1,)), Task("boom", fail, (7,)),
             Task("after", square, (2,), deps=("boom",))]
    run = execute(tasks, ResultCache(tmp_path), local_client, retries=0, progress=True)
    assert run.results == {"sq-0": {"x": 0, "y": 0}, "sq-1": {"x": 1, "y": 1}}
    assert run.failed == {"boom": "ValueError: fail: x = 7 is refused", "after": "ValueError: fail: x = 7 is refused"}
    assert sorted(p.name for p in tmp_path.iterdir()) == ["sq-0.json", "sq-1.json"]
    final = capsys.readouterr().err.replace("\r", "\n").strip().splitlines()[-1]
    assert "tasks finished" in final and "2/4" in final and "failed=2" in final, final      # not 4/4


def test_separate_scheduler_and_worker_processes_give_the_local_cluster_s_results(tmp_path, local_client,
                                                                                 process_cluster):
    local = execute(closed_form_tasks(6), ResultCache(tmp_path / "local"), local_client, progress=False)
    with Client(process_cluster) as client:
        client.wait_for_workers(2, timeout=60)
        assert len(client.scheduler_info()["workers"]) == 2
        remote = execute(closed_form_tasks(6), ResultCache(tmp_path / "remote"), client, progress=False)
    assert not local.failed and not remote.failed
    assert remote.results == local.results == expected(6)
    assert _cache_files(tmp_path / "remote") == _cache_files(tmp_path / "local")


def test_a_worker_killed_mid_task_loses_and_duplicates_nothing(tmp_path, process_cluster):
    markers, n = tmp_path / "markers", 4
    markers.mkdir()
    tasks = [Task(f"held-{x}", held, (str(markers), x)) for x in range(n)]
    cache = ResultCache(tmp_path / "cache")
    with Client(process_cluster) as client:
        client.wait_for_workers(2, timeout=60)
        box = {}                                      # execute runs in a thread while this one kills a worker
        runner = threading.Thread(target=lambda: box.update(run=execute(tasks, cache, client, progress=False)))
        runner.start()
        end = time.monotonic() + 60
        while not list(markers.glob("started-*")):
            assert time.monotonic() < end, "no task started"
            time.sleep(0.05)
        victim = sorted(markers.glob("started-*"))[0].name.split("-")
        x_killed, pid = int(victim[1]), int(victim[2])
        os.kill(pid, signal.SIGKILL)                  # the worker process running task x_killed, mid-task
        (markers / "release").touch()
        runner.join(timeout=120)
        assert not runner.is_alive()
    run = box["run"]
    assert not run.failed, run.failed
    assert sorted(run.submitted) == sorted(t.key for t in tasks)
    assert run.results == {f"held-{x}": {"x": x, "y": x * x} for x in range(n)}
    assert sorted(_cache_files(tmp_path / "cache")) == sorted(f"held-{x}.json" for x in range(n))
    started = [p.name.split("-")[1] for p in markers.glob("started-*")]
    assert started.count(str(x_killed)) == 2          # it was running when killed, and ran again elsewhere
    done = sorted(int(p.name.split("-")[1]) for p in markers.glob("done-*"))
    assert done == list(range(n))                     # every task finished exactly once
