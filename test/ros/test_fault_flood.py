"""Fault injection, foreign publishers (issue 18, items 3 and 4, the controller's side): a setpoint flood from a
second publisher of /rto/setpoints, a fast setpoint stream from the only publisher, a second plant on the same
domain, and the controller restricted to one setpoint source.

The real-time loop is measured from DDS timestamps seen by the test's probe: each /kite/state sample's source
timestamp (when the plant published it) and the received timestamp of the steering answering it (system clock, one
machine). The numbers go into the fault table; the assertions are the ones that do not depend on the machine's
speed (warnings that name the sources, at most one setpoint change applied per answered sample, the first kite
kept), plus a generous bound on the answered fraction (see the flood test).
"""
import json
import math
import os
import re
import sys
import time

import numpy as np
import pytest
from nav_msgs.msg import Path
from rclpy.qos import QoSProfile, ReliabilityPolicy
from sensor_msgs.msg import JointState

from kite_rto.flight.path import DEFAULT_SETPOINTS, Setpoints
from kite_rto.runtime.setpoint_rate import RATE_LIMIT, RATE_PERIOD, RATE_WINDOW
from kite_rto.runtime.sources import UNKNOWN_NODE
from kite_rto.nodes.interface import LATCHED, stamp_to_ns

from faultgraph import QUIET, Proc, decode_path, node, stop_all
from faultlog import fault_row
from rosutil import Probe

pytestmark = [pytest.mark.ros, pytest.mark.faults]
DT_NS = 20_000_000
DEEP = QoSProfile(depth=5000, reliability=ReliabilityPolicy.RELIABLE)      # the probe must not drop samples
FLOOD_HZ, FLOOD_S = 500.0, 8.0
TOO_FAST = "setpoints change faster than the path can follow"
RATE_TEXT = re.compile(r"(/\w+) \(gid \w+\) changed /rto/setpoints (\d+) times in ([\d.]+) s of flight up to "
                       r"t = ([\d.]+) s \(([\d.]+) changes per s of flight")
OPTIMIZER_C = Setpoints.from_degrees(34.0, 50.0, 8.0).as_array().tolist()   # the stand-in optimizer's setpoints


@pytest.fixture
def probe():
    p = Probe("optimizer")              # stands in for the optimizer: a second, legitimate setpoint publisher
    yield p
    p.close()


class LoopTimes:
    """Per-sample DDS timestamps (system clock, ns): when the plant published each /kite/state (source timestamp)
    and when the steering answering it arrived at the probe (received timestamp); first of each stamp kept."""

    def __init__(self, node):
        self.state, self.steer = {}, {}
        self.states, self.steers = [], []          # every (stamp, timestamp), e.g. of two plants
        node.create_subscription(JointState, "/kite/state", self._state, DEEP)
        node.create_subscription(JointState, "/kite/steering", self._steer, DEEP)

    def _state(self, msg, info):
        k = stamp_to_ns(msg.header.stamp)
        self.state.setdefault(k, info["source_timestamp"])
        self.states.append((k, info["source_timestamp"]))

    def _steer(self, msg, info):
        k = stamp_to_ns(msg.header.stamp)
        self.steer.setdefault(k, info["received_timestamp"])
        self.steers.append((k, info["received_timestamp"]))

    def window(self, t0_ns: int, t1_ns: int, stamps=None) -> dict:
        """Samples published in [t0, t1] (optionally only ``stamps``): count, answered fraction, latency ms."""
        ks = [k for k, t in list(self.state.items()) if t0_ns <= t <= t1_ns and (stamps is None or k in stamps)]
        lat = np.array([(self.steer[k] - self.state[k]) * 1e-6 for k in ks if k in self.steer])
        return {"n": len(ks), "answered": len(lat) / max(len(ks), 1),
                "p50_ms": float(np.percentile(lat, 50)) if len(lat) else math.nan,
                "p99_ms": float(np.percentile(lat, 99)) if len(lat) else math.nan,
                "max_ms": float(lat.max()) if len(lat) else math.nan}


def _fmt(w: dict) -> str:
    return (f"{100 * w['answered']:.1f} % of {w['n']} samples answered, latency p50 {w['p50_ms']:.1f} ms, "
            f"p99 {w['p99_ms']:.1f} ms, max {w['max_ms']:.1f} ms")


def _summaries(lines) -> tuple[int, int]:
    """Setpoint messages received and changes applied, summed over the controller's throttled summary lines and
    its individual 'new setpoints' lines."""
    received = applied = 0
    for ln in lines:
        m = re.search(r"(\d+) setpoint messages in the last [\d.]+ s, applied (\d+)", ln)
        if m:
            received, applied = received + int(m.group(1)), applied + int(m.group(2))
    return received, applied


def cpu_seconds(pid: int) -> float:
    """User + system CPU time (s) of process ``pid`` so far (Linux /proc; NaN elsewhere)."""
    try:
        fields = open(f"/proc/{pid}/stat").read().rsplit(")", 1)[1].split()
        return (int(fields[11]) + int(fields[12])) / os.sysconf("SC_CLK_TCK")
    except (OSError, IndexError, ValueError):
        return math.nan


def _flood(env, tmp_path, rate=FLOOD_HZ, duration=FLOOD_S, name="intruder") -> Proc:
    return Proc(name, [sys.executable, "-m", "kite_rto.testing.setpoint_flood", "--rate", str(rate), "--duration",
                       str(duration), "--name", name], env, tmp_path)


def _flood_summary(proc: Proc) -> dict:
    for ln in proc.lines:
        if "setpoint_flood summary: " in ln:
            return json.loads(ln.split("setpoint_flood summary: ", 1)[1])
    raise AssertionError("the flood printed no summary:\n" + proc.text()[-2000:])


def _publish_setpoints(probe, c):
    pub = probe.node.create_publisher(JointState, "/rto/setpoints", LATCHED)
    pub.publish(JointState(name=list(Setpoints.names()), position=[float(v) for v in c]))
    return pub


def _fly_realtime(probe, times, ros_env, tmp_path, procs: list, setpoints=None):
    """Start the controller and (once the probe published ``setpoints``, if any) the plant in real time; both are
    appended to ``procs`` (stopped by the caller) and returned once 200 samples were answered."""
    procs.append(node("controller", "controller", ros_env, tmp_path))
    assert probe.spin_until(lambda: probe.node.count_publishers("/kite/steering") > 0, 60.0), procs[0].text()
    if setpoints is not None:
        _publish_setpoints(probe, setpoints)
    procs.append(node("plant", "plant", ros_env, tmp_path, {"mode": "realtime", "seed": 5, **QUIET}))
    assert probe.spin_until(lambda: len(times.steer) > 200, 90.0), procs[1].text()[-2000:]
    return procs


def test_setpoint_flood_does_not_starve_the_realtime_loop(probe, ros_env, request, tmp_path):
    """A foreign node floods /rto/setpoints with alternating valid setpoints at 500 Hz for 8 s while the plant flies
    in real time: the controller coalesces them (at most one change per sample), warns naming the second
    publisher, and keeps answering the 50 Hz samples."""
    with fault_row(request, "setpoint flood from a foreign publisher (controller, real time)",
                   f"a second node (/intruder) publishes valid /rto/setpoints alternating between two setpoints at "
                   f"{FLOOD_HZ:.0f} Hz for {FLOOD_S:.0f} s while the plant flies in real time (rate 1) and the "
                   "probe (/optimizer) has published the latched setpoints") as row:
        times, procs = LoopTimes(probe.node), []
        try:
            ctrl, _ = _fly_realtime(probe, times, ros_env, tmp_path, procs, OPTIMIZER_C)
            cpu = [(time.monotonic(), cpu_seconds(ctrl.pid))]
            probe.spin_until(lambda: False, 3.0)
            cpu.append((time.monotonic(), cpu_seconds(ctrl.pid)))
            flood = _flood(ros_env, tmp_path)
            procs.append(flood)
            assert probe.spin_until(lambda: flood.count("setpoint_flood summary") > 0, FLOOD_S + 60.0), flood.text()
            cpu.append((time.monotonic(), cpu_seconds(ctrl.pid)))   # includes the flooder's start-up (~1-2 s)
            probe.spin_until(lambda: False, 7.0)             # the controller's next summary (every 5 s)
        finally:
            stop_all(procs)
        fl = _flood_summary(flood)
        t0, t1 = fl["t_start_ns"], fl["t_end_ns"]
        before = times.window(t0 - 3_000_000_000, t0)
        during = times.window(t0, t1)
        received, applied = _summaries(ctrl.lines)
        warned = ctrl.matching("/intruder")
        load = [100 * (c1 - c0) / (w1 - w0) for (w0, c0), (w1, c1) in zip(cpu, cpu[1:])]
        row.outcome = (f"flood {fl['sent']} messages at {fl['rate_hz']:.0f} Hz; during it {_fmt(during)} "
                       f"(3 s before: {_fmt(before)}); controller CPU {load[1]:.0f} % of a core from the flooder's "
                       f"start to its end ({load[0]:.0f} % before); load average {os.getloadavg()[0]:.1f}; controller counted {received} setpoint messages and applied "
                       f"{applied} changes (coalesced at sample boundaries); {len(warned)} warnings naming /intruder "
                       f"({ctrl.count(TOO_FAST)} of them: setpoints changing too fast); "
                       f"'new setpoints' lines {ctrl.count('new setpoints')}")
        row.unsafe_setpoints = 0                            # both flooded setpoints are valid: nothing unsafe
        assert warned and "/optimizer" in warned[0], ctrl.text()[-3000:]
        assert received > 0 and applied <= during["answered"] * during["n"] + 5     # coalesced: <= 1 per sample
        assert ctrl.count("new setpoints") <= 2 * FLOOD_S / 5 + 4                     # throttled, not per message
        # Generous bound: 50 % is what the unfixed controller managed; the measured value is in the row (target
        # >= 99 %, p99 < 20 ms on an idle machine: docs/interface.md).
        assert during["n"] > 100 and during["answered"] > 0.5, row.outcome


def test_a_fast_setpoint_stream_from_one_node_is_warned_about(probe, ros_env, request, tmp_path):
    """The only publisher of /rto/setpoints streams valid setpoints, alternating, at 500 Hz for 8 s while the plant
    flies in real time: the controller answers the samples and warns once per interval of flight (RATE_PERIOD s),
    naming the node and the rate of changes. The warnings are counted per interval of flight (the stamps in their
    text), so the verdict does not depend on the machine's speed."""
    with fault_row(request, "fast setpoint stream from the only publisher (controller, real time)",
                   f"one node (/streamer), the only publisher of /rto/setpoints, publishes valid setpoints "
                   f"alternating between two at {FLOOD_HZ:.0f} Hz for {FLOOD_S:.0f} s while the plant flies in real "
                   "time (rate 1)") as row:
        times, procs = LoopTimes(probe.node), []
        try:
            ctrl, _ = _fly_realtime(probe, times, ros_env, tmp_path, procs)
            flood = _flood(ros_env, tmp_path, name="streamer")
            procs.append(flood)
            assert probe.spin_until(lambda: flood.count("setpoint_flood summary") > 0, FLOOD_S + 60.0), flood.text()
            # the interval opened by the first change closes RATE_PERIOD s of flight later (real time: wall s)
            probe.spin_until(lambda: ctrl.count(TOO_FAST) > 0, 2 * RATE_PERIOD + 30.0)
            probe.spin_until(lambda: False, RATE_PERIOD / 2)    # a second warning would need changes after it
        finally:
            stop_all(procs)
        fl = _flood_summary(flood)
        during = times.window(fl["t_start_ns"], fl["t_end_ns"])
        received, applied = _summaries(ctrl.lines)
        warned = ctrl.matching(TOO_FAST)
        found = [RATE_TEXT.search(w) for w in warned]
        parsed = [(m.group(1), int(m.group(2)), float(m.group(3)), float(m.group(4)), float(m.group(5)))
                  for m in found if m]
        ends = [t for *_, t, _ in parsed]
        row.outcome = (f"{fl['sent']} messages at {fl['rate_hz']:.0f} Hz; during it {_fmt(during)}; controller "
                       f"counted {received} setpoint messages and applied {applied} changes; {len(warned)} warnings "
                       "'setpoints change faster than the path can follow' (" + "; ".join(
                           f"{who}: {n} changes in {span:.1f} s of flight up to t = {t:.1f} s, {rate:.1f} per s"
                           for who, n, span, t, rate in parsed) + f"), limit {RATE_LIMIT} changes per "
                       f"{RATE_WINDOW:g} s of flight; 'new setpoints' lines {ctrl.count('new setpoints')}")
        row.unsafe_setpoints = 0                            # both streamed setpoints are valid: nothing unsafe
        assert warned and len(parsed) == len(warned), ctrl.text()[-3000:]
        assert all(who == "/streamer" for who, *_ in parsed)
        assert all(b - a >= RATE_PERIOD for a, b in zip(ends, ends[1:]))         # at most one per interval
        assert all(n > RATE_LIMIT and abs(rate - n / span) <= 0.1 for _, n, span, _, rate in parsed)
        assert sum(n for _, n, *_ in parsed) <= fl["sent"]                         # changes of what was sent
        assert during["n"] > 100 and during["answered"] >= 0.99, row.outcome


def _log_time(line: str) -> float:
    """The wall time (system clock, s) of an rclpy log line ``[WARN] [1700000000.123456789] [node]: ...``."""
    m = re.search(r"\[(\d+\.\d+)\]", line)
    return float(m.group(1)) if m else math.nan


def test_second_plant_is_named_and_the_first_kite_kept(probe, ros_env, request, tmp_path):
    """A second plant starts on the domain while the first flies in real time: the controller warns naming both
    publishers of /kite/state and keeps steering the first kite; the second one's samples are not answered."""
    with fault_row(request, "second plant on the same domain (controller, real time)",
                   "a second plant process (/plant, seed 6, one_plant_check:=false) starts in real time while the "
                   "first (seed 5) has flown "
                   "about 15 s; it runs 10 s, then stops") as row:
        times = LoopTimes(probe.node)
        ctrl = node("controller", "controller", ros_env, tmp_path)
        plant_a = plant_b = None
        try:
            assert probe.spin_until(lambda: probe.node.count_publishers("/kite/steering") > 0, 60.0), ctrl.text()
            plant_a = node("plant_a", "plant", ros_env, tmp_path, {"mode": "realtime", "seed": 5, **QUIET})
            assert probe.spin_until(lambda: times.steer and max(times.steer) > 15 * 10**9, 120.0), plant_a.text()
            a0 = max(times.state)                       # the first plant's sim time when the second one starts
            # a second plant that does not check for the first (plants refuse to start by default: test_fault_plant_side)
            plant_b = node("plant_b", "plant", ros_env, tmp_path, {"mode": "realtime", "seed": 6, **QUIET,
                                                                   "one_plant_check": False})
            assert probe.spin_until(lambda: any(k < a0 - 10**9 for k, _ in times.states[-20:]), 60.0), \
                plant_b.text()
            probe.spin_until(lambda: False, 10.0)
            plant_b.stop()
            b_end = max(t for k, t in times.states if k < a0 - 10**9)
            probe.spin_until(lambda: False, 3.0)
        finally:
            stop_all([plant_b, plant_a, ctrl])
        b_first, b_k = min((t, k) for k, t in times.states if k < a0 - 10**9 and t > times.state[a0])
        b_start = (b_first - b_k) * 1e-9        # wall time of its sample 0 (real time, rate 1: stamp = elapsed)
        b_stamps = {k for k, t in times.states if t >= b_first and k < a0 - 10**9}
        b_answered = len({k for k, t in times.steers if t >= b_first and k in b_stamps})
        a_during = times.window(b_first, b_end, stamps={k for k in times.state if k > a0})
        a_after = times.window(b_end, b_end + 2 * 10**9, stamps={k for k in times.state if k > a0})
        warned = ctrl.matching("publishers of /kite/state: ")
        named = [ln for ln in warned if len(set(re.findall(r"/plant \(gid ([0-9a-f]+)\)", ln))) == 2]
        delay = _log_time(warned[0]) - b_start if warned else math.nan
        delay_named = _log_time(named[0]) - b_start if named else math.nan
        other = ctrl.matching("another plant on this domain")
        seen = re.search(r"stamped ([\d.]+) s", other[0]) if other else None
        row.outcome = (f"first warning {delay:.2f} s after the second plant published its first sample, naming both "
                       f"/plant publishers by GID {delay_named:.2f} s after it, {len(warned)} in all (throttled); "
                       f"discovery: the first sample of the second plant the probe got was its {b_k * 1e-9:.2f} s "
                       f"one, the controller's {seen.group(1) if seen else '?'} s one; the first kite during the "
                       "overlap: "
                       f"{_fmt(a_during)}; after: {_fmt(a_after)}; second plant: {b_answered} of {len(b_stamps)} "
                       f"samples answered; 'jumped back' {ctrl.count('jumped back')}, other-plant rejections "
                       f"warned {ctrl.count('another plant on this domain')}")
        row.unsafe_setpoints = 0
        assert named, ctrl.text()[-3000:]
        assert delay_named < 15.0               # generous: DDS discovery takes 2-3 s here, then GRAPH_PERIOD (0.5 s)
        assert ctrl.count("jumped back") == 0 and ctrl.count("another plant on this domain") >= 1
        assert b_answered <= 2 < len(b_stamps)                  # a race with discovery may answer its first
        assert a_during["answered"] > 0.5 and a_after["answered"] > 0.5, row.outcome


def test_setpoint_source_ignores_a_foreign_publisher(probe, ros_env, request, tmp_path):
    """With setpoint_source:=/optimizer the flood of a foreign node is never applied; the optimizer's setpoints
    published meanwhile are fetched again (latched) once the foreign node is gone."""
    with fault_row(request, "setpoint flood with setpoint_source:=/optimizer (controller, lockstep)",
                   f"/intruder publishes two alternating valid setpoints at {FLOOD_HZ:.0f} Hz for 3 s while the "
                   "lockstep loop flies; meanwhile the probe (/optimizer) publishes new setpoints once") as row:
        paths = []
        probe.node.create_subscription(Path, "/kite/reference_path", lambda m: paths.append(decode_path(m)), LATCHED)
        ctrl = node("controller", "controller", ros_env, tmp_path, {"setpoint_source": "/optimizer"})
        plant = flood = None
        new_c = Setpoints.from_degrees(32.0, 48.0, 7.5).as_array()
        try:
            assert probe.spin_until(lambda: probe.node.count_publishers("/kite/steering") > 0, 60.0), ctrl.text()
            pub = _publish_setpoints(probe, OPTIMIZER_C)
            plant = node("plant", "plant", ros_env, tmp_path, {"seed": 5, **QUIET})
            assert probe.spin_until(lambda: paths and np.allclose(paths[-1], OPTIMIZER_C, atol=2e-3), 90.0), \
                ctrl.text()[-2000:]
            flood = _flood(ros_env, tmp_path, duration=3.0)
            assert probe.spin_until(lambda: ctrl.count("ignoring /rto/setpoints") > 0, 60.0), ctrl.text()[-2000:]
            pub.publish(JointState(name=list(Setpoints.names()), position=new_c.tolist()))
            assert probe.spin_until(lambda: flood.count("setpoint_flood summary") > 0, 60.0), flood.text()
            assert probe.spin_until(lambda: np.allclose(paths[-1], new_c, atol=2e-3), 30.0), ctrl.text()[-2000:]
        finally:
            stop_all([flood, plant, ctrl])
        fl = _flood_summary(flood)
        flooded = [Setpoints.from_degrees(33.0, 46.0, 7.0).as_array(), Setpoints.from_degrees(35.0, 52.0, 8.0).as_array()]
        applied_flood = sum(any(np.allclose(p, f, atol=2e-3) for f in flooded) for p in paths)
        ignored = ctrl.matching("ignoring /rto/setpoints")
        named = sum("/intruder" in w for w in ignored)
        row.outcome = (f"{fl['sent']} flooded messages at {fl['rate_hz']:.0f} Hz, {applied_flood} applied (paths "
                       f"decoded: {[np.degrees(p).round(2).tolist() for p in paths]}); {len(ignored)} warnings, "
                       f"{named} naming /intruder (the others before discovery had named it: its gid); the optimizer's "
                       "setpoints published during the flood were applied once /intruder had left (subscribed again)")
        row.unsafe_setpoints = 0
        assert applied_flood == 0
        # each warning names the foreign publisher: by node name once discovery knows it, by gid before (on a busy
        # machine the flood can start before the controller's graph has the intruder's name)
        assert ignored and all("/intruder" in w or (UNKNOWN_NODE in w and "gid" in w) for w in ignored), ignored
        assert np.allclose(paths[-1], new_c, atol=2e-3)
