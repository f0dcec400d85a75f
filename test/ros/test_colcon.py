"""The package builds with colcon (ament_python) and the installed executables run, as after `ros2 run`."""
import shutil
import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[2]
pytestmark = pytest.mark.ros


@pytest.fixture(scope="module")
def workspace(tmp_path_factory):
    ws = tmp_path_factory.mktemp("colcon_ws")
    src = ws / "src" / "kite_rto"
    files = subprocess.run(["git", "ls-files", "--cached", "--others", "--exclude-standard"], cwd=ROOT,
                           capture_output=True, text=True, check=True).stdout.split()
    for f in files:
        if (ROOT / f).is_file():
            (src / f).parent.mkdir(parents=True, exist_ok=True)
            shutil.copy2(ROOT / f, src / f)
    venv_bin = Path(sys.executable).parent
    res = subprocess.run(f'export PATH="{venv_bin}:$PATH" && colcon build --event-handlers console_direct-',
                         shell=True, cwd=ws, capture_output=True, text=True, timeout=600, executable="/bin/bash")
    assert res.returncode == 0, res.stdout[-3000:] + res.stderr[-3000:]
    return ws


def run_installed(ws, exe, args, env, timeout=120):
    cmd = f"source install/setup.bash && install/kite_rto/lib/kite_rto/{exe} {args}"
    return subprocess.run(cmd, shell=True, cwd=ws, capture_output=True, text=True, timeout=timeout,
                          executable="/bin/bash", env=env)


def test_colcon_installs_package_files(workspace):
    share = workspace / "install" / "kite_rto" / "share"
    assert (share / "ament_index" / "resource_index" / "packages" / "kite_rto").exists()
    assert (share / "kite_rto" / "package.xml").exists()
    installed = share / "kite_rto" / "config" / "kite_rto.yaml"
    assert installed.read_text() == (ROOT / "config" / "kite_rto.yaml").read_text()
    profile = share / "kite_rto" / "config" / "fastdds_profile.xml"
    assert profile.read_text() == (ROOT / "config" / "fastdds_profile.xml").read_text()
    for exe in ("plant", "echo_pilot"):
        assert (workspace / "install" / "kite_rto" / "lib" / "kite_rto" / exe).exists()


def test_installed_plant_runs_and_validates(workspace, ros_env):
    res = run_installed(workspace, "plant", "--ros-args -p mode:=realtime -p rate_factor:=10.0 -p duration:=0.5", ros_env)
    assert res.returncode == 0, res.stdout + res.stderr
    assert "duration reached" in res.stdout + res.stderr
    # the installed node found the installed DDS profile through the ament index
    assert "share/kite_rto/config/fastdds_profile.xml (shipped with kite_rto)" in res.stdout + res.stderr
    res = run_installed(workspace, "plant", "--ros-args -p r:=-5.0", ros_env)
    assert res.returncode == 2 and "parameter r = -5.0" in res.stderr


def test_installed_plant_reads_params_file(workspace, ros_env):
    cfg = workspace / "install" / "kite_rto" / "share" / "kite_rto" / "config" / "kite_rto.yaml"
    res = run_installed(workspace, "plant", f"--ros-args --params-file {cfg} -p mode:=realtime -p rate_factor:=10.0 -p duration:=0.2 "
                        , ros_env)
    assert res.returncode == 0, res.stdout + res.stderr
    # a value from the command line after the installed file still goes through the same check
    res = run_installed(workspace, "controller", f"--ros-args --params-file {cfg} -p k_psi:=500.0", ros_env)
    assert res.returncode == 2 and "parameter k_psi = 500.0: expected a number in [0.01, 100] 1/s" in res.stderr
