"""Path controller: setpoint handling, measured-only inputs, saturation, dead-time compensation."""
import math
from dataclasses import replace
from types import SimpleNamespace

import numpy as np
import pytest

from kite_rto.flight.closed_loop import make_closed_loop, run_closed_loop
from kite_rto.flight.controller import ControllerSettings, PathController
from kite_rto.kite.params import KiteParams, ParameterError
from kite_rto.flight.path import DEFAULT_SETPOINTS, SetpointBox, SetpointError, Setpoints
from kite_rto.flight.shape import ShapeBox
from kite_rto.kite.model import shared_model
from kite_rto.kite.plant import PlantConfig

QUIET = PlantConfig().without_disturbances()


def _controller(**kw):
    return PathController(shared_model(), KiteParams(), DEFAULT_SETPOINTS, ControllerSettings(**kw))


@pytest.mark.parametrize("bad, match", [
    (Setpoints(math.nan, 0.8, 0.12), "theta_0 = nan"),
    ((0.6, 0.8, math.inf), "A_theta = inf"),
    (Setpoints.from_degrees(35, 45, 20), "A_theta .* outside the box"),
    (Setpoints.from_degrees(35, 80, 7), "A_phi .* outside the box"),
    ([1.0, 2.0], "expected 3 values"),
])
def test_bad_setpoints_rejected_and_path_kept(bad, match):
    ctl = _controller()
    before = ctl.path.setpoints
    with pytest.raises(SetpointError, match=match):
        ctl.set_setpoints(bad)
    assert ctl.setpoints == DEFAULT_SETPOINTS and ctl.path.setpoints == before


def test_infeasible_setpoints_rejected():
    wide = SetpointBox(theta_0=(0.3, 1.2), A_phi=(0.1, 1.0), A_theta=(0.01, 0.2))
    ctl = _controller(box=wide)
    with pytest.raises(SetpointError, match="infeasible turn"):
        ctl.set_setpoints(Setpoints.from_degrees(22, 15, 4))
    assert ctl.setpoints == DEFAULT_SETPOINTS
    with pytest.raises(SetpointError):
        PathController(shared_model(), KiteParams(), Setpoints.from_degrees(22, 15, 4), ControllerSettings())


def test_settings_validation_names_the_value():
    with pytest.raises(ParameterError, match="delta_max = 1.5"):
        ControllerSettings(delta_max=1.5)
    with pytest.raises(ParameterError, match="look_ahead"):
        ControllerSettings(look_ahead=-0.1)


def test_uses_only_measured_quantities_and_saturates():
    """A bare object with the ground station's measurements is enough; |delta| <= delta_max always."""
    ctl = _controller(delta_max=0.8)
    m = SimpleNamespace(t=0.0, theta=0.6, phi=0.3, psi=2.5, theta_dot=-0.05, phi_dot=0.1, psi_dot=0.0,
                        wind_ref=8.0)
    out = []
    for k in range(100):
        m.t = k * 0.02
        out.append(ctl.command(m))
    assert all(abs(u) <= 0.8 + 1e-12 for u in out)
    assert max(abs(u) for u in out) == pytest.approx(0.8)
    assert np.max(np.abs(np.diff(out))) <= 5.0 * 0.02 + 1e-12          # rate limit of the commands
    assert ctl.status.saturated


def test_smooth_setpoint_change():
    """Switching to another figure in flight: no steering jump, no crash, small error on the moving path,
    and the blend beats an instantaneous switch."""
    new = Setpoints.from_array(ShapeBox().from_unit([0.8, 0.5, 0.5]))    # (38, 52, 8.1) deg
    results = {}
    for blend in (10.0, 0.0):
        plant, ctl = make_closed_loop(DEFAULT_SETPOINTS, QUIET, seed=0, settings=ControllerSettings(blend_time=blend))
        run_closed_loop(plant, ctl, 40.0)
        ctl.set_setpoints(new)
        r = run_closed_loop(plant, ctl, 40.0)
        results[blend] = r
        assert r.crashes == 0
        assert ctl.path.setpoints == new
        assert np.max(np.abs(np.diff(r.delta))) <= 0.1 + 1e-12
        assert r.rms_cross_track_deg(t_from=r.t[0] + 20.0) < 0.5          # tracks the new path afterwards
    smooth = np.degrees(np.max(np.abs(results[10.0].cross_track)))
    jump = np.degrees(np.max(np.abs(results[0.0].cross_track[:50])))
    assert smooth < 1.0
    assert smooth < jump


def test_dead_time_compensation_helps():
    """With the plant's 0.25 s dead time, predicting over it reduces the tracking error."""
    rms = {}
    for dead in (0.25, 0.0):
        plant, ctl = make_closed_loop(DEFAULT_SETPOINTS, QUIET, seed=0, settings=ControllerSettings(dead_time=dead))
        r = run_closed_loop(plant, ctl, 60.0)
        rms[dead] = r.rms_cross_track_deg(t_from=30.0)
    assert rms[0.25] < 0.5
    assert rms[0.25] < 0.7 * rms[0.0]
