"""The true plant optimum ("oracle"): direct optimization of the deterministic closed loop over the setpoints.

:func:`plant_performance` flies setpoints ``c`` on the plant with turbulence and noise off, from launch, and
averages whole laps after the transient. :func:`find_oracle` maximizes the mean tension over the optimizer's
:class:`~kite_rto.flight.shape.ShapeBox` subject to ``min altitude >= h_min``: a coarse grid, then Nelder–Mead
(box-normalized shape coordinates, clipped,
with a penalty on altitude violation) from the best grid points. Results are cached as ``oracle_<hash>.json``
keyed by the plant configuration, the box and the evaluation settings, in the directory of
:func:`oracle_cache_dir`: an explicit ``cache_dir``, else the environment variable ``KITE_RTO_CACHE``, else the
platform's user cache directory (``platformdirs.user_cache_dir("kite_rto")``, e.g. ``~/.cache/kite_rto`` on
Linux), never inside the installed package. Entries are written atomically (a temporary file renamed into place),
so processes that share the cache (a campaign's workers) never read half a file; an unreadable entry is recomputed.
"""
from __future__ import annotations

import hashlib
import itertools
import json
import math
import os
import tempfile
from dataclasses import dataclass, asdict

import numpy as np

from ..cache import CACHE_ENV
from ..cache import cache_dir as shared_cache_dir
from .experiment import ExperimentSpec, PlantFlight
from ..flight.shape import ShapeBox
from ..kite.plant import PlantConfig

__all__ = ["OracleResult", "plant_performance", "find_oracle", "oracle_cache_dir", "CACHE_ENV"]

_SPEC = ExperimentSpec(settle_time=40.0, settle_laps=1, n_laps=3, normalize=False, wind_source="observer")
"""The oracle's experiment: raw lap tensions (``normalize=False``; the wind source is then unused and pinned, so
that a change of the default wind source keeps the cached oracles' keys)."""
_MEMO: dict = {}


def plant_performance(config: PlantConfig | None = None, c=None, spec: ExperimentSpec = _SPEC) -> tuple:
    """``(mean tension kN, min altitude m)`` of the deterministic plant (turbulence and noise off) at ``c``
    (rad), from launch, after ``spec.settle_time`` s and ``spec.settle_laps`` laps, over ``spec.n_laps``
    laps. Memoized per process. A crash gives ``(0, -inf)``.
    """
    config = (config or PlantConfig()).without_disturbances()
    c = np.asarray(c, dtype=float)
    key = (repr(config), tuple(np.round(c, 10)), spec)
    if key not in _MEMO:
        out = PlantFlight(config, 0, spec).fly(c, max_repeats=0)
        _MEMO[key] = (out.mean_tension_kn, out.min_altitude) if out.valid and not out.timed_out \
            else (0.0, -math.inf)
    return _MEMO[key]


@dataclass
class OracleResult:
    """The plant optimum: ``c`` rad, ``c_deg``, ``tension_kn``, ``min_altitude`` m, evaluations used."""

    c: list
    c_deg: list
    tension_kn: float
    min_altitude: float
    evaluations: int
    key: str


def oracle_cache_dir(cache_dir: str | os.PathLike | None = None) -> str:
    """The oracle cache directory: ``cache_dir`` if given, else :func:`kite_rto.cache.cache_dir` (``$KITE_RTO_CACHE``
    if set and non-empty, else ``platformdirs.user_cache_dir("kite_rto")``). Created when the first result is
    written."""
    return os.fspath(cache_dir) if cache_dir is not None else shared_cache_dir()


def _key(config: PlantConfig, box: ShapeBox, h_min: float, spec: ExperimentSpec, grid: int) -> str:
    text = repr((config.without_disturbances(), box, h_min, spec, grid, "v1"))
    return hashlib.sha1(text.encode()).hexdigest()[:12]


def find_oracle(config: PlantConfig | None = None, box: ShapeBox | None = None, *, h_min: float,
                spec: ExperimentSpec = _SPEC, grid: int = 3, starts: int = 2, maxfev: int = 40,
                penalty: float = 5.0, cache_dir: str | os.PathLike | None = None, cache: bool = True
                ) -> OracleResult:
    """Maximize the deterministic plant's mean tension over ``box`` s.t. min altitude >= ``h_min`` (m).

    Args:
        config: plant configuration (disturbances are switched off here).
        box: :class:`ShapeBox` searched (the optimizer's default); the result is in setpoints.
        h_min: the run's minimum altitude, m (its :attr:`ExperimentSpec.h_min
            <kite_rto.rto.experiment.ExperimentSpec>`; no default, so no run is judged against another's floor).
        grid: points per setpoint of the initial grid (>= 2).
        starts: Nelder–Mead runs, from the best feasible grid points.
        maxfev: evaluations per Nelder–Mead run.
        penalty: kN per metre of altitude violation.
        cache_dir: JSON cache directory; None: :func:`oracle_cache_dir` (``$KITE_RTO_CACHE``, else the
            platform's user cache directory).
        cache: read and write the cache (False: always compute, write nothing).
    """
    from scipy.optimize import minimize
    config = config or PlantConfig()
    box = box or ShapeBox()
    key = _key(config, box, h_min, spec, grid)
    cache_dir = oracle_cache_dir(cache_dir) if cache else None
    path = None if cache_dir is None else os.path.join(cache_dir, f"oracle_{key}.json")
    if path:
        try:
            with open(path) as f:
                return OracleResult(**json.load(f))
        except (OSError, ValueError, TypeError):
            pass                                  # missing, unreadable or foreign entry: computed and written below
    evals = []

    def f(x):
        xc = np.clip(x, 0.0, 1.0)
        c = box.from_unit(xc)
        t, z = plant_performance(config, c, spec)
        evals.append((t, z, c))
        return -t + penalty * max(0.0, h_min - z) + 1e3 * float(np.sum((x - xc) ** 2))

    pts = [np.array(p, dtype=float) for p in itertools.product(np.linspace(0, 1, grid), repeat=3)]
    vals = [f(p) for p in pts]
    for i in np.argsort(vals)[:starts]:
        minimize(f, pts[i], method="Nelder-Mead",
                 options={"maxfev": maxfev, "xatol": 0.01, "fatol": 0.05, "initial_simplex":
                          np.clip(pts[i] + np.vstack([np.zeros(3), -0.25 * np.sign(pts[i] - 0.5 + 1e-9)
                                                      * np.eye(3)]), 0, 1)})
    feas = [e for e in evals if e[1] >= h_min] or evals
    t, z, c = max(feas, key=lambda e: e[0])
    res = OracleResult(c=c.tolist(), c_deg=np.degrees(c).tolist(), tension_kn=float(t), min_altitude=float(z),
                       evaluations=len(evals), key=key)
    if path:
        _write_atomic(path, asdict(res))
    return res


def _write_atomic(path: str, value: dict) -> None:
    """Write ``value`` as JSON to ``path`` through a temporary file in the same directory and :func:`os.replace`."""
    directory = os.path.dirname(path)
    os.makedirs(directory, exist_ok=True)
    fd, tmp = tempfile.mkstemp(dir=directory, prefix=".oracle-", suffix=".tmp")
    try:
        with os.fdopen(fd, "w") as fh:
            json.dump(value, fh, indent=1)
        os.replace(tmp, path)
    except BaseException:
        os.unlink(tmp)
        raise
