"""Modifiers and Decision: the modified problem's inputs and what GMA did, read back from stored histories."""
import casadi as ca
import numpy as np
import pytest

from kite_rto.gma import GMA, Decision, GMASettings, History, ModelProblem, Modifiers, TrustRegion, run_offline


def test_zero_modifiers_leave_the_model_as_it_is():
    m = Modifiers.zero([1.0, 2.0], 1, backoff=[0.5])
    assert m.eps.tolist() == [0.0] and m.lam.tolist() == [0.0, 0.0] and m.mu.shape == (1, 2)
    assert m.backoff.tolist() == [0.5] and Modifiers.zero([1.0], 0).mu.shape == (0, 1)


def test_shifted_modifiers_follow_their_linearization():
    m = Modifiers(np.array([1.0, 2.0]), np.array([0.3]), np.array([4.0, 5.0]), np.array([[2.0, -1.0]]),
                  np.array([0.1]))
    s = m.shifted([1.5, 1.0])
    assert s.eps.tolist() == [0.3 + 2.0 * 0.5 - 1.0 * -1.0]
    assert s.lam.tolist() == [0.0, 0.0] and s.c.tolist() == [1.5, 1.0]
    assert s.mu is m.mu and s.backoff is m.backoff


@pytest.mark.parametrize("decision", list(Decision))
def test_decision_text_round_trip(decision):
    assert Decision.of(decision.describe()) is decision
    assert Decision.of(decision.describe("trust region active on c[0, 2]")) is decision
    assert decision.moved == (decision in (Decision.STEP, Decision.CONVERGED))


def test_unknown_decision_text_is_refused():
    with pytest.raises(ValueError, match="nothing"):
        Decision.of("nothing")


def test_stored_decision_texts_read_back_as_decisions():
    """The texts written by earlier versions (JSON histories and SQLite stores keep them verbatim)."""
    texts = {"step": Decision.STEP, "step (trust region active on c[1, 2])": Decision.STEP,
             "converged": Decision.CONVERGED, "hold: the model cannot realize c_k": Decision.HOLD_NO_REALIZATION,
             "hold: unusable gradient estimate": Decision.HOLD_BAD_GRADIENT,
             "hold: the modified problem failed": Decision.HOLD_SOLVE_FAILED}
    for text, decision in texts.items():
        assert Decision.of(text) is decision


def _problem():
    u = ca.SX.sym("u", 2)
    return ModelProblem(u=u, cost=(u[0] - 0.5) ** 2 + (u[1] - 1.5) ** 2, constraints=0.9 * u[0] + u[1] - 2.2,
                        outputs=u, lbu=-5, ubu=5, u0=[0, 0], c_lb=[-2, -2], c_ub=[3, 3], name="mods")


def test_records_carry_their_decision_through_json():
    gma = GMA(_problem(), GMASettings(filter_gain=1.0, trust_region=TrustRegion(radius=0.05, min_radius=0.05)))
    run_offline(gma, lambda c: ((c[0] - 1) ** 2 + 2 * (c[1] - 1) ** 2, [c[0] + c[1] - 1.5]), 2)
    first = gma.records[0]
    assert first.outcome is Decision.STEP and first.decision.startswith("step (trust region active on c[")
    back = History.from_json(gma.history.to_json())
    assert [r.outcome for r in back.iterations] == [r.outcome for r in gma.records]
