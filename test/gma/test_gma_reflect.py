"""Reflected alternation (``reflect`` of DirectionalGradient) and alternation counted from the last long step
(``GMASettings.alternate_within``).

Closed form: model ``phi = (u1 - 0.5)^2 + (u2 - 1.5)^2``, plant ``phi_p = 2 c1 + (c2 - 1)^2`` without noise, box
``c1 in [0, 3]``, ``c2 in [-2, 3]``: the plant optimum ``(0, 1)`` lies on c1's lower bound, interior in c2. The
directions ``d1 = (0.4, 1)``, ``d2 = (1, -0.2)`` mix c1 with c2, step 0.5: perturbations ``p1 = (0.2, 0.5)``,
``p2 = (0.5, -0.1)``. Forward differences carry the truncation errors ``b_i = p_i^T H p_i / 2 = (0.25, 0.01)``,
so the estimated gradient is off by ``P^-T b``, 0.456 in c2: GMA stops at ``c2 = 1 - 0.456 / 2 = 0.772``. A
backward step of either direction leaves the box in c1, so plain ``alternate`` flies forward every time and stays
there; ``reflect`` flies ``(0.2, -0.5)`` and ``(0.5, 0.1)`` in the backward iterations, whose errors in c2 are the
forward ones with the other sign (H has no c1-c2 term), and the filtered iterates stand at ``c2 = 1``.
"""
import casadi as ca
import numpy as np
import pytest

from kite_rto.gma import (GMA, DirectionalGradient, ExperimentResult, GMASettings, History, ModelProblem,
                          run_offline)

U = np.array([[0.4, 1.0], [1.0, -0.2]])
STEP = 0.5
LB, UB = np.array([0.0, -2.0]), np.array([3.0, 3.0])
SECANT_C2 = 1.0 - 0.4556 / 2          # where the forward differences' estimate of the c2 derivative vanishes


def model():
    u = ca.SX.sym("u", 2)
    return ModelProblem(u=u, cost=(u[0] - 0.5) ** 2 + (u[1] - 1.5) ** 2, constraints=None, outputs=u,
                        lbu=-5, ubu=5, u0=[0, 0], c_lb=LB, c_ub=UB, name="reflect")


def plant(c):
    return ExperimentResult("", 2.0 * c[0] + (c[1] - 1.0) ** 2, [], cost_std=1e-3, constraints_std=[])


def run(reflect: bool, n: int = 30, **settings):
    est = DirectionalGradient(U, step=STEP, reuse=False, alternate=True, reflect=reflect)
    gma = GMA(model(), GMASettings(filter_gain=1.0, trust_radius=0.3, trust_radius_min=1e-3, modifier_drift=0.5,
                                   **settings), est)
    return run_offline(gma, plant, n)


def perturbations(hist) -> dict:
    """{iteration: (nominal, displacements (m, 2))} of a history."""
    by_k = {}
    for q, _ in hist.experiments:
        by_k.setdefault(q.iteration, []).append(np.asarray(q.c, float))
    return {k: (pts[0], np.array(pts[1:]) - pts[0]) for k, pts in by_k.items()}


def test_plain_alternation_cannot_change_side_at_the_bound():
    hist = run(reflect=False)
    tail = np.array([r.c_next for r in hist.iterations[-10:]])
    np.testing.assert_allclose(tail[:, 0], 0.0, atol=1e-6)
    np.testing.assert_allclose(tail[:, 1], SECANT_C2, atol=2e-3)


def test_reflected_alternation_cancels_the_free_setpoints_error():
    hist = run(reflect=True)
    tail = np.array([r.c_next for r in hist.iterations[-10:]])
    np.testing.assert_allclose(tail[:, 0], 0.0, atol=1e-6)
    assert abs(tail[:, 1].mean() - 1.0) < 0.02, tail[:, 1]
    assert np.ptp(tail[:, 1]) < 0.1                       # a small 2-cycle around c2 = 1, not a wander
    pert = perturbations(hist)
    for k in (20, 21):                                     # at the bound c1 = 0: c1 forward always, c2 alternates
        c, dc = pert[k]
        assert c[0] == pytest.approx(0.0, abs=1e-6)
        sign = -1.0 if k % 2 else 1.0
        np.testing.assert_allclose(dc, [[0.2, sign * 0.5], [0.5, -sign * 0.1]], atol=1e-9)


def test_reflection_is_clipped_to_the_box_and_kept_where_too_short():
    est = DirectionalGradient(np.eye(2), step=STEP, reuse=False, alternate=True, reflect=True)
    lb, ub = np.zeros(2), np.ones(2)
    c = np.array([0.7, 0.1])
    # forward: c1 + 0.5 leaves the box, so c1 goes backwards (-0.5); c2 forward (+0.5)
    np.testing.assert_allclose(est.plan_iteration(c, lb, ub, [], 0), [[0.2, 0.1], [0.7, 0.6]])
    # backward: c1's reflection +0.5 is clipped to +0.3 (more than half: taken); c2's -0.5 to -0.1 (kept forward)
    np.testing.assert_allclose(est.plan_iteration(c, lb, ub, [], 1), [[1.0, 0.1], [0.7, 0.6]])
    # without reflect the backward iteration is the forward one here (each backward step leaves the box)
    plain = DirectionalGradient(np.eye(2), step=STEP, reuse=False, alternate=True)
    np.testing.assert_allclose(plain.plan_iteration(c, lb, ub, [], 1), [[0.2, 0.1], [0.7, 0.6]])


def test_alternation_counts_from_the_last_long_step():
    """With ``alternate_within`` the perturbations after a long step go forward, and sides alternate only while
    the steps stay short; the side of every iteration follows from the recorded steps."""
    within = 0.02
    hist = run(reflect=True, alternate_within=within)
    width = UB - LB
    pert, n_short = perturbations(hist), 0
    backward_seen = forward_after_long = 0
    for k, rec in enumerate(hist.iterations):
        c, dc = pert[k]
        backward = bool(dc[0, 1] < 0)                      # p1's c2 component: +0.5 forward, -0.5 backward
        assert backward == (n_short % 2 == 1), (k, n_short, dc)
        backward_seen += backward
        forward_after_long += (n_short == 0 and k > 0)
        n_short = n_short + 1 if np.max(np.abs(rec.step) / width) <= within else 0
    assert backward_seen >= 3 and forward_after_long >= 1
    tail = np.array([r.c_next for r in hist.iterations[-10:]])
    assert abs(tail[:, 1].mean() - 1.0) < 0.03, tail[:, 1]


def test_a_resumed_run_plans_the_same_sides():
    first = run(reflect=True, n=12, alternate_within=0.02)
    est = DirectionalGradient(U, step=STEP, reuse=False, alternate=True, reflect=True)
    settings = GMASettings(filter_gain=1.0, trust_radius=0.3, trust_radius_min=1e-3, modifier_drift=0.5,
                           alternate_within=0.02)
    part = History(c0=first.c0, meta=first.meta, iterations=first.iterations[:7],
                   experiments=[(q, r) for q, r in first.experiments if q.iteration < 7])
    resumed = GMA(model(), settings, est, history=part)
    np.testing.assert_allclose([q.c for q in resumed.pending_requests()],
                               [q.c for q, _ in first.experiments if q.iteration == 7], atol=1e-12)


def test_bad_values_are_named():
    with pytest.raises(ValueError, match="reflect='yes'"):
        DirectionalGradient(U, reflect="yes")
    with pytest.raises(ValueError, match="alternate_within=0"):
        GMASettings(alternate_within=0)
