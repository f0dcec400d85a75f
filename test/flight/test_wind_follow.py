"""The figure-eight follows the wind (kite_rto/flight/wind_follow.py): the vane's filter and rate limit in closed form,
the measurement turned into the path's frame, the controller unchanged when it does not follow, and a 30 deg turn of
the mean wind (IEC's extreme direction change): the path re-centred within 60 s, the next 10 minutes' energy >= 97 %
of a ground station that knows the true mean direction."""
import math
from dataclasses import replace

import numpy as np
import pytest

from kite_rto.flight.closed_loop import make_closed_loop
from kite_rto.flight.wind_follow import WindFollower, WindFollowSettings
from kite_rto.kite.mean_wind import EDC_DURATION, MeanWindSettings
from kite_rto.kite.params import ParameterError
from kite_rto.kite.plant import Measurement, PlantConfig
from kite_rto.kite.wind_field import WindFieldSettings
from kite_rto.kite.wind_frame import rotate_state, wind_rotation
from kite_rto.testing.wind_turn import fly_following


def test_the_direction_is_filtered_and_rate_limited():
    f = WindFollower(WindFollowSettings(enabled=True, filter_time=10.0, rate_limit=math.radians(2.0)), 0.1)
    assert f.update(0.0) == 0.0
    a = 1.0 - math.exp(-0.01)
    step = math.radians(30.0)
    seen = [f.update(step) for _ in range(300)]
    assert seen[0] == pytest.approx(math.radians(0.2))           # rate limited: 2 deg/s x 0.1 s
    filtered = step * (1.0 - (1.0 - a) ** 300)
    assert f.filtered == pytest.approx(filtered) and seen[-1] == pytest.approx(filtered, abs=1e-9)
    assert f.update(float("nan")) == seen[-1]                    # a bad reading is skipped
    g = WindFollower(WindFollowSettings(enabled=True, filter_time=1.0, rate_limit=10.0), 0.1)
    g.update(math.pi - 0.05)
    g.update(-math.pi + 0.05)                                     # across +-pi: a 0.1 rad change, not 2 pi
    assert g.filtered == pytest.approx(math.pi - 0.05 + 0.1 * (1.0 - math.exp(-0.1)))
    with pytest.raises(ParameterError, match="WindFollowSettings.filter_time = 0: expected"):
        WindFollowSettings(filter_time=0)
    with pytest.raises(ParameterError, match="dt = 0: expected a sample time > 0 s"):
        WindFollower(WindFollowSettings(), 0)


def _measurement(theta, phi, psi, rates=(0.1, -0.3, 0.8)):
    return Measurement(t=1.0, theta=theta, phi=phi, psi=psi, theta_dot=rates[0], phi_dot=rates[1], psi_dot=rates[2],
                       tension=5e5, position=(300.0, -40.0, 180.0), wind_ref=8.0, delta=0.0, crashes=0, step=50,
                       wind_direction=0.4)


def test_a_measurement_in_the_path_frame():
    f = WindFollower(WindFollowSettings(enabled=True, filter_time=1e-9, rate_limit=100.0), 0.02)
    m = _measurement(0.5, 0.2, 1.0)
    assert f.to_path_frame(m) is m                                # direction 0: the measurement itself
    f.update(0.3)
    p = f.to_path_frame(m)
    assert [p.theta, p.phi, p.psi] == pytest.approx(rotate_state([0.5, 0.2, 1.0], wind_rotation(0.3)))
    assert p.tension == m.tension and p.wind_ref == 8.0 and p.step == 50         # the rest as measured
    assert p.altitude == pytest.approx(180.0)
    # the rates: the image of the motion, to first order
    h = 1e-6
    later = rotate_state([0.5 + h * 0.1, 0.2 - h * 0.3, 1.0 + h * 0.8], wind_rotation(0.3))
    assert [p.theta_dot, p.phi_dot, p.psi_dot] == pytest.approx(
        [(a - b) / h for a, b in zip(later, [p.theta, p.phi, p.psi])], rel=1e-3)


def test_a_controller_that_does_not_follow_sees_the_measurement_itself():
    plant, ctl = make_closed_loop(seed=0)
    m = plant.measure()
    assert ctl.wind is None and ctl.in_path_frame(m) is m


@pytest.mark.parametrize("seed", [2])
def test_after_a_30_degree_turn_the_path_follows_and_keeps_the_energy(seed, tmp_path, monkeypatch):
    monkeypatch.setenv("KITE_RTO_CACHE", str(tmp_path))
    turn = 100.0
    config = replace(PlantConfig(), wind_field=WindFieldSettings(points=(512, 32, 32), components="uvw"),
                     mean_wind=MeanWindSettings(edc_time=turn))
    flown, plant = fly_following(config, WindFollowSettings(enabled=True), seed, turn + EDC_DURATION + 600.0)
    best, _ = fly_following(config, WindFollowSettings(enabled=True, filter_time=1e-9, rate_limit=100.0), seed,
                   turn + EDC_DURATION + 600.0, true_vane=True)
    t, tension, direction, crashes = flown
    new = plant.wind.mean.direction
    assert math.degrees(new) == pytest.approx(29.2, abs=0.2) and crashes[-1] == 0
    end = turn + EDC_DURATION
    recentred = t[(t > end) & (np.abs(direction - new) < math.radians(5.0))]
    assert recentred.size and recentred[0] - end <= 60.0
    after = t > end
    assert tension[after].sum() / best[1][after].sum() >= 0.97
