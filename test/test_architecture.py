"""The architecture contracts in ``.importlinter`` (docs/architecture.md): they hold on this tree, and each one
fails when its rule is broken in a copy of the package.

import-linter builds the import graph statically (function-level imports count too) from the ``kite_rto`` found
first on ``PYTHONPATH``; every run here puts the tree under test first, so the installed copy is never linted.
"""
import os
import shutil
import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
CONFIG = ROOT / ".importlinter"
CONTRACTS = 5
LINT = "from importlinter.cli import lint_imports_command; lint_imports_command()"


def lint(tree: Path) -> subprocess.CompletedProcess:
    """Run ``lint-imports`` (no cache: nothing is written into the tree) on the ``kite_rto`` package in ``tree``."""
    env = dict(os.environ, PYTHONPATH=os.pathsep.join([str(tree), os.environ.get("PYTHONPATH", "")]),
               NO_COLOR="1", COLUMNS="200")
    return subprocess.run([sys.executable, "-c", LINT, str(CONFIG), "--no-cache", "--no-logo"], cwd=tree, env=env,
                          capture_output=True, text=True, timeout=120)


def test_the_architecture_contracts_hold():
    res = lint(ROOT)
    assert res.returncode == 0, res.stdout + res.stderr
    assert f"Contracts: {CONTRACTS} kept, 0 broken." in res.stdout, res.stdout


CROSSINGS = {
    # a module of one layer gets one line that breaks one rule: (file, line, the contract that must fail)
    "rclpy in kite": ("kite/params.py", "import rclpy", "never imports ROS 2"),
    "a message package in rto, inside a function": ("rto/session.py", "def _late():\n    import std_msgs.msg",
                                                    "never imports ROS 2"),
    "flight in kite": ("kite/wind.py", "from ..flight import path", "Layers"),
    "rto in flight": ("flight/laps.py", "from ..rto import experiment", "Layers"),
    "tools in nodes": ("nodes/topics.py", "from ..tools import progress", "Layers"),
    "kite in gma": ("gma/settings.py", "from ..kite import params", "gma is a generic library"),
    "a cycle inside tools": ("tools/progress.py", "from . import demo", "No import cycle"),
    "rclpy in campaign": ("campaign/tasks.py", "import rclpy", "never imports ROS 2"),
    "campaign in rto": ("rto/baselines.py", "from ..campaign import scenarios", "Layers"),
    "nodes in campaign": ("campaign/summary.py", "from ..nodes import topics", "Layers"),
    "rclpy in runtime": ("runtime/pace.py", "import rclpy", "never imports ROS 2"),
    "runtime in rto": ("rto/session.py", "from ..runtime import sample_join", "Layers"),
    "nodes in runtime": ("runtime/run_db.py", "from ..nodes import topics", "Layers"),
    "the test rig in nodes, inside a function": ("nodes/topics.py", "def _late():\n    from ..testing import launch",
                                                 "never imported by the runtime path"),
    "the executables in tools": ("tools/progress.py", "from .. import executables", "Layers"),
}


@pytest.mark.parametrize("crossing", sorted(CROSSINGS))
def test_a_crossed_rule_breaks_its_contract(tmp_path, crossing):
    path, line, contract = CROSSINGS[crossing]
    shutil.copytree(ROOT / "kite_rto", tmp_path / "kite_rto", ignore=shutil.ignore_patterns("__pycache__"))
    with open(tmp_path / "kite_rto" / path, "a") as f:
        f.write(f"\n{line}\n")
    res = lint(tmp_path)
    assert res.returncode == 1, res.stdout + res.stderr
    assert "Broken contracts" in res.stdout and " 0 broken." not in res.stdout, res.stdout
    broken = res.stdout[res.stdout.index("Broken contracts"):]      # an upward import is a cycle as well
    assert contract in broken, res.stdout
