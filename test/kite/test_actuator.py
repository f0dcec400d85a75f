"""The steering actuator written once (plant and controller predictor): dead time, rate limit, prediction."""
import numpy as np
import pytest

from kite_rto.kite.actuator import Actuator, step_toward


def test_step_toward_limits_the_change():
    assert step_toward(0.0, 1.0, 0.1) == 0.1
    assert step_toward(0.0, -1.0, 0.1) == -0.1
    assert step_toward(0.5, 0.55, 0.1) == 0.55


def test_dead_time_then_rate_limit():
    act = Actuator(dead_time=0.06, rate_limit=5.0, dt=0.02)
    assert act.n_delay == 3 and act.max_change == pytest.approx(0.1)
    applied = [act.push(1.0) for _ in range(6)]
    assert applied[:3] == [0.0] * 3
    np.testing.assert_allclose(applied[3:], [0.1, 0.2, 0.3])


@pytest.mark.parametrize("dead_time", [0.0, 0.02, 0.25])
def test_pending_predicts_the_next_applied_values(dead_time):
    act = Actuator(dead_time, 5.0, 0.02)
    rng = np.random.default_rng(0)
    for u in rng.uniform(-1, 1, 50):
        act.push(float(u))
    predicted = list(act.pending())
    assert len(predicted) == act.n_delay
    assert predicted == [act.push(float(u)) for u in rng.uniform(-1, 1, act.n_delay)]


def test_reset_empties_the_line():
    act = Actuator(0.1, 5.0, 0.02)
    for _ in range(10):
        act.push(1.0)
    act.reset()
    assert act.applied == 0.0 and list(act.pending()) == [0.0] * act.n_delay
