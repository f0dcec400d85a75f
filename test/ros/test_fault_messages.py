"""Fault injection, bad messages (issue 7, item 2): NaN, Inf, out-of-range values, wrong array lengths, stale and
future stamps on every input topic of the plant, the controller and the optimizer.

Each node must reject them with a throttled warning that names the value, keep the loop flying, and never apply
or publish anything unsafe. Bad messages are published by the test's own rclpy node (the probe) into a running
graph. Lockstep makes the checks exact: a loop that rejected every bad message flies bit for bit like the
fault-free pure runner.
"""
import math
import re
import time

import numpy as np
import pytest
from rclpy.qos import QoSProfile, ReliabilityPolicy
from geometry_msgs.msg import PointStamped, Vector3Stamped, WrenchStamped
from sensor_msgs.msg import JointState

from kite_rto.flight.closed_loop import make_closed_loop, run_closed_loop
from kite_rto.rto.experiment import ExperimentSpec
from kite_rto.rto.settings import KiteRTOSettings
from kite_rto.rto.runner import run_rto
from kite_rto.flight.path import DEFAULT_SETPOINTS, Setpoints
from kite_rto.flight.shape import setpoints_from_shape
from kite_rto.kite.plant import PlantConfig
from kite_rto.gma import HistoryStore
from kite_rto.runtime.optimizer_sync import SYNC_NAMES
from kite_rto.runtime.plan import Plan
from kite_rto.nodes.interface import LATCHED, MEASUREMENTS, RELIABLE_10, ns_to_stamp, stamp_to_ns

from faultgraph import QUIET, SHORT, Watch, node, steering_recorder, stop_all
from faultlog import fault_row
from rosutil import Probe

PER = KiteRTOSettings().experiments_per_iteration()   # experiments of one GMA iteration

pytestmark = [pytest.mark.ros, pytest.mark.faults]
DT_NS = 20_000_000
NAN, INF = math.nan, math.inf


@pytest.fixture
def probe():
    p = Probe()
    yield p
    p.close()


def suppressed(lines) -> int:
    """Rejections that the throttled warnings in ``lines`` report as not warned about individually."""
    return sum(int(m.group(1)) for ln in lines for m in re.finditer(r"\[(\d+) more rejected", ln))


def _steer(stamp_ns, position):
    m = JointState(name=["delta"] * len(position), position=[float(v) for v in position])
    m.header.stamp = ns_to_stamp(stamp_ns)
    return m


# ------------------------------------------------------------------------------------------------ the plant
def test_bad_steering_never_unblocks_lockstep(probe, ros_env, request, tmp_path):
    """Bad steering stamped with the sample the plant waits for must not advance it; a good one then does."""
    with fault_row(request, "bad steering messages (plant, lockstep)",
                   "probe answers each sample first with a bad /kite/steering stamped with that sample (NaN, +-Inf, "
                   "1.5, -7, 0 or 2 values) or with a stamp 1 s ahead / 1 s behind, then with a good one") as row:
        states = []
        steer = probe.node.create_publisher(JointState, "/kite/steering", MEASUREMENTS)
        probe.node.create_subscription(JointState, "/kite/state", states.append,
                                       QoSProfile(depth=1000, reliability=ReliabilityPolicy.RELIABLE))
        plant = node("plant", "plant", ros_env, tmp_path, {"command_timeout": 30.0, "resend_period": 0.05})
        try:
            assert probe.spin_until(lambda: states, 30.0), plant.text()
            # an answer sent before the plant's steering subscription has matched is lost (volatile) and the plant
            # would wait for it for ever: on a busy machine discovery can take longer than the first state
            assert probe.spin_until(lambda: steer.get_subscription_count() >= 1, 60.0), "plant not subscribed"

            def answer_good():
                now = stamp_to_ns(states[-1].header.stamp)
                steer.publish(_steer(now, [0.1]))
                assert probe.spin_until(lambda: stamp_to_ns(states[-1].header.stamp) == now + DT_NS, 60.0), \
                    "a good answer did not advance the plant"

            for _ in range(60):                        # 1.2 s of flight, so that a stamp 1 s behind exists
                answer_good()
            bad_values = [[NAN], [INF], [-INF], [1.5], [-7.0], [], [0.1, 0.2]]
            bad_stamps = [1_000_000_000, -1_000_000_000]
            sent = advanced_on_bad = 0
            t0 = time.monotonic()
            for _ in range(3):
                for kind in bad_values + bad_stamps:
                    now = stamp_to_ns(states[-1].header.stamp)
                    if isinstance(kind, list):
                        steer.publish(_steer(now, kind))
                    else:
                        steer.publish(_steer(now + kind, [0.1]))
                    sent += 1
                    n = len(states)
                    probe.spin_until(lambda: False, 0.12)
                    advanced_on_bad += any(stamp_to_ns(s.header.stamp) != now for s in states[n:])
                    answer_good()
            wall = time.monotonic() - t0
        finally:
            plant.stop()
        warnings = plant.matching("rejected steering")
        counted = len(warnings) + suppressed(warnings)
        row.outcome = (f"plant advanced on {advanced_on_bad} of {sent} bad messages and by one step on each of the "
                       f"{sent} good answers after them; {len(warnings)} warnings in {wall:.1f} s, throttled to one "
                       f"per 2 s for bad values and one for bad stamps, each naming its value and counting those "
                       f"not warned about ({counted} of the {sent} accounted for)")
        row.unsafe_setpoints = advanced_on_bad
        assert advanced_on_bad == 0
        assert "[nan]" in warnings[0] and any("stale or future" in w for w in warnings), plant.text()
        assert 2 <= len(warnings) <= 2 * (wall / 2.0 + 1) and len(warnings) < sent / 3
        assert len(warnings) < counted <= sent


def test_bad_steering_realtime_is_not_a_command(probe, ros_env, request, tmp_path):
    """Real time: bad, stale and future steering is not taken as a command (the plant flies neutral), the clock
    keeps its pace, and good commands are taken again afterwards."""
    with fault_row(request, "bad, stale and future steering (plant, real time)",
                   "probe steers well for 1 s, then sends only bad /kite/steering for 3 s, one every 20 ms or so "
                   "(NaN, 2.0, 2 values, stamps 2 s behind and 2 s ahead), then good ones again") as row:
        clock = []
        states = []
        steer = probe.node.create_publisher(JointState, "/kite/steering", MEASUREMENTS)
        probe.node.create_subscription(JointState, "/kite/state", states.append, RELIABLE_10)
        plant = node("plant", "plant", ros_env, tmp_path, {"mode": "realtime", "command_timeout": 0.5})
        try:
            assert probe.spin_until(lambda: states and stamp_to_ns(states[-1].header.stamp) > 2_500_000_000, 30.0)

            def phase(seconds, make):
                n = 0
                end = time.monotonic() + seconds
                while time.monotonic() < end:
                    now = stamp_to_ns(states[-1].header.stamp)
                    steer.publish(make(now, n))
                    n += 1
                    probe.spin_until(lambda: False, 0.02)
                return n

            phase(1.0, lambda now, n: _steer(now, [0.05]))
            bad = [lambda now: _steer(now, [NAN]), lambda now: _steer(now, [2.0]),
                   lambda now: _steer(now, [0.1, 0.1]), lambda now: _steer(now - 2_000_000_000, [0.1]),
                   lambda now: _steer(now + 2_000_000_000, [0.1])]
            t_sim0, t_wall0, t_epoch0 = stamp_to_ns(states[-1].header.stamp), time.monotonic(), time.time()
            sent = phase(3.0, lambda now, n: bad[n % len(bad)](now))
            pace = (stamp_to_ns(states[-1].header.stamp) - t_sim0) * 1e-9 / (time.monotonic() - t_wall0)
            clock.append(pace)
            t_epoch1 = time.time()
            phase(1.0, lambda now, n: _steer(now, [0.05]))
            probe.spin_until(lambda: False, 0.2)
        finally:
            plant.stop()

        def wall_stamps(text):
            """The plant log's wall stamps (epoch s) of its lines containing ``text``."""
            return [float(m.group(1)) for ln in plant.matching(text)
                    for m in [re.match(r"\[\w+\] \[(\d+\.\d+)\]", ln)] if m]
        # Which of the plant's events came in which phase (the order, not how fast): every kind of bad message
        # recurs every 0.1 s, so had one been taken as a command the plant could not have gone neutral during the
        # bad phase (command_timeout 0.5 s), and had one been taken after it went neutral, "steering commands are
        # back" would be logged before the good phase began.
        went_neutral = [t for t in wall_stamps("flying neutral") if t_epoch0 <= t < t_epoch1]
        came_back = wall_stamps("steering commands are back")
        back_early = [t for t in came_back if went_neutral and went_neutral[0] < t < t_epoch1]
        neutral = bool(went_neutral)
        neutral_after = went_neutral[0] - t_epoch0 if neutral else math.nan
        back = sum(t >= t_epoch1 for t in came_back)
        finite = all(all(map(math.isfinite, s.position)) for s in states)
        warnings = plant.matching("rejected steering")
        taken = not neutral or bool(back_early)
        row.outcome = (f"{sent} bad messages, none taken as a command: the plant went neutral {neutral_after:.2f} s "
                       f"after they began (command_timeout 0.5 s) and took good commands again afterwards "
                       f"({back > 0}); sim pace {pace:.2f}x wall during the bad phase; all {len(states)} states "
                       f"finite; {len(warnings)} throttled warnings")
        row.unsafe_setpoints = int(taken)
        assert not taken, plant.text()
        assert back >= 1 and finite
        assert 0 < pace < 1.2           # it kept flying, never faster than real time (how fast: the fault table)
        assert "[nan]" in warnings[0].lower() and any("stale or future" in w for w in warnings), plant.text()
        assert len(warnings) < sent / 5


# ------------------------------------------------------------------------------------------- the controller
def _bad_controller_inputs():
    """(topic, kind, builder(now_ns, ok) -> message); ``ok`` holds the latest genuine readings."""
    def state(pos, vel=(0.0, 0.0, 0.0), names=("theta", "phi", "psi"), dt=0):
        def build(now, ok):
            m = JointState(name=list(names), position=[float(v) for v in pos], velocity=[float(v) for v in vel])
            m.header.stamp = ns_to_stamp(now + dt)
            return m
        return build

    def good_state(dt):
        def build(now, ok):
            m = JointState(name=["theta", "phi", "psi"], position=list(ok["state"]), velocity=[0.0, 0.0, 0.0])
            m.header.stamp = ns_to_stamp(max(0, now + dt))
            return m
        return build

    def wind(v, dt=0):
        def build(now, ok):
            m = Vector3Stamped()
            m.header.stamp = ns_to_stamp(max(0, now + dt))
            m.vector.x = float(v)
            return m
        return build

    def tension(v, dt=0):
        def build(now, ok):
            m = WrenchStamped()
            m.header.stamp = ns_to_stamp(max(0, now + dt))
            m.wrench.force.x = float(v)
            return m
        return build

    def position(xyz, dt=0):
        def build(now, ok):
            m = PointStamped()
            m.header.stamp = ns_to_stamp(max(0, now + dt))
            m.point.x, m.point.y, m.point.z = (float(v) for v in xyz)
            return m
        return build

    def setpoints(names, values):
        def build(now, ok):
            return JointState(name=list(names), position=[float(v) for v in values])
        return build

    s5, names3 = 30_000_000_000, ("theta_0", "A_phi", "A_theta")
    return {
        "/kite/state": [("NaN", state([NAN, 0.1, 0.2])), ("Inf", state([0.6, 0.1, 0.2], [INF, 0, 0])),
                        ("2 values", state([0.6, 0.1])), ("4 values", state([0.6, 0.1, 0.2, 0.3])),
                        ("wrong names", state([0.6, 0.1, 0.2], names=("a", "b", "c"))),
                        ("theta 5 rad", state([5.0, 0.1, 0.2])), ("rate 1e5 rad/s", state([0.6, 0, 0], [1e5, 0, 0])),
                        ("stamp 30 s behind", good_state(-s5)), ("stamp 30 s ahead", good_state(s5))],
        "/kite/wind": [("NaN", wind(NAN)), ("-3 m/s", wind(-3.0)), ("1e3 m/s", wind(1e3)), ("Inf", wind(INF)),
                       ("stamp 30 s behind", wind(8.0, -s5)), ("stamp 30 s ahead", wind(8.0, s5))],
        "/kite/tension": [("NaN", tension(NAN)), ("-1 N", tension(-1.0)), ("1e12 N", tension(1e12)),
                          ("Inf", tension(INF)), ("stamp 30 s behind", tension(5e5, -s5)),
                          ("stamp 30 s ahead", tension(5e5, s5))],
        "/kite/position": [("NaN", position([NAN, 0, 200])), ("Inf", position([300, INF, 200])),
                           ("1e9 m", position([300, 0, 1e9])), ("stamp 30 s behind", position([300, 0, 200], -s5)),
                           ("stamp 30 s ahead", position([300, 0, 200], s5))],
        "/rto/setpoints": [("NaN", setpoints(names3, [NAN, 0.8, 0.12])),
                           ("theta_0 11 deg (outside the box)", setpoints(names3, [0.2, 0.8, 0.12])),
                           ("A_phi 17 deg, A_theta 17 deg (outside the box)", setpoints(names3, [0.6, 0.3, 0.3])),
                           ("2 values", setpoints(names3[:2], [0.6, 0.8])),
                           ("wrong names", setpoints(("a", "b", "c"), [0.6, 0.8, 0.12]))],
    }


def _bad_sync_messages():
    """Bad /rto/sync messages (the optimizer's plans to a synchronized controller)."""
    def sync(values, names=tuple(SYNC_NAMES), dt=0):
        def build(now, ok):
            m = JointState(name=list(names), position=[float(v) for v in values])
            m.header.stamp = ns_to_stamp(max(0, now + dt))
            return m
        return build
    good, s5 = Plan((0.6, 0.8, 0.12), 1, 1).values(), 30_000_000_000
    return [("NaN", sync([NAN, *good[1:]])), ("Inf updates", sync([*good[:3], INF, *good[4:]])),
            ("3 values", sync(good[:3])), ("wrong names", sync(good, names=("a",) * len(good))),
            ("mode 7", sync([*good[:5], 7.0, *good[6:]])),
            ("stamp 30 s behind", sync(good, dt=-s5)), ("stamp 30 s ahead", sync(good, dt=s5))]


TYPES = {"/kite/state": JointState, "/kite/wind": Vector3Stamped, "/kite/tension": WrenchStamped,
         "/kite/position": PointStamped, "/rto/setpoints": JointState, "/rto/sync": JointState}
WORD = {"/kite/state": "state", "/kite/wind": "wind", "/kite/tension": "tension", "/kite/position": "position",
        "/rto/setpoints": "setpoints", "/rto/sync": "sync"}


class _Fanout:
    """A 'publisher' for (topic, message) pairs: publishes each on its topic and counts per topic."""

    def __init__(self, pubs):
        self.pubs = dict(pubs)
        self.sent = {t: 0 for t in pubs}

    def publish(self, item):
        topic, msg = item
        self.pubs[topic].publish(msg)
        self.sent[topic] += 1


def _on(topic, build):
    return lambda now, ok: (topic, build(now, ok))


def _inject_phases(probe, pubs, cases, ok, now_ns, per_topic=150, period=0.01, stop=lambda: False):
    """Publish ``per_topic`` of every topic's bad messages round-robin (about ``period`` s apart), one topic after
    the other; return counts per topic. A count, not a duration: how many are sent must not depend on how fast
    the machine runs the probe."""
    sent = {}
    for topic, kinds in cases.items():
        n = 0
        while n < per_topic and not stop():
            _, build = kinds[n % len(kinds)]
            pubs[topic].publish(build(now_ns(), ok))
            n += 1
            next_t = time.monotonic() + period
            while (left := next_t - time.monotonic()) > 0:
                probe.executor.spin_once(timeout_sec=min(0.005, left))
        sent[topic] = n
    return sent


def test_bad_controller_inputs_fly_bit_for_bit(probe, ros_env, request, tmp_path):
    """Every bad message to the controller is rejected: the lockstep loop answers exactly like the pure runner."""
    cases = _bad_controller_inputs()
    steering = steering_recorder(probe.node)
    watch = Watch(probe.node, clock=False)      # the probe must keep up with ~1500 answers/s: nothing else fast
    ok = {"state": [0.6, 0.0, 0.0]}             # plausible values for the messages whose only fault is the stamp
    pubs = {t: probe.node.create_publisher(TYPES[t], t, LATCHED if t == "/rto/setpoints" else RELIABLE_10)
            for t in cases}
    ctrl = node("controller", "controller", ros_env, tmp_path)
    plant = None
    try:
        assert probe.spin_until(lambda: probe.node.count_publishers("/kite/steering") > 0
                                and all(p.get_subscription_count() > 0 for p in pubs.values()), 60.0), ctrl.text()
        probe.spin_until(lambda: False, 1.0)
        plant = node("plant", "plant", ros_env, tmp_path, {"seed": 5, "wait_subscribers": 1})
        assert probe.spin_until(lambda: len(steering) > 50, 60.0), plant.text()
        sent = _inject_phases(probe, pubs, cases, ok, lambda: max(steering) if steering else 0)
    finally:
        stop_all([plant])
        # the controller still serves its reliable history while the probe catches up on the answers it has not
        # heard yet (a busy probe lags the lockstep loop): until no new answer comes for 2 s (at most 60 s)
        end, heard = time.monotonic() + 60.0, -1
        while len(steering) != heard and time.monotonic() < end:
            heard = len(steering)
            probe.spin_until(lambda: False, 2.0)
        stop_all([ctrl])
    n = max(steering) // DT_NS + 1
    c = Setpoints.from_degrees(*DEFAULT_SETPOINTS.degrees())
    pure_plant, controller = make_closed_loop(c, seed=5)
    ref = run_closed_loop(pure_plant, controller, n * 0.02)
    got = np.array([steering.get(k * DT_NS, np.nan) for k in range(len(ref.delta))])
    missed = int(np.sum(np.isnan(got)))                 # answers the probe did not hear (not the controller's)
    differ = int(np.sum(got[~np.isnan(got)] != ref.delta[~np.isnan(got)]))
    text = ctrl.text()
    for topic, kinds in cases.items():
        word = WORD[topic]
        lines = [ln for ln in ctrl.lines if f"rejected {word}" in ln]
        with fault_row(request, f"bad {topic} messages (controller)",
                       f"{sent[topic]} messages in {len(kinds)} kinds, ~10 ms apart, while the lockstep loop flies: "
                       f"{', '.join(k for k, _ in kinds)}") as row:
            row.outcome = (f"{len(lines)} throttled warnings naming the values; the loop answered {n} samples "
                           f"bit for bit like the fault-free pure runner ({differ} of {n - missed} heard differ)"
                           + (f"; paths applied: {len(watch.paths)}, all from valid setpoints"
                              if topic == "/rto/setpoints" else ""))
            row.unsafe_setpoints = watch.unsafe_applied()
            assert sent[topic] >= 50 and lines, f"no warning for {topic}:\n{text[-3000:]}"
            assert len(lines) <= sent[topic] / 10
            # the warning names the rejected value (the first kind sent is NaN, but on a busy machine the latched
            # or reliable history may hand the controller a later kind first)
            assert re.search(r"nan|inf|\d", lines[0].lower().split(f"rejected {word}", 1)[1]), lines[0]
            if any("stamp" in k for k, _ in kinds):
                assert any("stale or future" in ln for ln in lines), f"no stamp warning for {topic}"
            if topic == "/rto/setpoints":
                assert any("rejected setpoints message" in ln for ln in lines)
            # every answer the probe heard is the pure runner's; how many it heard depends on its speed (a probe
            # more than the publisher's history behind loses the oldest): at least 20 s of flight compared
            assert differ == 0 and n > 1000 and n - missed >= 1000, (n, missed)
            assert row.unsafe_setpoints == 0
            assert len(watch.paths) == 1                    # only the initial path: every setpoint was refused


# -------------------------------------------------------------------------------------------- the optimizer
@pytest.mark.slow
def test_bad_optimizer_inputs_keep_the_experiments_clean(probe, ros_env, request, tmp_path):
    """Bad measurements (and bad /rto/sync messages to the synchronized controller) during a GMA iteration: the
    optimizer's experiments are exactly those of the fault-free pure runner."""
    cases = {k: v for k, v in _bad_controller_inputs().items() if k != "/rto/setpoints"}
    cases["/rto/sync"] = _bad_sync_messages()
    db = tmp_path / "rto.sqlite"
    watch = Watch(probe.node)
    ok = {"state": [0.6, 0.0, 0.0]}
    probe.node.create_subscription(JointState, "/kite/state", lambda m: ok.update(state=list(m.position)),
                                   RELIABLE_10)
    pubs = {t: probe.node.create_publisher(TYPES[t], t, MEASUREMENTS) for t in cases}
    procs = []
    with fault_row(request, "bad measurements into the optimizer",
                   "probe publishes the controller's bad-input set on /kite/state, /kite/wind, /kite/tension and "
                   "/kite/position (NaN, Inf, out of range, wrong lengths and names, stamps 30 s behind and "
                   "ahead), and bad /rto/sync messages to the synchronized controller, during a "
                   f"{PER}-experiment GMA iteration") as row:
        try:
            opt = node("optimizer", "optimizer", ros_env, tmp_path, {"db": str(db), **SHORT})
            procs.append(opt)
            assert probe.spin_until(lambda: probe.node.count_publishers("/rto/setpoints") > 0, 120.0), opt.text()
            ctrl = node("controller", "controller", ros_env, tmp_path, {"sync_optimizer": True})
            procs.append(ctrl)
            assert probe.spin_until(lambda: probe.node.count_publishers("/kite/steering") > 0, 60.0)
            plant = node("plant", "plant", ros_env, tmp_path, {**QUIET, "wait_subscribers": 2})
            procs.append(plant)
            assert probe.spin_until(lambda: watch.t > 1.0, 60.0)
            # all four topics at once (the iteration may take only a few seconds of wall time)
            mixed = {"all": [(f"{t} {k}", _on(t, b)) for t, kinds in cases.items() for k, b in kinds]}
            pubs["all"] = _Fanout(pubs)
            sent_all = _inject_phases(probe, pubs, mixed, ok, lambda: watch.clock_ns, per_topic=400,
                                      stop=lambda: not opt.alive())["all"]
            sent = pubs["all"].sent
            assert probe.spin_until(lambda: not opt.alive(), 600.0), "optimizer did not finish"
            code = opt.proc.returncode
        finally:
            stop_all(procs)
        store = HistoryStore(db)
        try:
            history, counts = store.load(), store.counts()
        finally:
            store.close()
        settings = KiteRTOSettings(experiment=ExperimentSpec(n_laps=1, settle_laps=0))
        pure = run_rto(PlantConfig().without_disturbances(), seed=0, n_iter=1, settings=settings)
        ros_c = np.array([setpoints_from_shape(q.c) for q, _ in history.experiments])   # GMA: shape coordinates
        pure_c = np.array([e.c for e in pure.experiments])
        ids = [q.request_id for q, _ in history.experiments]
        dc = float(np.max(np.abs(ros_c - pure_c))) if ros_c.shape == pure_c.shape else math.inf
        cost = np.array([r.cost for _, r in history.experiments])
        rel = float(np.max(np.abs(cost / [e.outcome.cost for e in pure.experiments] - 1))) \
            if len(cost) == len(pure.experiments) else math.inf
        warned = {t: (ctrl if t == "/rto/sync" else opt).count(f"rejected {WORD[t]}") for t in cases}
        discarded = opt.count("off the timeline")
        row.experiments_lost = len(pure.experiments) - len(set(ids))
        row.unsafe_setpoints = watch.unsafe_published() + watch.unsafe_applied()
        row.outcome = (f"{sum(sent.values())} bad messages; {counts['experiments']} experiments stored "
                       f"({len(set(ids))} distinct), setpoints equal to the fault-free pure runner within {dc:.1e} "
                       f"rad, costs within {100 * rel:.2f} % (bit for bit: 0.00 %); "
                       f"{sum(warned.values())} value warnings + {discarded} stale/future-stamp warnings (throttled)")
        assert code == 0, opt.text()[-3000:]
        assert counts == {"experiments": PER, "iterations": 1}
        # The synchronized graph flies the pure runner's sequence bit for bit, so any bad message that got through
        # shows (before the stamp checks, nodes let junk through and the costs were 13 % off).
        assert dc == 0 and rel == 0, (dc, rel)
        assert sent_all == sum(sent.values()) and min(sent.values()) >= 50, sent
        assert all(warned.values()) and discarded >= 1, warned
        assert sum(warned.values()) + discarded < sum(sent.values()) / 10
        assert row.unsafe_setpoints == 0 and row.experiments_lost == 0



# ------------------------------------------------------------------------------- the join, without DDS
def test_sample_join_keeps_the_timeline():
    """The optimizer's join: lone junk parts never complete and are reported; only a complete sample stamped
    before the last one is a plant restart; a flood of junk cannot starve genuine samples."""
    from kite_rto.runtime.sample_join import SampleJoin

    j = SampleJoin(max_pending=8)

    def sample(stamp):
        out = None
        for part, value in (("tension", 5e5), ("position", (300.0, 0.0, 200.0)), ("wind", 8.0),
                            ("state", (0.6, 0.1, 0.2))):
            out = j.add(stamp, part, value) or out
        return out

    assert sample(0) is not None and sample(DT_NS) is not None
    assert j.add(DT_NS, "state", (0.6, 0.1, 0.2)) is None                     # duplicate of the last sample
    assert j.add(30 * 10**9, "state", (0.6, 0.1, 0.2)) is None                # future junk: never completes
    assert j.add(0, "wind", 8.0) is None                                      # stale junk
    m = sample(2 * DT_NS)
    assert m is not None and not m.jumped_back and j.last == 2 * DT_NS
    assert [s for s, _ in j.discarded] == [30 * 10**9]                        # reported (the stale one is near)
    j.discarded.clear()
    for k in range(20):                                                       # a flood of lone future parts
        j.add(40 * 10**9 + k * DT_NS, "tension", 5e5)
    assert sample(3 * DT_NS) is not None
    assert len(j.discarded) >= 12
    assert sample(DT_NS // 2) is None                       # complete but earlier: a candidate only
    assert sample(4 * DT_NS) is not None and j.discarded[-1][0] == DT_NS // 2   # the old timeline went on
    j.discarded.clear()
    assert sample(DT_NS // 2) is None                       # a restarted plant's first sample ...
    back = sample(DT_NS // 2 + DT_NS)                       # ... and its second: the restart is confirmed
    assert back is not None and back.jumped_back and j.last == DT_NS // 2 + DT_NS
    assert sample(200 * 10**9) is None                      # far from the new timeline: a candidate again
