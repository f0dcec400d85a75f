"""Fault injection, node loss and kite crash (issue 7, items 3 and 5).

Nodes are killed with SIGKILL (no clean shutdown) in the middle of a GMA iteration of the full graph (optimizer,
controller, plant in lockstep; one lap per experiment) and started again. The optimizer's SQLite database must
end with the iteration's four experiments, each measured once and none lost: the same experiment list (ids and
setpoints) as the fault-free pure runner. A crash is caused by a faulty pilot (``fault_relay --dive-at``) that
steers the kite into the ground; the optimizer must discard and repeat the experiment it spoiled.
"""
import math
import re
import time
from dataclasses import replace

import numpy as np
import pytest

from kite_rto.flight.shape import setpoints_from_shape
from kite_rto.flight.closed_loop import make_closed_loop
from kite_rto.flight.controller import ControllerSettings
from kite_rto.rto.experiment import ExperimentSpec
from kite_rto.rto.settings import KiteRTOSettings
from kite_rto.rto.session import RTOSession
from kite_rto.rto.builder import make_gma
from kite_rto.rto.runner import run_rto
from kite_rto.flight.path import Setpoints

PER = KiteRTOSettings().experiments_per_iteration()   # experiments of one GMA iteration
from kite_rto.kite.plant import PlantConfig
from kite_rto.gma import HistoryStore

from faultgraph import QUIET, SHORT, Watch, node, relay, stop_all, unsafe
from faultlog import fault_row
from rosutil import Probe

pytestmark = [pytest.mark.ros, pytest.mark.faults]
SETTINGS = KiteRTOSettings(experiment=ExperimentSpec(n_laps=1, settle_laps=0))


@pytest.fixture
def probe():
    p = Probe()
    yield p
    p.close()


@pytest.fixture(scope="module")
def pure():
    """The fault-free pure runner's iteration: the experiment list every faulty run must end with."""
    return run_rto(PlantConfig().without_disturbances(), seed=0, n_iter=1, settings=SETTINGS)


def stored(db):
    store = HistoryStore(db)
    try:
        return store.load(), store.counts()
    finally:
        store.close()


def n_stored(db) -> int:
    return stored(db)[1]["experiments"] if db.exists() else 0


def logged_experiments(*procs) -> list[str]:
    """Request ids of every 'experiment <id>: tension ...' line (one per experiment measured and stored)."""
    return [m.group(1) for p in procs for ln in p.lines for m in [re.search(r"experiment (\S+): tension", ln)] if m]


def wall_stamp(line: str) -> float:
    """The wall-clock stamp of a ROS log line ``[LEVEL] [seconds] [node]: ...``."""
    m = re.match(r"\[\w+\] \[(\d+\.\d+)\]", line)
    return float(m.group(1)) if m else math.nan


def check_iteration(db, pure, done_before=(), *logs):
    """(experiments lost, repeated, max setpoint difference to the pure runner rad, history) of the stored run."""
    history, counts = stored(db)
    ids = [q.request_id for q, _ in history.experiments]
    c = np.array([setpoints_from_shape(q.c) for q, _ in history.experiments])   # GMA: shape coordinates
    pure_c = np.array([e.c for e in pure.experiments])
    dc = float(np.max(np.abs(c - pure_c))) if c.shape == pure_c.shape else math.inf
    lost = len(set(done_before) - set(ids)) + max(0, len(pure.experiments) - len(set(ids)))
    logged = logged_experiments(*logs)
    repeated = len(logged) - len(set(logged))
    return lost, repeated, dc, history, counts


def start_graph(probe, env, log_dir, db, controller_remap=None, plant_extra=None, extra=()):
    """Optimizer, controller (and extra processes), then the plant: as in test_optimizer_node.py."""
    procs = [node("optimizer", "optimizer", env, log_dir, {"db": str(db), **SHORT})]
    assert probe.spin_until(lambda: probe.node.count_publishers("/rto/setpoints") > 0, 120.0), procs[0].text()
    procs.append(node("controller", "controller", env, log_dir, remap=controller_remap))
    procs += [make() for make in extra]
    assert probe.spin_until(lambda: probe.node.count_publishers("/kite/steering") > 0, 60.0)
    probe.spin_until(lambda: False, 0.5)
    procs.append(node("plant", "plant", env, log_dir, {**QUIET, "wait_subscribers": 2, **(plant_extra or {})}))
    return procs


def wait_exit(probe, proc, timeout=600.0):
    assert probe.spin_until(lambda: not proc.alive(), timeout), f"{proc.label} did not finish"
    return proc.proc.returncode


# ------------------------------------------------------------------------------------- controller, optimizer
@pytest.mark.slow
def test_controller_and_optimizer_killed_and_restarted(probe, ros_env, request, tmp_path, pure):
    db = tmp_path / "rto.sqlite"
    watch = Watch(probe.node)
    procs = start_graph(probe, ros_env, tmp_path, db)
    opt, ctrl, plant = procs
    c, o, err = {}, {}, None
    try:
        # the controller: SIGKILL 12 s into the first experiment, restart 3 s later
        assert probe.spin_until(lambda: watch.t > 12.0, 120.0)
        c["t_kill"] = watch.t
        ctrl.kill()
        w_kill = time.monotonic()
        # DDS drops a killed controller from the graph after its participant lease; then the lockstep plant flies
        # neutral (generous wait: the lease, not the machine's speed, sets when)
        assert probe.spin_until(lambda: plant.count("flying neutral") >= 1, 90.0), plant.text()[-2000:]
        c["w_neutral"] = time.monotonic() - w_kill
        t0 = watch.t
        probe.spin_until(lambda: False, 3.0)
        c["neutral_sim"] = watch.t - t0                    # the plant kept its clock going, steering neutral
        latched = np.degrees(watch.setpoints[-1])           # what /rto/setpoints holds for a late joiner
        ctrl2 = node("controller2", "controller", ros_env, tmp_path)
        procs.append(ctrl2)
        w0 = time.monotonic()
        assert probe.spin_until(lambda: plant.count("steering commands are back") >= 1, 60.0)
        c["w_back"] = time.monotonic() - w0
        t_back, w_back = watch.t, time.monotonic()
        assert probe.spin_until(lambda: watch.t > t_back + 10.0, 60.0)     # the loop runs again
        c["rate"] = 10.0 / (time.monotonic() - w_back)
        first = ctrl2.matching("new setpoints")
        took = [float(v) for v in re.findall(r"([\d.]+) deg", first[0])] if first else []
        back = plant.matching("steering commands are back")
        # took them before its first answer reached the plant (log wall stamps)
        c["synced"] = int(len(took) == 3 and np.allclose(took, latched, atol=0.051)
                          and wall_stamp(first[0]) <= wall_stamp(back[-1]))
        c["took"], c["latched"] = took, [round(float(v), 2) for v in latched]
        # the optimizer: SIGKILL after two stored experiments, restart on the same database
        assert probe.spin_until(lambda: n_stored(db) >= 2, 300.0)
        o["done_before"] = [q.request_id for q, _ in stored(db)[0].experiments]
        o["t_kill"] = watch.t
        opt.kill()
        opt2 = node("optimizer2", "optimizer", ros_env, tmp_path, {"db": str(db), **SHORT})
        procs.append(opt2)
        o["code"] = wait_exit(probe, opt2)
    except BaseException as exc:                      # still write the rows (failed), then re-raise
        err = exc
    finally:
        stop_all(procs)
    unsafe = watch.unsafe_published() + watch.unsafe_applied()
    with fault_row(request, "controller killed and restarted",
                   "SIGKILL of the controller once /clock has passed 12 s (the kill time is in the outcome); "
                   "restarted 3 s (wall) later") as row:
        if err is not None:
            raise err
        lost, repeated, dc, history, counts = check_iteration(db, pure, o["done_before"], opt, opt2)
        row.experiments_lost, row.unsafe_setpoints = lost, unsafe
        row.outcome = (f"killed at t = {c['t_kill']:.1f} s; the plant flew neutral after {c['w_neutral']:.1f} s wall "
                       f"(once DDS dropped the killed controller from the graph) and kept its clock ({c['neutral_sim']:.2f} s simulated in 3 s wall); "
                       f"the restarted controller answered {c['w_back']:.1f} s after its start, having first taken "
                       f"the current setpoints from the latched /rto/setpoints ({c['took']} deg, latched "
                       f"{c['latched']} deg); the loop ran on at {c['rate']:.0f}x real time; the iteration "
                       f"finished with all {counts['experiments']} experiments")
        assert c["neutral_sim"] > 0.2 and c["synced"] == 1
        assert lost == 0 and unsafe == 0
    with fault_row(request, "optimizer killed and restarted",
                   "SIGKILL of the optimizer after 2 stored experiments; restarted on the same database") as row:
        resumed = opt2.count(f"resumed from {db}: {len(o['done_before'])} experiments")
        row.experiments_lost, row.unsafe_setpoints = lost, unsafe
        row.outcome = (f"killed at t = {o['t_kill']:.1f} s with {len(o['done_before'])} experiments stored; the "
                       f"restarted optimizer resumed from them ({resumed == 1}) and finished the iteration: "
                       f"{counts['experiments']} experiments, {repeated} measured twice, setpoints equal to the "
                       f"fault-free pure runner's within {dc:.1e} rad")
        assert o["code"] == 0, opt2.text()[-3000:]
        assert resumed == 1 and counts == {"experiments": PER, "iterations": 1}
        assert lost == 0 and repeated == 0 and dc < 1e-9 and unsafe == 0


# ------------------------------------------------------------------------------------------------ the plant
@pytest.mark.slow
def test_plant_killed_and_restarted_restarts_the_experiment(probe, ros_env, request, tmp_path, pure):
    db = tmp_path / "rto.sqlite"
    watch = Watch(probe.node)
    with fault_row(request, "plant killed and restarted (sim time jumps back)",
                   "SIGKILL of the plant 5 s into the second experiment; a new plant started 1.5 s (wall) later "
                   "from t = 0") as row:
        procs = start_graph(probe, ros_env, tmp_path, db)
        opt, ctrl, plant = procs
        try:
            assert probe.spin_until(lambda: n_stored(db) >= 1, 300.0)
            t_first = stored(db)[0].experiments[0][1].extra["t_end"]
            assert probe.spin_until(lambda: watch.t > t_first + 5.0, 60.0)
            t_kill = watch.t
            plant.kill()
            probe.spin_until(lambda: False, 1.5)
            plant2 = node("plant2", "plant", ros_env, tmp_path, {**QUIET, "wait_subscribers": 2})
            procs.append(plant2)
            code = wait_exit(probe, opt)
        finally:
            stop_all(procs)
        lost, repeated, dc, history, counts = check_iteration(db, pure, [], opt)
        extra = [r.extra for _, r in history.experiments]
        ctrl_sync = ctrl.count("sim time jumped back")
        opt_restart = opt.count("experiment starts again")
        row.experiments_lost = lost
        row.unsafe_setpoints = watch.unsafe_published() + watch.unsafe_applied()
        row.outcome = (f"killed at t = {t_kill:.1f} s; controller re-synchronized ({ctrl_sync}x 'sim time jumped "
                       f"back') and optimizer restarted the experiment ({opt_restart}x); experiment 1 finished before "
                       f"the kill was kept (t = {extra[0]['t_start']:.1f}-{extra[0]['t_end']:.1f} s), experiment 2 "
                       f"was measured again on the new plant (t = {extra[1]['t_start']:.1f}-{extra[1]['t_end']:.1f} "
                       f"s); {counts['experiments']} experiments, {repeated} measured twice, setpoints equal to the "
                       f"pure runner's within {dc:.1e} rad")
        assert code == 0, opt.text()[-3000:]
        assert ctrl_sync == 1 and opt_restart == 1
        assert counts == {"experiments": PER, "iterations": 1} and lost == 0 and repeated == 0 and dc < 1e-9
        assert extra[0]["t_end"] <= t_kill                           # kept from the old plant
        # started again on the new plant's clock, which began at t = 0: before the killed experiment had begun on
        # the old one (how far into the new clock depends on how soon the optimizer saw the jump, i.e. machine speed)
        assert extra[1]["t_start"] < t_first and extra[1]["t_end"] > extra[1]["t_start"]
        assert row.unsafe_setpoints == 0


# ------------------------------------------------------------------------------------------------ kite crash
def _dive(psi: float) -> float:
    """The crash pilot of fault_relay --dive-at: turn to psi = pi (straight down)."""
    return max(-1.0, min(1.0, 2.0 * ((math.pi - psi + math.pi) % (2 * math.pi) - math.pi)))


def test_kite_crash_discards_and_repeats_the_experiment_pure(request):
    """Pure runner (the optimizer node's RTOSession): a crash in the first experiment; fast, in the default suite."""
    with fault_row(request, "kite crash (pure runner, RTOSession)",
                   "from t = 20 s a faulty pilot steers to psi = pi until the kite crashes (same law as "
                   "fault_relay --dive-at)") as row:
        gma = make_gma(SETTINGS)
        session = RTOSession(gma, SETTINGS.experiment, SETTINGS.max_repeats)
        c0 = Setpoints.from_array(setpoints_from_shape(gma.next_request().c))   # GMA works in shape coordinates
        plant, controller = make_closed_loop(c0, PlantConfig().without_disturbances(), seed=0,
                                             settings=replace(ControllerSettings(), box=SETTINGS.box.setpoint_box()))
        m = plant.measure()
        new = session.start(m.t)
        crash_t = None
        while not gma.records and not session.stopped and m.t < 600:
            if new is not None:
                controller.set_setpoints(Setpoints.from_array(new))
            delta = controller.command(m)
            if m.t >= 20.0 and crash_t is None:
                delta = _dive(m.psi)
            m = plant.step(delta)
            if m.crashes and crash_t is None:
                crash_t = m.t
            new = session.on_measurement(m)
        logs = session.experiments
        ids = [e.request_id for e in logs]
        stored_t = [r.extra["t_start"] for _, r in gma.history.experiments]
        row.experiments_lost = PER - len(set(ids) & {q.request_id for q, _ in gma.history.experiments})
        row.unsafe_setpoints = sum(unsafe(e.c) for e in logs)
        row.outcome = (f"crash at t = {crash_t:.1f} s counted ({m.crashes}) and relaunched; the experiment in "
                       f"progress was discarded and repeated ({logs[0].repeats} repeat, measured again from "
                       f"t = {stored_t[0]:.1f} s); the iteration completed with {len(logs)} distinct experiments")
        assert m.crashes == 1 and crash_t is not None and not session.stopped and len(gma.records) == 1
        assert [e.repeats for e in logs] == [1] + [0] * (PER - 1) and len(set(ids)) == PER
        assert stored_t[0] >= crash_t and row.experiments_lost == 0 and row.unsafe_setpoints == 0


@pytest.mark.slow
def test_kite_crash_discards_and_repeats_the_experiment(probe, ros_env, request, tmp_path, pure):
    """Over DDS: the plant detects, counts (/kite/crashes) and relaunches; the optimizer repeats the experiment."""
    db = tmp_path / "rto.sqlite"
    watch = Watch(probe.node)
    with fault_row(request, "kite crash",
                   "fault_relay --dive-at 20 between controller and plant: from t = 20 s the steering turns the kite "
                   "straight down until /kite/crashes counts a crash") as row:
        pilot = lambda: relay("pilot", ros_env, tmp_path, in_="/kite/steering_raw", out="/kite/steering",  # noqa: E731
                              type="sensor_msgs/JointState", dive_at=20.0)
        procs = start_graph(probe, ros_env, tmp_path, db, controller_remap={"/kite/steering": "/kite/steering_raw"},
                            plant_extra={"wait_subscribers": 3}, extra=[pilot])
        opt, ctrl, relay_proc, plant = procs
        try:
            code = wait_exit(probe, opt)
            probe.spin_until(lambda: False, 0.5)
        finally:
            stop_all(procs)
        lost, repeated, dc, history, counts = check_iteration(db, pure, [], opt)
        crash = [float(m.group(1)) for ln in plant.matching("kite crashed")
                 for m in [re.search(r"at t = ([\d.]+) s", ln)] if m]
        repeats = opt.matching("its data is discarded, repeating it")
        t0 = history.experiments[0][1].extra["t_start"]
        row.experiments_lost = lost
        row.unsafe_setpoints = watch.unsafe_published() + watch.unsafe_applied()
        row.outcome = (f"crash at t = {crash[0] if crash else math.nan:.1f} s detected and relaunched by the plant, "
                       f"/kite/crashes = {watch.crashes}; the optimizer discarded the experiment in progress and "
                       f"repeated it ({len(repeats)}x), measured again from t = {t0:.1f} s; {counts['experiments']} "
                       f"experiments, {repeated} measured twice, setpoints equal to the pure runner's within "
                       f"{dc:.1e} rad")
        assert code == 0, opt.text()[-3000:]
        assert len(crash) == 1 and watch.crashes == 1 and len(repeats) == 1, plant.text()[-2000:]
        assert t0 >= crash[0]
        assert counts == {"experiments": PER, "iterations": 1} and lost == 0 and repeated == 0 and dc < 1e-9
        assert row.unsafe_setpoints == 0
