"""History: JSON round trip, and resuming a run without repeating finished experiments."""
import json

import casadi as ca
import numpy as np

from kite_rto.gma import (GMA, ExperimentResult, FiniteDifferenceGradient, GMASettings, History, ModelProblem,
                          run_offline)


def problem():
    u = ca.SX.sym("u", 3)
    y = ca.vertcat(u[0] + 0.5 * u[2], u[1])
    return ModelProblem(u=u, cost=(u[0] - 0.5) ** 2 + (u[1] - 1.5) ** 2 + u[2] ** 2,
                        constraints=0.9 * u[0] + u[1] - 2.2, outputs=y, lbu=-5, ubu=5, u0=np.zeros(3),
                        c_lb=[-2, -2], c_ub=[3, 3], name="hist")


class Plant:
    def __init__(self):
        self.log = []

    def __call__(self, c):
        self.log.append(np.array(c))
        return ExperimentResult("", (c[0] - 1) ** 2 + 2 * (c[1] - 1) ** 2, [c[0] + c[1] - 1.5],
                                cost_std=1e-3, extra={"laps": 3})


def make(history=None):
    return GMA(problem(), GMASettings(filter_gain=0.8), FiniteDifferenceGradient(1e-5, "central"),
               history=history)


def test_json_round_trip_is_lossless():
    gma = make()
    run_offline(gma, Plant(), 3)
    text = gma.history.to_json()
    json.loads(text)  # strict JSON
    back = History.from_json(text)
    assert back.to_dict() == gma.history.to_dict()
    rec, rec0 = back.iterations[-1], gma.history.iterations[-1]
    assert rec.mu.shape == (1, 2) and rec.jac_g_hat.shape == (1, 2)
    np.testing.assert_array_equal(rec.c_next, rec0.c_next)
    assert back.experiments[0][1].extra == {"laps": 3}
    assert back.experiments[0][1].cost_std == 1e-3 and back.experiments[0][1].constraints_std is None


def test_save_and_load(tmp_path):
    gma = make()
    run_offline(gma, Plant(), 1)
    gma.history.save(tmp_path / "h.json")
    assert History.load(tmp_path / "h.json").to_dict() == gma.history.to_dict()


def test_resume_mid_iteration_does_not_repeat_experiments():
    reference = make()
    run_offline(reference, Plant(), 6)

    gma, plant = make(), Plant()
    run_offline(gma, plant, 3)
    for _ in range(2):  # two experiments of iteration 3 done, then "crash"
        req = gma.next_request()
        res = plant(req.c)
        res.request_id = req.request_id
        gma.submit(res)
    saved = gma.history.to_json()
    done = {q.request_id for q, _ in gma.history.experiments}

    resumed = make(History.from_json(saved))
    assert resumed.k == 3
    first = resumed.next_request()
    assert first.request_id not in done and first.purpose == "perturbation"
    run_offline(resumed, plant, 3)
    ids = [q.request_id for q, _ in resumed.history.experiments]
    assert len(ids) == len(set(ids))
    assert len(resumed.history.iterations) == 6
    np.testing.assert_allclose(resumed.c, reference.c, atol=1e-7)
    np.testing.assert_allclose([r.c_next for r in resumed.history.iterations],
                               [r.c_next for r in reference.history.iterations], atol=1e-7)


def test_resume_between_iterations():
    gma = make()
    run_offline(gma, Plant(), 2)
    resumed = make(History.from_json(gma.history.to_json()))
    assert resumed.k == 2 and resumed.next_request().request_id == "k2-0-nominal"
    np.testing.assert_array_equal(resumed.c, gma.c)
