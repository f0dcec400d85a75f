"""Storage faults (issue 18): nothing lost when the optimizer's database cannot be written, nothing touched when it
cannot be read or belongs to another run.

Pure part (the real OptimizerRun, GMA and SQLite store; an analytic plant and a fake wall clock, ``storage_flight``):
a disk that fills at every write of a 2-iteration run, for good or for a few tries, and a process killed at any
sample; then a restart on the same file. Measured against the fault-free run: records lost, duplicated, setpoints
published while memory held a record the file lacked (unsafe), experiments measured at other setpoints.

Node part (``ros``): the optimizer process on damaged and mismatched databases (exit 2, file byte-identical), and in
the full graph with writes that fail like a full disk (``KITE_RTO_TEST_STORE_FULL``, the store's test hook: SQLite's
own disk-full error raised inside the write transaction, which SQLite rolls back; ``test_gma_store.py`` shows a real
SQLITE_FULL ends the same way) at an experiment write and at an iteration write, then restarted.
"""
import hashlib
import math
import os
import re
import subprocess
import time

import numpy as np
import pytest
from sensor_msgs.msg import JointState

import kite_rto.gma.gma as gma_module
from kite_rto.flight.shape import setpoints_from_shape
from kite_rto.gma import History, HistoryStore
from kite_rto.runtime.store_fault import DiskFull
from kite_rto.nodes.interface import LATCHED, stamp_to_ns
from kite_rto.nodes.optimizer_params import PARAMS, run_settings
from kite_rto.rto.builder import make_gma
from kite_rto.rto.experiment import ExperimentSpec
from kite_rto.runtime.run_db import SETTINGS_KEY, RunDatabaseError, open_run_database, settings_differences
from kite_rto.rto.settings import KiteRTOSettings
from kite_rto.tools.graph import node_command

from faultgraph import QUIET, SHORT, node, stop_all
from faultgraph import unsafe as outside_box
from faultlog import fault_row
from rosutil import Probe
from storage_flight import Flight, compare

pytestmark = [pytest.mark.faults]
PER = KiteRTOSettings().experiments_per_iteration()      # experiments of one iteration (directional, 3 directions)
# every write of a 2-iteration run: its start, the experiment-only writes, the writes that complete an iteration
WRITES = ["start:1"] + [f"experiment:{n}" for n in range(1, 5)] + ["iteration:1", "iteration:2"]


@pytest.fixture(scope="module", autouse=True)
def shared_nlps():
    """One pair of GMA NLPs for every GMA of this module (building them takes seconds; their warm start is then
    shared, so iterates agree with the reference to solver tolerance, not bit for bit)."""
    made, real = {}, gma_module.NLPPair

    def shared(problem, settings):
        key = (id(problem), repr(settings))
        if key not in made:
            made[key] = real(problem, settings)
        return made[key]
    with pytest.MonkeyPatch.context() as mp:
        mp.setattr(gma_module, "NLPPair", shared)
        yield


@pytest.fixture(scope="module")
def reference(tmp_path_factory):
    db = tmp_path_factory.mktemp("reference") / "rto.sqlite"
    f = Flight(db).fly()
    assert f.finished and f.unsafe == 0 and f.mismeasured == 0
    store = HistoryStore(db)
    h = store.load()
    store.close()
    assert len(h.experiments) == 2 * PER and len(h.iterations) == 2
    return h


def digest(path) -> str:
    return hashlib.sha256(open(path, "rb").read()).hexdigest()


# ----------------------------------------------------------------------------------------------- pure: writes
def test_disk_full_at_every_write_then_restart(request, tmp_path, reference):
    """The disk fills at one write and stays full: the run holds its setpoints, gives up after storage_timeout;
    the restarted run completes. Every write position of the run, one after the other."""
    with fault_row(request, "disk full at every write, then restart (pure)",
                   f"OptimizerRun + real SQLite store, writes fail (DiskFull) from {', '.join(WRITES)}; "
                   "storage_timeout 5 s; restart without the fault") as row:
        lost = dup = unsafe = mism = 0
        for spec in WRITES:
            db = tmp_path / f"{spec.replace(':', '-')}.sqlite"
            first = Flight(db, fault=DiskFull.parse(spec)).fly()
            assert first.storage_lost and not first.finished, spec
            errors = first.log.text("error")
            assert f"cannot write {db}: database or disk is full" in errors and "Traceback" not in errors, errors
            assert "stopping" in errors, errors
            again = Flight(db).fly()
            assert again.finished, spec
            c = compare(db, reference)
            lost, dup = lost + c["lost"], dup + c["duplicated"]
            unsafe += first.unsafe + again.unsafe
            mism += first.mismeasured + again.mismeasured
            assert c["extra"] == 0 and c["same_order"] and c["dc"] < 1e-6, (spec, c)
            assert c["experiments"] == 2 * PER and c["iterations"] == 2, (spec, c)
        row.outcome = (f"{len(WRITES)} write positions: each run held its setpoints and stopped (exit 3 in the node) "
                       f"after the timeout; each restart completed the run; {lost} records lost, {dup} duplicated, "
                       f"{mism} experiments measured at other setpoints")
        row.experiments_lost, row.unsafe_setpoints = lost, unsafe
        assert lost == dup == unsafe == mism == 0


def test_disk_full_for_a_while_at_every_write(request, tmp_path, reference):
    """The disk is full for 3 tries (about 1.5 s) at one write, then has room: the run holds its setpoints, stores
    everything and goes on; the held experiment starts when its setpoints are published."""
    with fault_row(request, "disk full for 3 tries at every write (pure)",
                   f"DiskFull(KIND, N, attempts=3) at {', '.join(WRITES)}") as row:
        lost = dup = unsafe = mism = held = 0
        for spec in WRITES:
            db = tmp_path / f"{spec.replace(':', '-')}.sqlite"
            f = Flight(db, fault=DiskFull.parse(spec + ":3")).fly()
            assert f.finished and not f.storage_lost, spec
            assert "database or disk is full" in f.log.text("error") and "after" in f.log.text("info"), spec
            held += "stored in" in f.log.text("info")
            c = compare(db, reference)
            lost, dup, unsafe, mism = lost + c["lost"], dup + c["duplicated"], unsafe + f.unsafe, mism + f.mismeasured
            assert c["extra"] == 0 and c["same_order"] and c["dc"] < 1e-6, (spec, c)
        row.outcome = (f"{held}/{len(WRITES)} runs held their setpoints until the write succeeded, then went on to "
                       f"the end without a restart; {lost} records lost, {dup} duplicated, {mism} experiments "
                       "measured at other setpoints")
        row.experiments_lost, row.unsafe_setpoints = lost, unsafe
        assert held == len(WRITES) and lost == dup == unsafe == mism == 0


def test_killed_at_any_sample_then_restart(request, tmp_path, reference):
    """A process killed (no close) at any sample: the restart completes the run, each record once."""
    kills = list(range(3, 75, 6))
    with fault_row(request, "optimizer killed at any sample, then restart (pure)",
                   f"the run abandoned after {kills[0]}, {kills[1]}, ..., {kills[-1]} samples (10 per experiment)") \
            as row:
        lost = dup = unsafe = 0
        for n in kills:
            db = tmp_path / f"kill-{n}.sqlite"
            first = Flight(db).fly(kill_after=n)
            again = Flight(db).fly()
            assert again.finished, n
            c = compare(db, reference)
            lost, dup, unsafe = lost + c["lost"], dup + c["duplicated"], unsafe + first.unsafe + again.unsafe
            assert c["extra"] == 0 and c["same_order"] and c["dc"] < 1e-6, (n, c)
        row.outcome = f"{len(kills)} kills, each restart completed the run: {lost} records lost, {dup} duplicated"
        row.experiments_lost, row.unsafe_setpoints = lost, unsafe
        assert lost == dup == unsafe == 0


def test_resume_stores_the_iteration_completed_again(request, tmp_path, reference):
    """A file of an older version, killed between its experiment write and its iteration write: the last experiment
    of iteration 0 is stored, its record is not. The resumed GMA completes iteration 0 in memory; the run stores
    that record before it publishes anything (it used to count it as stored, and it was lost)."""
    with fault_row(request, "killed between the experiment and the iteration write (older file)",
                   "a file with every experiment of iteration 0 and no record 0; resumed") as row:
        db = tmp_path / "old.sqlite"
        h = reference
        store = HistoryStore(db)
        store.save_meta({**h.meta, "c0": h.c0})
        store.save_pending([q for q, _ in h.experiments[:PER]])
        for req, res in h.experiments[:PER]:
            store.save_experiment(req, res)                   # one transaction each, no iteration: the old state
        store.close()
        f = Flight(db)
        assert f.run.c_published is None
        f.fly()
        c = compare(db, reference)
        row.outcome = (f"record 0 stored before the first setpoints; the run completed with {c['iterations']} "
                       f"iterations, {c['lost']} records lost, {c['duplicated']} duplicated")
        row.experiments_lost, row.unsafe_setpoints = c["lost"], f.unsafe
        assert f.finished and f.unsafe == 0 and c["lost"] == c["duplicated"] == c["extra"] == 0, c


# --------------------------------------------------------------------------------------------- pure: opening
def test_open_refuses_a_used_file_without_resume_or_with_other_settings(tmp_path):
    db = tmp_path / "rto.sqlite"
    Flight(db, n_iter=1, settings={"n_laps": 1, "h_min": 10.0, "box_aspect": [0.16, 0.22]}).fly()
    before = digest(db)
    with pytest.raises(RunDatabaseError, match=rf"database {db} holds a run \({PER} experiments, 1 iterations\) and "
                                               "resume is false.*resume:=true, or to start a new run, move it aside"):
        open_run_database(db, {"n_laps": 1, "h_min": 10.0, "box_aspect": [0.16, 0.22]}, resume=False)
    with pytest.raises(RunDatabaseError) as err:
        open_run_database(db, {"n_laps": 2, "h_min": 10.0, "box_aspect": [0.16, 0.25], "gradient": "forward"},
                          resume=True)
    text = str(err.value)
    for part in ("n_laps = 1 (stored) vs 2 (now)", "box_aspect = [0.16, 0.22] (stored) vs [0.16, 0.25] (now)",
                 "gradient = '<not stored>' (stored) vs 'forward' (now)", "move it aside"):
        assert part in text, text
    assert "h_min" not in text
    assert digest(db) == before
    store, history, note = open_run_database(db, {"n_laps": 1, "h_min": 10.0, "box_aspect": [0.16, 0.22]}, True)
    assert history is not None and len(history.iterations) == 1 and note == ""
    store.close()


def test_settings_differences():
    assert settings_differences({"a": 1.0, "b": [1.0, 2.0]}, {"a": 1.0, "b": [1.0, 2.0]}) == []
    assert settings_differences({"a": 1}, {"a": 1.0}) == []                 # JSON numbers
    assert settings_differences({"a": 1.0}, {"a": 2.0, "c": "x"}) == ["a = 1.0 (stored) vs 2.0 (now)",
                                                                      "c = '<not stored>' (stored) vs 'x' (now)"]


def test_open_resumes_an_older_file_with_a_note(tmp_path, reference):
    db = tmp_path / "old.sqlite"
    old = History.from_dict(reference.to_dict())
    del old.meta[SETTINGS_KEY]                           # written before the settings were stored
    store = HistoryStore(db)
    store.save_history(old)
    store.close()
    store, history, note = open_run_database(db, {"n_laps": 1}, True)
    store.close()
    assert history is not None and "without its settings" in note and str(db) in note


# ---------------------------------------------------------------------------------------- node: start-up (exit 2)
def node_defaults() -> dict:
    """The optimizer's run settings for its default parameters (what a default node stores with a new run)."""
    return run_settings({s.name: s.default for s in PARAMS})


def start_optimizer(db, env, *args, timeout=300):
    """``optimizer --ros-args -p db:=DB ARGS``, run to its end; (exit code, output)."""
    res = subprocess.run(node_command("optimizer", {"db": str(db)}) + list(args), env=env, capture_output=True,
                         text=True, timeout=timeout, cwd=os.path.dirname(db))
    return res.returncode, res.stdout + res.stderr


def used_database(path, settings=None):
    """A database holding a finished 1-iteration run made with the node's default settings."""
    Flight(path, n_iter=1, settings=node_defaults() if settings is None else settings).fly()
    return path


def damaged_database(path, kind):
    if kind == "corrupt":
        path.write_bytes(np.random.default_rng(7).bytes(32768))
    else:
        used_database(path)
        data = path.read_bytes()
        path.write_bytes(data[: len(data) // 2])
    return path


def refusal(code, out, folder) -> str:
    """The node's refusal line, its directory shown as DIR."""
    line = next((ln.strip() for ln in out.splitlines() if "refusing to start" in ln), f"exit {code}: no message")
    return line.replace(str(folder), "DIR")


@pytest.mark.ros
@pytest.mark.parametrize("kind, injection, cause", [
    ("corrupt", "32 KiB of random bytes", "file is not a database"),
    ("truncated", "a database holding a run, cut to half its size", "malformed")])
def test_damaged_database_stops_the_optimizer(request, ros_env, tmp_path, kind, injection, cause):
    db = damaged_database(tmp_path / "rto.sqlite", kind)
    files, before = sorted(os.listdir(tmp_path)), digest(db)
    with fault_row(request, f"{kind} database at start-up", f"optimizer -p db:=rto.sqlite on {injection}") as row:
        code, out = start_optimizer(db, ros_env)
        unchanged = digest(db) == before and sorted(os.listdir(tmp_path)) == files
        row.outcome = f"exit {code}: {refusal(code, out, tmp_path)}; file byte-identical: {unchanged}"
        row.experiments_lost, row.unsafe_setpoints = 0, 0
        assert code == 2 and unchanged, out
        assert f"database {db} cannot be read" in out and cause in out and "Move it aside" in out, out
        assert "Traceback" not in out, out


@pytest.mark.ros
def test_used_database_without_resume_is_refused(request, ros_env, tmp_path):
    db = used_database(tmp_path / "rto.sqlite")
    before = digest(db)
    with fault_row(request, "resume:=false on a database that holds a run",
                   "optimizer -p resume:=false on a database with a finished 1-iteration run") as row:
        code, out = start_optimizer(db, ros_env, "-p", "resume:=false")
        row.outcome = f"exit {code}: {refusal(code, out, tmp_path)}; file byte-identical: {digest(db) == before}"
        row.experiments_lost, row.unsafe_setpoints = 0, 0
        assert code == 2 and digest(db) == before, out
        assert f"database {db} holds a run ({PER} experiments, 1 iterations) and resume is false" in out, out


@pytest.mark.ros
def test_resume_with_changed_settings_is_refused(request, ros_env, tmp_path):
    db = used_database(tmp_path / "rto.sqlite")
    before = digest(db)
    changed = ["h_min:=20.0", "n_laps:=2", "gradient:=forward", "box_aspect:=[0.16,0.21]"]
    with fault_row(request, "resume with changed settings",
                   f"optimizer -p {' -p '.join(changed)} on a database made with the defaults") as row:
        code, out = start_optimizer(db, ros_env, *[a for c in changed for a in ("-p", c)])
        row.outcome = f"exit {code}: {refusal(code, out, tmp_path)}; file byte-identical: {digest(db) == before}"
        row.experiments_lost, row.unsafe_setpoints = 0, 0
        assert code == 2 and digest(db) == before, out
        for part in ("h_min = 100.0 (stored) vs 20.0 (now)", "n_laps = 4 (stored) vs 2 (now)",
                     "gradient = 'directional' (stored) vs 'forward' (now)",
                     "box_aspect = [0.16, 0.22] (stored) vs [0.16, 0.21] (now)", str(db)):
            assert part in out, (part, out)


# ---------------------------------------------------------------------------------- node: disk full in the graph
@pytest.fixture
def probe():
    p = Probe()
    yield p
    p.close()


def log_wall(line: str) -> float:
    """The wall-clock stamp (s) of a ROS log line ``[LEVEL] [seconds] [node]: ...``."""
    m = re.match(r"\[\w+\] \[(\d+\.\d+)\]", line)
    return float(m.group(1)) if m else math.nan


@pytest.mark.ros
@pytest.mark.slow
def test_disk_full_in_the_graph_then_restart(request, probe, ros_env, tmp_path):
    """Optimizer 1: the disk fills at its 2nd experiment write and stays full; optimizer 2 (restarted): at its first
    iteration write; optimizer 3: no fault. Plant and controller fly on throughout. Each faulty optimizer must hold
    its setpoints, log the error (file and cause), stop with exit 3 after storage_timeout (3 s), and publish no
    setpoint after the failed write; the last one completes the iteration with each experiment stored once."""
    db = tmp_path / "rto.sqlite"
    sent = []                                                  # (header stamp s, setpoints rad) of /rto/setpoints
    probe.node.create_subscription(JointState, "/rto/setpoints", lambda m: sent.append(
        (stamp_to_ns(m.header.stamp) * 1e-9, np.array(m.position, dtype=float))), LATCHED)
    params = {"db": str(db), **SHORT, "storage_timeout": 3.0}
    faults = [("experiment:2", "its 2nd experiment write"), ("iteration:1", "its first iteration write"), (None, "")]
    procs, runs, err = [], [], None
    try:
        for i, (spec, _) in enumerate(faults):
            env = dict(ros_env, **({"KITE_RTO_TEST_STORE_FULL": spec} if spec else {}))
            opt = node(f"optimizer{i + 1}", "optimizer", env, tmp_path, params)
            procs.append(opt)
            if i == 0:
                assert probe.spin_until(lambda: probe.node.count_publishers("/rto/setpoints") > 0, 180.0), opt.text()
                procs.append(node("controller", "controller", ros_env, tmp_path))
                assert probe.spin_until(lambda: probe.node.count_publishers("/kite/steering") > 0, 60.0)
                procs.append(node("plant", "plant", ros_env, tmp_path, {**QUIET, "wait_subscribers": 2}))
            assert probe.spin_until(lambda: not opt.alive(), 900.0), f"optimizer{i + 1} did not finish"
            ended = time.time()
            store = HistoryStore(db)
            runs.append({"code": opt.proc.returncode, "proc": opt, "ended": ended, "counts": store.counts()})
            store.close()
    except BaseException as exc:                               # still write the rows (failed), then re-raise
        err = exc
    finally:
        stop_all(procs)
    store = HistoryStore(db)
    history, counts = store.load(), store.counts()
    store.close()
    planned = make_gma(KiteRTOSettings(experiment=ExperimentSpec(n_laps=1, settle_laps=0))).history.pending
    flown = {q.request_id: q for q, _ in history.experiments} if history else {}
    lost = sum(q.request_id not in flown for q in planned) + (1 - min(counts["iterations"], 1))
    allowed = [q.c for q in planned] + ([r.c_next for r in history.iterations] if history else [])
    allowed = [setpoints_from_shape(x) for x in allowed]
    for i, (spec, where) in enumerate(faults[:2]):
        with fault_row(request, f"disk full at {spec.split(':')[0]} write, then restart",
                       f"optimizer {i + 1}: KITE_RTO_TEST_STORE_FULL={spec} (writes fail like a full disk from "
                       f"{where} on), storage_timeout 3 s; then restarted on the same database") as row:
            if err is not None:
                raise err
            run = runs[i]
            out = run["proc"].text()
            failed = [ln for ln in run["proc"].lines if f"cannot write {db}: database or disk is full" in ln]
            t_fail = log_wall(failed[0]) if failed else math.inf
            after = [c for t, c in sent if t_fail <= t <= run["ended"]]        # published after the failed write
            bad = len(after) + sum(outside_box(c) or not any(np.allclose(c, a, atol=1e-12) for a in allowed)
                                   for _, c in sent)
            row.outcome = (f"exit {run['code']} after holding its setpoints; database then: {run['counts']}; "
                           f"{len(after)} setpoints published after the failed write; the last optimizer finished "
                           f"the iteration: {counts['experiments']} experiments, {counts['iterations']} iteration, "
                           f"{len(history.experiments) - len(flown)} duplicated")
            row.experiments_lost, row.unsafe_setpoints = lost, bad
            assert run["code"] == 3 and failed and "Traceback" not in out, out[-3000:]
            assert "stopping" in out and "storage_timeout" in out, out[-3000:]
            assert bad == 0 and lost == 0, (after, sent)
    assert runs[0]["counts"] == {"experiments": 1, "iterations": 0}
    # the experiment that completes the iteration is written in the iteration's transaction, which fails
    assert runs[1]["counts"] == {"experiments": PER - 1, "iterations": 0}
    assert runs[2]["code"] == 0 and counts == {"experiments": PER, "iterations": 1}, runs[2]["proc"].text()[-3000:]
    assert [q.request_id for q, _ in history.experiments] == [q.request_id for q in planned]
