"""Parameters (issue 6): descriptors, start-up and runtime validation, runtime changes applied, -p and params files.

Over real DDS: each node is started as its own process and its ``/<node>/set_parameters`` service is called with
an out-of-range value, a read-only parameter and a valid runtime change. In process: the values reach the core
objects (timer period, controller settings, optimizer limits).
"""
import math
import subprocess
import time
from pathlib import Path

import pytest
import rclpy
import rclpy.executors
from rcl_interfaces.srv import DescribeParameters, GetParameters, SetParameters, SetParametersAtomically
from rclpy.parameter import Parameter, parameter_value_to_python
from rosgraph_msgs.msg import Clock
from sensor_msgs.msg import JointState

from kite_rto.flight.controller import ControllerSettings, PathController
from kite_rto.kite.params import KiteParams, ParameterError
from kite_rto.flight.path import DEFAULT_SETPOINTS, Setpoints
from kite_rto.kite.model import shared_model
from kite_rto.nodes.interface import RELIABLE_10, ns_to_stamp
from kite_rto.nodes.parameters import READ_ONLY, ParamSpec
from kite_rto.tools.graph import node_command

from rosutil import DIE_WITH_PARENT, Probe, start_node, stop

ROOT = Path(__file__).resolve().parents[2]
CONFIG = ROOT / "config" / "kite_rto.yaml"
pytestmark = pytest.mark.ros


@pytest.fixture
def probe():
    p = Probe("param_probe")
    yield p
    p.close()


# ------------------------------------------------------------------------------------------- service helpers
def _call(probe, srv_type, service, request, timeout=30.0):
    client = probe.node.create_client(srv_type, service)
    try:
        assert probe.spin_until(client.service_is_ready, 60.0), f"{service} not available"
        future = client.call_async(request)
        assert probe.spin_until(future.done, timeout), f"{service}: no answer"
        return future.result()
    finally:
        probe.node.destroy_client(client)


def set_params(probe, node, **values):
    """``/<node>/set_parameters``: one result per parameter."""
    req = SetParameters.Request(parameters=[Parameter(k, value=v).to_parameter_msg() for k, v in values.items()])
    return list(_call(probe, SetParameters, f"/{node}/set_parameters", req).results)


def set_atomically(probe, node, **values):
    req = SetParametersAtomically.Request(
        parameters=[Parameter(k, value=v).to_parameter_msg() for k, v in values.items()])
    return _call(probe, SetParametersAtomically, f"/{node}/set_parameters_atomically", req).result


def get_params(probe, node, *names):
    res = _call(probe, GetParameters, f"/{node}/get_parameters", GetParameters.Request(names=list(names)))
    return [parameter_value_to_python(v) for v in res.values]


def describe(probe, node, *names):
    req = DescribeParameters.Request(names=list(names))
    return list(_call(probe, DescribeParameters, f"/{node}/describe_parameters", req).descriptors)


def assert_rejected(result, *needles):
    assert not result.successful, "expected a refusal"
    for n in needles:
        assert n in result.reason, (n, result.reason)


def wait_exit(proc, timeout=60.0):
    try:
        proc.wait(timeout)
    except subprocess.TimeoutExpired:
        pass
    return stop(proc)


# ------------------------------------------------------------------------------------------------ ParamSpec
def test_param_spec_messages_name_parameter_value_and_expected():
    cases = [(ParamSpec("k", 3.0, "gain", 0.01, 100.0, unit="1/s"), -1.0, "parameter k = -1.0: expected a number in "
              "[0.01, 100] 1/s"),
             (ParamSpec("k", 3.0, "gain", 0.01, 100.0), "abc", "parameter k = 'abc': expected a number"),
             (ParamSpec("k", 3.0, "gain", 0.01, 100.0), True, "parameter k = True: expected a number"),
             (ParamSpec("k", 3.0, "gain", 0.01, 100.0), math.inf, "parameter k = inf: expected"),
             (ParamSpec("n", 4, "laps", 1, 100), 2.5, "parameter n = 2.5: expected an integer in [1, 100]"),
             (ParamSpec("b", True, "flag"), "yes", "parameter b = 'yes': expected true or false"),
             (ParamSpec("m", "a", "mode", choices=("a", "b")), "c", "parameter m = 'c': expected one of 'a', 'b'"),
             (ParamSpec("db", "x.sqlite", "file"), "", "parameter db = '': expected a non-empty string"),
             (ParamSpec("db", "x.sqlite", "file"), 5, "parameter db = 5: expected a non-empty string"),
             (ParamSpec("box", [1.0, 2.0], "pair", 0.0, 10.0, unit="deg"), [1.0], "parameter box = [1.0]: expected "
              "a list of 2 numbers, each in [0, 10] deg"),
             (ParamSpec("box", [1.0, 2.0], "pair", 0.0, 10.0), [1.0, 11.0], "parameter box = [1.0, 11.0]"),
             (ParamSpec("box", [1.0, 2.0], "pair", 0.0, 10.0), None, "parameter box = <empty or not set>")]
    for spec, value, message in cases:
        with pytest.raises(ParameterError) as err:
            spec.check(value)
        assert message in str(err.value)
    for spec, value in [(ParamSpec("k", 3.0, "gain", 0.01, 100.0), 100), (ParamSpec("n", 4, "laps", 1, 100), 1),
                        (ParamSpec("box", [1.0, 2.0], "pair", 0.0, 10.0), (0, 10.0))]:
        spec.check(value)                       # bounds included; an integer is a valid float value
    d = ParamSpec("k", 3.0, "gain", 0.01, 100.0, unit="1/s", runtime=True).descriptor()
    assert d.description == "gain [1/s]" and not d.read_only and d.floating_point_range[0].to_value == 100.0
    d = ParamSpec("dt", 0.02, "sample time", 0.001, 0.1, unit="s").descriptor()
    assert d.read_only and READ_ONLY in d.additional_constraints


def test_every_parameter_has_a_description_and_numbers_have_units_and_ranges():
    from kite_rto.tools.config_yaml import node_params
    for node, specs in node_params():
        assert len({s.name for s in specs}) == len(specs), node
        for s in specs:
            assert s.description, (node, s.name)
            if isinstance(s.default, list) and s.default and isinstance(s.default[0], str):
                assert set(s.default) <= set(s.choices), (node, s.name)
                s.check(s.default)
            elif isinstance(s.default, float) or isinstance(s.default, list):
                assert s.unit and s.low is not None and s.high is not None, (node, s.name)
                s.check(s.default)
            elif isinstance(s.default, int) and not isinstance(s.default, bool):
                assert s.low is not None and s.high is not None, (node, s.name)
                s.check(s.default)


def test_plant_defaults_are_the_plant_config_defaults():
    """Every plant parameter that sets a PlantConfig field defaults to that field of PlantConfig() (in deg for
    ``*_deg``), and the defaults build PlantConfig() back; the other parameters are the node's own."""
    from kite_rto.kite.plant import PlantConfig
    from kite_rto.nodes.plant_config import CONFIG_FIELDS, PARAMS, config_from_params
    config = PlantConfig()
    specs = {s.name: s for s in PARAMS}
    for name, path in CONFIG_FIELDS.items():
        field = config
        for part in path.split("."):
            field = field[int(part)] if part.isdigit() else getattr(field, part)
        default = math.radians(specs[name].default) if name.endswith("_deg") else specs[name].default
        assert type(default) is type(field), (name, path)
        assert default == (field if isinstance(field, str) else pytest.approx(field, rel=1e-12, abs=0)), (name, path)
    assert config_from_params({s.name: s.default for s in PARAMS}) == config
    assert set(specs) - set(CONFIG_FIELDS) == {"mode", "rate_factor", "seed", "duration", "command_timeout",
                                               "wait_subscribers", "resend_period", "recorder_timeout",
                                               "one_plant_check"}


def test_optimizer_defaults_build_the_kite_defaults_and_gma_parameters_reach_gma():
    """The optimizer's parameter defaults build KiteRTOSettings() back; ``mechanisms`` switches GMA's mechanisms on
    and off (off = None), each dotted ``<mechanism>.<field>`` parameter lands in its sub-object, and the effort
    schedule, back-off and filter gain in GMASettings."""
    from kite_rto.gma import MECHANISMS
    from kite_rto.nodes.optimizer_params import PARAMS, settings_from_params
    from kite_rto.rto.settings import KiteRTOSettings
    v = {s.name: s.default for s in PARAMS}
    assert settings_from_params(v) == KiteRTOSettings()
    kite = KiteRTOSettings().gma
    assert sorted(v["mechanisms"]) == sorted(m for m in MECHANISMS if getattr(kite, m) is not None)
    assert kite.settle is None and "settle" not in v["mechanisms"]             # in the library, off for the kite
    dotted = [s.name for s in PARAMS if "." in s.name]
    assert dotted and all(s.split(".")[0] in MECHANISMS for s in dotted)
    for name in dotted:
        mech, field = name.split(".")
        spec = next(s for s in PARAMS if s.name == name)
        value = spec.high if spec.default != spec.high else spec.low
        if mech == "trust_region" and field == "min_radius":
            value = 0.5
        got = getattr(getattr(settings_from_params({**v, name: value, "mechanisms": list(MECHANISMS)}).gma, mech),
                      field)
        assert got == value, name
    off = settings_from_params({**v, "mechanisms": ["trust_region", "safe_step"]}).gma
    assert off.undo is None and off.bound_hold is None and off.model_secant is None and off.noise_filter is None
    assert off.modifier_filter is None and off.trust_region == KiteRTOSettings().gma.trust_region
    s = settings_from_params({**v, "effort_schedule": [1.0, 1.5, 3.0], "backoff": 6.0, "filter_gain": 0.7}).gma
    assert s.effort_schedule == (1.0, 1.5, 3.0) and s.backoff == 6.0 and s.filter_gain == 0.7
    # a run is stored with the parameters of the mechanisms that are on: an older run resumes as it was stored
    from kite_rto.nodes.optimizer_params import run_settings
    stored = run_settings(v)
    assert "undo.sigma" in stored and not any(k.startswith("settle.") for k in stored)
    assert "settle.step" in run_settings({**v, "mechanisms": v["mechanisms"] + ["settle"]})


def test_optimizer_refuses_bad_gma_parameters_naming_them():
    from kite_rto.nodes.optimizer_params import PARAMS, settings_from_params
    specs = {s.name: s for s in PARAMS}
    with pytest.raises(ParameterError, match=r"parameter mechanisms = \['undo', 'bogus'\]: expected a list of "
                                             "distinct names, each one of 'modifier_filter'"):
        specs["mechanisms"].check(["undo", "bogus"])
    with pytest.raises(ParameterError, match=r"parameter effort_schedule = \[\]: expected a list of 1 or more"):
        specs["effort_schedule"].check([])
    v = {s.name: s.default for s in PARAMS}
    with pytest.raises(ParameterError, match="TrustRegion.min_radius=0.9: expected <= radius=0.7"):
        settings_from_params({**v, "trust_region.min_radius": 0.9})


def test_path_controller_retune():
    c = PathController(shared_model(), KiteParams(), DEFAULT_SETPOINTS, ControllerSettings())
    with pytest.raises(ValueError, match="dead_time cannot change in flight"):
        c.retune(dead_time=0.1)
    with pytest.raises(ParameterError, match="k_psi"):
        c.retune(k_psi=-1.0)
    assert c.settings.k_psi == 3.0
    target = Setpoints.from_degrees(33.0, 46.0, 7.0)
    c.set_setpoints(target)                                  # a 10 s blend starts
    assert c.path.setpoints != target
    c.retune(k_psi=4.0, blend_time=0.0)                      # 0 ends the blend at once
    assert c.settings.k_psi == 4.0 and c.path.setpoints == target


# -------------------------------------------------------------------------------------------------- in process
@pytest.fixture
def rcl():
    if not rclpy.ok():
        rclpy.init()
    nodes = []
    yield nodes
    for n in nodes:
        n.destroy_node()


def test_plant_applies_runtime_parameters_to_its_timer_and_end(rcl):
    from kite_rto.nodes.plant_node import PlantNode
    node = PlantNode(parameter_overrides=[Parameter("mode", value="realtime"), Parameter("rate_factor", value=2),
                                          Parameter("turbulence", value=False)])
    rcl.append(node)
    assert node.p["rate_factor"] == 2.0 and node._timer.timer_period_ns == 10_000_000
    r = node.set_parameters([Parameter("rate_factor", value=4.0)])[0]
    assert r.successful and node._timer.timer_period_ns == 5_000_000 and node.p["rate_factor"] == 4.0
    assert node.get_parameter("rate_factor").value == 4.0
    r = node.set_parameters([Parameter("rate_factor", value=500.0)])[0]
    assert_rejected(r, "parameter rate_factor = 500.0", "[0.01, 100]")
    assert node._timer.timer_period_ns == 5_000_000 and node.p["rate_factor"] == 4.0
    assert node.set_parameters([Parameter("duration", value=1.0)])[0].successful and node._end_step == 50
    assert node.set_parameters([Parameter("command_timeout", value=0.5)])[0].successful
    assert node.p["command_timeout"] == 0.5
    r = node.set_parameters([Parameter("dt", value=0.01)])[0]
    assert_rejected(r, "parameter dt = 0.01", READ_ONLY)
    assert node.p["dt"] == 0.02 and node.get_parameter("dt").value == 0.02
    # atomically: one read-only parameter refuses the whole request, nothing changes
    r = node.set_parameters_atomically([Parameter("command_timeout", value=2.0), Parameter("seed", value=3)])
    assert_rejected(r, "parameter seed = 3", READ_ONLY)
    assert node.p["command_timeout"] == 0.5 and node.get_parameter("command_timeout").value == 0.5


def test_controller_retunes_the_flying_controller(rcl):
    from kite_rto.nodes.controller_node import ControllerNode
    node = ControllerNode()
    rcl.append(node)
    r = node.set_parameters_atomically([Parameter("k_psi", value=4.0), Parameter("look_ahead", value=0.08),
                                        Parameter("k_i", value=0), Parameter("blend_time", value=0.0)])
    assert r.successful, r.reason
    for st in (node.controller.settings, node.settings):
        assert (st.k_psi, st.look_ahead, st.k_i, st.blend_time) == (4.0, 0.08, 0.0, 0.0)
    assert isinstance(node.get_parameter("k_i").value, int) and node.controller.settings.k_i == 0.0
    r = node.set_parameters([Parameter("k_psi", value=0.0)])[0]
    assert_rejected(r, "parameter k_psi = 0.0", "[0.01, 100] 1/s")
    r = node.set_parameters([Parameter("box_A_phi_deg", value=[40.0, 45.0])])[0]
    assert_rejected(r, "parameter box_A_phi_deg = [40.0, 45.0]", READ_ONLY)
    assert node.controller.settings.k_psi == 4.0 and node.settings.box.A_phi[0] == math.radians(42.0)
    # the optimizer synchronization cannot be switched at runtime
    assert_rejected(node.set_parameters([Parameter("sync_optimizer", value=True)])[0],
                    "parameter sync_optimizer = True", READ_ONLY)
    assert not node.loop.sync


def test_optimizer_runtime_limits_and_cross_checks(rcl, tmp_path):
    from kite_rto.nodes.optimizer_node import OptimizerNode
    node = OptimizerNode(parameter_overrides=[Parameter("db", value=str(tmp_path / "rto.sqlite")),
                                              Parameter("n_iter", value=3)])
    rcl.append(node)
    assert node.p["n_iter"] == 3
    assert node.set_parameters([Parameter("n_iter", value=0)])[0].successful and node.p["n_iter"] == 0
    r = node.set_parameters([Parameter("exit_when_done", value=True)])[0]          # n_iter = 0 never ends
    assert_rejected(r, "exit_when_done = True, n_iter = 0", "expected n_iter > 0")
    r = node.set_parameters_atomically([Parameter("n_iter", value=2), Parameter("exit_when_done", value=True)])
    assert r.successful and node.p["n_iter"] == 2 and node.p["exit_when_done"] is True
    assert_rejected(node.set_parameters([Parameter("n_iter", value=-1)])[0], "parameter n_iter = -1", "[0, 10000]")
    assert_rejected(node.set_parameters([Parameter("filter_gain", value=0.5)])[0], "filter_gain", READ_ONLY)
    assert node.wait_until_started(600.0)                  # the NLPs are built off the executor thread
    assert node.run.n_iter == 2                            # taken from the parameters changed during start-up
    node.run.done, node.run.phase = True, "done"                                        # the run has ended
    assert_rejected(node.set_parameters([Parameter("n_iter", value=5)])[0], "parameter n_iter = 5",
                    "restart the node")
    # exit_when_done set after the run ended: the node exits (SystemExit out of a plain executor's spin)
    assert node.set_parameters([Parameter("exit_when_done", value=False)])[0].successful
    executor = rclpy.executors.SingleThreadedExecutor()
    executor.add_node(node)
    try:
        for _ in range(20):
            executor.spin_once(timeout_sec=0.1)                 # no exit while exit_when_done is false
        assert node.set_parameters([Parameter("exit_when_done", value=True)])[0].successful
        with pytest.raises(SystemExit) as ended:
            end = time.monotonic() + 10.0
            while time.monotonic() < end:
                executor.spin_once(timeout_sec=0.1)
        assert ended.value.code == 0
    finally:
        executor.remove_node(node)


# ------------------------------------------------------------------------------------------------ over DDS
def test_plant_parameters_over_dds(probe, ros_env):
    """-p at start-up; set_parameters refuses out-of-range and read-only values; rate_factor and duration act."""
    proc = start_node("plant", {"mode": "realtime", "rate_factor": 10.0, "turbulence": False}, ros_env)
    clocks = []
    probe.node.create_subscription(Clock, "/clock", clocks.append, 10)

    def sim_time():
        probe.spin_until(lambda: False, 0.05)
        return clocks[-1].clock.sec + clocks[-1].clock.nanosec * 1e-9

    def pace(wall):
        t0, w0 = sim_time(), time.monotonic()
        probe.spin_until(lambda: False, wall)
        return (sim_time() - t0) / (time.monotonic() - w0)

    try:
        assert probe.spin_until(lambda: clocks, 60.0)
        assert get_params(probe, "plant", "rate_factor", "mode", "dt") == [10.0, "realtime", 0.02]
        d = describe(probe, "plant", "rate_factor", "dt")
        assert not d[0].read_only and d[1].read_only and d[1].description == "sample time [s]"
        assert_rejected(set_params(probe, "plant", rate_factor=500.0)[0], "parameter rate_factor = 500.0",
                        "expected a number in [0.01, 100]")
        assert_rejected(set_params(probe, "plant", rate_factor="fast")[0], "parameter rate_factor = 'fast'",
                        "expected a number")
        assert_rejected(set_params(probe, "plant", dt=0.01)[0], "parameter dt = 0.01", READ_ONLY)
        assert get_params(probe, "plant", "rate_factor", "dt") == [10.0, 0.02]
        # rate_factor bounds the pace from above; a busy machine only slows it (no verdict on how fast it runs)
        fast = pace(1.0)
        assert fast < 12.5, fast
        assert set_params(probe, "plant", rate_factor=1.0)[0].successful
        probe.spin_until(lambda: False, 0.3)
        slow = pace(2.0)
        assert slow < 1.6, (fast, slow)                       # ~10x before where the machine could keep up
        print(f"plant pace: {fast:.2f}x at rate_factor 10, {slow:.2f}x at 1")
        assert get_params(probe, "plant", "rate_factor") == [1.0]
        # duration set to a time already passed: the run ends at the next step, exit code 0
        assert set_params(probe, "plant", duration=1.0)[0].successful
        out = wait_exit(proc, 30.0)
        assert proc.returncode == 0, out
    finally:
        out = stop(proc)
    assert "parameters changed: rate_factor = 1.0" in out and "duration reached" in out


def test_controller_parameters_over_dds_and_params_files(probe, ros_env, tmp_path):
    """--params-file (the shipped config, then an override file) at start-up; runtime gains over the service."""
    override = tmp_path / "tuning.yaml"
    override.write_text("/controller:\n  ros__parameters:\n    k_psi: 2.5\n    blend_time: 5.0\n")
    cmd = node_command("controller") + ["--params-file", str(CONFIG), "--params-file", str(override)]
    proc = subprocess.Popen(cmd, env=ros_env, stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True,
                            start_new_session=True, preexec_fn=DIE_WITH_PARENT)
    try:
        assert get_params(probe, "controller", "k_psi", "blend_time", "dt", "box_A_phi_deg") == \
            [2.5, 5.0, 0.02, [42.0, 62.0]]
        assert_rejected(set_params(probe, "controller", k_psi=500.0)[0], "parameter k_psi = 500.0",
                        "[0.01, 100] 1/s")
        assert_rejected(set_params(probe, "controller", delta_max=0.5)[0], "parameter delta_max = 0.5", READ_ONLY)
        r = set_atomically(probe, "controller", k_psi=4.0, look_ahead=0.08)
        assert r.successful, r.reason
        assert get_params(probe, "controller", "k_psi", "look_ahead", "delta_max") == [4.0, 0.08, 1.0]
        r = set_atomically(probe, "controller", k_i=1.0, dt=0.01)        # all or nothing
        assert_rejected(r, "parameter dt = 0.01", READ_ONLY)
        assert get_params(probe, "controller", "k_i") == [0.5]
    finally:
        out = stop(proc)
    assert "parameters changed: k_psi = 4.0, look_ahead = 0.08" in out
    assert "k_i = 1.0" not in out


def test_optimizer_parameters_over_dds(probe, ros_env, tmp_path):
    proc = start_node("optimizer", {"db": str(tmp_path / "rto.sqlite"), "n_iter": 3}, ros_env)
    try:
        assert get_params(probe, "optimizer", "n_iter", "exit_when_done") == [3, False]
        assert_rejected(set_params(probe, "optimizer", n_iter=20000)[0], "parameter n_iter = 20000", "[0, 10000]")
        assert_rejected(set_params(probe, "optimizer", h_min=50.0)[0], "parameter h_min = 50.0", READ_ONLY)
        assert set_params(probe, "optimizer", n_iter=0)[0].successful
        assert_rejected(set_params(probe, "optimizer", exit_when_done=True)[0], "expected n_iter > 0")
        assert set_atomically(probe, "optimizer", n_iter=1, exit_when_done=True).successful
        assert get_params(probe, "optimizer", "n_iter", "exit_when_done", "h_min") == [1, True, 100.0]
    finally:
        out = stop(proc)
    assert "parameters changed: n_iter = 1, exit_when_done = True" in out


def test_echo_pilot_answers_with_the_new_delta(probe, ros_env):
    """A runtime change is used: the echo pilot's answers carry the delta set over the service."""
    proc = start_node("echo_pilot", {"delta": 0.1}, ros_env)
    answers = []
    state = probe.node.create_publisher(JointState, "/kite/state", RELIABLE_10)
    probe.node.create_subscription(JointState, "/kite/steering", answers.append, RELIABLE_10)

    def answer(k):
        msg = JointState(name=["theta", "phi", "psi"], position=[0.5, 0.0, 0.0], velocity=[0.0] * 3)
        msg.header.stamp = ns_to_stamp(k * 20_000_000)
        end = time.monotonic() + 30.0
        while time.monotonic() < end:
            state.publish(msg)
            if probe.spin_until(lambda: any(a.header.stamp == msg.header.stamp for a in answers), 0.5):
                return next(a.position[0] for a in answers if a.header.stamp == msg.header.stamp)
        raise AssertionError("no answer")

    try:
        assert answer(1) == 0.1
        assert_rejected(set_params(probe, "echo_pilot", delta=1.5)[0], "parameter delta = 1.5", "[-1, 1]")
        assert set_params(probe, "echo_pilot", delta=-0.3)[0].successful
        assert answer(2) == -0.3
    finally:
        stop(proc)


# ----------------------------------------------------------------------------------------- start-up, files
def test_params_file_with_a_bad_value_stops_the_node(ros_env, tmp_path):
    bad = tmp_path / "bad.yaml"
    bad.write_text(CONFIG.read_text().replace("    w_ref: 8.0", "    w_ref: -8.0"))
    assert "w_ref: -8.0" in bad.read_text()
    res = subprocess.run(node_command("plant") + ["--params-file", str(bad)], env=ros_env, capture_output=True,
                         text=True, timeout=60, cwd=tmp_path)
    assert res.returncode == 2, res.stdout + res.stderr
    assert "parameter w_ref = -8.0: expected a number in [0.5, 40] m/s" in res.stderr


def test_shipped_params_file_starts_the_plant(ros_env, tmp_path):
    """The installed defaults file plus -p overrides given after it (the later value wins)."""
    cmd = node_command("plant") + ["--params-file", str(CONFIG), "-p", "mode:=realtime", "-p", "rate_factor:=20.0",
                                   "-p", "duration:=0.2"]
    res = subprocess.run(cmd, env=ros_env, capture_output=True, text=True, timeout=60, cwd=tmp_path)
    assert res.returncode == 0, res.stdout + res.stderr
    assert "plant up: mode=realtime" in res.stdout + res.stderr and "duration reached" in res.stdout + res.stderr
