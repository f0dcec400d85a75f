"""A node process for a test or a benchmark: started like ``ros2 run kite_rto <name>``, stopped with its output."""
from __future__ import annotations

import os
import signal
import subprocess

from ..tools.graph import node_command, start_process

__all__ = ["start_node", "stop_node"]


def start_node(name: str, params: dict | None = None, env=None, die_with_parent: bool = False,
               namespace: str | None = None) -> subprocess.Popen:
    """Start a node (in ``namespace``, default the root) in its own process group, output (stdout + stderr) on a
    text pipe."""
    return start_process(node_command(name, params, namespace), env, die_with_parent)


def stop_node(proc: subprocess.Popen, timeout: float = 10.0) -> str:
    """Ctrl-C the node (SIGINT), wait, kill its process group if it hangs; return its remaining output."""
    if proc.poll() is None:
        proc.send_signal(signal.SIGINT)
    try:
        out, _ = proc.communicate(timeout=timeout)
    except subprocess.TimeoutExpired:
        os.killpg(proc.pid, signal.SIGKILL)
        out, _ = proc.communicate()
    return out or ""
