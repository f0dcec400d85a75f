"""The main job as a user runs it: ``python -m kite_rto.tools.demo`` with progress, recording, and Ctrl-C.

Ctrl-C is sent the way a terminal sends it: SIGINT to the demo's process group. The demo must stop every node it
started (they run in their own sessions, so only the demo hears the terminal), exit quickly with code 130 (or 0)
and no traceback, leave a partial report and a readable recording.
"""
import json
import os
import re
import signal
import subprocess
import sys
import threading
import time
import uuid

import pytest
from mcap.reader import make_reader
from mcap_ros2.reader import read_ros2_messages

from kite_rto.tools.record_time import PER_SAMPLE

from rosutil import DIE_WITH_PARENT

PY = sys.executable


def children(pid: int) -> dict:
    """Direct children of ``pid``: {child pid: command line} (from /proc)."""
    out = {}
    for entry in os.listdir("/proc"):
        if not entry.isdigit():
            continue
        try:
            with open(f"/proc/{entry}/stat") as f:
                stat = f.read()
            if int(stat.rsplit(")", 1)[1].split()[1]) == pid:
                with open(f"/proc/{entry}/cmdline", "rb") as f:
                    out[int(entry)] = f.read().replace(b"\0", b" ").decode(errors="replace")
        except (OSError, IndexError, ValueError):
            continue
    return out


def tagged_env(ros_env) -> dict:
    """The test's ROS environment plus a unique tag that every process the demo starts inherits."""
    return dict(ros_env, KITE_RTO_TEST_TAG=uuid.uuid4().hex)


def tagged_processes(env: dict) -> dict:
    """Processes (other than this one) whose environment carries ``env``'s tag: what the demo left running."""
    found = {}
    needle = f"KITE_RTO_TEST_TAG={env['KITE_RTO_TEST_TAG']}".encode()
    for entry in os.listdir("/proc"):
        if not entry.isdigit() or int(entry) == os.getpid():
            continue
        try:
            with open(f"/proc/{entry}/environ", "rb") as f:
                env = f.read().split(b"\0")
            with open(f"/proc/{entry}/cmdline", "rb") as f:
                cmd = f.read().replace(b"\0", b" ").decode(errors="replace")
        except OSError:
            continue
        if needle in env:
            found[int(entry)] = cmd
    return found


class Output:
    """Read a process's stdout in a thread, keeping the lines."""

    def __init__(self, proc):
        self.lines = []
        self.thread = threading.Thread(target=self._read, args=(proc,), daemon=True)
        self.thread.start()

    def _read(self, proc):
        for line in proc.stdout:
            self.lines.append(line.rstrip("\n"))

    def wait_for(self, pred, timeout):
        end = time.monotonic() + timeout
        while time.monotonic() < end:
            if any(pred(ln) for ln in self.lines):
                return True
            time.sleep(0.1)
        return False


def start_demo(args, env):
    return subprocess.Popen([PY, "-m", "kite_rto.tools.demo", *args], env=env, stdout=subprocess.PIPE,
                            stderr=subprocess.PIPE, text=True, start_new_session=True, preexec_fn=DIE_WITH_PARENT)


def test_progress_line_of_the_optimization():
    from kite_rto.rto.settings import KiteRTOSettings
    from kite_rto.tools.progress import OptimizeProgress, eta_text

    per = {g: KiteRTOSettings(gradient=g).experiments_per_iteration() for g in ("forward", "central", "directional")}
    assert per == {"forward": 4, "central": 7, "directional": 4}
    assert KiteRTOSettings(n_directions=1).experiments_per_iteration() == 2
    assert (eta_text(None), eta_text(42.4), eta_text(125)) == ("ETA ?", "ETA 42 s", "ETA 2 min 05 s")
    p = OptimizeProgress(n_iter=10, per_iteration=4)
    first = p.text({"iteration": "0", "experiments_done": "0", "experiment": "k0-0-nominal"}, 12.0, 2.0)
    assert first == ("  t =     12 s sim ( 6.0x real time), iteration 1/10, experiment 1/4 (k0-0-nominal),   0 % done, "
                     "ETA ?")
    # 6 experiments of 40 in 32 s of wall since the first status: 34 more take 34 x 5.33 s
    later = p.text({"iteration": "1", "experiments_done": "6", "experiment": "k1-2-perturbation"}, 500.0, 34.0)
    assert "iteration 2/10, experiment 3/4 (k1-2-perturbation),  15 % done, ETA 3 min 01 s" in later
    assert "all 10 iterations done" in p.text({"iteration": "10", "experiments_done": "40"}, 4000.0, 300.0)


@pytest.mark.ros
def test_ctrl_c_stops_the_demo_and_every_node(ros_env, tmp_path):
    mcap = tmp_path / "run.mcap"
    env = tagged_env(ros_env)
    demo = start_demo(["--mode", "fly", "--duration", "3000", "--out", str(tmp_path), "--record", str(mcap),
                       "--progress", "0.5"], env)
    out = Output(demo)
    try:
        assert out.wait_for(lambda ln: "s sim" in ln and "ETA" in ln, 90.0), f"no progress line: {out.lines}"
        # the first lap the line shows depends on when it is printed: any lap (re: "lap N:")
        assert out.wait_for(lambda ln: re.search(r"lap \d+:", ln) is not None, 60.0), \
            f"no lap in the progress line: {out.lines}"
        kids = children(demo.pid)
        assert len(kids) == 4, kids                            # recorder, kite_viz, controller, plant
        os.killpg(demo.pid, signal.SIGINT)                     # what a terminal does on Ctrl-C
        t0 = time.monotonic()
        demo.wait(timeout=180)                                 # generous: a busy machine stops slowly
        took = time.monotonic() - t0
    finally:
        if demo.poll() is None:
            os.killpg(demo.pid, signal.SIGKILL)
            demo.wait()
    err = demo.stderr.read()
    out.thread.join(timeout=5)
    text = "\n".join(out.lines)
    assert demo.returncode in (130, 0), (demo.returncode, text, err)
    print(f"the demo stopped {took:.1f} s after Ctrl-C")          # a speed, not a verdict (docs/testing.md)
    assert "Traceback" not in err and "Traceback" not in text, err
    assert "interrupted: every node stopped" in text
    left = [pid for pid in kids if os.path.exists(f"/proc/{pid}")]
    assert not left, {pid: kids[pid] for pid in left}
    assert not tagged_processes(env)
    assert "Traceback" not in (tmp_path / "nodes.log").read_text()
    summary = json.loads((tmp_path / "summary.json").read_text())       # the partial report
    assert summary["interrupted"] is True and summary["laps"] >= 1, (summary, text)
    with open(mcap, "rb") as f:                                          # the recorder closed its file
        stats = make_reader(f).get_summary().statistics
    assert stats.message_count > 1000


@pytest.mark.ros
def test_short_fly_run_with_recording(ros_env, tmp_path):
    mcap = tmp_path / "run.mcap"
    env = tagged_env(ros_env)
    res = subprocess.run([PY, "-m", "kite_rto.tools.demo", "--mode", "fly", "--duration", "42", "--out",
                          str(tmp_path), "--record", str(mcap), "--progress", "1"], env=env,
                         capture_output=True, text=True, timeout=900)     # generous: a busy machine is slow
    assert res.returncode == 0, res.stdout + res.stderr
    assert "Traceback" not in res.stderr
    assert "ETA" in res.stdout and "/ 42 s sim" in res.stdout
    assert f"recording every topic to {mcap}" in res.stdout and "wrote" in res.stdout
    summary = json.loads((tmp_path / "summary.json").read_text())
    assert summary["laps"] >= 1 and summary["interrupted"] is False
    with open(mcap, "rb") as f:
        s = make_reader(f).get_summary()
    counts = {ch.topic: s.statistics.channel_message_counts.get(cid, 0) for cid, ch in s.channels.items()}
    # 2101 samples (0 .. 42 s), every one of them: the demo's recorder is lossless (the lockstep plant waits for it)
    with open(mcap, "rb") as f:
        gaps = {m.name: m.metadata for m in make_reader(f).iter_metadata()}["kite_record_gaps"]
    assert counts["/kite/state"] == 2101 and gaps == {"all": "no sample missing"}, (counts, gaps)
    assert "no sample missing" in res.stdout and counts["/kite/laps"] == summary["laps"]
    assert not tagged_processes(env)
    # The recording of the main job on simulated time: it decodes with mcap_ros2, its log times span the flight
    # (0 .. 42 s), each sample is in it once, the 3-D scene (kite_viz) is in it, and so are the nodes' parameters.
    log_times, stamps, scenes, parts = [], {}, 0, set()
    for m in read_ros2_messages(str(mcap)):
        log_times.append(m.log_time_ns)
        topic = m.channel.topic
        if topic == "/kite/markers":
            scenes += 1
            # the latched path and the first wind reading may reach kite_viz after its first scenes (busy machine)
            parts |= {mk.ns for mk in m.ros_msg.markers}
            assert {mk.ns for mk in m.ros_msg.markers} >= {"kite", "tether", "h_min"}
            assert m.log_time_ns == m.ros_msg.markers[0].header.stamp.sec * 10**9 + \
                m.ros_msg.markers[0].header.stamp.nanosec
        elif topic.lstrip("/") in PER_SAMPLE:               # channels: the graph's names, /kite/state
            st = m.ros_msg.clock if topic == "/clock" else m.ros_msg.header.stamp
            stamps.setdefault(topic, []).append(st.sec * 10**9 + st.nanosec)
    assert min(log_times) == 0 and 42 * 10**9 - 20_000_000 <= max(log_times) <= 42 * 10**9
    for topic, s in stamps.items():
        assert len(s) == len(set(s)), f"{topic}: {len(s) - len(set(s))} samples recorded twice"
    # at most one scene per 0.1 s of the flight (kite_viz without a wall-rate cap when recording): 421 at most. Its
    # subscriptions are best effort, so a loaded machine costs some (seen here: 246 to 419 at load average 6-7 on 2
    # cores); the count depends on the machine's speed, the presence of the scene does not.
    assert 1 <= scenes <= 421 and counts["/kite/markers"] == scenes and {"reference", "wind"} <= parts
    with open(mcap, "rb") as f:
        meta = {m.name: m.metadata for m in make_reader(f).iter_metadata()}
    assert {"/plant", "/controller", "/kite_viz", "kite_record"} <= set(meta), sorted(meta)
    assert meta["/plant"]["duration"] == "42.0"
    print(f"recording: {len(log_times)} messages, log time {min(log_times) / 1e9:g} .. {max(log_times) / 1e9:g} s, "
          f"{scenes} scenes, metadata {sorted(meta)}; {res.stdout.splitlines()[-1] if res.stdout else ''}")


@pytest.mark.ros
@pytest.mark.slow
def test_ctrl_c_during_optimization_keeps_the_database(ros_env, tmp_path):
    env = tagged_env(ros_env)
    demo = start_demo(["--iterations", "2", "--out", str(tmp_path), "--progress", "1"], env)
    out = Output(demo)
    try:
        assert out.wait_for(lambda ln: "] experiment k0-0-nominal" in ln, 600.0), out.lines
        assert out.wait_for(lambda ln: "iteration 1/2" in ln and "ETA" in ln, 60.0), out.lines
        kids = children(demo.pid)
        assert len(kids) == 3, kids                            # optimizer, controller, plant
        os.killpg(demo.pid, signal.SIGINT)
        demo.wait(timeout=180)
    finally:
        if demo.poll() is None:
            os.killpg(demo.pid, signal.SIGKILL)
            demo.wait()
    err = demo.stderr.read()
    out.thread.join(timeout=5)
    text = "\n".join(out.lines)
    assert demo.returncode == 130, (text, err)
    assert "Traceback" not in err + text
    assert not [pid for pid in kids if os.path.exists(f"/proc/{pid}")]
    assert not tagged_processes(env)
    assert "--resume continues" in text and (tmp_path / "rto.sqlite").exists()
