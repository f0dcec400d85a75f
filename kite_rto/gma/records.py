"""What GMA asks the plant for, what the plant answers, and the JSON-serializable history of both.

All arrays are stored as numpy arrays and written as JSON lists; non-finite numbers are written as
``null`` (NaN) or the strings ``"inf"``/``"-inf"``.
"""
from __future__ import annotations

import json
import math
from dataclasses import dataclass, field, fields
from typing import Any

import numpy as np

from .modifiers import Decision

__all__ = ["ExperimentRequest", "ExperimentResult", "IterationRecord", "History"]


def _plain(v):
    if isinstance(v, np.ndarray):
        return _plain(v.tolist())
    if isinstance(v, (list, tuple)):
        return [_plain(x) for x in v]
    if isinstance(v, dict):
        return {str(k): _plain(x) for k, x in v.items()}
    if isinstance(v, (np.floating, float)):
        v = float(v)
        if math.isnan(v):
            return None
        if math.isinf(v):
            return "inf" if v > 0 else "-inf"
        return v
    if isinstance(v, np.integer):
        return int(v)
    if isinstance(v, np.bool_):
        return bool(v)
    return v


def _num(v):
    if isinstance(v, list):
        return [_num(x) for x in v]
    if v is None:
        return math.nan
    if v in ("inf", "-inf"):
        return float(v)
    return v


class _Serializable:
    """``to_dict``/``from_dict`` for dataclasses; fields listed in ``_arrays`` come back as float arrays."""

    _arrays: tuple[str, ...] = ()
    _optional_arrays: tuple[str, ...] = ()

    def to_dict(self) -> dict:
        return {f.name: _plain(getattr(self, f.name)) for f in fields(self)}

    @classmethod
    def from_dict(cls, data: dict):
        kwargs = dict(data)
        known = {f.name for f in fields(cls)}
        unknown = sorted(set(kwargs) - known)
        if unknown:
            raise ValueError(f"{cls.__name__}: unknown fields {unknown} (written by another version of kite_rto?)")
        for name in cls._arrays + cls._optional_arrays:
            if name in kwargs and kwargs[name] is not None:
                kwargs[name] = np.asarray(_num(kwargs[name]), dtype=float)
        return cls(**kwargs)


@dataclass
class ExperimentRequest(_Serializable):
    """One experiment GMA asks for.

    Attributes:
        request_id: unique id (``"k<iteration>-<index>-<purpose>"``); a submitted id is never requested again.
        c: setpoints to apply, shape (n_c,), plant setpoint units.
        purpose: ``"nominal"`` (the operating point ``c_k``) or ``"perturbation"`` (gradient estimation).
        iteration: the GMA iteration ``k`` the experiment belongs to.
        effort: how long to measure, as a multiple of the unit the plant side defines (e.g. cycles averaged):
            ``GMASettings.effort_schedule`` of the iteration, ``> 0``.
    """

    request_id: str
    c: np.ndarray
    purpose: str
    iteration: int
    effort: float = 1.0
    _arrays = ("c",)


@dataclass
class ExperimentResult(_Serializable):
    """The plant's answer to a request.

    Attributes:
        request_id: id of the :class:`ExperimentRequest` answered.
        cost: measured plant cost ``phi_p(c)`` (scalar, minimized).
        constraints: measured plant constraints ``g_p(c)``, shape (n_g,) (``<= 0`` is feasible).
        cost_std: optional standard deviation of ``cost`` (e.g. the standard error of a mean).
        constraints_std: optional standard deviations of ``constraints``, shape (n_g,).
        extra: free, JSON-serializable data stored with the experiment (e.g. how many cycles were averaged).
    """

    request_id: str
    cost: float
    constraints: np.ndarray = field(default_factory=lambda: np.zeros(0))
    cost_std: float | None = None
    constraints_std: np.ndarray | None = None
    extra: dict = field(default_factory=dict)
    _arrays = ("constraints",)
    _optional_arrays = ("constraints_std",)

    def __post_init__(self):
        self.constraints = np.atleast_1d(np.asarray(self.constraints, dtype=float)).ravel()
        if self.constraints_std is not None:
            self.constraints_std = np.atleast_1d(np.asarray(self.constraints_std, dtype=float)).ravel()
        self.cost = float(self.cost)
        if self.cost_std is not None:
            self.cost_std = float(self.cost_std)


@dataclass
class IterationRecord(_Serializable):
    """Everything GMA computed in iteration ``k`` (arrays: n_c setpoints, n_g constraints).

    Plant side: ``c_k``, measured ``cost``/``constraints``, gradient estimates ``grad_cost`` (n_c,) and
    ``jac_constraints`` (n_g, n_c) with ``gradient_quality`` and ``gradient_method``. Model side (model's
    realization of ``c_k``): ``phi_hat``, ``g_hat``, ``grad_phi_hat``, ``jac_g_hat``, ``u_hat``,
    ``model_status``. Modifiers ``eps`` (n_g,), ``lam`` (n_c,), ``mu`` (n_g, n_c), constraint ``backoff``
    (n_g,). Modified problem:
    ``u_star``, ``modified_cost``, ``modified_status``, ``c_star = y(u_star)``. Update: ``step`` (filtered,
    bounded), ``c_next``, relative trust radii ``trust_radius`` (used) and ``trust_radius_next``, ``converged``,
    ``decision`` (the text of a :class:`~kite_rto.gma.Decision`, read back with :attr:`outcome`), ``notes``,
    wall-clock ``solve_time`` (s) and the ids of the experiments used, nominal first. ``grad_cost_std``: the
    estimate's standard deviation of each entry of ``grad_cost`` (n_c,), ``None`` without measured standard
    deviations.
    """

    k: int
    c_k: np.ndarray
    cost: float
    constraints: np.ndarray
    grad_cost: np.ndarray
    jac_constraints: np.ndarray
    gradient_quality: float
    gradient_method: str
    phi_hat: float
    g_hat: np.ndarray
    grad_phi_hat: np.ndarray
    jac_g_hat: np.ndarray
    u_hat: np.ndarray
    model_status: str
    eps: np.ndarray
    lam: np.ndarray
    mu: np.ndarray
    backoff: np.ndarray
    u_star: np.ndarray
    modified_cost: float
    modified_status: str
    c_star: np.ndarray
    step: np.ndarray
    c_next: np.ndarray
    trust_radius: np.ndarray
    trust_radius_next: np.ndarray
    converged: bool
    decision: str
    notes: list[str]
    solve_time: float
    experiment_ids: list[str]
    grad_cost_std: np.ndarray | None = None
    _optional_arrays = ("grad_cost_std",)
    _arrays = ("c_k", "constraints", "grad_cost", "jac_constraints", "g_hat", "grad_phi_hat", "jac_g_hat",
               "u_hat", "eps", "lam", "mu", "backoff", "u_star", "c_star", "step", "c_next", "trust_radius",
               "trust_radius_next")

    @property
    def outcome(self) -> Decision:
        """What GMA did in this iteration, as a :class:`~kite_rto.gma.Decision`."""
        return Decision.of(self.decision)

    @classmethod
    def from_dict(cls, data: dict):
        rec = super().from_dict(data)
        for name in ("cost", "phi_hat", "modified_cost", "gradient_quality"):
            setattr(rec, name, float(_num(getattr(rec, name))))
        n_c = rec.c_k.size
        for name in ("jac_constraints", "jac_g_hat", "mu"):
            setattr(rec, name, getattr(rec, name).reshape(-1, n_c))
        return rec


@dataclass
class History:
    """Finished experiments and iteration records of a GMA run; JSON round trip and resume.

    Attributes:
        c0: initial setpoints (n_c,).
        experiments: finished experiments, in submission order, as ``(request, result)`` pairs.
        iterations: one :class:`IterationRecord` per completed iteration.
        pending: the requests of the open iteration (finished ones among them are in ``experiments``).
        meta: free data (problem name, sizes, settings) for the reader.
    """

    c0: np.ndarray
    experiments: list[tuple[ExperimentRequest, ExperimentResult]] = field(default_factory=list)
    iterations: list[IterationRecord] = field(default_factory=list)
    pending: list[ExperimentRequest] = field(default_factory=list)
    meta: dict[str, Any] = field(default_factory=dict)

    def finished_ids(self) -> set[str]:
        """Ids of all submitted experiments."""
        return {req.request_id for req, _ in self.experiments}

    def to_dict(self) -> dict:
        return {"c0": _plain(self.c0),
                "experiments": [{"request": q.to_dict(), "result": r.to_dict()} for q, r in self.experiments],
                "iterations": [rec.to_dict() for rec in self.iterations],
                "pending": [q.to_dict() for q in self.pending],
                "meta": _plain(self.meta)}

    @classmethod
    def from_dict(cls, data: dict) -> "History":
        return cls(c0=np.asarray(_num(data["c0"]), dtype=float),
                   experiments=[(ExperimentRequest.from_dict(e["request"]), ExperimentResult.from_dict(e["result"]))
                                for e in data.get("experiments", [])],
                   iterations=[IterationRecord.from_dict(r) for r in data.get("iterations", [])],
                   pending=[ExperimentRequest.from_dict(q) for q in data.get("pending", [])],
                   meta=dict(data.get("meta", {})))

    def to_json(self, indent: int | None = None) -> str:
        """Strict JSON text (no NaN/Infinity literals)."""
        return json.dumps(self.to_dict(), indent=indent, allow_nan=False)

    @classmethod
    def from_json(cls, text: str) -> "History":
        return cls.from_dict(json.loads(text))

    def save(self, path) -> None:
        """Write :meth:`to_json` to ``path``."""
        with open(path, "w", encoding="utf-8") as fh:
            fh.write(self.to_json(indent=1))

    @classmethod
    def load(cls, path) -> "History":
        with open(path, encoding="utf-8") as fh:
            return cls.from_json(fh.read())
