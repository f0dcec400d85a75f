"""The hook protocol: GMA calls every mechanism's hooks at the named points, in order, and a mechanism of one's
own takes part like the built-in ones."""
import casadi as ca
import numpy as np

from kite_rto.gma import GMA, FiniteDifferenceGradient, GMASettings, Mechanism, ModelProblem, TrustRegion, run_offline


def quadratic():
    """Model ``(u - 1)^2`` per setpoint; the plant's optimum is at 2 (a linear cost mismatch)."""
    u = ca.SX.sym("u", 2)
    return ModelProblem(u=u, cost=ca.sumsqr(u - 1.0), constraints=None, outputs=u, lbu=-5, ubu=5, u0=[0, 0],
                        c_lb=[-3, -3], c_ub=[4, 4])


def plant(c):
    return float(np.sum((c - 2.0) ** 2)), np.zeros(0)


class Recorder(Mechanism):
    """Records the hooks in the order GMA calls them."""

    def __init__(self):
        self.calls = []

    def estimate(self, it):
        self.calls.append("estimate")

    def modify(self, it):
        self.calls.append("modify")

    def solve(self, it, solve):
        self.calls.append("solve")

    def revise(self, it, shrink):
        self.calls.append("revise")

    def limit(self, it):
        self.calls.append("limit")

    def adapt(self, it):
        self.calls.append("adapt")


def test_hooks_are_called_in_the_documented_order():
    rec = Recorder()
    run_offline(GMA(quadratic(), GMASettings(filter_gain=1.0), c0=[0.0, 0.0], mechanisms=[rec]), plant, 2)
    assert rec.calls == ["estimate", "modify", "solve", "revise", "limit", "adapt"] * 2


class HalfStep(Mechanism):
    """Takes half of every step (a ``limit`` hook)."""

    def limit(self, it):
        return 0.5


class GoBack(Mechanism):
    """Rejects every point after the first step (a ``revise`` hook), telling the trust region."""

    def revise(self, it, shrink):
        if it.k == 1:
            it.target = np.asarray(it.history.c0, float)
            shrink(True)


def test_a_mechanism_of_ones_own_changes_the_step():
    s = GMASettings(filter_gain=1.0, trust_region=None)
    central = FiniteDifferenceGradient(0.1, "central")           # exact on a quadratic: one MA step reaches 2
    full = run_offline(GMA(quadratic(), s, central, c0=[0.0, 0.0]), plant, 1).iterations[0]
    half = run_offline(GMA(quadratic(), s, central, c0=[0.0, 0.0], mechanisms=[HalfStep()]), plant, 1).iterations[0]
    np.testing.assert_allclose(full.c_next, [2.0, 2.0], atol=1e-6)
    np.testing.assert_allclose(half.step, 0.5 * full.step, rtol=1e-12)


def test_a_revise_hook_sets_the_next_point_and_narrows_the_trust_region():
    gma = GMA(quadratic(), GMASettings(filter_gain=1.0, trust_region=TrustRegion(radius=1.0, adapt=False)),
              c0=[0.0, 0.0], mechanisms=[GoBack()])
    run_offline(gma, plant, 2)
    first, second = gma.records
    assert second.decision == "step undone"
    np.testing.assert_array_equal(second.c_next, [0.0, 0.0])
    np.testing.assert_allclose(second.trust_radius_next, [0.5, 0.5])
