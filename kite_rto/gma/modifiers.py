"""What a GMA iteration computes: the model's point, the modifiers (plant minus model) and the decision."""
from __future__ import annotations

from dataclasses import dataclass
from enum import StrEnum

import numpy as np

__all__ = ["ModelRealization", "Modifiers", "Decision"]


@dataclass
class ModelRealization:
    """The model's point for setpoints ``c`` and its gradients with respect to ``c``.

    Attributes:
        u: model decision vector (n_u,).
        phi: model cost there.
        g: model constraints (n_g,).
        grad_phi: ``d phi_hat / d c`` (n_c,).
        jac_g: ``d g_hat / d c`` (n_g, n_c).
        success: the model solve succeeded (otherwise ``g``, ``grad_phi``, ``jac_g`` are NaN).
        status: the solver's status text.
    """

    u: np.ndarray
    phi: float
    g: np.ndarray
    grad_phi: np.ndarray
    jac_g: np.ndarray
    success: bool
    status: str


@dataclass
class Modifiers:
    """First-order corrections of the model at the setpoints ``c`` (n_c,) where they were computed.

    The modified problem minimizes ``phi(u) + lam^T d`` s.t. ``g(u) + eps + mu d + backoff <= 0`` with
    ``d = y(u) - c``.

    Attributes:
        c: the operating point ``c_k`` of the modifiers (n_c,), plant setpoint units.
        eps: constraint-value modifier ``g_p(c_k) - g_hat(c_k)`` (n_g,), constraint units.
        lam: cost-gradient modifier ``grad phi_p - grad phi_hat`` (n_c,), cost units per setpoint unit.
        mu: constraint-gradient modifier ``grad g_p - grad g_hat`` (n_g, n_c).
        backoff: tightening of the modified constraints (n_g,), constraint units (>= 0).
    """

    c: np.ndarray
    eps: np.ndarray
    lam: np.ndarray
    mu: np.ndarray
    backoff: np.ndarray

    @classmethod
    def zero(cls, c, n_g: int, backoff=None) -> "Modifiers":
        """No correction at ``c``: the model as it is (with ``backoff`` (n_g,), default none)."""
        c = np.asarray(c, float).copy()
        return cls(c, np.zeros(n_g), np.zeros(c.size), np.zeros((n_g, c.size)),
                   np.zeros(n_g) if backoff is None else np.asarray(backoff, float).copy())

    def shifted(self, c) -> "Modifiers":
        """The constraint modifiers carried along their own linearization to ``c``:
        ``eps + mu (c - self.c)``, same ``mu`` and ``backoff``, no cost modifier (``lam = 0``)."""
        c = np.asarray(c, float)
        return Modifiers(c, self.eps + self.mu @ (c - self.c), np.zeros(c.size), self.mu, self.backoff)


class Decision(StrEnum):
    """What GMA did in an iteration; the value is the text recorded in ``IterationRecord.decision``."""

    STEP = "step"
    """Moved towards the modified problem's solution (filtered, bounded)."""
    CONVERGED = "converged"
    """Moved by less than ``tol_c``: a fixed point."""
    UNDONE = "step undone"
    """Went back to ``c_{k-1}``: a mechanism rejected ``c_k`` (e.g. :class:`~kite_rto.gma.Undo`: its cost rose)."""
    HOLD_NO_REALIZATION = "hold: the model cannot realize c_k"
    """Stayed: the model has no realization of the operating point."""
    HOLD_BAD_GRADIENT = "hold: unusable gradient estimate"
    """Stayed: the plant-gradient estimate is not finite or has quality 0."""
    HOLD_SOLVE_FAILED = "hold: the modified problem failed"
    """Stayed and shrank the trust region: the modified problem has no solution."""
    WATCHED = "watched"
    """Stayed without learning: a settled point flown alone and its measurements tested for a change
    (:class:`~kite_rto.gma.Settle`); with a detail when a change ends the watch."""

    @property
    def moved(self) -> bool:
        """True when the operating point took the modified problem's step (``STEP`` or ``CONVERGED``)."""
        return self in (Decision.STEP, Decision.CONVERGED)

    def describe(self, detail: str = "") -> str:
        """The recorded text: the value, then ``detail`` in parentheses if any."""
        return f"{self.value} ({detail})" if detail else self.value

    @classmethod
    def of(cls, text: str) -> "Decision":
        """The decision a recorded text (:meth:`describe`) stands for; ``ValueError`` for an unknown one."""
        head = text.split(" (", 1)[0]
        try:
            return cls(head)
        except ValueError:
            raise ValueError(f"Decision.of: {text!r} is none of {[d.value for d in cls]}") from None
