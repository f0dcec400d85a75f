"""The yield of a whole flight (kite_rto/rto/flight_yield.py) on closed-form judges: a weighted mean of the segments
in a stationary wind, the time integral in a wind that changes, the floor, the timeline read from a GMA history, the
kite's judge_flight and the run report's line."""
import math
from types import SimpleNamespace

import numpy as np
import pytest

from kite_rto.gma import ExperimentRequest, ExperimentResult, History
from kite_rto.kite.plant import PlantConfig
from kite_rto.rto import judge as judge_module
from kite_rto.rto.flight_yield import Segment, flight_yield, segments_of_history
from kite_rto.rto.judge import judge_flight
from kite_rto.tools.rto_report import yield_line


def _quadratic(c, t):
    """A plant whose tension falls quadratically away from c* = (1, 1), 100 kN there; min altitude 100 m, or 90 m
    beyond c[0] = 1.5."""
    d = np.asarray(c) - 1.0
    return 100.0 - 10.0 * float(d @ d), 90.0 if c[0] > 1.5 else 100.0


def test_a_stationary_flight_is_the_time_weighted_mean_of_its_segments():
    segs = [Segment(0.0, 100.0, (1.0, 1.0), "nominal"), Segment(100.0, 400.0, (2.0, 1.0), "perturbation"),
            Segment(400.0, 500.0, (1.0, 0.0), "perturbation")]
    y = flight_yield(segs, _quadratic, lambda t: 100.0, floor=98.0)
    assert y.flight_time == 500.0
    assert y.energy == pytest.approx(100 * 100 + 90 * 300 + 90 * 100)
    assert y.percent == pytest.approx(100.0 * (10000 + 27000 + 9000) / 50000)
    assert y.below_floor_s == 300.0                      # the segment at c[0] = 2 flies at 90 m
    assert y.by_purpose["nominal"] == (100.0, pytest.approx(100.0))
    assert y.by_purpose["perturbation"] == (400.0, pytest.approx(90.0))
    assert [r.percent for r in y.segments] == pytest.approx([100.0, 90.0, 90.0])
    assert y.summary()["energy_MJ"] == pytest.approx(46.0)


def test_a_changing_wind_is_integrated_over_time():
    # the oracle's tension grows linearly in time, the flown setpoints give 90 % of it: a midpoint rule is exact
    oracle = lambda t: 100.0 + t                                  # noqa: E731
    judge = lambda c, t: (0.9 * oracle(t), 120.0)               # noqa: E731
    segs = [Segment(0.0, 250.0, (1.0,)), Segment(250.0, 1000.0, (2.0,))]
    y = flight_yield(segs, judge, oracle, floor=98.0, resolution=10.0)
    assert y.percent == pytest.approx(90.0)
    assert y.oracle_energy == pytest.approx(100.0 * 1000 + 0.5 * 1000**2)
    # in a wind that changes, a segment judged once at its middle is not the integral: resolution matters
    step = lambda t: 100.0 if t < 500 else 200.0                 # noqa: E731
    fine = flight_yield([Segment(0.0, 1000.0, (1.0,))], lambda c, t: (step(t) if t < 500 else 0.5 * step(t), 120.0),
                        step, floor=98.0, resolution=50.0)
    assert fine.percent == pytest.approx(100.0 * (50000 + 50000) / (50000 + 100000))


def test_bad_inputs_are_named():
    with pytest.raises(ValueError, match="t_start = 5.0, t_end = 1.0"):
        Segment(5.0, 1.0, (1.0,))
    with pytest.raises(ValueError, match="resolution = 0"):
        flight_yield([], _quadratic, lambda t: 100.0, 98.0, resolution=0)
    with pytest.raises(ValueError, match=r"oracle\(50\) = 0.0: expected a tension > 0 kN"):
        flight_yield([Segment(0.0, 100.0, (1.0, 1.0))], _quadratic, lambda t: 0.0, 98.0)
    empty = flight_yield([], _quadratic, lambda t: 100.0, 98.0)
    assert math.isnan(empty.percent) and empty.flight_time == 0.0


def _history(times, purposes=None):
    h = History(c0=np.zeros(3))
    for i, (t0, t1) in enumerate(times):
        req = ExperimentRequest(f"k0-{i}", np.full(3, float(i)), (purposes or ["nominal"] * len(times))[i], 0)
        extra = {} if t0 is None else {"t_start": t0, "t_end": t1}
        h.experiments.append((req, ExperimentResult(req.request_id, -1.0, np.zeros(1), extra=extra)))
    return h


def test_the_timeline_of_a_history_is_contiguous_and_gaps_fly_the_next_setpoints():
    segs = segments_of_history(_history([(10.0, 80.0), (80.0, 150.0), (190.0, 260.0)]))
    assert [(s.t_start, s.t_end, s.c[0]) for s in segs] == [(10.0, 80.0, 0.0), (80.0, 150.0, 1.0),
                                                            (150.0, 260.0, 2.0)]
    with pytest.raises(ValueError, match="experiment 'k0-1' has no t_start/t_end"):
        segments_of_history(_history([(0.0, 10.0), (None, None)]))


def test_judge_flight_judges_every_experiment_on_the_deterministic_plant(monkeypatch):
    seen = []

    def performance(config, c):
        seen.append((config, tuple(c)))
        return (600.0, 120.0) if c[0] < 1.5 else (540.0, 97.0)
    monkeypatch.setattr(judge_module, "plant_performance", performance)
    monkeypatch.setattr(judge_module, "setpoints_from_shape", lambda c: np.asarray(c))
    plant = PlantConfig()
    flight = judge_flight(plant, 100.0, 600.0, _history([(0.0, 100.0), (100.0, 200.0), (200.0, 400.0)],
                                                         ["nominal", "perturbation", "perturbation"]))
    assert [s for _, s in seen] == [(0.0,) * 3, (1.0,) * 3, (2.0,) * 3] and all(p is plant for p, _ in seen)
    assert flight.percent == pytest.approx(100.0 * (600 * 200 + 540 * 200) / (600 * 400))
    assert flight.below_floor_s == 200.0                  # 97 m < 100 - 2
    line = yield_line(flight)
    assert "95.00 % of the oracle's energy over 400 s" in line
    assert "nominal 100 s at 100.00 %, perturbation 300 s at 93.33 %" in line and "below the floor: 200 s" in line
    with pytest.raises(ValueError, match="oracle_tension_kn = 0"):
        judge_flight(plant, 100.0, 0.0, SimpleNamespace(experiments=[]))
