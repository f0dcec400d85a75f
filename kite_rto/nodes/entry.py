"""Entry points of the executables (``ros2 run kite_rto <name>``, ``.venv/bin/<name>``, or
``python -m kite_rto.nodes.entry <name> [args]``).

Each installs :data:`~kite_rto.nodes.stop_signals.STOP` first and only then imports its module (rclpy, numpy,
CasADi: up to seconds on a busy machine), so a Ctrl-C at any moment of the start-up is a clean stop.
"""
from __future__ import annotations

import importlib
import sys

from .stop_signals import STOP

__all__ = ["MODULES", "run", "plant", "controller", "optimizer", "echo_pilot", "kite_record", "kite_viz",
           "kite_foxglove"]

MODULES = {"plant": "kite_rto.nodes.plant_node", "controller": "kite_rto.nodes.controller_node",
           "optimizer": "kite_rto.nodes.optimizer_node", "echo_pilot": "kite_rto.nodes.echo_pilot",
           "kite_record": "kite_rto.tools.record", "kite_viz": "kite_rto.tools.viz",
           "kite_foxglove": "kite_rto.tools.foxglove_live"}
"""Executable name -> module with a ``main()``."""


def run(name: str):
    """Install the stop handlers, import ``MODULES[name]`` and run its ``main()``."""
    STOP.install()
    if STOP.signum is not None:
        return 0
    return importlib.import_module(MODULES[name]).main()


def plant():
    return run("plant")


def controller():
    return run("controller")


def optimizer():
    return run("optimizer")


def echo_pilot():
    return run("echo_pilot")


def kite_record():
    return run("kite_record")


def kite_viz():
    return run("kite_viz")


def kite_foxglove():
    return run("kite_foxglove")


if __name__ == "__main__":
    if len(sys.argv) < 2 or sys.argv[1] not in MODULES:
        print(f"usage: python -m kite_rto.nodes.entry {{{','.join(MODULES)}}} [args]", file=sys.stderr)
        sys.exit(2)
    exe = sys.argv.pop(1)
    sys.argv[0] = exe
    sys.exit(run(exe))
