"""Fault injection, bad parameters (issue 7, item 1): every node refuses to start on a bad value or combination.

Each case starts the node as ``ros2 run kite_rto <node> --ros-args ...`` would and expects exit code 2 with a
message on stderr that names the parameter, the value and what is allowed. Each case records one row
``{"fault", "injection", "outcome", "experiments_lost", "unsafe_setpoints", "passed"}`` as a JSON line in
``$KITE_RTO_FAULT_LOG/fault_params.jsonl`` when that variable names a directory (the fault-suite table).
"""
import json
import os
import subprocess
from pathlib import Path

import pytest

from kite_rto.tools.graph import node_command

pytestmark = [pytest.mark.ros, pytest.mark.faults]

CONFIG = Path(__file__).resolve().parents[2] / "config" / "kite_rto.yaml"
LOG_ENV = "KITE_RTO_FAULT_LOG"

# (fault, node, --ros-args arguments, substrings expected on stderr); "{bad_yaml}" is a params file of the shipped
# defaults with w_ref: -8.0, "{missing}" a directory that does not exist.
CASES = [
    ("negative tether length", "plant", ["-p", "r:=-5.0"],
     ["parameter r = -5.0", "expected a number in [1, 5000] m"]),
    ("glide ratio E <= 0", "plant", ["-p", "E:=0.0"], ["parameter E = 0.0", "expected a number in [0.5, 30]"]),
    ("glide loss c_E >= E", "plant", ["-p", "E:=4.0", "-p", "c_E:=4.5"],
     ["KiteParams.c_E = 4.5", "expected a value in [0, E) = [0, 4)"]),
    ("unknown mode", "plant", ["-p", "mode:=fast"],
     ["parameter mode = 'fast'", "expected one of 'lockstep', 'realtime'"]),
    ("non-numeric sample time", "plant", ["-p", "dt:=abc"],
     ["parameter dt = 'abc'", "expected a number in [0.001, 0.1] s"]),
    ("non-integer seed", "plant", ["-p", "seed:=1.5"],
     ["parameter seed = 1.5", "expected an integer in [0, 2147483647]"]),
    ("negative wind in a params file", "plant", ["--params-file", "{bad_yaml}"],
     ["parameter w_ref = -8.0", "expected a number in [0.5, 40] m/s"]),
    ("inverted setpoint box", "controller", ["-p", "box_A_phi_deg:=[50.0,40.0]"],
     ["parameter box_A_phi_deg = [50.0, 40.0]", "with low <= high"]),
    ("empty setpoint box", "controller", ["-p", "box_theta_0_deg:=[]"],
     ["parameter box_theta_0_deg = <empty or not set>", "expected a list of 2 numbers, each in [1, 89] deg"]),
    ("initial setpoint outside the box", "controller", ["-p", "theta_0_deg:=20.0"],
     ["initial setpoints (theta_0_deg, A_phi_deg, A_theta_deg)", "outside the box", "[30, 40] deg"]),
    ("negative controller gain", "controller", ["-p", "k_psi:=-3.0"],
     ["parameter k_psi = -3.0", "expected a number in [0.01, 100] 1/s"]),
    ("NaN steering limit", "controller", ["-p", "delta_max:=.nan"],
     ["parameter delta_max = nan", "expected a number in [0.05, 1]"]),
    ("zero laps per experiment", "optimizer", ["-p", "n_laps:=0"],
     ["parameter n_laps = 0", "expected an integer in [1, 100] laps"]),
    ("unknown gradient method", "optimizer", ["-p", "gradient:=newton"],
     ["parameter gradient = 'newton'", "expected one of 'directional', 'forward', 'central', 'least_squares'"]),
    ("more privileged directions than setpoints", "optimizer", ["-p", "n_directions:=4"],
     ["parameter n_directions = 4", "expected an integer in [1, 3] directions"]),
    ("settle time not below the experiment limit", "optimizer", ["-p", "settle_time:=400.0"],
     ["parameters settle_time = 400.0, max_duration = 300.0", "expected settle_time < max_duration"]),
    ("exit_when_done with no iteration limit", "optimizer", ["-p", "exit_when_done:=true", "-p", "n_iter:=0"],
     ["parameters exit_when_done = True, n_iter = 0", "expected n_iter > 0"]),
    ("database in a missing directory", "optimizer", ["-p", "db:={missing}/rto.sqlite"],
     ["parameter db = '{missing}/rto.sqlite'", "expected a file in an existing directory"]),
    ("inverted optimizer box", "optimizer", ["-p", "box_aspect:=[0.22,0.16]"],
     ["parameter box_aspect = [0.22, 0.16]", "with low < high"]),
    ("untrackable optimizer box", "optimizer", ["-p", "box_aspect:=[0.10,0.22]"],
     ["box_aspect = [0.1, 0.22]", "trackable", "infeasible turn"]),
    ("misspelt parameter name", "plant", ["-p", "w_reff:=20.0"],
     ["unknown parameter w_reff = 20.0", "node plant has no such parameter", "did you mean w_ref?"]),
    ("misspelt parameter in a params file", "controller", ["--params-file", "{typo_yaml}"],
     ["unknown parameter k_pis = 3.0", "node controller has no such parameter", "did you mean k_psi?"]),
]


def _record(row: dict) -> None:
    directory = os.environ.get(LOG_ENV)
    if directory:
        Path(directory).mkdir(parents=True, exist_ok=True)
        with open(Path(directory) / "fault_params.jsonl", "a") as f:
            f.write(json.dumps(row) + "\n")


def test_cases_cover_every_node():
    assert len(CASES) >= 12
    assert {c[1] for c in CASES} == {"plant", "controller", "optimizer"}
    assert len({c[0] for c in CASES}) == len(CASES)


@pytest.mark.parametrize("fault,node,args,needles", CASES, ids=[c[0].replace(" ", "_") for c in CASES])
def test_bad_parameter_stops_the_node(fault, node, args, needles, ros_env, tmp_path):
    bad_yaml = tmp_path / "bad.yaml"
    bad_yaml.write_text(CONFIG.read_text().replace("    w_ref: 8.0", "    w_ref: -8.0"))
    typo_yaml = tmp_path / "typo.yaml"
    typo_yaml.write_text(CONFIG.read_text().replace("    k_psi:", "    k_pis:"))
    subst = {"bad_yaml": str(bad_yaml), "typo_yaml": str(typo_yaml), "missing": str(tmp_path / "missing")}
    raw_args, args = args, [a.format(**subst) for a in args]
    needles = [n.format(**subst) for n in needles]
    shown = {"bad_yaml": "bad.yaml (the shipped defaults with w_ref: -8.0)",
             "typo_yaml": "typo.yaml (the shipped defaults with k_psi written k_pis)", "missing": "/missing-dir"}
    injection = f"{node} --ros-args {' '.join(a.format(**shown) for a in raw_args)}"
    row = {"fault": f"bad parameter: {fault}", "injection": injection, "outcome": "", "experiments_lost": 0,
           "unsafe_setpoints": 0, "passed": False}
    try:
        # cwd: a scratch directory, so that an optimizer which wrongly starts writes nothing into the repository
        # generous: the optimizer's checks of n_directions need the model's directions (40 s cold on a busy machine)
        res = subprocess.run(node_command(node) + args, env=ros_env, capture_output=True, text=True, timeout=300,
                             cwd=tmp_path)
        message = next((line for line in res.stderr.splitlines() if "refusing to start" in line),
                       (res.stderr.strip().splitlines() or ["(no message)"])[-1])
        row["outcome"] = f"exit {res.returncode}: {message.strip()}"
        row["passed"] = res.returncode == 2 and all(n in res.stderr for n in needles)
    except subprocess.TimeoutExpired:
        row["outcome"] = "still running after 300 s: the node accepted the bad value"
    finally:
        _record(row)
    assert row["passed"], (row["outcome"], needles)
