"""Helpers of the fault-injection tests: node processes with remapping and logs, the fault relay, a topic watch
that counts unsafe setpoints, and a probe in a second ROS domain."""
from __future__ import annotations

import json
import math
import os
import signal
import subprocess
import sys
import threading
import time

import numpy as np
import rclpy
from nav_msgs.msg import Path
from rclpy.context import Context
from rclpy.executors import SingleThreadedExecutor
from rclpy.node import Node
from rosgraph_msgs.msg import Clock
from sensor_msgs.msg import JointState
from std_msgs.msg import UInt32

from kite_rto.kite.params import KiteParams
from kite_rto.flight.path import SetpointBox, SetpointError, validate_setpoints
from kite_rto.nodes.interface import LATCHED, RELIABLE_10, stamp_to_ns
from kite_rto.tools.graph import node_command
from rosutil import DIE_WITH_PARENT, Probe

QUIET = {"turbulence": False, "anemometer_noise": 0.0, "noise_angle_deg": 0.0, "noise_rate": 0.0,
         "noise_tension": 0.0}
SHORT = {"n_laps": 1, "settle_laps": 0, "n_iter": 1, "exit_when_done": True}


class Proc:
    """A command in its own process group; output lines kept in ``lines`` and copied to ``log_path``."""

    def __init__(self, label: str, cmd: list, env: dict, log_dir=None):
        self.label = label
        self.cmd = cmd
        self.lines: list[str] = []
        self.log_path = None if log_dir is None else os.path.join(str(log_dir), f"{label}.log")
        self._log = None if self.log_path is None else open(self.log_path, "a")
        self.proc = subprocess.Popen(cmd, env=env, stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True,
                                     start_new_session=True, preexec_fn=DIE_WITH_PARENT)
        self.pid = self.proc.pid
        self._reader = threading.Thread(target=self._read, daemon=True)
        self._reader.start()

    def _read(self):
        for line in self.proc.stdout:
            line = line.rstrip("\n")
            self.lines.append(line)
            if self._log is not None:
                self._log.write(line + "\n")
                self._log.flush()

    def text(self) -> str:
        return "\n".join(self.lines)

    def count(self, needle: str) -> int:
        return sum(needle in line for line in list(self.lines))

    def matching(self, needle: str) -> list[str]:
        return [line for line in list(self.lines) if needle in line]

    def alive(self) -> bool:
        return self.proc.poll() is None

    def kill(self) -> int:
        """SIGKILL the process group (a crash: no clean shutdown); return the exit code."""
        if self.proc.poll() is None:
            os.killpg(self.pid, signal.SIGKILL)
        code = self.proc.wait()
        self._reader.join(timeout=2.0)
        return code

    def stop(self, timeout: float = 10.0) -> int:
        """Ctrl-C, wait, SIGKILL the group if it hangs; return the exit code."""
        if self.proc.poll() is None:
            self.proc.send_signal(signal.SIGINT)
            try:
                self.proc.wait(timeout)
            except subprocess.TimeoutExpired:
                os.killpg(self.pid, signal.SIGKILL)
                self.proc.wait()
        self._reader.join(timeout=2.0)
        if self._log is not None:
            self._log.close()
            self._log = None
        return self.proc.returncode


def node(label: str, name: str, env: dict, log_dir=None, params: dict | None = None, remap: dict | None = None):
    """``ros2 run kite_rto <name> --ros-args -p ... -r from:=to`` as a :class:`Proc`."""
    cmd = node_command(name, params)
    for a, b in (remap or {}).items():
        cmd += ["-r", f"{a}:={b}"]
    return Proc(label, cmd, env, log_dir)


def relay(label: str, env: dict, log_dir=None, **opts) -> Proc:
    """``python -m kite_rto.testing.fault_relay --in .. --out .. --type ..`` (opts: in_, out, type, drop, ...)."""
    cmd = [sys.executable, "-m", "kite_rto.testing.fault_relay"]
    for k, v in opts.items():
        k = k.rstrip("_").replace("_", "-")
        if v is True:
            cmd.append(f"--{k}")
        elif v is not None and v is not False:
            cmd += [f"--{k}", str(v)]
    cmd += ["--name", f"relay_{label}"]
    return Proc(label, cmd, env, log_dir)


def relay_summary(proc: Proc) -> dict:
    """The counts a stopped relay printed (``fault_relay summary: {json}``)."""
    for line in reversed(proc.lines):
        if "fault_relay summary: " in line:
            return json.loads(line.split("fault_relay summary: ", 1)[1])
    raise AssertionError(f"relay {proc.label} printed no summary:\n" + "\n".join(proc.lines[-20:]))


def stop_all(procs) -> None:
    for p in reversed([p for p in procs if p is not None]):
        p.stop()


# ----------------------------------------------------------------------------------------------- observation
_BOX_TOL = 1e-9     # rad: a decoded path is checked against the box widened by float round-off only


def decode_path(msg: Path, r: float = KiteParams().r) -> np.ndarray:
    """Setpoints (theta_0, A_phi, A_theta), rad, of a /kite/reference_path (181 poses over s in [0, 2 pi])."""
    xyz = np.array([(p.pose.position.x, p.pose.position.y, p.pose.position.z) for p in msg.poses])
    theta = np.arctan2(np.hypot(xyz[:, 1], xyz[:, 2]), xyz[:, 0])
    phi = np.arctan2(xyz[:, 1], xyz[:, 2])
    s = np.linspace(0.0, 2 * math.pi, len(xyz))
    a_phi = float(np.dot(phi, np.sin(s)) / np.dot(np.sin(s), np.sin(s)))
    (theta_0, a_theta), *_ = np.linalg.lstsq(np.c_[np.ones_like(s), np.sin(2 * s)], theta, rcond=None)
    return np.array([theta_0, a_phi, a_theta])


def unsafe(c, tol: float = 0.0) -> bool:
    """True if ``c`` (rad) fails :func:`validate_setpoints` on the default box (widened by ``tol``)."""
    b = SetpointBox()
    box = SetpointBox(*[(lo - tol, hi + tol) for lo, hi in (b.theta_0, b.A_phi, b.A_theta)])
    try:
        validate_setpoints(np.asarray(c, dtype=float), box, KiteParams())
        return False
    except SetpointError:
        return True


class Watch:
    """Subscribes what every fault test checks: /clock, /rto/setpoints, /kite/reference_path, /kite/crashes."""

    def __init__(self, node: Node, clock: bool = True):
        self.clock_ns = -1
        self.clocks = 0
        self.setpoints: list[np.ndarray] = []
        self.paths: list[np.ndarray] = []
        self.crashes = None
        if clock:
            node.create_subscription(Clock, "/clock", self._clock, 10)
        node.create_subscription(JointState, "/rto/setpoints", self._setpoints, LATCHED)
        node.create_subscription(Path, "/kite/reference_path", self._path, LATCHED)
        node.create_subscription(UInt32, "/kite/crashes", self._crashes, LATCHED)

    def _clock(self, msg):
        self.clock_ns = stamp_to_ns(msg.clock)
        self.clocks += 1

    def _setpoints(self, msg):
        d = dict(zip(msg.name, msg.position))
        try:
            self.setpoints.append(np.array([d["theta_0"], d["A_phi"], d["A_theta"]], dtype=float))
        except KeyError:
            self.setpoints.append(np.full(3, np.nan))

    def _path(self, msg):
        self.paths.append(decode_path(msg))

    def _crashes(self, msg):
        self.crashes = int(msg.data)

    @property
    def t(self) -> float:
        return self.clock_ns * 1e-9

    def unsafe_published(self) -> int:
        return sum(unsafe(c) for c in self.setpoints)

    def unsafe_applied(self) -> int:
        return sum(unsafe(c, _BOX_TOL) for c in self.paths)


class DomainProbe(Probe):
    """An rclpy node in another ROS domain (its own context), spun on demand like ``rosutil.Probe``."""

    def __init__(self, domain_id: int, name: str = "probe_b"):
        self.context = Context()
        rclpy.init(context=self.context, domain_id=domain_id)
        self.node = Node(name, context=self.context)
        self.executor = SingleThreadedExecutor(context=self.context)
        self.executor.add_node(self.node)

    def close(self):
        super().close()
        rclpy.try_shutdown(context=self.context)


def spin_all(probes, seconds: float) -> None:
    """Spin several probes (e.g. two domains) round-robin for ``seconds`` wall."""
    end = time.monotonic() + seconds
    while time.monotonic() < end:
        for p in probes:
            p.executor.spin_once(timeout_sec=0.005)


def steering_recorder(node: Node, topic: str = "/kite/steering", depth: int = 5000) -> dict:
    """{stamp ns: first delta answered} of every steering message on ``topic`` (deep queue: none lost)."""
    from rclpy.qos import QoSProfile, ReliabilityPolicy
    got: dict = {}

    def cb(m):
        got.setdefault(stamp_to_ns(m.header.stamp), m.position[0] if len(m.position) == 1 else math.nan)

    node.create_subscription(JointState, topic, cb, QoSProfile(depth=depth, reliability=ReliabilityPolicy.RELIABLE))
    return got


__all__ = ["QUIET", "SHORT", "Proc", "node", "relay", "relay_summary", "stop_all", "decode_path", "unsafe", "Watch",
           "DomainProbe", "spin_all", "steering_recorder", "RELIABLE_10"]
