"""The kite's periodic-lap OCP as a GMA ModelProblem: it solves, it is a lap, and its fields mean what they say."""
import math

import casadi as ca
import numpy as np
import pytest

from kite_rto.rto.ocp import (DEFAULT_C_LB, DEFAULT_C_UB, KiteOCPSettings, model_problem,
                                    path_guess, unpack)
from kite_rto.rto.ocp_solve import realize_setpoints, solve_model_optimum
from kite_rto.kite.model import KiteModel
from kite_rto.kite.params import KiteParams, ParameterError
from kite_rto.flight.projection import project_samples

DEG = math.pi / 180.0
C_INTERIOR = np.array([28.0, 30.0, 7.0]) * DEG


@pytest.fixture(scope="module")
def problem():
    return model_problem(settings=KiteOCPSettings(altitude="lap"))


@pytest.fixture(scope="module")
def optimum(problem):
    return solve_model_optimum(problem)


@pytest.fixture(scope="module")
def realized(problem):
    return realize_setpoints(problem, C_INTERIOR)


def test_problem_shapes(problem):
    n = problem.settings.n_intervals
    assert problem.n_u == 4 * n + 1 and problem.n_c == 3 and problem.n_g == 1
    assert problem.equalities.numel() == 3 * n + 1
    assert isinstance(problem.u, ca.SX)
    assert np.all(problem.lbu <= problem.u0) and np.all(problem.u0 <= problem.ubu)


def test_guess_flies_the_requested_figure_eight(problem):
    c = np.array([25.0, 20.0, 5.0]) * DEG
    u = path_guess(problem.params, problem.settings, c)
    _, _, y = problem.evaluate(u)
    # the kite is slower at the lobes, so time-uniform samples bias the projection a little
    np.testing.assert_allclose(y, c, atol=2.0 * DEG)


def test_optimum_solves_from_default_guess(optimum):
    assert optimum.status == "Solve_Succeeded"
    assert optimum.iterations < 100


def test_optimum_is_a_periodic_lap(problem, optimum):
    model, p = KiteModel(), problem.params.as_vector()
    n = problem.settings.n_intervals
    x = optimum.states[0].copy()
    h = optimum.period / n / 20
    for k in range(n):
        for _ in range(20):
            x = np.asarray(model.f_step(x, optimum.delta[k], p, h)).ravel()
        np.testing.assert_allclose(x, optimum.states[(k + 1) % n], atol=1e-4)
    assert optimum.states[0, 1] == pytest.approx(0.0, abs=1e-9)       # phase fix
    assert np.sin(optimum.states[0, 2]) < 0.0                          # phi increasing at node 0


def test_optimum_respects_bounds_and_altitude(problem, optimum):
    st = problem.settings
    assert np.all(np.abs(optimum.delta) <= st.delta_max + 1e-8)
    assert optimum.g <= 1e-6
    assert 0.0 <= optimum.softmin_bias <= st.softmin_sharpness * math.log(st.n_intervals)
    assert optimum.min_altitude >= problem.h_min - 1e-6


def test_outputs_are_the_projection_of_the_nodes(problem, optimum):
    theta, phi = optimum.states[:, 0], optimum.states[:, 1]
    np.testing.assert_allclose(optimum.c, project_samples(theta, phi), atol=1e-12)
    z = problem.params.r * np.sin(theta) * np.cos(phi)
    assert optimum.min_altitude == pytest.approx(z.min())


def test_optimum_is_interior_and_sensible(problem, optimum):
    assert np.all(optimum.c > DEFAULT_C_LB + 0.5 * DEG) and np.all(optimum.c < DEFAULT_C_UB - 0.5 * DEG)
    # SPEC §2: small, fast figure-eights near theta_0 = 22 deg (tension ~ cos^2(theta) z^(2a) peaks at 21 deg)
    assert 19 * DEG < optimum.c[0] < 25 * DEG
    assert 12 * DEG < optimum.c[1] < 25 * DEG and 2 * DEG < optimum.c[2] < 8 * DEG
    assert 600.0 < optimum.mean_tension_kn < 700.0
    assert 3.0 < optimum.period < 15.0


def test_cost_is_mean_tension_in_kn(problem, optimum):
    reg = problem.settings.delta_rate_weight * np.sum((optimum.delta - np.roll(optimum.delta, -1))**2)
    assert optimum.cost == pytest.approx(-optimum.mean_tension_kn + reg, rel=1e-9)


def test_realize_hits_setpoints(realized):
    np.testing.assert_allclose(realized.c, C_INTERIOR, atol=1e-8)


def test_realize_multipliers_are_the_model_gradient(problem, realized):
    h = 0.05 * DEG
    e = np.array([h, 0.0, 0.0])
    plus = realize_setpoints(problem, C_INTERIOR + e, warm=realized)
    minus = realize_setpoints(problem, C_INTERIOR - e, warm=realized)
    fd = (plus.cost - minus.cost) / (2 * h)
    assert -realized.lam_g[-3] == pytest.approx(fd, rel=1e-3)


def test_warm_resolve_is_fast(problem, realized):
    c = C_INTERIOR + np.array([0.3, -0.4, 0.2]) * DEG
    warm = realize_setpoints(problem, c, warm=realized)
    np.testing.assert_allclose(warm.c, c, atol=1e-8)
    assert warm.iterations <= 15
    assert warm.solve_time < 1.0


def test_unpack_checks_length():
    with pytest.raises(ValueError, match="4 N"):
        unpack(np.zeros(10), KiteOCPSettings())


@pytest.mark.parametrize("kwargs", [{"n_intervals": 4}, {"delta_max": 1.5}, {"period_bounds": (5.0, 2.0)},
                                    {"softmin_sharpness": 0.0}])
def test_settings_validate(kwargs):
    with pytest.raises((ParameterError, ValueError)):
        KiteOCPSettings(**kwargs)


def test_other_params_build(problem):
    other = model_problem(KiteParams(E=4.6, g_s=0.035), KiteOCPSettings(n_intervals=24, delta_max=1.0))
    assert other.n_u == 4 * 24 + 1
    phi, g, y = other.evaluate(other.u0)
    assert np.isfinite(phi) and np.all(np.isfinite(g)) and np.all(np.isfinite(y))
