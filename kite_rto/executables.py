"""Entry points of the executables (``ros2 run kite_rto <name>``, ``.venv/bin/<name>``, or
``python -m kite_rto.executables <name> [args]``): the top of the layer stack, above the tools and the nodes.

Each installs :data:`~kite_rto.nodes.stop_signals.STOP` first and only then imports its module (rclpy, numpy,
CasADi: up to seconds on a busy machine), so a Ctrl-C at any moment of the start-up is a clean stop. The imports
are inside the functions, where import-linter sees them like any other.
"""
from __future__ import annotations

import functools
import sys

from .nodes.stop_signals import STOP

__all__ = ["EXECUTABLES", "plant", "controller", "optimizer", "echo_pilot", "kite_record", "kite_viz",
           "kite_foxglove"]


def _entry(load):
    """The entry point of the executable ``load.__name__``: installs the stop handlers, then imports its module
    (``load()`` returns the module's ``main``) and runs it; exit 0 without starting if a stop signal already
    arrived."""
    @functools.wraps(load)
    def run():
        STOP.install()
        if STOP.signum is not None:
            return 0
        return load()()
    return run


@_entry
def plant():
    from .nodes.plant_node import main
    return main


@_entry
def controller():
    from .nodes.controller_node import main
    return main


@_entry
def optimizer():
    from .nodes.optimizer_node import main
    return main


@_entry
def echo_pilot():
    from .nodes.echo_pilot import main
    return main


@_entry
def kite_record():
    from .tools.record import main
    return main


@_entry
def kite_viz():
    from .tools.viz import main
    return main


@_entry
def kite_foxglove():
    from .tools.foxglove_live import main
    return main


EXECUTABLES = {f.__name__: f for f in (plant, controller, optimizer, echo_pilot, kite_record, kite_viz,
                                       kite_foxglove)}
"""Executable name -> entry point (the names of setup.py's console scripts that run through this module)."""


if __name__ == "__main__":
    if len(sys.argv) < 2 or sys.argv[1] not in EXECUTABLES:
        print(f"usage: python -m kite_rto.executables {{{','.join(EXECUTABLES)}}} [args]", file=sys.stderr)
        sys.exit(2)
    exe = sys.argv.pop(1)
    sys.argv[0] = exe
    sys.exit(EXECUTABLES[exe]())
