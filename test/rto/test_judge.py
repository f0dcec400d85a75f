"""The one judge (kite_rto/rto/judge.py) on a closed-form stand-in for the deterministic plant: the target's edges
(exactly 99 % of the oracle, exactly h_min - 2 m), a crash, the verdict of a run, refused inputs, and the run
report's rows judged by it."""
import math
from dataclasses import replace
from types import SimpleNamespace

import numpy as np
import pytest

from kite_rto.kite.plant import PlantConfig
from kite_rto.rto import judge as judge_module
from kite_rto.rto.judge import (ALTITUDE_TOLERANCE_M, REACH_FRACTION, REACH_PERCENT, altitude_floor, judge,
                                judge_point, reaches)
from kite_rto.tools.rto_report import judge_iterates

PLANT = PlantConfig()
ORACLE = 600.0
# setpoint theta_0 (rad) -> (tension kN, min altitude m) of the stand-in plant
FLOWN = {0.1: (593.9, 120.0), 0.2: (REACH_FRACTION * ORACLE, 98.0), 0.3: (610.0, 97.99), 0.4: (0.0, -math.inf),
         0.5: (605.0, 130.0)}


@pytest.fixture(autouse=True)
def stand_in_plant(monkeypatch):
    seen = []

    def perf(config, c):
        seen.append(config)
        return FLOWN[round(float(c[0]), 3)]
    monkeypatch.setattr(judge_module, "plant_performance", perf)
    return seen


def _c(theta):
    return np.array([theta, 0.8, 0.5])


def test_the_target_and_the_floor_are_defined_once():
    assert REACH_FRACTION == 0.99 and REACH_PERCENT == 99.0 and ALTITUDE_TOLERANCE_M == 2.0
    assert altitude_floor(100.0) == 98.0 and altitude_floor(150.0) == 148.0


def test_a_point_reaches_at_exactly_99_percent_and_exactly_the_floor(stand_in_plant):
    edge = judge_point(PLANT, 100.0, ORACLE, _c(0.2))
    assert edge.reached and edge.above_floor and edge.percent == pytest.approx(99.0)
    assert not judge_point(PLANT, 100.0, ORACLE, _c(0.1)).reached                   # 593.9 kN < 0.99 x 600 kN
    low = judge_point(PLANT, 100.0, ORACLE, _c(0.3))
    assert not low.reached and not low.above_floor and low.percent > 100.0          # 1 cm below the floor
    assert judge_point(PLANT, 99.99, ORACLE, _c(0.3)).reached                        # the run's own h_min decides
    crash = judge_point(PLANT, 100.0, ORACLE, _c(0.4))
    assert crash == judge_module.Judged(0.0, -math.inf, 0.0, False, False)
    assert reaches(PLANT, 100.0, ORACLE, _c(0.5)) and not reaches(PLANT, 100.0, ORACLE, _c(0.1))
    other = replace(PLANT, dead_time=0.5)
    judge_point(other, 100.0, ORACLE, _c(0.5))
    assert stand_in_plant[-1] is other                                              # flown on the plant given


def test_a_verdict_names_the_first_reaching_iterate_its_time_and_whether_it_held():
    v = judge(PLANT, 100.0, ORACLE, [_c(0.1), _c(0.5), _c(0.3), _c(0.2), _c(0.5)], [0.0, 400.0, 800.0, 1200.0, 1600.0])
    assert v.reached == (False, True, False, True, True)
    assert (v.reach_index, v.reach_time, v.held_from) == (1, 400.0, 3)
    assert v.below_floor == 1 and v.lowest_altitude == 97.99
    assert v.percent[1] == 100.0 * 605.0 / ORACLE
    never = judge(PLANT, 100.0, ORACLE, [_c(0.1), _c(0.4)], [0.0, 300.0])
    assert (never.reach_index, never.reach_time, never.held_from) == (None, math.inf, None)
    assert never.lowest_altitude == -math.inf and never.below_floor == 1


@pytest.mark.parametrize("args, match", [
    ((None, 100.0, ORACLE), r"plant = None: expected the PlantConfig"),
    ((PLANT, math.nan, ORACLE), r"h_min = nan: expected the run's altitude floor"),
    ((PLANT, 100.0, 0.0), r"oracle_tension_kn = 0.0: expected the oracle's mean tension"),
])
def test_a_judge_without_its_plant_floor_or_oracle_is_refused(args, match):
    with pytest.raises(ValueError, match=match):
        judge_point(*args, _c(0.5))
    with pytest.raises(ValueError, match=match):
        judge(*args, [_c(0.5)], [0.0])


def test_one_time_per_iterate():
    with pytest.raises(ValueError, match="2 iterates but 1 times"):
        judge(PLANT, 100.0, ORACLE, [_c(0.1), _c(0.5)], [0.0])


def test_the_run_report_judges_with_the_same_judge(monkeypatch):
    monkeypatch.setattr("kite_rto.tools.rto_report.setpoints_from_shape", lambda c: np.asarray(c, dtype=float))
    record = SimpleNamespace(c_next=_c(0.2), cost=-596.0, constraints=np.array([-3.0]), decision="step")
    history = SimpleNamespace(c0=_c(0.3), iterations=[record])
    rows = judge_iterates(history, PLANT, 100.0, SimpleNamespace(tension_kn=ORACLE))
    assert [(r["feasible"], r["reached"]) for r in rows] == [(False, False), (True, True)]
    assert rows[0]["judged_min_altitude_m"] == 97.99 and rows[0]["measured_tension_kN"] == 596.0
    assert [r["reached"] for r in judge_iterates(history, PLANT, 99.99, SimpleNamespace(tension_kn=ORACLE))] == \
        [True, True]
    assert all(r["judged_tension_kN"] is None for r in judge_iterates(history, PLANT, 100.0, None))
