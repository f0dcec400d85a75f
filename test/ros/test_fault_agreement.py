"""Parameters that must agree between controller and plant (issue 18, item 5): a mismatch is reported at start-up.

The controller asks the plant (the publisher of /kite/state) for its parameters through the plant's standard
``get_parameters`` service as soon as the plant appears, and logs one error line per parameter that must be equal
(``dt``, ``r``, ``z_ref``). Model parameters (E, g_s, shear) differ by design: one info line.
"""
import pytest

from kite_rto.nodes.peer_check import compare

from faultgraph import node, stop_all
from faultlog import fault_row
from rosutil import Probe

pytestmark = [pytest.mark.ros]


def test_compare_separates_must_agree_from_model_parameters():
    mine = {"dt": 0.02, "r": 300.0, "z_ref": 10.0, "E": 5.0, "g_s": 0.04}
    theirs = {"dt": 0.02, "r": 400.0, "z_ref": 10.0 + 1e-13, "E": 4.6, "g_s": 0.04}
    assert compare(mine, theirs) == (["r"], ["E"])
    assert compare(mine, {}) == ([], [])              # a plant that did not answer a name: nothing claimed


CHECK_TIMEOUT = 120.0
"""Wall s the controller gets to log its parameter check once the plant flies (it asks within a few seconds)."""


def _checked(line: str) -> bool:
    """A line of the controller's parameter check: an error per differing parameter, or the agreement line. All
    lines of one check are logged in one callback, and a node stops only between callbacks: once one is out, all
    are."""
    return "differs from plant" in line or line.endswith(" agree")


def _flight(ros_env, controller_params):
    """Controller, then a plant that flies until stopped; both are stopped once the controller has logged its
    check (or the plant exited): the verdict does not depend on how fast the flight runs."""
    probe = Probe("agreement_probe")
    ctrl = node("controller", "controller", ros_env, params=controller_params)
    plant = None
    try:
        assert probe.spin_until(lambda: probe.node.count_subscribers("/kite/state") > 0, 120.0), ctrl.text()
        plant = node("plant", "plant", ros_env, params={"duration": 0.0, "turbulence": False})
        probe.spin_until(lambda: any(_checked(line) for line in list(ctrl.lines)) or not plant.alive(),
                         CHECK_TIMEOUT)
        assert plant.alive(), "plant exited before the controller's check:\n" + plant.text()[-2000:]
    finally:
        stop_all([ctrl, plant])
        probe.close()
    assert plant.proc.returncode == 0, plant.text()[-2000:]
    return ctrl.text()


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
