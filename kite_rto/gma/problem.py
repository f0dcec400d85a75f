"""The model side of GMA: an open-loop model, written once in CasADi symbols.

A :class:`ModelProblem` holds the model's decision vector ``u`` (which may include the internal states of an
optimal control problem), its cost ``phi(u)``, the constraints ``g(u) <= 0`` that the plant also measures,
and the controlled variables ``y(u)`` that link the model to the plant's setpoints, ``c = y(u)``.
"""
from __future__ import annotations

from dataclasses import dataclass, field

import casadi as ca
import numpy as np

__all__ = ["ModelProblem"]


def _column(expr, what: str, sym_type):
    """Return ``expr`` as a dense column of the same symbolic type as ``u`` (empty when ``None``)."""
    if expr is None:
        return sym_type(0, 1)
    if isinstance(expr, (int, float, np.ndarray, list, tuple)):
        expr = sym_type(ca.DM(np.atleast_1d(np.asarray(expr, dtype=float))))
    if not isinstance(expr, (ca.SX, ca.MX, ca.DM)):
        raise TypeError(f"ModelProblem.{what} must be a CasADi expression, got {type(expr).__name__}")
    if expr.numel() == 0:
        return sym_type(0, 1)
    if not (expr.is_column() or expr.is_row()):
        raise ValueError(f"ModelProblem.{what} must be a vector, got shape {expr.shape}")
    return ca.vec(expr)


def _vector(value, n: int, what: str) -> np.ndarray:
    arr = np.asarray(value, dtype=float).ravel()
    if arr.size == 1 and n != 1:
        arr = np.full(n, float(arr[0]))
    if arr.size != n:
        raise ValueError(f"ModelProblem.{what} has {arr.size} entries, expected {n}")
    return arr


@dataclass
class ModelProblem:
    """Open-loop model of the plant, for Generalized Modifier Adaptation.

    Attributes:
        u: model decision vector, a CasADi ``SX`` or ``MX`` symbol of shape ``(n_u,)``.
        cost: ``phi(u)``, scalar expression of ``u`` (minimized).
        constraints: ``g(u) <= 0``, shape ``(n_g,)``; the constraints the plant measures and that get
            modifiers. ``n_g`` may be 0 (pass ``None`` or an empty expression).
        outputs: ``y(u)``, controlled variables, shape ``(n_c,)``, in the units of the plant's setpoints.
        lbu, ubu: bounds on ``u``, shape ``(n_u,)`` (scalars broadcast; use ``±inf`` for none).
        u0: initial guess for ``u``, shape ``(n_u,)``.
        c_lb, c_ub: the plant's safe setpoint box, shape ``(n_c,)``, finite, ``c_lb < c_ub``.
        equalities: ``h(u) = 0``, model-internal (e.g. OCP dynamics), never modified.
        inner_constraints: model-internal inequalities ``<= 0``, never modified.
        name: a label used in records and solver names.
    """

    u: ca.SX | ca.MX
    cost: ca.SX | ca.MX
    constraints: ca.SX | ca.MX | None
    outputs: ca.SX | ca.MX
    lbu: np.ndarray
    ubu: np.ndarray
    u0: np.ndarray
    c_lb: np.ndarray
    c_ub: np.ndarray
    equalities: ca.SX | ca.MX | None = None
    inner_constraints: ca.SX | ca.MX | None = None
    name: str = "model"
    _fun: ca.Function = field(init=False, repr=False, compare=False)
    _jac: ca.Function = field(init=False, repr=False, compare=False)

    def __post_init__(self):
        if not isinstance(self.u, (ca.SX, ca.MX)) or not self.u.is_valid_input():
            raise TypeError("ModelProblem.u must be a CasADi SX or MX symbol")
        sym = type(self.u)
        self.u = ca.vec(self.u)
        if self.u.numel() == 0:
            raise ValueError("ModelProblem.u must have at least one entry")
        self.cost = _column(self.cost, "cost", sym)
        if self.cost.numel() != 1:
            raise ValueError(f"ModelProblem.cost must be scalar, got {self.cost.numel()} entries")
        self.constraints = _column(self.constraints, "constraints", sym)
        self.outputs = _column(self.outputs, "outputs", sym)
        if self.outputs.numel() == 0:
            raise ValueError("ModelProblem.outputs must have at least one entry (n_c >= 1)")
        self.equalities = _column(self.equalities, "equalities", sym)
        self.inner_constraints = _column(self.inner_constraints, "inner_constraints", sym)
        self.lbu = _vector(self.lbu, self.n_u, "lbu")
        self.ubu = _vector(self.ubu, self.n_u, "ubu")
        self.u0 = _vector(self.u0, self.n_u, "u0")
        self.c_lb = _vector(self.c_lb, self.n_c, "c_lb")
        self.c_ub = _vector(self.c_ub, self.n_c, "c_ub")
        if np.any(self.lbu > self.ubu):
            raise ValueError(f"ModelProblem: lbu > ubu at indices {np.flatnonzero(self.lbu > self.ubu).tolist()}")
        if not (np.all(np.isfinite(self.c_lb)) and np.all(np.isfinite(self.c_ub))):
            raise ValueError("ModelProblem: the setpoint box c_lb, c_ub must be finite")
        if np.any(self.c_lb >= self.c_ub):
            raise ValueError(f"ModelProblem: need c_lb < c_ub, got c_lb={self.c_lb}, c_ub={self.c_ub}")
        self._fun = ca.Function(
            f"{self.name}_eval", [self.u], [self.cost, self.constraints, self.outputs],
            ["u"], ["phi", "g", "y"])
        u = self.u
        self._jac = ca.Function(
            f"{self.name}_jac", [u],
            [ca.jacobian(self.cost, u), ca.jacobian(self.constraints, u), ca.jacobian(self.outputs, u),
             ca.jacobian(self.equalities, u), ca.jacobian(self.inner_constraints, u), self.inner_constraints],
            ["u"], ["dphi", "dg", "dy", "dh", "dgin", "gin"])

    @property
    def n_u(self) -> int:
        """Number of model decision variables."""
        return int(self.u.numel())

    @property
    def n_c(self) -> int:
        """Number of controlled variables / plant setpoints."""
        return int(self.outputs.numel())

    @property
    def n_g(self) -> int:
        """Number of measured (modified) constraints."""
        return int(self.constraints.numel())

    @property
    def c_width(self) -> np.ndarray:
        """Width of the setpoint box, ``c_ub - c_lb``, shape ``(n_c,)``; the scale of all relative settings."""
        return self.c_ub - self.c_lb

    def evaluate(self, u) -> tuple[float, np.ndarray, np.ndarray]:
        """Evaluate the model at ``u``: returns ``(phi, g (n_g,), y (n_c,))``."""
        phi, g, y = self._fun(np.asarray(u, dtype=float))
        return float(phi), np.asarray(g, dtype=float).ravel(), np.asarray(y, dtype=float).ravel()

    def jacobians(self, u) -> dict[str, np.ndarray]:
        """Dense Jacobians at ``u``: ``dphi`` (1, n_u), ``dg`` (n_g, n_u), ``dy`` (n_c, n_u), ``dh`` (n_h, n_u),
        ``dgin`` (n_in, n_u), and the inner-constraint values ``gin`` (n_in,)."""
        out = self._jac(np.asarray(u, dtype=float))
        names = ("dphi", "dg", "dy", "dh", "dgin", "gin")
        res = {n: np.asarray(ca.DM(v).full(), dtype=float) for n, v in zip(names, out)}
        res["gin"] = res["gin"].ravel()
        return res

    def tangent_right_inverse(self, u, tol: float = 1e-7) -> np.ndarray:
        """A right inverse ``R`` (n_u, n_c) of ``dy/du`` inside the tangent space of the model-internal
        constraints active at ``u`` (equalities, active inner constraints, active bounds):
        ``dy R = I``, ``dh R = 0``, ``dgin_active R = 0``, ``R[i] = 0`` for bounded ``u_i``. Minimum norm.
        ``grad_u f(u) R`` is then the gradient of ``f`` with respect to the setpoints along the model.

        An active inner constraint or bound whose row is a combination of the rows before it (``dy``, ``dh``,
        the active constraints kept so far) is left out: it holds because ``y(u) = c`` holds (e.g. an input
        passed straight into ``y`` whose bounds are the setpoint box, at one of them), so the setpoints move
        it, and keeping it would contradict ``dy R = I`` and bias the least-squares solution.
        """
        u = np.asarray(u, dtype=float)
        J = self.jacobians(u)
        at_bound = (np.abs(u - self.lbu) <= tol * (1 + np.abs(self.lbu))) | \
                   (np.abs(u - self.ubu) <= tol * (1 + np.abs(self.ubu)))
        active = np.vstack([J["dgin"][J["gin"] >= -tol * (1 + np.abs(J["gin"]))], np.eye(self.n_u)[at_bound]])
        base = np.vstack([J["dy"], J["dh"]])
        M = np.vstack([base, active[_independent_rows(base, active)]])
        E = np.zeros((M.shape[0], self.n_c))
        E[: self.n_c] = np.eye(self.n_c)
        R, *_ = np.linalg.lstsq(M, E, rcond=None)
        return R


def _independent_rows(base: np.ndarray, rows: np.ndarray, rtol: float = 1e-9) -> list[int]:
    """Indices of ``rows`` that are not linear combinations of the rows of ``base`` and of the rows kept
    before them (relative residual of the projection onto their span > ``rtol``), in order."""
    if base.shape[0]:
        _, sv, vt = np.linalg.svd(base, full_matrices=False)
        basis = vt[sv > rtol * sv[0]] if sv.size and sv[0] > 0 else vt[:0]
    else:
        basis = np.zeros((0, rows.shape[1]))
    keep = []
    for i, row in enumerate(rows):
        r = row - basis.T @ (basis @ row)
        r = r - basis.T @ (basis @ r)          # second Gram-Schmidt pass: keeps the basis orthonormal
        n = np.linalg.norm(r)
        if n > rtol * max(np.linalg.norm(row), 1e-300):
            basis = np.vstack([basis, r / n])
            keep.append(i)
    return keep
