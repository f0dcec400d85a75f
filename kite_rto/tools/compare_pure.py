"""Check a run of the ROS graph against the pure runner: same experiments, costs and iterates, bit for bit.

The optimizer's SQLite database holds every experiment (setpoints, measured cost and constraint) and every
iteration (everything GMA computed). This re-flies the same number of iterations with :func:`~kite_rto.rto.runner.run_rto` on
the default plant and settings (what the main job uses) with the given seed, and compares.

Usage: ``python -m kite_rto.tools.compare_pure --db runs/demo/rto.sqlite [--seed 0]``; exit 0 when everything
is identical, 1 when anything differs (the first difference is printed), 2 for a missing or empty database.
"""
from __future__ import annotations

import argparse
import os
import sys

from dataclasses import replace

import numpy as np

from ..rto.runner import run_rto
from ..kite.plant import DEFAULT_WIND_MODEL, WIND_MODELS, PlantConfig
from ..rto.experiment import default_wind_source
from ..rto.settings import KiteRTOSettings
from ..gma import History, HistoryStore, StoreError

__all__ = ["compare_histories", "main"]


WALL_CLOCK_FIELDS = ("solve_time",)
"""Fields that measure this machine's speed, not the run: left out of the comparison."""


def compare_histories(graph: History, pure: History) -> list[str]:
    """Differences between two GMA histories, one line per field that is not identical to the bit (empty:
    identical). Every field of every request, result and iteration record is compared (model realization,
    gradients, modifiers, steps, decisions, ...), except the wall-clock :data:`WALL_CLOCK_FIELDS`."""
    out = []
    ge, pe = graph.experiments, pure.experiments
    if len(ge) != len(pe):
        out.append(f"{len(ge)} experiments in the graph's run, {len(pe)} in the pure runner's")
    if len(graph.iterations) != len(pure.iterations):
        out.append(f"{len(graph.iterations)} iterations in the graph's run, {len(pure.iterations)} in the pure "
                   f"runner's")

    def walk(where, a, b):
        if isinstance(a, dict) and isinstance(b, dict):
            for key in sorted(set(a) | set(b)):
                if key not in WALL_CLOCK_FIELDS:
                    walk(f"{where}.{key}", a.get(key), b.get(key))
        elif isinstance(a, list) and isinstance(b, list) and len(a) == len(b):
            for i, (x, y) in enumerate(zip(a, b)):
                walk(f"{where}[{i}]", x, y)
        elif not (a == b or (isinstance(a, float) and isinstance(b, float) and a != a and b != b)):   # NaN == NaN
            out.append(f"{where}: graph {a!r}, pure {b!r}")

    for (qa, ra), (qb, rb) in zip(ge, pe):
        walk(f"experiment {qa.request_id}: request", qa.to_dict(), qb.to_dict())
        walk(f"experiment {qa.request_id}: result", ra.to_dict(), rb.to_dict())
    for a, b in zip(graph.iterations, pure.iterations):
        walk(f"iteration {a.k}", a.to_dict(), b.to_dict())
    return out


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(prog="kite_rto compare_pure", description=__doc__.splitlines()[0])
    ap.add_argument("--db", required=True, help="the optimizer's SQLite database")
    ap.add_argument("--seed", type=int, default=0, help="plant seed of the run (the demo's --seed)")
    ap.add_argument("--wind-model", choices=WIND_MODELS, default=DEFAULT_WIND_MODEL,
                    help=f"the plant's wind model of the run (the demo's --wind-model; default {DEFAULT_WIND_MODEL})")
    args = ap.parse_args(argv)
    if not os.path.isfile(args.db):
        print(f"compare_pure: no database at {args.db!r}", file=sys.stderr)
        return 2
    try:
        store = HistoryStore(args.db)
    except StoreError as exc:                                           # damaged or foreign: say so
        print(f"compare_pure: {exc}", file=sys.stderr)
        return 2
    graph = store.load()
    store.close()
    if graph is None or not graph.iterations:
        print(f"compare_pure: {args.db!r} holds no finished iteration", file=sys.stderr)
        return 2
    settings = replace(KiteRTOSettings(), experiment=replace(KiteRTOSettings().experiment,
                                                             wind_source=default_wind_source(args.wind_model)))
    pure = run_rto(PlantConfig(wind_model=args.wind_model), seed=args.seed, n_iter=len(graph.iterations),
                   settings=settings).history
    diff = compare_histories(graph, pure)
    n_e, n_i = len(graph.experiments), len(graph.iterations)
    if diff:
        print(f"differs from the pure runner (seed {args.seed}): {len(diff)} differences; first: {diff[0]}")
        return 1
    print(f"identical to the pure runner (seed {args.seed}) bit for bit: {n_e} experiments (setpoints, costs, "
          f"constraints, standard errors) and {n_i} iterations (every recorded field but the solve times)")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
