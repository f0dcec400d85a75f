"""Start kite_rto nodes as separate processes (no ROS launch system needed) and stop them cleanly."""
from __future__ import annotations

import ctypes
import os
import random
import signal
import subprocess
import sys
import threading
import time

__all__ = ["GraphRun", "NodeProcess", "isolated_ros_env", "node_command", "start_process", "stop_all", "close_graph",
           "stopped_by_signal"]

SIGNALLED = False
"""Set by the demo's SIGINT/SIGTERM handler: an error raised inside rclpy after it is part of the stop, not a bug."""

_PR_SET_PDEATHSIG = 1


def _prctl():
    """libc's prctl, looked up in the parent (the child between fork and exec must not import anything)."""
    try:
        return ctypes.CDLL(None, use_errno=True).prctl
    except (OSError, AttributeError):
        return None


_PRCTL = _prctl() if sys.platform.startswith("linux") else None


def _die_with_parent():
    """In the child before exec: ask Linux to send SIGTERM when the parent dies (even by SIGKILL), so that a
    killed launcher leaves no orphan nodes. (Tied to the thread that started the child: start from the main
    thread.)"""
    _PRCTL(_PR_SET_PDEATHSIG, int(signal.SIGTERM), 0, 0, 0)


def node_command(name: str, params: dict | None = None, namespace: str | None = None) -> list[str]:
    """The command line of ``ros2 run kite_rto <name> --ros-args [-r __ns:=<namespace>] -p k:=v ...`` for this
    interpreter (a process started through :mod:`kite_rto.executables`, not an import of it)."""
    cmd = [sys.executable, "-m", "kite_rto.executables", name, "--ros-args"]
    if namespace not in (None, "/"):
        cmd += ["-r", f"__ns:={namespace}"]
    for k, v in (params or {}).items():
        cmd += ["-p", f"{k}:={str(v).lower() if isinstance(v, bool) else v}"]
    return cmd


def start_process(cmd: list, env=None, die_with_parent: bool = False) -> subprocess.Popen:
    """Start ``cmd`` in its own session and process group (a terminal's Ctrl-C does not reach it: the launcher
    stops it), output (stdout + stderr) on a text pipe; ``die_with_parent``: SIGTERM it if the launcher dies."""
    return subprocess.Popen(cmd, env=env or dict(os.environ), stdout=subprocess.PIPE, stderr=subprocess.STDOUT,
                            text=True, start_new_session=True,
                            preexec_fn=_die_with_parent if die_with_parent and _PRCTL is not None else None)


def isolated_ros_env(domain_id: int | None = None) -> dict:
    """Set (in os.environ, before rclpy.init) a ROS domain and localhost-only discovery; return the env."""
    if domain_id is None:
        domain_id = int(os.environ.get("ROS_DOMAIN_ID", random.Random(os.getpid()).randint(1, 100)))
    os.environ["ROS_DOMAIN_ID"] = str(domain_id)
    os.environ.setdefault("ROS_AUTOMATIC_DISCOVERY_RANGE", "LOCALHOST")
    os.environ["PYTHONUNBUFFERED"] = "1"
    return dict(os.environ)


class NodeProcess:
    """One node in its own process, the same entry point as ``ros2 run kite_rto <name>`` (or any ``cmd``).

    Its output lines go to ``log`` (a file object) and are kept in ``lines``. The process gets SIGTERM if the
    launcher dies without stopping it.
    """

    def __init__(self, name: str, params: dict | None = None, log=None, env=None, cmd: list | None = None,
                 namespace: str | None = None):
        self.name = name
        self.lines: list[str] = []
        self.proc = start_process(cmd or node_command(name, params, namespace), env, die_with_parent=True)
        self._log = log
        self._reader = threading.Thread(target=self._read, daemon=True)
        self._reader.start()

    def _read(self):
        for line in self.proc.stdout:
            self.lines.append(line.rstrip())
            if self._log is not None:
                self._log.write(f"[{self.name}] {line}")
                self._log.flush()

    def alive(self) -> bool:
        return self.proc.poll() is None

    def interrupt(self) -> None:
        """Send Ctrl-C (SIGINT) if it still runs."""
        if self.proc.poll() is None:
            try:
                self.proc.send_signal(signal.SIGINT)
            except ProcessLookupError:
                pass

    def stop(self, timeout: float = 10.0) -> int:
        """Ctrl-C the node, wait, kill its process group if it hangs; return its exit code."""
        self.interrupt()
        try:
            self.proc.wait(timeout)
        except subprocess.TimeoutExpired:
            try:
                os.killpg(self.proc.pid, signal.SIGKILL)
            except ProcessLookupError:
                pass
            self.proc.wait()
        self._reader.join(timeout=2.0)
        return self.proc.returncode


def stop_all(procs, timeout: float = 10.0) -> None:
    """Stop several :class:`NodeProcess` at once: Ctrl-C all of them in the given order, then wait for each
    (killing what hangs past ``timeout`` s in total). A second Ctrl-C of the launcher meanwhile is ignored, so the
    nodes are always reaped."""
    previous = signal.getsignal(signal.SIGINT) if threading.current_thread() is threading.main_thread() else None
    if previous is not None:
        signal.signal(signal.SIGINT, signal.SIG_IGN)
    try:
        for p in procs:
            p.interrupt()
        deadline = time.monotonic() + timeout
        for p in procs:
            p.stop(max(0.1, deadline - time.monotonic()))
    finally:
        if previous is not None:
            signal.signal(signal.SIGINT, previous)


def stopped_by_signal(exc: BaseException) -> bool:
    """True for Ctrl-C (``KeyboardInterrupt``) and for the ``RuntimeError`` rclpy's C++ layer raises when SIGINT or
    SIGTERM arrived inside one of its calls (:data:`SIGNALLED` set): a stop, not a failure."""
    return isinstance(exc, KeyboardInterrupt) or (isinstance(exc, RuntimeError) and SIGNALLED)


def close_graph(procs, node, log) -> None:
    """Stop the node processes (last started first), close their shared log, destroy the in-process observer
    ``node`` and shut rclpy down."""
    import rclpy    # here, not on top: the demo imports this module before `--help` is answered (rclpy: ~0.4 s)
    stop_all(list(reversed(procs)))
    log.close()
    node.destroy_node()
    rclpy.try_shutdown()


class GraphRun:
    """``with GraphRun(procs, node, log, progress) as run:`` around a run of the graph: whatever happens, the
    progress line is cleared and the graph closed (:func:`close_graph`); a stop by signal (Ctrl-C, SIGTERM) ends
    the block quietly with ``run.interrupted = True``, any other error propagates."""

    def __init__(self, procs, node, log, progress):
        self.procs, self.node, self.log, self.progress = procs, node, log, progress
        self.interrupted = False

    def __enter__(self) -> "GraphRun":
        return self

    def __exit__(self, exc_type, exc, tb) -> bool:
        self.progress.clear()
        close_graph(self.procs, self.node, self.log)
        self.interrupted = exc is not None and stopped_by_signal(exc)
        return self.interrupted
