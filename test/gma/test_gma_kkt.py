"""The measured-KKT test at a held bound (issue #14 item 2; kite_rto.gma.kkt, GMASettings.structure_kkt).

Closed-form problem, setpoints c = (c1, c2) in the box [0, 1] x [0, 2]:

    model  phi = 6.3 c1 + (c2 - T)^2,  g = c2 - 0.5 - c1 <= 0,  y = u,  T = 3.5,  -1 <= u <= 3
    plant  phi_p = phi,                g_p = c2 - 0.5 - 1.15 c1 <= 0

The model optimum is (0, 0.5): the constraint is active with nu = 2 (T - 0.5) = 6, and along c1 the model's
Lagrangian grows, 6.3 - 6 * 1 = +0.3: c1 sits on its lower bound with a positive multiplier. The plant's
constraint slope in c1 is 1.15, so its Lagrangian slope there is 6.3 - 6 * 1.15 = -0.6: the plant leaves the bound.
On c2 = 0.5 + 1.15 c1 the plant cost is 6.3 c1 + (1.15 c1 - 3)^2, smallest at c1 = 0.6 / 2.645: the plant optimum
is (0.22684, 0.76087), cost 8.93194, against 9 at the held point (0, 0.5).

The model is defined beyond the box (bounds -1 <= u <= 3), so that the central differences of lagrangian_gradient
at c1 = 0 can be realized. DMA with the uncertain T measures only c2 and holds c1 (T moves only the c2 component of the Lagrangian gradient).
The mismatch test of the structure check (kite_rto.gma.structure) does not see the error: along dc = (0.1, 0) the
cost changes as predicted and the constraint by -0.115 against the predicted -0.1, within structure_rel_tol = 0.2
of it. Their combination, the Lagrangian, changes by 0.63 - 6 * 0.115 = -0.06: the wrong sign.
"""
import re

import casadi as ca
import numpy as np
import pytest

from kite_rto.gma import (GMA, DirectionalGradient, ExperimentResult, GMASettings, History, ModelProblem,
                          PlantPoint, kkt_test, lagrangian_gradient, model_optimum, privileged_directions,
                          run_offline)

C_LB, C_UB = np.array([0.0, 0.0]), np.array([1.0, 2.0])
A, T, NU = 6.3, 3.5, 6.0
PLANT_OPT = np.array([0.6 / 2.645, 0.5 + 1.15 * 0.6 / 2.645])
HELD = np.array([0.0, 0.5])
H = 1e-3                        # DMA step (multiples of the direction, which is one box width long)


def model(theta=T):
    u = ca.SX.sym("u", 2)
    return ModelProblem(u=u, cost=A * u[0] + (u[1] - theta) ** 2, constraints=u[1] - 0.5 - u[0], outputs=u,
                        lbu=-1.0, ubu=3.0, u0=[0.5, 1.0], c_lb=C_LB, c_ub=C_UB, name="kkt_model")


def plant(c, slope=1.15):
    return A * c[0] + (c[1] - T) ** 2, np.array([c[1] - 0.5 - slope * c[0]])


def noisy(sigma, seed, slope=1.15):
    rng = np.random.default_rng(seed)

    def measure(c):
        f, g = plant(c, slope)
        return ExperimentResult("", f + rng.normal(0, sigma), g + rng.normal(0, sigma, 1), cost_std=sigma,
                                constraints_std=[sigma])
    return measure


def dma(step=H):
    """DMA at the model optimum: one privileged direction (c2), c1 held at its bound."""
    pr = model()
    c0 = model_optimum(pr)
    np.testing.assert_allclose(c0, HELD, atol=1e-7)
    pd = privileged_directions(lambda th: lagrangian_gradient(model(th[0]), c0, [NU]), [T], [0.3], 1,
                               scale=pr.c_width, at_bound=[-1, 0])
    assert pd.fixed.tolist() == [True, False]
    np.testing.assert_allclose(pd.gradient, [A - NU, 0.0], atol=1e-5)       # +0.3: the model holds c1
    return DirectionalGradient(pd.directions, step=step, reuse=False)


def kkt_numbers(note):
    """(Lagrangian change, std, threshold) of a measured-KKT note."""
    m = re.search(r"Lagrangian change ([-+.\de]+) \(std ([-.\de]+), threshold -([-.\de]+)\)", note)
    return tuple(float(x) for x in m.groups())


def settings(kkt):
    return GMASettings(structure_stall=0.01, structure_kkt=kkt)


def test_without_the_kkt_test_the_mismatch_check_holds_the_bound():
    gma = GMA(model(), settings(False), dma())
    run_offline(gma, plant, 12)
    np.testing.assert_allclose(gma.c, HELD, atol=1e-3)
    checks = [n for r in gma.records for n in r.notes if n.startswith("structure check along")]
    assert len(checks) >= 5 and all(n.endswith("model agrees") for n in checks)
    assert not any(r.restored_directions for r in gma.records)
    assert plant(gma.c)[0] == pytest.approx(9.0, abs=5e-3)


def test_the_kkt_test_releases_the_bound_and_reaches_the_plant_optimum():
    """Iteration 0 stalls on the held point; iteration 1 flies the structure experiment, whose Lagrangian change
    has the wrong sign: c1 is measured from iteration 2 on and GMA reaches the plant optimum. Fails if the test
    is switched off (previous test)."""
    gma = GMA(model(), settings(True), dma())
    run_offline(gma, plant, 20)
    np.testing.assert_allclose(gma.c, PLANT_OPT, atol=5e-3)
    first = gma.records[1]
    assert first.experiment_ids == ["k1-0-nominal", "k1-1-perturbation", "k1-2-structure"]
    assert any(n.endswith("model agrees") for n in first.notes)                 # the mismatch test misses it
    kkt = [n for n in first.notes if n.startswith("measured KKT at the held bound c[0] (lower)")]
    assert len(kkt) == 1 and "multiplier sign wrong" in kkt[0]
    change, std, threshold = kkt_numbers(kkt[0])     # nu = 6 up to the forward-difference bias along c2
    assert change == pytest.approx(-0.06, abs=1e-3) and std == threshold == 0.0
    np.testing.assert_allclose(np.asarray(first.restored_directions), [[1.0, 0.0]])
    assert gma.gradient.n_directions == 2
    assert sum(len(r.restored_directions) for r in gma.records) == 1
    assert gma.records[2].experiment_ids == ["k2-0-nominal", "k2-1-perturbation", "k2-2-perturbation"]
    assert plant(gma.c)[0] == pytest.approx(8.93194, abs=1e-3) and plant(gma.c)[1][0] <= 1e-6


def test_a_plant_whose_multiplier_keeps_its_sign_keeps_the_bound():
    """Plant constraint slope 1.03: its Lagrangian slope 6.3 - 6.18 = +0.12 keeps c1 on the bound (the plant
    optimum is the held point): the test agrees at every stall, also with noise."""
    gma = GMA(model(), settings(True), dma())
    run_offline(gma, lambda c: plant(c, 1.03), 8)
    np.testing.assert_allclose(gma.c, HELD, atol=1e-3)
    kkt = [n for r in gma.records for n in r.notes if n.startswith("measured KKT")]
    assert len(kkt) >= 5 and all(n.endswith("multiplier sign agrees") for n in kkt)
    assert not any(r.restored_directions for r in gma.records)
    noisy_run = GMA(model(), settings(True), dma(step=0.05))
    run_offline(noisy_run, noisy(2e-3, seed=1, slope=1.03), 12)
    assert not any(r.restored_directions for r in noisy_run.records)


def test_with_noise_the_release_is_significant_in_standard_errors():
    """sigma = 5e-4 on cost and constraint (seeded): the standard error of the Lagrangian change is
    sigma sqrt(2 + 2 nu^2) = 4.3e-3 (nu = 6), the threshold 3 of them, 0.013 < 0.06. GMA releases c1 after a
    stall and ends near the plant optimum: the forward difference of 0.1 along c2 biases d phi_p / d c2 by +0.1
    (f'' = 2), so the fixed point is the optimum of 6.3 c1 + (c2 - 3.5)^2 + 0.1 c2 on the constraint,
    c1 = 0.485 / 2.645, instead of 0.6 / 2.645."""
    gma = GMA(model(), settings(True), dma(step=0.05))
    run_offline(gma, noisy(5e-4, seed=2), 25)
    released = [r.k for r in gma.records if r.restored_directions]
    assert len(released) == 1 and gma.records[released[0] - 1].c_next[0] == 0.0
    note = next(n for n in gma.records[released[0]].notes if n.startswith("measured KKT"))
    change, std, threshold = kkt_numbers(note)
    nu = np.sqrt((std / 5e-4) ** 2 / 2 - 1)                  # the modified problem's multiplier, measured
    assert nu == pytest.approx(NU, abs=0.2) and threshold == pytest.approx(3 * std, rel=1e-2)
    assert change == pytest.approx(0.63 - nu * 0.115, abs=3 * std) and change < -threshold
    biased = np.array([0.485 / 2.645, 0.5 + 1.15 * 0.485 / 2.645])
    assert np.abs(gma.c - biased).max() < 0.03                 # seeds 0-5: at most 0.027
    assert plant(gma.c)[0] < 8.94


def test_resume_keeps_the_released_direction():
    gma = GMA(model(), settings(True), dma())
    run_offline(gma, plant, 3)
    resumed = GMA(model(), settings(True), dma(), history=History.from_json(gma.history.to_json()))
    np.testing.assert_allclose(resumed.gradient.U, gma.gradient.U)
    run_offline(gma, plant, 4)
    run_offline(resumed, plant, 4)
    np.testing.assert_allclose(resumed.c, gma.c, atol=1e-9)


def test_kkt_test_in_closed_form():
    nominal = PlantPoint(np.array([0.0, 1.0]), 1.0, np.array([0.0, -1.0]), 0.01, np.array([0.02, 0.02]))
    step = PlantPoint(np.array([0.1, 1.0]), 1.05, np.array([-0.1, -1.0]), 0.01, np.array([0.02, 0.02]))
    # dL = 0.05 + 1.0 * (-0.1) + 0 (nu[1] = -3 counts as 0) = -0.05; std = sqrt(2e-4 + 1 * 8e-4) = 0.0316
    t = kkt_test([0.0, 1.0], nominal, step, [1.0, -3.0], [0.0, 0.0], [1.0, 2.0], 1.0)
    assert t.held == [0] and t.sides == [-1]
    assert t.change == pytest.approx(-0.05) and t.std == pytest.approx(0.001 ** 0.5)
    assert t.wrong_sign and t.describe().endswith("the plant leaves the bound: direction restored")
    assert not kkt_test([0.0, 1.0], nominal, step, [1.0, 0.0], [0.0, 0.0], [1.0, 2.0], 2.0).wrong_sign
    # the same change at an upper bound: moving down off it (dc < 0) raises no alarm when L grows
    up = PlantPoint(np.array([0.9, 1.0]), 1.05, np.array([0.0, -1.0]), None, None)
    t = kkt_test([1.0, 1.0], PlantPoint(np.array([1.0, 1.0]), 1.0, np.zeros(2)), up, [0.0, 0.0], [0.0, 0.0],
                 [1.0, 2.0], 3.0)
    assert t.sides == [1] and t.std == 0.0 and not t.wrong_sign and "c[0] (upper)" in t.describe()
    # a move that leaves no bound (c_k free, or along a bound) is not a KKT test
    assert kkt_test([0.5, 1.0], nominal, step, [1.0, 0.0], [0.0, 0.0], [1.0, 2.0], 1.0) is None
    along = PlantPoint(np.array([0.0, 1.2]), 0.9, np.zeros(2))
    assert kkt_test([0.0, 1.0], nominal, along, [1.0, 0.0], [0.0, 0.0], [1.0, 2.0], 1.0) is None


def test_kkt_settings_are_validated():
    with pytest.raises(ValueError, match=r"structure_kkt=True with structure_stall=0.0: expected structure_stall > 0"):
        GMASettings(structure_kkt=True)
    with pytest.raises(ValueError, match=r"structure_kkt=1: expected True or False"):
        GMASettings(structure_stall=0.01, structure_kkt=1)
    assert not GMASettings().structure_kkt                  # off by default
