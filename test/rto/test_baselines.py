"""The Bayesian-optimization baseline on the default plant: a short budget, candidates in the box, seeded, stops."""
import numpy as np

from kite_rto.flight.shape import ShapeBox
from kite_rto.rto.baselines import bayes_opt_plant
from kite_rto.rto.builder import model_only_optimum
from kite_rto.rto.settings import KiteRTOSettings


def test_bayes_opt_flies_its_budget_and_recommends_measured_points_in_the_box():
    box, c0 = ShapeBox(), model_only_optimum(KiteRTOSettings()).c
    run = bayes_opt_plant(None, 3, c0, 450.0, box=box, init_points=1)
    assert run.flight_time >= 450.0 and run.experiments >= 4       # c0, one random point, then the GP's picks
    assert run.flight_time < 450.0 + 300.0                           # stops after the experiment that crosses it
    assert np.allclose(run.candidates[0], c0) and run.times[0] == 0.0
    assert np.all(np.diff(run.times) > 0)
    for c in run.candidates:
        z = box.to_unit(c)
        assert np.all(z >= -1e-9) and np.all(z <= 1 + 1e-9), z
    again = bayes_opt_plant(None, 3, c0, 450.0, box=box, init_points=1)
    assert np.array_equal(np.array(again.candidates), np.array(run.candidates))   # seeded: same run


def test_bayes_opt_stops_once_a_candidate_is_accepted():
    seen = []

    def stop(c):
        seen.append(c)
        return len(seen) == 2
    run = bayes_opt_plant(None, 0, model_only_optimum(KiteRTOSettings()).c, 5000.0, init_points=2, stop=stop)
    assert run.stopped and len(run.candidates) == 2 and run.flight_time < 5000.0
