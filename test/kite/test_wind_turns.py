"""A wind that turns (kite_rto/kite/wind_frame.py, mean_wind.py and the plant's wind-frame step): the state in a
turned frame against geometry, the mean wind's processes and the IEC extreme direction change, and the kite in a
turning wind: the defaults unchanged, the three components and a 30 deg turn flown, deterministic per seed."""
import math
from dataclasses import replace

import numpy as np
import pytest

from kite_rto.flight.closed_loop import make_closed_loop, run_closed_loop
from kite_rto.kite.mean_wind import EDC_DURATION, MeanWind, MeanWindSettings, edc_amplitude
from kite_rto.kite.params import ParameterError
from kite_rto.kite.plant import KitePlant, PlantConfig
from kite_rto.kite.wind_field import WindFieldSettings
from kite_rto.kite.wind_frame import rotate_state, rotate_vector, transpose, wind_rotation

SMALL = WindFieldSettings(points=(512, 32, 32))
"""A 4 km box: generated in about a second, long enough for these flights."""


def _unit(theta, phi):
    return np.array([math.cos(theta), math.sin(theta) * math.sin(phi), math.sin(theta) * math.cos(phi)])


def _heading(theta, phi, psi):
    e_theta = np.array([-math.sin(theta), math.cos(theta) * math.sin(phi), math.cos(theta) * math.cos(phi)])
    e_phi = np.array([0.0, math.cos(phi), -math.sin(phi)])
    return math.cos(psi) * e_theta - math.sin(psi) * e_phi


@pytest.mark.parametrize("direction, tilt", [(math.radians(30.0), 0.0), (-0.4, 0.05), (1.2, -0.1)])
def test_a_turned_frame_keeps_the_tether_and_the_heading(direction, tilt):
    rot = wind_rotation(direction, tilt)
    m = np.array(rot)
    assert m @ m.T == pytest.approx(np.eye(3)) and np.linalg.det(m) == pytest.approx(1.0)
    rng = np.random.default_rng(1)
    for _ in range(20):
        s = [rng.uniform(0.2, 1.2), rng.uniform(-1.2, 1.2), rng.uniform(-3.0, 3.0)]
        t = rotate_state(s, rot)
        assert _unit(*t[:2]) == pytest.approx(m @ _unit(*s[:2]), abs=1e-12)        # the same tether
        assert _heading(*t) == pytest.approx(m @ _heading(*s), abs=1e-12)          # the same heading
        back = rotate_state(t, transpose(rot))
        assert back[:2] == pytest.approx(s[:2], abs=1e-12)
        assert math.remainder(back[2] - s[2], math.tau) == pytest.approx(0.0, abs=1e-12)


def test_a_tether_along_the_turned_wind_is_on_its_axis():
    chi = math.radians(30.0)
    assert rotate_state([math.pi / 2, chi + math.pi / 2 - chi, 0.0], wind_rotation(math.pi / 2))[0] == \
        pytest.approx(0.0, abs=1e-7)                                 # along ground y, the wind from +90 deg
    assert rotate_state([chi, 0.0, 0.0], wind_rotation(0.0, chi))[0] == pytest.approx(0.0, abs=1e-7)
    # a kite straight downwind at 30 deg elevation, the wind turned by 30 deg: 30 deg off the axis in azimuth
    theta = rotate_state([math.radians(60.0), 0.0, 0.0], wind_rotation(chi))[0]
    assert math.cos(theta) == pytest.approx(math.cos(math.radians(60.0)) * math.cos(chi))
    assert rotate_vector(wind_rotation(chi), (math.cos(chi), math.sin(chi), 0.0)) == pytest.approx((1.0, 0.0, 0.0))


def test_the_mean_wind_drifts_deterministically_with_its_time_scale():
    s = MeanWindSettings(drift=True, time_scale=600.0)

    def series(seed):
        mean = MeanWind(s, np.random.default_rng(seed))
        out = []
        for k in range(1, 36001):
            mean.advance(float(k))
            out.append((mean.speed_factor, mean.direction))
        return np.array(out)
    a, b, c = series(0), series(0), series(1)
    assert np.array_equal(a, b) and not np.array_equal(a, c)
    assert a[0] != pytest.approx((1.0, 0.0)) and abs(a[0, 1]) < 0.02                  # starts in the nominal wind
    # 10 h = 60 correlation times: the stationary standard deviations and the lag-1-time-scale correlation
    d = a[:, 1] / s.direction_std
    assert 0.8 < d.std() < 1.2 and 0.8 < (a[:, 0] - 1).std() / s.speed_std < 1.2
    assert np.corrcoef(d[:-600], d[600:])[0, 1] == pytest.approx(math.exp(-1.0), abs=0.15)


def test_the_extreme_direction_change_is_iec_s():
    # IEC 61400-1 ed. 3 6.3.2.4 at the default plant's hub wind (14.56 m/s) and sigma_1 (2.31 m/s), D = 100 m
    amp = edc_amplitude(2.3128, 14.56, 100.0)
    assert math.degrees(amp) == pytest.approx(29.2, abs=0.1)
    mean = MeanWind(MeanWindSettings(edc_time=100.0, edc_sign=-1), np.random.default_rng(0), amp)
    seen = []
    for t in (99.0, 100.0, 100.0 + EDC_DURATION / 2, 100.0 + EDC_DURATION, 500.0):
        mean.advance(t)
        seen.append(mean.direction)
    assert seen == pytest.approx([0.0, 0.0, -amp / 2, -amp, -amp]) and mean.speed_factor == 1.0


def test_bad_settings_are_named():
    with pytest.raises(ParameterError, match="MeanWindSettings.edc_sign = 0: expected"):
        MeanWindSettings(edc_sign=0)
    with pytest.raises(ParameterError, match=r"MeanWindSettings.speed_std = 0.9: expected a value in \[0, 0.5\]"):
        MeanWindSettings(speed_std=0.9)
    with pytest.raises(ParameterError, match="WindFieldSettings.components = 'uv': expected one of u, uvw"):
        WindFieldSettings(components="uv")
    with pytest.raises(ParameterError, match="a changing mean wind needs wind_model 'field'"):
        PlantConfig(wind_model="uniform", mean_wind=MeanWindSettings(drift=True))


def _config(**mean):
    return replace(PlantConfig(), wind_field=replace(SMALL, components="uvw"), mean_wind=MeanWindSettings(**mean))


def test_without_disturbances_forgets_the_changing_wind():
    assert _config(drift=True, edc_time=5.0).without_disturbances() == PlantConfig().without_disturbances()


def test_the_kite_flies_in_three_components_deterministically(cache):
    plant, ctl = make_closed_loop(plant_config=_config(), seed=2)
    r = run_closed_loop(plant, ctl, 300.0)
    assert plant.wind.turns and r.crashes == 0 and r.altitude[r.t > 60].min() > 100.0
    vane = [plant.step(ctl.command(plant.measure())).wind_direction for _ in range(3000)]
    assert math.radians(3.0) < np.std(vane) < math.radians(20.0)        # the gusts turn the wind at the vane
    first, second = KitePlant(_config(), seed=2), KitePlant(_config(), seed=2)
    assert [first.step(0.1) for _ in range(500)] == [second.step(0.1) for _ in range(500)]


def test_a_30_degree_turn_left_at_the_old_azimuth_costs_about_cos_squared(cache):
    """The path stays centred on azimuth 0 while the mean wind turns by ~29 deg (IEC EDC): the kite keeps flying,
    above the floor, and the lap tension falls to about cos^2 of the misalignment."""
    plant, ctl = make_closed_loop(plant_config=_config(edc_time=200.0), seed=0)
    r = run_closed_loop(plant, ctl, 600.0)
    before = np.mean([lap.mean_tension for lap in r.laps if 40.0 < lap.t_start < 200.0])
    after = np.mean([lap.mean_tension for lap in r.laps if lap.t_start > 260.0])
    amp = plant.wind.mean.direction
    assert math.degrees(amp) == pytest.approx(29.2, abs=0.2)
    assert r.crashes == 0 and r.altitude[r.t > 60].min() > 100.0
    assert after / before == pytest.approx(math.cos(amp) ** 2, abs=0.1)
    vane = np.mean([plant.step(ctl.command(plant.measure())).wind_direction for _ in range(3000)])
    assert math.degrees(vane) == pytest.approx(math.degrees(amp), abs=6.0)        # the vane sees the turn
