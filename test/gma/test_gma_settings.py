"""Validation: settings, model problems, strategies and the request/submit protocol raise clear errors."""
import math

import casadi as ca
import numpy as np
import pytest

from kite_rto.gma import (GMA, ExperimentResult, FiniteDifferenceGradient, GMASettings, LeastSquaresGradient,
                          ModelProblem)


def small_problem(**kw):
    u = ca.SX.sym("u", 2)
    args = dict(u=u, cost=ca.sumsqr(u - 1), constraints=u[0] - 2, outputs=u, lbu=-5, ubu=5, u0=[0, 0],
                c_lb=[-2, -2], c_ub=[3, 3])
    args.update(kw)
    return ModelProblem(**args)


def test_defaults_are_valid_and_round_trip():
    s = GMASettings()
    assert GMASettings.from_dict(s.to_dict()) == s
    s2 = GMASettings(trust_radius=math.inf, filter_gain=[0.5, 1.0])
    assert GMASettings.from_dict(s2.to_dict()).trust_radius == math.inf


@pytest.mark.parametrize("field, value, expected", [
    ("filter_gain", 0.0, "(0.0, 1.0]"),
    ("filter_gain", [0.5, 1.5], "(0.0, 1.0]"),
    ("modifier_filter", 0.0, "(0.0, 1.0]"),
    ("modifier_filter", 1.5, "(0.0, 1.0]"),
    ("trust_radius", -1.0, "(0.0, inf]"),
    ("trust_shrink", 1.0, "(0.0, 1.0)"),
    ("trust_grow", 0.5, "[1.0, inf]"),
    ("max_step", 0.0, "(0.0, inf]"),
    ("convexification", -0.1, "[0.0, inf]"),
    ("backoff", math.nan, "[0.0, inf]"),
    ("tol_c", 0.0, "(0.0, inf]"),
    ("model_fd_step", 0.5, "(0.0, 0.1]"),
    ("averaging", 0.0, "(0.0, inf]"),
    ("constraint_penalty", -1.0, "(0.0, inf]"),
])
def test_invalid_settings_name_field_value_and_range(field, value, expected):
    with pytest.raises(ValueError) as err:
        GMASettings(**{field: value})
    msg = str(err.value)
    assert f"GMASettings.{field}=" in msg and repr(value) in msg and expected in msg


@pytest.mark.parametrize("field, value", [("trust_adapt", 1), ("max_ipopt_iter", 0), ("model_point", "x"),
                                          ("ipopt_options", "tol=1"), ("trust_radius_min", 0.5)])
def test_invalid_other_settings(field, value):
    with pytest.raises(ValueError, match=f"GMASettings.{field}="):
        GMASettings(**{field: value})


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
