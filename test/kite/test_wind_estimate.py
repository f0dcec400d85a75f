"""The wind observer on known synthetic cases: exact without noise, free of the glide ratio, unbiased with noise."""
import math
from types import SimpleNamespace

import numpy as np
import pytest

from kite_rto.kite.model import shared_model
from kite_rto.kite.params import KiteParams
from kite_rto.kite.wind_estimate import WindObserver, WindObserverSettings, drift_measurement, tension_wind

MODEL = shared_model()


def kite_sample(params, theta, phi, psi, delta):
    """A noise-free measurement of a kite with ``params`` at the given state and steering, and its true wind."""
    xdot, (_w_ap, wind) = MODEL.rhs_py([theta, phi, psi], delta, params.as_vector())
    return SimpleNamespace(theta=theta, phi=phi, psi=psi, theta_dot=xdot[0], phi_dot=xdot[1]), wind


@pytest.mark.parametrize("E,c_E,g_s", [(5.0, 0.0, 0.04), (3.7, 1.5, 0.03), (6.5, 2.5, 0.05)])
def test_drift_measurement_is_exact_and_free_of_the_glide_ratio(E, c_E, g_s):
    p = KiteParams(E=E, c_E=c_E, g_s=g_s, w_ref=9.3, shear=0.22)
    rng = np.random.default_rng(1)
    for _ in range(50):
        m, wind = kite_sample(p, rng.uniform(0.3, 1.0), rng.uniform(-0.8, 0.8), rng.uniform(-3, 3),
                              rng.uniform(-1, 1))
        y, h = drift_measurement(m.theta, m.psi, m.theta_dot, m.phi_dot, p.r)
        assert y == pytest.approx(h * wind, abs=1e-9)


def test_observer_recovers_the_wind_of_a_mismatched_kite_flying_a_figure_eight():
    """A kite with other E, glide loss and shear than the observer's model, along a figure-eight sweep: the
    estimate is the h^2-weighted exponential average of the true wind at the kite."""
    plant = KiteParams(E=4.6, c_E=2.0, g_s=0.035, w_ref=8.0, shear=0.20)
    obs = WindObserver(KiteParams(), 0.02)
    f = math.exp(-0.02 / obs.settings.time_constant)
    num = den = 0.0
    for k in range(3000):
        s = 2 * math.pi * k / 1000
        m, wind = kite_sample(plant, 0.6 + 0.1 * math.sin(2 * s), 0.7 * math.sin(s), math.pi / 2 * math.cos(s),
                              0.8 * math.sin(s))
        h = math.sin(m.theta) * math.sin(m.psi)
        num, den = f * num + h * h * wind, f * den + h * h
        est = obs.update(m)
        if k > 100:
            assert est == pytest.approx(num / den, rel=1e-9)
            assert est == pytest.approx(wind, rel=0.1)           # lags a fast altitude sweep by a few %
    assert obs.reference_wind(100.0) == pytest.approx(obs.wind / (100.0 / 10.0) ** 0.15)
    m.position = (300.0, 0.0, 120.0)
    observed = obs.observe(m)
    assert observed == pytest.approx(obs.wind / (120.0 / 10.0) ** 0.15)


def test_observer_is_unbiased_under_rate_noise_and_follows_a_step():
    p = KiteParams(E=4.6, c_E=2.0)
    rng = np.random.default_rng(2)
    obs = WindObserver(KiteParams(), 0.02, WindObserverSettings(time_constant=2.0))
    errors = []
    for k in range(40000):
        w_ref = 8.0 if k < 20000 else 10.0
        s = 2 * math.pi * k / 1000
        m, wind = kite_sample(KiteParams(E=p.E, c_E=p.c_E, w_ref=w_ref), 0.55, 0.6 * math.sin(s),
                              math.pi / 2 * math.cos(s) + 0.2, 0.5)
        m.theta_dot += 0.005 * rng.standard_normal()
        m.phi_dot += 0.005 * rng.standard_normal()
        est = obs.update(m)
        if 1000 < k < 20000 or k > 20000 + 5 * 100:            # 5 time constants after the step
            errors.append(est - wind)
    errors = np.array(errors)
    assert abs(errors.mean()) < 0.05 and errors.std() < 1.0


def test_observer_holds_until_informed_and_resets():
    obs = WindObserver(KiteParams(), 0.02, initial=8.0)
    vertical = SimpleNamespace(theta=0.5, phi=0.0, psi=0.0, theta_dot=0.1, phi_dot=0.0)     # h = 0
    assert obs.update(vertical) == 8.0
    m, wind = kite_sample(KiteParams(), 0.5, 0.2, 1.4, 0.0)
    for _ in range(200):
        obs.update(m)
    assert obs.wind == pytest.approx(wind)
    obs.reset()
    m2, wind2 = kite_sample(KiteParams(w_ref=11.0), 0.5, 0.2, 1.4, 0.0)
    for _ in range(200):
        obs.update(m2)
    assert obs.wind == pytest.approx(wind2)


def test_tension_wind_inverts_the_model_tension():
    p = KiteParams()
    for theta, phi, w_ref in ((0.5, 0.2, 8.0), (0.7, -0.5, 11.0)):
        q = KiteParams(w_ref=w_ref)
        out = MODEL.outputs([theta, phi, 0.0], 0.0, q)
        wind = w_ref * (out["altitude"] / q.z_ref) ** q.shear
        assert tension_wind(MODEL, p, theta, phi, out["tension"]) == pytest.approx(wind)
