"""The Erhard model's known facts (SPEC §2) and parameter validation."""
import math

import casadi as ca
import numpy as np
import pytest

from kite_rto.kite import KiteModel, KiteParams, ParameterError

MODEL = KiteModel()
P = KiteParams()


def settle(params, psi, seconds=600.0, dt=0.02, theta0=0.4):
    x = [theta0, 0.0, psi]
    pv = params.as_vector()
    for _ in range(int(seconds / dt)):
        x, _ = MODEL.step_py(x, 0.0, pv, dt)
        x[2] = psi                          # hold the orientation fixed
    return x


def test_zenith_equilibrium_is_atan_E():
    x = settle(P, 0.0)
    assert x[0] == pytest.approx(math.atan(P.E), abs=1e-6)
    assert x[1] == pytest.approx(0.0, abs=1e-12)


@pytest.mark.parametrize("psi_deg", [20.0, 45.0])
def test_fixed_orientation_equilibrium_theta(psi_deg):
    """For fixed psi, theta' = 0 at theta = atan(E cos psi) (Erhard & Strauch eq. 5)."""
    psi = math.radians(psi_deg)
    theta_eq = math.atan(P.E * math.cos(psi))
    xdot = MODEL.rhs([theta_eq, 0.1, psi], 0.0, P)
    assert xdot[0] == pytest.approx(0.0, abs=1e-12)
    assert MODEL.zenith_equilibrium(P, psi) == pytest.approx(theta_eq)


def test_phi_rate_zero_when_psi_zero():
    for theta in (0.2, 0.7, 1.2):
        assert MODEL.rhs([theta, 0.3, 0.0], 0.5, P)[1] == 0.0


def test_phi_rate_has_one_over_sin_theta():
    theta, psi = 0.3, 0.4
    out = MODEL.outputs([theta, 0.0, psi], 0.0, P)
    assert MODEL.rhs([theta, 0.0, psi], 0.0, P)[1] == pytest.approx(
        -out["w_ap"] / (P.r * math.sin(theta)) * math.sin(psi))


def test_tension_and_shear_formulas():
    theta, phi = 0.5, 0.2
    out = MODEL.outputs([theta, phi, 0.0], 0.0, P)
    z = P.r * math.sin(theta) * math.cos(phi)
    w = P.w_ref * (z / P.z_ref) ** P.shear
    assert out["altitude"] == pytest.approx(z)
    assert out["w_ap"] == pytest.approx(w * P.E * math.cos(theta))
    expected = 0.5 * P.rho * P.area * w**2 * (P.E + 1) * math.sqrt(P.E**2 + 1) * math.cos(theta) ** 2
    assert out["tension"] == pytest.approx(expected)
    np.testing.assert_allclose(out["position"], P.r * np.array(
        [math.cos(theta), math.sin(theta) * math.sin(phi), z / P.r]))


def test_glide_loss_lowers_E_when_steering():
    p = KiteParams(c_E=2.0)
    t0 = MODEL.outputs([0.5, 0.0, 0.0], 0.0, p)["tension"]
    t1 = MODEL.outputs([0.5, 0.0, 0.0], 1.0, p)["tension"]
    e1 = p.E - p.c_E
    w = MODEL.outputs([0.5, 0.0, 0.0], 1.0, p)["w_ap"] / (e1 * math.cos(0.5))
    assert t1 == pytest.approx(0.5 * p.rho * p.area * w**2 * (e1 + 1) * math.sqrt(e1**2 + 1) * math.cos(0.5)**2)
    assert t1 < t0


def test_python_translation_matches_casadi():
    rng = np.random.default_rng(3)
    pv = KiteParams(c_E=1.0).as_vector()
    for _ in range(20):
        x = [rng.uniform(0.2, 1.2), rng.uniform(-0.8, 0.8), rng.uniform(-3, 3)]
        d = rng.uniform(-1, 1)
        xn, out = MODEL.step_py(x, d, pv, 0.02)
        np.testing.assert_allclose(xn, np.asarray(MODEL.f_step(x, d, pv, 0.02)).ravel(), rtol=1e-13, atol=1e-14)
        np.testing.assert_allclose(out[:6], np.asarray(MODEL.f_outputs(xn, d, pv)).ravel(), rtol=1e-12)
        np.testing.assert_allclose(out[6:], np.asarray(MODEL.f_rhs(xn, d, pv)).ravel(), rtol=1e-12, atol=1e-14)


def test_state_step_is_the_first_result_of_step_py_bit_for_bit():
    """The controller's prediction (state_step_py) flies exactly the plant's RK4 step, wind near the ground too."""
    rng = np.random.default_rng(4)
    for k in range(500):
        x = [rng.uniform(0.05, 1.5), rng.uniform(-1.2, 1.2), rng.uniform(-3.5, 3.5)]
        pv = KiteParams(w_ref=rng.uniform(0.5, 20.0), c_E=rng.uniform(0.0, 1.0)).as_vector()
        d, dt = rng.uniform(-1, 1), (0.02, 0.0, rng.uniform(0.0, 0.2))[k % 3]
        assert MODEL.state_step_py(x, d, pv, dt)[0] == MODEL.step_py(x, d, pv, dt)[0]


def test_rk4_converges_with_order_four():
    x0, d, pv, T = [0.4, 0.3, 0.8], 0.3, P.as_vector(), 2.0

    def final(n):
        x = x0
        for _ in range(n):
            x, _ = MODEL.step_py(x, d, pv, T / n)
        return np.array(x)

    ref = final(4096)
    errors = [np.linalg.norm(final(n) - ref) for n in (16, 32, 64)]
    orders = [math.log2(errors[i] / errors[i + 1]) for i in range(2)]
    assert all(3.6 < o < 4.4 for o in orders), orders


def test_symbolic_expressions_accept_mx():
    x, d, p = ca.MX.sym("x", 3), ca.MX.sym("d"), ca.MX.sym("p", KiteModel.n_p)
    e = KiteModel.expressions(x, d, p)
    f = ca.Function("t", [x, d, p], [e.tension])
    assert float(f([0.5, 0, 0], 0, P.as_vector())) == pytest.approx(MODEL.outputs([0.5, 0, 0], 0, P)["tension"])


@pytest.mark.parametrize("field,value", [("r", 0.0), ("r", -400.0), ("E", 0.0), ("area", -1.0), ("shear", -0.1),
                                         ("rho", float("nan")), ("g_s", float("inf")), ("E", "5")])
def test_invalid_parameters_name_field_value_and_range(field, value):
    with pytest.raises(ParameterError) as err:
        KiteParams(**{field: value})
    msg = str(err.value)
    assert f"KiteParams.{field} = {value!r}" in msg and "expected" in msg
