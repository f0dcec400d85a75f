"""The experiment cost's wind sources: the observer-normalized experiment on a synthetic kite, the lagged
anemometer, and the settings' validation."""
import math
from types import SimpleNamespace

import pytest

from kite_rto.kite.model import STEP_OUTPUT_NAMES, shared_model
from kite_rto.kite.params import KiteParams
from kite_rto.rto.experiment import DEFAULT_WIND_SOURCES, ExperimentEvaluator, ExperimentSpec, default_wind_source
from kite_rto.rto.wind_source import (PROFILE_EXPONENTS, WIND_SOURCES, LaggedAnemometer, ObserverWind,
                                     ProfileObserverWind, make_wind_source)

MODEL = shared_model()
PARAMS = KiteParams()
_TENSION = STEP_OUTPUT_NAMES.index("tension")


def gust(t: float) -> float:
    """A slow gust on the reference wind, m/s: +-20 % over 160 s, rising through the experiment."""
    return PARAMS.w_ref * (1.0 + GUST * math.sin(2 * math.pi * t / GUST_PERIOD))


GUST, GUST_PERIOD = 0.2, 160.0
TAU = 2.0
"""The observer's time constant, s: it normalizes by the wind ~tau earlier, an error in w^2 of at most
``2 tau max|w'| / w = 2 tau GUST 2 pi / GUST_PERIOD`` (3.1 %)."""


def kite(t: float, w_ref: float, anemometer: float, period: float = 10.0):
    """A noise-free measurement of the model kite sweeping a figure-eight (period s) in reference wind ``w_ref``
    (m/s), and its tension in the nominal wind; the anemometer reads ``anemometer``."""
    s = 2 * math.pi * t / period
    theta, phi, psi, delta = 0.6 + 0.1 * math.sin(2 * s), 0.7 * math.sin(s), math.pi / 2 * math.cos(s), 0.3
    p = PARAMS.as_vector()
    i = KiteParams.names().index("w_ref")
    p[i] = w_ref
    xdot, _ = MODEL.rhs_py([theta, phi, psi], delta, p)
    tension = MODEL.step_py([theta, phi, psi], delta, p, 0.0)[1][_TENSION]
    p[i] = PARAMS.w_ref
    nominal = MODEL.step_py([theta, phi, psi], delta, p, 0.0)[1][_TENSION]
    z = PARAMS.r * math.sin(theta) * math.cos(phi)
    m = SimpleNamespace(t=t, theta=theta, phi=phi, psi=psi, theta_dot=xdot[0], phi_dot=xdot[1], tension=tension,
                        position=(PARAMS.r * math.cos(theta), PARAMS.r * math.sin(theta) * math.sin(phi), z),
                        wind_ref=anemometer, crashes=0)
    return m, nominal


def calm(t: float) -> float:
    return PARAMS.w_ref


def fly_experiment(source: str, anemometer=calm, wind=gust):
    """One 4-lap experiment of the synthetic kite in ``wind`` (reference wind, m/s, of time); returns the outcome
    and the nominal-wind mean tension over the counted laps, kN."""
    ev = ExperimentEvaluator(ExperimentSpec(settle_time=5.0, settle_laps=1, n_laps=4, wind_source=source))
    ev.start(0.0)
    t, out, nominal = 0.0, None, []
    while out is None:
        t += 0.02
        m, t_nom = kite(t, wind(t), anemometer(t))
        nominal.append((t, t_nom))
        out = ev.update(m)
    lo, hi = out.laps[0].t_start, out.laps[-1].t_end
    ref = [v for tt, v in nominal if lo <= tt < hi]
    return out, sum(ref) / len(ref) / 1e3


def test_observer_normalized_experiment_gives_the_tension_in_the_nominal_wind():
    out, nominal = fly_experiment("observer")
    steady, steady_nominal = fly_experiment("observer", wind=calm)
    raw, _ = fly_experiment("none")
    assert out.valid and out.n_laps == 4
    assert nominal == pytest.approx(steady_nominal, rel=1e-9)         # same laps, same path
    # the gust removed to within the observer's lag: the cost is that of the steady nominal wind, itself 2.1 %
    # below the true nominal tension (the observer lags the fast altitude sweep of this figure-eight)
    assert -out.cost == pytest.approx(-steady.cost, rel=2 * TAU * GUST * 2 * math.pi / GUST_PERIOD)
    assert -steady.cost == pytest.approx(nominal, rel=0.03)
    assert -raw.cost / nominal - 1.0 > 0.2                            # the raw tension carries the gust
    assert out.cost_std < 0.5 * raw.cost_std                          # and so does its lap-to-lap scatter
    assert raw.mean_tension_kn == pytest.approx(out.mean_tension_kn)  # same laps, same raw tension
    # an anemometer that does not see the kite's gust removes nothing
    blind, _ = fly_experiment("anemometer")
    assert -blind.cost == pytest.approx(-raw.cost, rel=1e-9)
    # one that sees it exactly (same reference wind) removes it exactly
    exact, _ = fly_experiment("anemometer", anemometer=gust)
    assert -exact.cost == pytest.approx(nominal, rel=0.005)


def test_observer_wind_calibrations():
    obs = ObserverWind(8.0, PARAMS, calibration="none")
    run = ObserverWind(8.0, PARAMS, calibration="observer")
    ratio = ObserverWind(8.0, PARAMS, calibration="anemometer")
    estimates = []
    for k in range(3000):
        m = kite(0.02 * k, 9.0, 6.0)[0]
        run.update(m)
        ratio.update(m)
        estimates.append(obs.update(m))
    assert math.isnan(estimates[0])                                     # no information yet
    finite = [w for w in estimates if math.isfinite(w)]
    assert obs.scale() == 8.0
    assert run.scale() == pytest.approx(sum(finite) / len(finite), rel=1e-12)   # the run's mean at z_ref
    assert run.scale() == pytest.approx(9.0, rel=0.02)                 # (the altitude sweep's lag: 1.1 %)
    assert ratio.scale() == pytest.approx(8.0 * run.scale() / 6.0, rel=1e-12)  # nominal x observer / anemometer
    with pytest.raises(ValueError, match="'kalman'"):
        ObserverWind(8.0, PARAMS, calibration="kalman")


def test_observer_names_a_missing_rate():
    ev = ExperimentEvaluator(ExperimentSpec(wind_source="observer"))
    ev.start(0.0)
    m = SimpleNamespace(t=0.02, theta=0.5, phi=0.1, psi=1.0, tension=5e5, position=(300.0, 0.0, 150.0),
                        wind_ref=8.0, crashes=0)
    with pytest.raises(ValueError, match="theta_dot"):
        ev.update(m)


def test_lagged_anemometer_delays_by_the_transport_time():
    lag = LaggedAnemometer(8.0, PARAMS)
    signal = lambda t: 8.0 + math.sin(t / 5.0)                         # noqa: E731
    out = []
    for k in range(6000):
        t = 0.02 * k
        # kite 240 m downwind at z_ref: transport lag = 240 m / mean anemometer (~8 m/s) ~ 30 s
        out.append(lag.update(SimpleNamespace(t=t, wind_ref=signal(t), position=(240.0, 0.0, PARAMS.z_ref))))
    assert lag.lag == pytest.approx(240.0 / 8.0, rel=0.02)
    assert out[-1] == pytest.approx(signal(0.02 * 5999 - lag.lag), abs=1e-3)
    assert lag.scale() == 8.0


def test_wind_source_settings_are_validated_with_the_bad_value_named():
    with pytest.raises(ValueError, match=r"ExperimentSpec\.wind_source = 'anemo'.*observer"):
        ExperimentSpec(wind_source="anemo")
    with pytest.raises(ValueError, match="'gusty'"):
        default_wind_source("gusty")
    with pytest.raises(ValueError, match="'sonic'"):
        make_wind_source("sonic", 8.0)
    assert ExperimentSpec(normalize=False, wind_source="observer").source == "none"   # old settings still work
    assert ExperimentSpec(wind_source="anemometer_lagged").source == "anemometer_lagged"
    assert set(DEFAULT_WIND_SOURCES.values()) <= set(WIND_SOURCES)
    assert default_wind_source("uniform") == "anemometer"


def sheared_kite(t: float, shear: float, theta_amp: float, period: float = 10.0):
    """The synthetic kite of :func:`kite` (reference wind 8 m/s, read exactly by the anemometer) in a wind profile
    of exponent ``shear``, its figure-eight ``theta_amp`` rad high: a kite that sweeps through the shear."""
    s = 2 * math.pi * t / period
    theta, phi, psi, delta = 0.6 + theta_amp * math.sin(2 * s), 0.7 * math.sin(s), math.pi / 2 * math.cos(s), 0.3
    p = PARAMS.as_vector()
    p[KiteParams.names().index("shear")] = shear
    xdot, _ = MODEL.rhs_py([theta, phi, psi], delta, p)
    tension = MODEL.step_py([theta, phi, psi], delta, p, 0.0)[1][_TENSION]
    z = PARAMS.r * math.sin(theta) * math.cos(phi)
    return SimpleNamespace(t=t, theta=theta, phi=phi, psi=psi, theta_dot=xdot[0], phi_dot=xdot[1], tension=tension,
                           position=(PARAMS.r * math.cos(theta), PARAMS.r * math.sin(theta) * math.sin(phi), z),
                           wind_ref=PARAMS.w_ref, crashes=0)


@pytest.mark.parametrize("exponent", PROFILE_EXPONENTS)
def test_profile_observer_learns_the_plants_shear(exponent):
    """In a steady profile of exponent 0.25 (the model's is 0.15) the learned exponent is the plant's and the
    estimate at z_c is the true wind there; before ``learn_after`` the prior is used."""
    src = ProfileObserverWind(8.0, PARAMS, z_c=150.0, learn_after=30.0, exponent=exponent)
    for k in range(1, 2500):
        w = src.update(sheared_kite(0.02 * k, 0.25, 0.15))
        if k == 1000:
            assert src.shear == PARAMS.shear                     # 20 s in: still the prior
    assert src.shear == pytest.approx(0.25, abs=0.005)
    assert src.wind == pytest.approx(PARAMS.w_ref * (150.0 / PARAMS.z_ref) ** 0.25, rel=0.002)
    assert w == pytest.approx(src.wind * (PARAMS.z_ref / 150.0) ** PARAMS.shear, rel=1e-12)
    assert src.scale() == 8.0


def _ratio(source: str, theta_amp: float) -> float:
    """Normalized over raw tension of one 4-lap experiment of :func:`sheared_kite` (exponent 0.25) after 70 s."""
    ev = ExperimentEvaluator(ExperimentSpec(settle_time=70.0, settle_laps=1, n_laps=4, wind_source=source))
    ev.start(0.0)
    t, out = 0.0, None
    while out is None:
        t += 0.02
        out = ev.update(sheared_kite(t, 0.25, theta_amp))
    return out.tension_kn / out.mean_tension_kn


def test_profile_observer_normalizes_every_path_alike():
    """A steady wind is no gust: the normalized / raw ratio must not depend on the path. With "observer" it
    does (its estimate at the kite lags the altitude sweep, and the model's exponent is not the plant's);
    with "observer_profile" it does not."""
    low, high = _ratio("observer", 0.05), _ratio("observer", 0.15)
    assert abs(high / low - 1.0) > 0.01
    low, high = _ratio("observer_profile", 0.05), _ratio("observer_profile", 0.15)
    assert high / low == pytest.approx(1.0, abs=0.001)


def test_profile_observer_names_bad_settings():
    with pytest.raises(ValueError, match="'kalman'"):
        ProfileObserverWind(8.0, PARAMS, exponent="kalman")
    with pytest.raises(ValueError, match="z_c"):
        ProfileObserverWind(8.0, PARAMS, z_c=-1.0)
    with pytest.raises(ValueError, match="theta_dot"):
        make_wind_source("observer_profile", 8.0).update(SimpleNamespace(t=0.0, theta=0.5, psi=1.0, phi=0.1,
                                                                         position=(0.0, 0.0, 100.0)))
