"""Operator tools: the monitor's lines (pure formatting, then the command against a lockstep graph), the echo
command's ros2-topic-echo layout, and the console scripts."""
import math
import os
import signal
import subprocess
import sys
import threading
from pathlib import Path

import pytest
from diagnostic_msgs.msg import DiagnosticArray, DiagnosticStatus, KeyValue
from sensor_msgs.msg import JointState

from kite_rto.nodes.interface import LATCHED, RELIABLE_10, ns_to_stamp
from kite_rto.nodes.controller_node import LAP_FIELDS
from kite_rto.tools.echo import to_yaml
from kite_rto.tools.monitor import Monitor, format_lap, format_status

from rosutil import DIE_WITH_PARENT, Probe, start_node, stop

PY = sys.executable
C0 = [math.radians(v) for v in (35.0, 45.0, 7.0)]              # the controller's default setpoints


def lap_values(index=3, tension=551_900.0):
    return [float(index), 18.5, tension, 131.4, 0.312, 8.6e3, *C0]


def status_kv(iteration=0, phase="experiment", experiment="k0-0-nominal", **extra):
    kv = {"iteration": str(iteration), "phase": phase, "experiments_done": "0", "experiment": experiment,
          "purpose": experiment.split("-")[-1], "setpoints_deg": "(35.00, 45.00, 7.00) deg"}
    kv.update(extra)
    return kv


def test_lap_line_shows_what_the_operator_needs():
    line = format_lap(dict(zip(LAP_FIELDS, lap_values())), 62.14, C0, status_kv(2, experiment="k2-1-perturbation"))
    assert line.startswith("lap     3  t 62.1 s  c (35.00, 45.00, 7.00) deg")
    for part in ("tension 551.9 kN", "min alt 131 m", "xtrack 0.31 deg", "[it 2 experiment perturbation]"):
        assert part in line, line
    # without setpoints (no optimizer, no /rto/setpoints yet): the lap's flown projection instead
    assert "flown (35.00, 45.00, 7.00) deg" in format_lap(dict(zip(LAP_FIELDS, lap_values())), 1.0)


def test_monitor_prints_changes_only():
    mon = Monitor()
    assert mon.setpoint(["theta_0", "A_phi", "A_theta"], C0) == ["setpoints  (35.00, 45.00, 7.00) deg"]
    assert mon.setpoint(["theta_0", "A_phi", "A_theta"], C0) == []                 # same setpoints again
    first = mon.status_message(status_kv())
    assert first == [format_status(status_kv())]
    assert "experiment k0-0-nominal (nominal) at (35.00, 45.00, 7.00) deg" in first[0]
    assert mon.status_message(status_kv()) == []                                  # 1 Hz repeat: nothing new
    assert len(mon.status_message(status_kv(experiment="k0-1-perturbation"))) == 1
    done = mon.status_message(status_kv(1, experiment="k1-0-nominal", measured_cost_kN="-566.60",
                                        measured_constraint_m="-31.40", c_next_deg="(35.00, 46.92, 7.00) deg",
                                        decision="step"))
    assert done[0] == ("rto        iteration 0 done: measured 566.6 kN, g -31.40 m, c_1 = (35.00, 46.92, 7.00) deg "
                       "(step)")
    assert done[1].startswith("rto        iteration 1  phase experiment  experiment k1-0-nominal")
    assert mon.status_message(status_kv(1, experiment="k1-0-nominal", c_next_deg="(1, 2, 3) deg")) == []
    lap = mon.lap(list(LAP_FIELDS), lap_values(), 40.0)
    assert len(lap) == 1 and "[it 1 experiment nominal]" in lap[0]
    assert mon.crash(0) == [] and mon.crash(2) == ["CRASH   #2  t 40.0 s"] and mon.crash(2) == []


def test_echo_layout_is_ros2_topic_echo_yaml():
    msg = JointState(name=["theta", "phi"], position=[0.5, -1e-3], velocity=[])
    msg.header.stamp = ns_to_stamp(3_020_000_000)
    msg.header.frame_id = "anchor"
    assert to_yaml(msg) == ("header:\n  stamp:\n    sec: 3\n    nanosec: 20000000\n  frame_id: anchor\n"
                            "name:\n- theta\n- phi\nposition:\n- 0.5\n- -0.001\nvelocity: []\neffort: []\n")
    st = DiagnosticStatus(level=DiagnosticStatus.ERROR, name="kite_rto/optimizer", message="",
                          values=[KeyValue(key="iteration", value="3"), KeyValue(key="decision", value="hold: x")])
    text = to_yaml(DiagnosticArray(status=[st]))
    assert ("status:\n- level: 2\n  name: kite_rto/optimizer\n  message: ''\n  hardware_id: ''\n  values:\n"
            "  - key: iteration\n    value: '3'\n  - key: decision\n    value: 'hold: x'\n") in text


class Lines:
    """Collect a subprocess's stdout lines in a thread."""

    def __init__(self, proc):
        self.lines = []
        self.thread = threading.Thread(target=self._read, args=(proc,), daemon=True)
        self.thread.start()

    def _read(self, proc):
        for line in proc.stdout:
            self.lines.append(line.rstrip("\n"))


def finish(proc, timeout=15.0) -> str:
    """Ctrl-C ``proc`` if it still runs, wait (kill if it hangs); return its stderr."""
    if proc.poll() is None:
        proc.send_signal(signal.SIGINT)
    try:
        proc.wait(timeout)
    except subprocess.TimeoutExpired:
        os.killpg(proc.pid, signal.SIGKILL)
        proc.wait()
    return proc.stderr.read()


@pytest.mark.ros
def test_monitor_command_on_a_lockstep_graph(ros_env):
    """The monitor against plant + controller, with the test in the optimizer's place on /rto/*."""
    probe = Probe("monitor_probe")
    pub_sp = probe.node.create_publisher(JointState, "/rto/setpoints", LATCHED)
    pub_st = probe.node.create_publisher(DiagnosticArray, "/rto/status", RELIABLE_10)
    mon = subprocess.Popen([PY, "-m", "kite_rto.tools.monitor", "--count", "5", "--duration", "900"], env=ros_env,
                           stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True, start_new_session=True, preexec_fn=DIE_WITH_PARENT)
    out = Lines(mon)
    ctrl = plant = None
    try:
        assert probe.spin_until(lambda: probe.node.count_subscribers("/kite/laps") >= 1
                                and pub_st.get_subscription_count() >= 1, 60.0), "monitor not up"
        pub_sp.publish(JointState(name=["theta_0", "A_phi", "A_theta"], position=C0))
        st = DiagnosticStatus(name="kite_rto/optimizer",
                              values=[KeyValue(key=k, value=v) for k, v in status_kv().items()])
        pub_st.publish(DiagnosticArray(status=[st]))
        ctrl = start_node("controller", {}, ros_env)
        assert probe.spin_until(lambda: probe.node.count_publishers("/kite/steering") > 0, 60.0)
        plant = start_node("plant", {"duration": 80.0}, ros_env)           # laps end near 39, 58 and 74 s
        # --duration is wall time: generous, so that a busy machine's slow lockstep loop still ends its laps first
        assert probe.spin_until(lambda: mon.poll() is not None, 900.0), f"monitor still running: {out.lines}"
    finally:
        for p in (plant, ctrl):
            if p is not None:
                stop(p)
        probe.close()
        err = finish(mon)
        out.thread.join(timeout=5)
    assert mon.returncode == 0, err
    lines = out.lines
    assert len(lines) == 5, lines                                           # --count 5, then it exits
    assert sum(ln.endswith("setpoints  (35.00, 45.00, 7.00) deg") for ln in lines[:2]) == 1, lines
    assert sum("rto        iteration 0  phase experiment  experiment k0-0-nominal (nominal)" in ln
               for ln in lines[:2]) == 1, lines
    laps = [ln for ln in lines if " lap " in ln]
    assert len(laps) == 3, lines
    for ln in laps:
        assert "c (35.00, 45.00, 7.00) deg" in ln and " kN" in ln and "min alt" in ln and "xtrack" in ln
        assert "[it 0 experiment nominal]" in ln
    assert "Traceback" not in err


@pytest.mark.ros
def test_echo_command_prints_samples(ros_env):
    quiet = {"turbulence": False, "noise_angle_deg": 0.0, "noise_rate": 0.0, "command_timeout": 30.0}
    plant = start_node("plant", quiet, ros_env)           # no controller: lockstep re-publishes sample 0
    try:
        res = subprocess.run([PY, "-m", "kite_rto.tools.echo", "/kite/state", "--count", "2", "--timeout", "60"],
                             env=ros_env, capture_output=True, text=True, timeout=90)
        latched = subprocess.run([PY, "-m", "kite_rto.tools.echo", "/kite/crashes", "--once", "--timeout", "60"],
                                 env=ros_env, capture_output=True, text=True, timeout=90)
    finally:
        stop(plant)
    assert res.returncode == 0, res.stderr
    msgs = res.stdout.split("---\n")
    assert len(msgs) == 3 and msgs[2] == ""
    assert msgs[0].startswith("header:\n  stamp:\n    sec: 0\n    nanosec: 0\n  frame_id: anchor\n"
                              "name:\n- theta\n- phi\n- psi\nposition:\n- 0.5235987755982")   # launch theta 30 deg
    assert latched.returncode == 0 and latched.stdout == "data: 0\n---\n", latched.stderr
    nothing = subprocess.run([PY, "-m", "kite_rto.tools.echo", "/rto/status", "--once", "--timeout", "2"],
                             env=ros_env, capture_output=True, text=True, timeout=60)
    assert nothing.returncode == 1 and "0 of 1 messages" in nothing.stderr


def test_console_scripts(ros_env):
    """The pip install's entry points (``kite_echo`` etc., next to the venv's python), as a user types them."""
    bin_dir = Path(PY).parent
    res = subprocess.run([str(bin_dir / "kite_echo"), "--list"], env=ros_env, capture_output=True, text=True,
                         timeout=60)
    assert res.returncode == 0, res.stderr
    assert "/kite/laps               sensor_msgs/msg/JointState" in res.stdout
    assert "/rto/status              diagnostic_msgs/msg/DiagnosticArray" in res.stdout
    bad = subprocess.run([str(bin_dir / "kite_echo"), "/kite/nope"], env=ros_env, capture_output=True, text=True,
                         timeout=60)
    assert bad.returncode == 2 and "not a kite_rto topic" in bad.stderr
    for script, needle in (("kite_monitor", "--count"), ("kite_record", "--out"), ("kite_report", "--mcap"),
                           ("kite_demo", "--record")):
        h = subprocess.run([str(bin_dir / script), "--help"], env=ros_env, capture_output=True, text=True,
                           timeout=60)
        assert h.returncode == 0 and needle in h.stdout, (script, h.stderr)
