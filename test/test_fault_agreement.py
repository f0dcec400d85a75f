"""Parameters that must agree between controller and plant (issue 18, item 5): a mismatch is reported at start-up.

The controller asks the plant (the publisher of /kite/state) for its parameters through the plant's standard
``get_parameters`` service as soon as the plant appears, and logs one error line per parameter that must be equal
(``dt``, ``r``, ``z_ref``). Model parameters (E, g_s, shear) differ by design: one info line.
"""
import pytest

from kite_rto.nodes.peer_check import compare

from faultlog import fault_row
from rosutil import Probe, start_node, stop

pytestmark = [pytest.mark.ros]


def test_compare_separates_must_agree_from_model_parameters():
    mine = {"dt": 0.02, "r": 300.0, "z_ref": 10.0, "E": 5.0, "g_s": 0.04}
    theirs = {"dt": 0.02, "r": 400.0, "z_ref": 10.0 + 1e-13, "E": 4.6, "g_s": 0.04}
    assert compare(mine, theirs) == (["r"], ["E"])
    assert compare(mine, {}) == ([], [])              # a plant that did not answer a name: nothing claimed


def _flight(ros_env, controller_params):
    probe = Probe("agreement_probe")
    ctrl = start_node("controller", controller_params, ros_env)
    try:
        assert probe.spin_until(lambda: probe.node.count_subscribers("/kite/state") > 0, 120.0)
        # long enough that the controller's parameter check (a service call to the plant) lands while the plant lives,
        # also on a quiet, fast machine (20 s of lockstep flight took about 2 s there, too short)
        plant = start_node("plant", {"duration": 300.0, "turbulence": False}, ros_env)
        plant_out = plant.communicate(timeout=300)[0]
        assert plant.returncode == 0, plant_out[-2000:]
    finally:
        out = stop(ctrl)
        probe.close()
    return out


@pytest.mark.faults
@pytest.mark.parametrize("params, bad", [({"dt": 0.01, "r": 300.0}, ["dt", "r"]), ({}, [])],
                         ids=["dt-and-r-differ", "defaults-agree"])
def test_controller_reports_parameters_that_differ_from_the_plants(request, ros_env, params, bad):
    fault = "controller dt and r differ from the plant's" if bad else "controller and plant with the defaults"
    injection = ("controller -p dt:=0.01 -p r:=300.0, plant with its defaults (dt 0.02 s, r 400 m)" if bad
                 else "controller and plant, defaults")
    with fault_row(request, fault, injection) as row:
        out = _flight(ros_env, params)
        errors = [line for line in out.splitlines() if "[ERROR]" in line and "differs from plant" in line]
        row.outcome = (f"{len(errors)} error line(s) at start-up: " + " | ".join(e.split("]: ", 1)[-1] for e in errors)
                       if errors else "no error line; " + next((line.split("]: ", 1)[-1] for line in out.splitlines()
                                                                 if "agree" in line), "no agreement line"))
        row.experiments_lost = None
        row.unsafe_setpoints = 0
        assert [n for n in ("dt", "r", "z_ref") if any(f"parameter {n} = " in e for e in errors)] == bad, out
        if bad:
            assert "restart controller with -p dt:=0.02" in out and "-p r:=400" in out
        else:
            assert "dt = 0.02, r = 400, z_ref = 10 agree" in out, out
