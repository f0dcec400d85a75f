"""Validation: settings, model problems, strategies and the request/submit protocol raise clear errors."""
import dataclasses
import math

import casadi as ca
import numpy as np
import pytest

from kite_rto.gma import (GMA, MECHANISMS, BoundHold, ExperimentResult, FiniteDifferenceGradient, GMASettings,
                          LeastSquaresGradient, ModelProblem, ModelSecant, ModelSettings, ModifierFilter, NoiseFilter,
                          SafeStep, TrustRegion, Undo)


def small_problem(**kw):
    u = ca.SX.sym("u", 2)
    args = dict(u=u, cost=ca.sumsqr(u - 1), constraints=u[0] - 2, outputs=u, lbu=-5, ubu=5, u0=[0, 0],
                c_lb=[-2, -2], c_ub=[3, 3])
    args.update(kw)
    return ModelProblem(**args)


def test_defaults_are_valid_and_round_trip():
    s = GMASettings()
    assert GMASettings.from_dict(s.to_dict()) == s
    s2 = GMASettings(trust_region=TrustRegion(radius=math.inf), filter_gain=[0.5, 1.0])
    assert GMASettings.from_dict(s2.to_dict()).trust_region.radius == math.inf


def test_every_mechanism_round_trips_and_off_is_none():
    s = GMASettings(effort_schedule=(1, 2), model=ModelSettings(point="realization", ipopt_options={"tol": 1e-9}),
                    modifier_filter=ModifierFilter(0.3), noise_filter=NoiseFilter(15.0, (20.0,)),
                    trust_region=None, safe_step=SafeStep(curvature=(20.0,), tolerance=1.0), undo=Undo(1.0),
                    bound_hold=BoundHold(2.0, after=1), model_secant=ModelSecant())
    data = s.to_dict()
    assert data["trust_region"] is None and data["undo"] == {"sigma": 1.0}
    assert GMASettings.from_dict(data) == s
    assert s.effort_schedule == (1.0, 2.0) and s.effort_at(0) == 1.0 and s.effort_at(7) == 2.0
    assert set(MECHANISMS) <= {f.name for f in dataclasses.fields(GMASettings)}


def test_the_settings_stay_small():
    """A few top-level values (five) and one sub-object per mechanism (eight): the design, not a flat bag of
    knobs."""
    assert len(dataclasses.fields(GMASettings)) <= 13


@pytest.mark.parametrize("make, owner, field, value, expected", [
    (lambda v: GMASettings(filter_gain=v), "GMASettings", "filter_gain", 0.0, "(0.0, 1.0]"),
    (lambda v: GMASettings(filter_gain=v), "GMASettings", "filter_gain", [0.5, 1.5], "(0.0, 1.0]"),
    (lambda v: GMASettings(backoff=v), "GMASettings", "backoff", math.nan, "[0.0, inf]"),
    (lambda v: GMASettings(tol_c=v), "GMASettings", "tol_c", 0.0, "(0.0, inf]"),
    (lambda v: ModifierFilter(gain=v), "ModifierFilter", "gain", 1.5, "(0.0, 1.0]"),
    (lambda v: NoiseFilter(drift=v), "NoiseFilter", "drift", -1.0, "[0.0, inf]"),
    (lambda v: TrustRegion(radius=v), "TrustRegion", "radius", -1.0, "(0.0, inf]"),
    (lambda v: TrustRegion(shrink=v), "TrustRegion", "shrink", 1.0, "(0.0, 1.0)"),
    (lambda v: TrustRegion(grow=v), "TrustRegion", "grow", 0.5, "[1.0, inf]"),
    (lambda v: SafeStep(curvature=v), "SafeStep", "curvature", -1.0, "[0.0, inf]"),
    (lambda v: Undo(sigma=v), "Undo", "sigma", math.inf, "[0.0, inf]"),
    (lambda v: BoundHold(sigma=v), "BoundHold", "sigma", -0.5, "[0.0, inf]"),
    (lambda v: ModelSettings(fd_step=v), "ModelSettings", "fd_step", 0.5, "(0.0, 0.1]"),
])
def test_invalid_settings_name_owner_field_value_and_range(make, owner, field, value, expected):
    with pytest.raises(ValueError) as err:
        make(value)
    msg = str(err.value)
    assert f"{owner}.{field}=" in msg and repr(value) in msg and expected in msg


@pytest.mark.parametrize("make, match", [
    (lambda: TrustRegion(adapt=1), "TrustRegion.adapt=1: expected True or False"),
    (lambda: TrustRegion(radius=0.2, min_radius=0.5), "TrustRegion.min_radius=0.5: expected <= radius"),
    (lambda: ModelSettings(max_iter=0), "ModelSettings.max_iter=0: expected an integer >= 1"),
    (lambda: ModelSettings(point="x"), "ModelSettings.point='x': expected one of 'consistent', 'realization'"),
    (lambda: ModelSettings(ipopt_options="tol=1"), "ModelSettings.ipopt_options='tol=1': expected a dict"),
    (lambda: BoundHold(after=1.5), "BoundHold.after=1.5: expected an integer >= 0"),
    (lambda: GMASettings(undo=1.0), r"GMASettings.undo=1.0: expected Undo\(...\) or None \(off\)"),
    (lambda: GMASettings(effort_schedule=(1, 0)), r"GMASettings.effort_schedule=\(1, 0\): expected"),
    (lambda: GMASettings.from_dict({"safe_curvature": 20.0}), r"GMASettings: unknown fields \['safe_curvature'\]"),
    (lambda: GMASettings.from_dict({"undo": {"z": 1}}), r"Undo: unknown fields \['z'\]"),
])
def test_invalid_other_settings(make, match):
    with pytest.raises(ValueError, match=match):
        make()


def test_per_setpoint_length_is_checked_against_the_problem():
    with pytest.raises(ValueError, match="filter_gain.*expected a scalar or 2 values, got 3"):
        GMA(small_problem(), GMASettings(filter_gain=[0.5, 0.5, 0.5]))


def test_model_problem_validation():
    u = ca.SX.sym("u", 2)
    with pytest.raises(ValueError, match="cost must be scalar"):
        small_problem(cost=u)
    with pytest.raises(ValueError, match="c_lb < c_ub"):
        small_problem(c_lb=[3, -2], c_ub=[3, 3])
    with pytest.raises(ValueError, match="lbu has 3 entries, expected 2"):
        small_problem(lbu=[0, 0, 0])
    with pytest.raises(ValueError, match="must be finite"):
        small_problem(c_ub=[np.inf, 3])
    with pytest.raises(TypeError, match="SX or MX symbol"):
        small_problem(u=np.zeros(2))
    p = small_problem(constraints=None)
    assert (p.n_u, p.n_c, p.n_g) == (2, 2, 0)


def test_mx_problems_work():
    u = ca.MX.sym("u", 3)
    p = ModelProblem(u=u, cost=ca.sumsqr(u - 1), constraints=u[0] + u[2] - 1, outputs=u[:2], lbu=-5, ubu=5,
                     u0=[0, 0, 0], c_lb=[-2, -2], c_ub=[3, 3])
    gma = GMA(p)
    np.testing.assert_allclose(gma.c, [0.5, 1.0], atol=1e-6)  # model optimum: u = (0.5, 1, 0.5)


def test_gradient_strategy_validation():
    with pytest.raises(ValueError, match="step"):
        FiniteDifferenceGradient(0.0)
    with pytest.raises(ValueError, match="scheme"):
        FiniteDifferenceGradient(0.1, "backward")
    with pytest.raises(ValueError, match="noise_std"):
        FiniteDifferenceGradient.from_noise(-1.0, 1.0)
    with pytest.raises(ValueError, match="rcond_min"):
        LeastSquaresGradient(FiniteDifferenceGradient(0.1), rcond_min=0.0)


def test_submit_protocol_errors():
    gma = GMA(small_problem(), c0=[0.0, 0.0])
    req = gma.next_request()
    assert gma.next_request().request_id == req.request_id  # same request until submitted
    with pytest.raises(ValueError, match="unknown request_id"):
        gma.submit(ExperimentResult("nope", 1.0, [0.0]))
    with pytest.raises(ValueError, match="expected n_g=1"):
        gma.submit(ExperimentResult(req.request_id, 1.0, [0.0, 1.0]))
    with pytest.raises(ValueError, match="non-finite"):
        gma.submit(ExperimentResult(req.request_id, math.nan, [0.0]))
    gma.submit(ExperimentResult(req.request_id, 1.0, [0.0]))
    with pytest.raises(ValueError, match="already submitted"):
        gma.submit(ExperimentResult(req.request_id, 1.0, [0.0]))
    with pytest.raises(ValueError, match="outside the setpoint box"):
        GMA(small_problem(), c0=[10.0, 0.0])
