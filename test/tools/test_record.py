"""MCAP recording: schemas and CDR that mcap_ros2 decodes, the kite_record command on a live graph, and the
report rebuilt from a recording (``rto_report --mcap``)."""
import json
import math
import signal
import subprocess
import sys

import numpy as np
import pytest
from diagnostic_msgs.msg import DiagnosticArray, DiagnosticStatus, KeyValue
from mcap.reader import make_reader
from mcap_ros2.reader import read_ros2_messages
from rclpy.serialization import serialize_message
from nav_msgs.msg import Path
from rosgraph_msgs.msg import Clock
from sensor_msgs.msg import JointState
from std_msgs.msg import Header, String, UInt32
from visualization_msgs.msg import Marker, MarkerArray

from kite_rto.nodes import topics as T
from kite_rto.nodes.interface import LATCHED, ns_to_stamp
from kite_rto.nodes.plant_config import PARAMS as PLANT_PARAMS
from kite_rto.nodes.plant_config import config_from_params
from kite_rto.rto.run import RunDescription
from kite_rto.rto.settings import KiteRTOSettings
from kite_rto.runtime.run_description import plant_from_json
from kite_rto.nodes.controller_node import LAP_FIELDS
from kite_rto.tools.record import (TOPICS, McapRecording, generated_definition, message_definition, type_name)
from kite_rto.tools.record_time import PER_SAMPLE, SampleGaps, SimLogTime, cdr_stamp

from rosutil import DIE_WITH_PARENT, Probe, start_node, stop

PY = sys.executable


def test_topic_table_covers_every_project_topic():
    names = {v for k, v in vars(T).items() if k.isupper() and isinstance(v, str)}
    assert names == set(TOPICS)
    assert PER_SAMPLE <= set(TOPICS)


def _cdr(msg) -> bytes:
    return serialize_message(msg)


def test_log_time_is_the_simulated_stamp_and_samples_count_once():
    types = {t: type_name(cls) for t, (cls, _) in TOPICS.items()}
    lt = SimLogTime(types)
    state = _example(JointState)                                          # stamped 12.34 s
    clock = Clock()
    clock.clock = ns_to_stamp(12_340_000_000)
    assert lt.log_time(T.CLOCK, _cdr(clock), wall_ns=99) == 12_340_000_000
    assert lt.log_time(T.STATE, _cdr(state), wall_ns=100) == 12_340_000_000
    assert lt.log_time(T.STATE, _cdr(state), wall_ns=101) is None        # the plant re-published it
    assert lt.log_time(T.STEERING, _cdr(state), wall_ns=102) == 12_340_000_000
    assert lt.duplicates == {T.STATE: 1}
    assert lt.log_time(T.LAPS, _cdr(state), 103) == lt.log_time(T.LAPS, _cdr(state), 104) == 12_340_000_000
    assert lt.log_time(T.CRASHES, _cdr(UInt32(data=1)), 105) == 12_340_000_000          # no header: the clock
    assert lt.log_time(T.REFERENCE_PATH, _cdr(Path()), 106) == 12_340_000_000           # stamp 0 = not set
    walled = _example(JointState)
    walled.header.stamp = ns_to_stamp(1_796_000_000_000_000_000)                        # a node on wall time
    assert lt.log_time(T.SETPOINTS, _cdr(walled), 107) == 12_340_000_000 and lt.replaced == 1
    markers = MarkerArray(markers=[Marker()])
    markers.markers[0].header.stamp = ns_to_stamp(12_300_000_000)
    assert lt.log_time(T.MARKERS, _cdr(markers), 108) == 12_300_000_000
    assert lt.log_time(T.MARKERS, _cdr(MarkerArray()), 109) == 12_340_000_000
    markers.markers[0].header.stamp = ns_to_stamp(0)
    assert lt.log_time(T.MARKERS, _cdr(markers), 109) == 0                              # the scene of sample 0
    restarted = _example(JointState)
    restarted.header.stamp = ns_to_stamp(0)
    assert lt.log_time(T.STATE, _cdr(restarted), 110) == 0              # a new plant: recorded, its time again
    assert lt.log_time(T.STATE, _cdr(restarted), 111) is None
    wall = SimLogTime(types, "wall")
    assert wall.log_time(T.STATE, _cdr(state), 5) == 5 and wall.log_time(T.STATE, _cdr(state), 6) is None
    assert cdr_stamp(b"\x00\x01", 4) is None
    with pytest.raises(ValueError, match="expected one of sim, wall"):
        SimLogTime(types, "gps")


def test_missing_samples_are_counted_from_the_steps_between_stamps():
    gaps = SampleGaps()
    ms = 1_000_000
    stamps = [0, 20, 40, 60, 160, 180, 200, 260, 280]                  # 4 missing at 80..140, 2 at 220, 240
    for a, b in zip(stamps, stamps[1:]):
        gaps.add(T.STATE, a * ms, b * ms)
    gaps.add(T.STATE, None, 0)                                          # a first sample: no step
    gaps.add(T.STATE, 280 * ms, 0)                                      # a restarted plant: a new span, no gap
    gaps.add(T.WIND, 0, 20 * ms)
    assert gaps.period_ns(T.STATE) == 20 * ms and gaps.period_ns(T.CLOCK) is None
    assert gaps.missing(T.STATE) == 6 and gaps.missing(T.WIND) == 0 and gaps.missing(T.CLOCK) == 0
    assert gaps.largest(T.STATE) == (60 * ms, 160 * ms) and gaps.largest(T.WIND) is None
    assert gaps.report() == {T.STATE: (6, (60 * ms, 160 * ms))}
    assert SampleGaps.summary(gaps.report(), T.graph_name) == \
        "samples missing: /kite/state 6 (largest gap 0.06 .. 0.16 s)"
    assert SampleGaps.summary(SampleGaps().report()) == "no sample missing"
    lt = SimLogTime({T.STATE: "sensor_msgs/msg/JointState"})            # the recorder's log-time rule feeds it
    for t in (0, 20, 20, 80):                                           # a re-publication is not a step
        msg = _example(JointState)
        msg.header.stamp = ns_to_stamp(t * ms)
        lt.log_time(T.STATE, _cdr(msg), 0)
    assert lt.gaps.missing(T.STATE) == 2 and lt.duplicates == {T.STATE: 1}


def _example(cls):
    """A message of ``cls`` with non-default values in its nested fields."""
    msg = cls()
    if cls is JointState:
        msg.header.stamp = ns_to_stamp(12_340_000_000)
        msg.header.frame_id = "anchor"
        msg.name, msg.position, msg.velocity = ["theta", "phi", "psi"], [0.5, -0.25, 3.0], [1e-3, 2.0, -4.5]
    elif cls is DiagnosticArray:
        msg.status = [DiagnosticStatus(level=DiagnosticStatus.WARN, name="kite_rto/optimizer", message="experiment",
                                       values=[KeyValue(key="iteration", value="3")])]
    elif hasattr(msg, "header"):
        msg.header.stamp = ns_to_stamp(7_020_000_000)
        msg.header.frame_id = "anchor"
    return msg


@pytest.mark.parametrize("from_files", [True, False], ids=["msg-files", "from-classes"])
def test_schemas_and_cdr_decode_back(tmp_path, from_files):
    """Every project type, with definitions from the installed .msg files and rebuilt from the classes alone."""
    path = tmp_path / "types.mcap"
    rec = McapRecording(path, use_files=from_files)
    sent = {}
    for i, (topic, (cls, qos)) in enumerate(sorted(TOPICS.items())):
        rec.add_topic(topic, cls, qos)
        sent[topic] = _example(cls)
        rec.write(topic, serialize_message(sent[topic]), log_time=1_000 + i)
    rec.close()
    got = {m.channel.topic: m for m in read_ros2_messages(str(path))}
    assert set(got) == {T.graph_name(t) for t in TOPICS}                # channels: the graph's names, /kite/state
    got = {T.relative(topic): m for topic, m in got.items()}
    for topic, m in got.items():
        cls = TOPICS[topic][0]
        assert m.schema.name == type_name(cls) and m.schema.encoding == "ros2msg"
        assert m.channel.message_encoding == "cdr"
        assert "offered_qos_profiles" in m.channel.metadata
        d = m.ros_msg
        if cls is JointState:
            assert list(d.name) == ["theta", "phi", "psi"] and list(d.position) == [0.5, -0.25, 3.0]
            assert (d.header.stamp.sec, d.header.stamp.nanosec, d.header.frame_id) == (12, 340_000_000, "anchor")
        elif cls is DiagnosticArray:
            st = d.status[0]
            assert (st.level, st.name, st.values[0].key, st.values[0].value) == (1, "kite_rto/optimizer",
                                                                                 "iteration", "3")
        elif hasattr(sent[topic], "header"):
            assert d.header.stamp.sec == 7 and d.header.frame_id == "anchor"
    text = (message_definition if from_files else generated_definition)(DiagnosticArray)
    assert "\nMSG: diagnostic_msgs/DiagnosticStatus\n" in text and "\nMSG: builtin_interfaces/Time\n" in text
    assert text.count("MSG: std_msgs/Header") == 1


def test_definition_from_files_is_rosbag2_text():
    """With the .msg files installed, the schema is the file text followed by the dependencies, as rosbag2 writes."""
    text = message_definition(JointState)
    assert text.startswith("# This is a message that holds data to describe the state of a set of torque")
    parts = text.split("\n" + "=" * 80 + "\n")
    assert [p.splitlines()[0] for p in parts[1:]] == ["MSG: std_msgs/Header", "MSG: builtin_interfaces/Time"]


@pytest.mark.ros
def test_record_command_on_a_live_graph_and_report(ros_env, tmp_path):
    out = tmp_path / "run.mcap"
    probe = Probe("record_probe")
    rec = subprocess.Popen([PY, "-m", "kite_rto.tools.record", "--out", str(out)], env=ros_env,
                           stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True, start_new_session=True, preexec_fn=DIE_WITH_PARENT)
    ctrl = plant = None
    run = RunDescription(KiteRTOSettings()).to_json()          # as an optimizer publishes it (latched)
    probe.node.create_publisher(String, T.RUN, LATCHED).publish(String(data=run))
    try:
        assert probe.spin_until(lambda: probe.node.count_subscribers(T.STATE) >= 1, 60.0), "recorder not up"
        ctrl = start_node("controller", {}, ros_env)
        assert probe.spin_until(lambda: probe.node.count_publishers(T.STEERING) > 0, 60.0)
        plant = start_node("plant", {"duration": 42.0, "wait_subscribers": 2}, ros_env)   # lap 0 ends near 39 s
        assert probe.spin_until(lambda: plant.poll() is not None, 120.0), "plant did not finish"
        assert plant.returncode == 0
        probe.spin_until(lambda: False, 1.0)
    finally:
        err = _stop_all(rec, probe, plant, ctrl)
    assert rec.returncode == 0, err
    assert "Traceback" not in err and f"to {out}" in err

    counts, stamps, log_times, types, texts = {}, {}, [], {}, {}
    for m in read_ros2_messages(str(out)):
        topic = T.relative(m.channel.topic)
        if topic in (T.PLANT_CONFIG, T.RUN):
            texts[topic] = m.ros_msg.data
        counts[topic] = counts.get(topic, 0) + 1
        types[topic] = m.schema.name
        log_times.append(m.log_time_ns)
        if hasattr(m.ros_msg, "header"):
            stamps.setdefault(topic, []).append(m.ros_msg.header.stamp.sec * 10**9 + m.ros_msg.header.stamp.nanosec)
            if topic in PER_SAMPLE:
                assert m.log_time_ns == stamps[topic][-1], topic           # log time = simulated time
    assert min(log_times) == 0 and max(log_times) >= 42 * 10**9 - 20_000_000            # the simulated span
    expected = {T.CLOCK, T.STATE, T.POSITION, T.TENSION, T.WIND, T.STEERING, T.LAPS, T.REFERENCE_PATH, T.CRASHES,
                T.PLANT_CONFIG, T.RUN}
    assert expected <= set(counts), counts
    assert {t: types[t] for t in (T.STATE, T.LAPS, T.CRASHES, T.REFERENCE_PATH)} == {
        T.STATE: "sensor_msgs/msg/JointState", T.LAPS: "sensor_msgs/msg/JointState",
        T.CRASHES: "std_msgs/msg/UInt32", T.REFERENCE_PATH: "nav_msgs/msg/Path"}
    # Every sample 0 .. 42 s, in order, each once. Two losses are possible and depend on the machine's speed, so no
    # verdict is drawn from their size: the plant exits right after publishing its last sample, which may then not
    # reach the recorder; and a recorder starved of CPU for longer than the publishers' history (1000 samples,
    # 20 s of lockstep flight; seen: a 5.4 s block lost at load average ~5) misses a block. The recorder must
    # then say so: its count of missing samples is checked against the file.
    n_expected = round(42.0 / 0.02) + 1
    with open(out, "rb") as f:
        gap_meta = {m.name: m.metadata for m in make_reader(f).iter_metadata()}["kite_record_gaps"]
    for topic in (T.STATE, T.POSITION, T.TENSION, T.WIND):
        s = np.array(stamps[topic])
        assert np.all(np.diff(s) > 0), f"{topic} stamps repeat or go back"  # each sample recorded once
        u = np.unique(s)
        assert u[0] == 0 and u[-1] >= 42 * 10**9 - 20_000_000, topic
        assert np.all(u % 20_000_000 == 0)
        inside = round((u[-1] - u[0]) / 20_000_000) + 1 - len(u)       # missing between the first and the last
        print(f"{topic}: {len(u)} of {n_expected} samples recorded")
        reported = gap_meta.get(T.graph_name(topic), "0 missing").split(" missing")[0]
        assert int(reported) == inside, (topic, gap_meta)
        assert (f"{T.graph_name(topic)} {inside} (largest gap" in err) == (inside > 0), err
    n_samples = len(np.unique(stamps[T.STATE]))
    assert np.all(np.diff(log_times) >= 0)
    assert counts[T.LAPS] >= 1
    with open(out, "rb") as f:
        reader = make_reader(f)
        summary = reader.get_summary()
        meta = {m.name: m.metadata for m in reader.iter_metadata()}
    assert summary.statistics.message_count == sum(counts.values())
    assert meta["kite_record"]["log_time"] == "sim"
    assert meta["kite_rto_run"] == {"description": run} and texts[T.RUN] == run            # the run it recorded
    assert plant_from_json(texts[T.PLANT_CONFIG]) == config_from_params({p.name: p.default for p in PLANT_PARAMS})
    assert meta["/plant"]["duration"] == "42.0" and meta["/plant"]["wait_subscribers"] == "2"   # the graph's parameters
    assert meta["/controller"]["k_psi"] and "re-published samples skipped" in err

    rep = subprocess.run([PY, "-m", "kite_rto.tools.rto_report", "--mcap", str(out), "--out", str(tmp_path / "rep"),
                          "--no-judge"], env=ros_env, capture_output=True, text=True, timeout=120)
    assert rep.returncode == 0, rep.stderr
    assert f"{n_samples} samples" in rep.stdout
    data = json.loads((tmp_path / "rep" / "summary.json").read_text())
    assert data["laps"] == counts[T.LAPS] and 1e5 < data["mean_tension_kN"] * 1e3 < 2e6
    assert (tmp_path / "rep" / "path.png").stat().st_size > 10_000


@pytest.mark.ros
def test_record_duration_ends_by_itself(ros_env, tmp_path):
    out = tmp_path / "idle.mcap"
    res = subprocess.run([PY, "-m", "kite_rto.tools.record", "--out", str(out), "--duration", "1.5",
                          "--topics", "/kite/laps", "rto/setpoints"], env=ros_env, capture_output=True, text=True, timeout=60)
    assert res.returncode == 0, res.stderr
    with open(out, "rb") as f:
        summary = make_reader(f).get_summary()
    assert sorted(ch.topic for ch in summary.channels.values()) == ["/kite/laps", "/rto/setpoints"]
    bad = subprocess.run([PY, "-m", "kite_rto.tools.record", "--out", str(out), "--topics", "/nope"], env=ros_env,
                         capture_output=True, text=True, timeout=60)
    assert bad.returncode == 2 and "/nope" in bad.stderr


def _status(iteration, experiment, done, t_start, extra=None):
    kv = {"iteration": str(iteration), "phase": "experiment", "experiments_done": str(done),
          "experiment": experiment, "purpose": experiment.split("-")[-1], "experiment_t_start": f"{t_start:.2f}",
          **(extra or {})}
    st = DiagnosticStatus(name="kite_rto/optimizer", values=[KeyValue(key=k, value=v) for k, v in kv.items()])
    return DiagnosticArray(status=[st])


def test_gma_report_from_a_recording(tmp_path):
    """A recording with two finished iterations (written here the way the nodes publish) gives the GMA table."""
    path = tmp_path / "gma.mcap"
    rec = McapRecording(path)
    for topic in (T.STATE, T.LAPS, T.SETPOINTS, T.STATUS):
        rec.add_topic(topic, *TOPICS[topic])
    c = [np.radians([30.0, 42.0, 6.5]), np.radians([30.0, 43.92, 6.5]), np.radians([31.0, 44.5, 6.7])]
    wall = [0]

    def put(topic, msg):
        wall[0] += 1_000_000
        rec.write(topic, serialize_message(msg), wall[0])

    def setpoints(cc):
        put(T.SETPOINTS, JointState(name=["theta_0", "A_phi", "A_theta"], position=list(cc)))

    t = 0.0
    setpoints(c[0])
    schedule = {}                      # sim time -> what the optimizer says then
    exps = [("k0-0-nominal", 0), ("k0-1-perturbation", 0), ("k1-0-nominal", 1), ("k1-1-perturbation", 1),
            ("k2-0-nominal", 2)]
    for i, (exp, k) in enumerate(exps):
        schedule[20.0 * i] = (exp, k, i)                # i experiments finished when this one starts
    for step in range(0, 5001):
        t = step * 0.02
        st = JointState(name=["theta", "phi", "psi"], position=[0.55 + 0.05 * math.sin(t), 0.7 * math.sin(t), 0.0],
                        velocity=[0.0, 0.0, 0.0])
        st.header.stamp = ns_to_stamp(step * 20_000_000)
        put(T.STATE, st)
        if step % 500 == 250:
            lap = JointState(name=list(LAP_FIELDS), position=[step / 500, 10.0, 5.5e5 + step, 130.0, 0.2, 8.6e3,
                                                              *c[0]])
            lap.header.stamp = st.header.stamp
            put(T.LAPS, lap)
        if round(t, 2) in schedule:
            exp, k, done = schedule[round(t, 2)]
            extra = {}
            if k >= 1:
                extra = {"measured_cost_kN": f"{-560.0 - k:.2f}", "measured_constraint_m": "-30.00",
                         "c_next_deg": "(" + ", ".join(f"{v:.2f}" for v in np.degrees(c[k])) + ") deg",
                         "decision": "step"}
            if exp.endswith("nominal"):
                setpoints(c[k])
            put(T.STATUS, _status(k, exp, done, t, extra))
    rec.close()
    res = subprocess.run([PY, "-m", "kite_rto.tools.rto_report", "--mcap", str(path), "--out", str(tmp_path / "r"),
                          "--no-judge"], capture_output=True, text=True, timeout=120)
    assert res.returncode == 0, res.stderr
    summary = json.loads((tmp_path / "r" / "summary.json").read_text())
    assert summary["iterations"] == 2 and summary["judged"] is False
    assert summary["experiments"] == 4                  # k2-0-nominal was still running
    got = np.array([r["c_deg"] for r in summary["rows"]])
    np.testing.assert_allclose(got, np.degrees(c), atol=0.006)       # status carries 0.01 deg
    assert [r["measured_tension_kN"] for r in summary["rows"]] == [561.0, 562.0, None]
    assert (tmp_path / "r" / "report.png").stat().st_size > 20_000
    assert "not judged on the deterministic plant" in res.stdout


def _stop_all(rec, probe, *nodes) -> str:
    """Stop the nodes and the probe, then the recorder (SIGINT); the recorder's stderr."""
    for p in nodes:
        if p is not None:
            stop(p)
    probe.close()
    if rec.poll() is None:
        rec.send_signal(signal.SIGINT)
    return rec.communicate(timeout=60)[1]


def _lossless_recorder(ros_env, out):
    return subprocess.Popen([PY, "-m", "kite_rto.tools.record", "--out", str(out), "--lossless", "--topics",
                             "/clock", "/kite/state", "/kite/position", "/kite/tension", "/kite/wind", "/kite/steering"],
                            env=ros_env, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True,
                            start_new_session=True, preexec_fn=DIE_WITH_PARENT)


@pytest.mark.ros
def test_a_lossless_recorder_stopped_for_2_s_in_lockstep_misses_no_sample(ros_env, tmp_path):
    """The lockstep plant waits for a ``--lossless`` recorder: stopped (SIGSTOP) for 2 s of wall time it misses no
    sample and records none twice, however fast the machine (the plant's wait is bounded by recorder_timeout only,
    set far beyond anything this test needs)."""
    out = tmp_path / "lossless.mcap"
    probe = Probe("lossless_probe")
    acks = []
    probe.node.create_subscription(Header, T.RECORDED, lambda m: acks.append(m), 10)
    rec = _lossless_recorder(ros_env, out)
    ctrl = plant = None
    stopped = False
    try:
        assert probe.spin_until(lambda: probe.node.count_subscribers(T.STATE) >= 1, 60.0), "recorder not up"
        ctrl = start_node("controller", {}, ros_env)
        assert probe.spin_until(lambda: probe.node.count_publishers(T.STEERING) > 0, 60.0)
        plant = start_node("plant", {"duration": 30.0, "wait_subscribers": 2, "recorder_timeout": 3600.0}, ros_env)
        assert probe.spin_until(lambda: any(a.stamp.sec >= 2 for a in acks), 120.0), "no acknowledgement"
        rec.send_signal(signal.SIGSTOP)
        stopped = True
        probe.spin_until(lambda: False, 2.0)
        rec.send_signal(signal.SIGCONT)
        stopped = False
        assert probe.spin_until(lambda: plant.poll() is not None, 300.0), "plant did not finish"
        assert plant.returncode == 0
    finally:
        if stopped:
            rec.send_signal(signal.SIGCONT)
        err = _stop_all(rec, probe, plant, ctrl)
    assert rec.returncode == 0, err
    assert "no sample missing" in err, err
    assert acks and all(a.frame_id == "/kite_record" for a in acks)                 # who acknowledged
    stamps = {}
    for m in read_ros2_messages(str(out)):
        topic = T.relative(m.channel.topic)
        stamps.setdefault(topic, []).append(m.ros_msg.header.stamp.sec * 10**9 + m.ros_msg.header.stamp.nanosec
                                            if topic != T.CLOCK else m.ros_msg.clock.sec * 10**9 + m.ros_msg.clock.nanosec)
    expected = list(range(0, 30 * 10**9 + 1, 20_000_000))             # every sample of the flight, once, in order
    for topic in (T.CLOCK, T.STATE, T.POSITION, T.TENSION, T.WIND):
        assert stamps[topic] == expected, (topic, len(stamps[topic]), len(expected))
    with open(out, "rb") as f:
        meta = {m.name: m.metadata for m in make_reader(f).iter_metadata()}
    assert meta["kite_record"]["lossless"].startswith("yes") and meta["kite_record_gaps"] == {"all": "no sample missing"}


@pytest.mark.ros
def test_a_stopped_lossless_recorder_never_holds_a_real_time_kite(ros_env, tmp_path):
    """In real time the plant never waits for a recorder: its clock goes on while the recorder is stopped."""
    probe = Probe("realtime_probe")
    clocks = []
    probe.node.create_subscription(Clock, T.CLOCK, lambda m: clocks.append(m.clock.sec + m.clock.nanosec * 1e-9), 10)
    rec = _lossless_recorder(ros_env, tmp_path / "rt.mcap")
    plant = None
    try:
        assert probe.spin_until(lambda: probe.node.count_subscribers(T.STATE) >= 1, 60.0), "recorder not up"
        plant = start_node("plant", {"mode": "realtime", "rate_factor": 5.0}, ros_env)
        assert probe.spin_until(lambda: clocks and clocks[-1] > 1.0, 60.0)
        rec.send_signal(signal.SIGSTOP)
        before = clocks[-1]
        # the kite flies on: a simulated second passes while the recorder stays stopped (waited for, not timed, so
        # that a busy machine cannot fail it; a plant held by the recorder never gets there)
        flew = probe.spin_until(lambda: clocks[-1] > before + 1.0, 60.0)
        during = clocks[-1]
        rec.send_signal(signal.SIGCONT)
        assert flew, (before, during)
    finally:
        rec.send_signal(signal.SIGCONT)
        if plant is not None:
            stop(plant)
        probe.close()
        rec.send_signal(signal.SIGINT)
        rec.communicate(timeout=60)
