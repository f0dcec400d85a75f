"""Learning only while it pays (:class:`~kite_rto.gma.Settle`, gma/settle.py) on a noisy closed-form plant whose
optimum moves: at a settled point GMA flies the nominal point alone, the CUSUM finds the move, GMA learns again and
reaches the new optimum; it loses far less than GMA that perturbs for ever; a resumed run decides the same."""
import math

import numpy as np
import pytest

from kite_rto.gma import (GMA, Decision, ExperimentResult, FiniteDifferenceGradient, GMASettings, History, Settle,
                          TrustRegion, run_offline)
from kite_rto.gma.settle import SettleMechanism

from test_gma_noise import quad_model

SIGMA = 1e-3


class MovingPlant:
    """The quadratic plant of test_gma_noise, whose constraint ``c0 + c1 <= b`` tightens from 1.5 to 1.2 and whose
    cost's centre moves from (1, 1) to (0.5, 1) at experiment ``move_at``: the optimum goes from (2/3, 5/6) to
    (0.3, 0.9) (the constraint stays active). Noise SIGMA on every measurement; ``losses`` holds, per experiment, the
    noise-free cost above the optimum of that moment; ``violations`` counts the experiments beyond the constraint."""

    def __init__(self, seed, move_at=math.inf):
        self.rng = np.random.default_rng(seed)
        self.move_at, self.n, self.losses, self.violations = move_at, 0, [], 0

    def centre_bound(self):
        return ((0.5, 1.0), 1.2) if self.n >= self.move_at else ((1.0, 1.0), 1.5)

    def optimum(self):
        (a, b), bound = self.centre_bound()
        # min (c0 - a)^2 + 2 (c1 - b)^2 on c0 + c1 = bound: c0 - a = 2 (c1 - b)
        c1 = (bound - a + 2 * b) / 3.0
        return np.array([bound - c1, c1])

    def true(self, c):
        (a, b), bound = self.centre_bound()
        return (c[0] - a) ** 2 + 2 * (c[1] - b) ** 2, c[0] + c[1] - bound

    def __call__(self, c):
        cost, g = self.true(c)
        best, _ = self.true(self.optimum())
        self.losses.append(cost - best)
        self.violations += g > 0.02                  # 20 noise standard deviations
        self.n += 1
        noise = SIGMA * self.rng.standard_normal(2)
        return ExperimentResult("", cost + noise[0], [g + noise[1]], cost_std=SIGMA, constraints_std=[SIGMA])


def _gma(settle):
    settings = GMASettings(filter_gain=0.7, trust_region=TrustRegion(radius=0.25, min_radius=1e-3), settle=settle)
    return GMA(quad_model(), settings, FiniteDifferenceGradient.from_noise(SIGMA, curvature=[2.0, 4.0],
                                                                         scheme="central"))


def _experiments(gma, plant, n):
    """Fly until ``n`` experiments are done."""
    while plant.n < n:
        req = gma.next_request()
        res = plant(np.array(req.c))
        res.request_id = req.request_id
        gma.submit(res)
    return gma.history


def test_a_settled_point_is_watched_without_perturbations_and_loses_far_less():
    losses = {}
    for settle in (None, Settle()):
        plant = MovingPlant(seed=0)
        hist = _experiments(_gma(settle), plant, 200)
        its = hist.iterations
        assert np.allclose(its[-1].c_next, plant.optimum(), atol=0.02)
        if settle is not None:
            watched = [r for r in its if r.outcome is Decision.WATCHED]
            assert len(watched) > 0.5 * len(its)
            assert all(len(r.experiment_ids) == 1 and np.array_equal(r.c_next, r.c_k) for r in watched)
            assert "settled point watched" in watched[0].notes
        losses[settle is not None] = sum(plant.losses[50:])       # once both have reached the optimum
    assert losses[True] < 0.2 * losses[False], losses


def test_a_moved_optimum_is_found_and_reached_again():
    """The move tightens the constraint (active at both optima) by 0.3, far beyond the noise: the CUSUM finds it
    within a few watched iterations; GMA learns again with its mechanisms afresh and settles at the new optimum."""
    plant = MovingPlant(seed=1, move_at=120)
    gma = _gma(Settle())
    hist = _experiments(gma, plant, 400)
    its = hist.iterations
    ends = [r for r in its if r.outcome is Decision.WATCHED and "change detected" in r.decision]
    assert ends, [r.decision for r in its]
    # the watch ended within a few watched iterations of the move (the first experiment after it is its nominal)
    ids = [q.request_id for q, _ in hist.experiments]
    moved_at = next(i for i, r in enumerate(its) if ids.index(r.experiment_ids[0]) >= 120)
    detected = next(its.index(r) for r in ends if its.index(r) >= moved_at)
    assert detected - moved_at <= 6
    # learning again: perturbations after the change, then the new optimum, then watched again
    assert any(len(r.experiment_ids) > 1 for r in its[detected + 1:])
    assert np.allclose(its[-1].c_next, plant.optimum(), atol=0.02)
    assert its[-1].outcome is Decision.WATCHED
    # the same GMA without it does not get there: its trust region shrank at the old optimum, and the tightened
    # constraint stays violated
    alone = MovingPlant(seed=1, move_at=120)
    other = _experiments(_gma(None), alone, 400)
    assert not np.allclose(other.iterations[-1].c_next, alone.optimum(), atol=0.1)
    assert plant.violations < 0.25 * alone.violations, (plant.violations, alone.violations)


def test_a_resumed_run_decides_as_the_uninterrupted_one():
    plant = MovingPlant(seed=2, move_at=60)
    full = _gma(Settle())
    hist = _experiments(full, plant, 150)
    k = len(hist.iterations)
    for cut in (k // 3, k // 2, k - 2):
        part = History.from_dict(hist.to_dict())
        part.iterations = part.iterations[:cut]
        done = {i for r in part.iterations for i in r.experiment_ids}
        part.experiments = [(q, r) for q, r in part.experiments if q.request_id in done]
        part.pending = []
        resumed = _gma(Settle())
        resumed = GMA(quad_model(), resumed.settings, resumed.gradient, history=part)
        watcher = next(m for m in resumed.mechanisms if isinstance(m, SettleMechanism))
        original = next(m for m in _gma(Settle()).mechanisms if isinstance(m, SettleMechanism))
        original.resume(History.from_dict({**hist.to_dict(), "iterations": hist.to_dict()["iterations"][:cut]}))
        assert watcher.watching == original.watching
        nxt = resumed.next_request()
        assert (len(resumed.pending_requests()) == 1) == watcher.watching
        assert np.allclose(nxt.c, hist.iterations[cut - 1].c_next)


def test_bad_settings_are_named():
    with pytest.raises(ValueError, match=r"Settle.step=0: expected every value in \(0.0, inf\]"):
        Settle(step=0)
    with pytest.raises(ValueError, match="Settle.after=0"):
        Settle(after=0)
    assert GMASettings.from_dict(GMASettings(settle=Settle()).to_dict()).settle == Settle()
