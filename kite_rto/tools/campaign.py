"""``kite_campaign``: GMA and its baselines over scenarios x seeds on Dask, judged against each scenario's oracle.

Runs on a ``LocalCluster`` (one process and one thread per worker, ``--workers`` default: the machine's cores)
or, with ``--scheduler ADDRESS``, on a running Dask scheduler and its workers. Finished runs are cached, one JSON
per run, in ``--cache-dir`` (default the ``campaign`` folder of the kite_rto cache) and never run again; only the
missing ones start a cluster. Writes ``results.csv``, its manifest ``results.manifest.json`` (the planned runs,
the failed ones, the code and library versions), ``wall.csv``, ``summary.md`` (computed from the table and the
manifest as written, so ``campaign_summary`` gives the same text) and ``campaign.png`` to ``--out`` and prints the
summary. Exit code 0, 1 if a run failed, 2 on a bad argument, 130 on Ctrl-C (finished runs stay cached).
docs/campaign.md.
"""
from __future__ import annotations

import argparse
import os
import sys
import time
from contextlib import contextmanager
from pathlib import Path

from ..cache import cache_dir
from ..campaign.executor import ResultCache, pending
from ..campaign.manifest import manifest_path, plan_of, read_manifest, write_manifest
from ..campaign.methods import GMA, METHODS
from ..campaign.plan import Campaign, CampaignRun, campaign_manifest, run_campaign
from ..campaign.results import write_table, write_wall_times
from ..campaign.scenarios import select_scenarios
from ..campaign.summary import summarize
from ..campaign.tables import read_table
from ..campaign.variants import load_variants, parse_variant
from ..campaign.version import library_versions
from ..rto.settings import KiteRTOSettings
from .campaign_plot import plot_campaign

__all__ = ["main", "build_campaign", "write_outputs"]


def _parser() -> argparse.ArgumentParser:
    ap = argparse.ArgumentParser(prog="kite_campaign", description=__doc__.splitlines()[0])
    ap.add_argument("--scenarios", default="all",
                    help="all, tuning, report, or comma-separated names (kite_rto/campaign/scenarios.py)")
    ap.add_argument("--seeds", type=int, default=3, help="plant seeds per scenario")
    ap.add_argument("--first-seed", type=int, default=0, help="seeds first-seed .. first-seed + seeds - 1")
    ap.add_argument("--methods", default=",".join(METHODS),
                    help=f"comma-separated, from {', '.join(METHODS)} (gma: every GMA variant)")
    ap.add_argument("--iters", type=int, default=10, help="GMA iterations")
    ap.add_argument("--budget", type=float, default=4.0,
                    help="a baseline's flight time over GMA's time to 99 %% on the same scenario and seed")
    ap.add_argument("--flight", type=float, default=None, metavar="SECONDS",
                    help="fixed flights: every method flies this long and is judged by the yield of the whole flight "
                         "(GMA iterates as long as it holds; --iters and --budget unused)")
    ap.add_argument("--variant", action="append", default=[], metavar="NAME=FIELD=VALUE[,FIELD=VALUE]",
                    help="a GMA variant: KiteRTOSettings fields changed from the defaults, e.g. "
                         "undo2=gma.undo.sigma=2.0 (repeatable; NAME gma changes the reference)")
    ap.add_argument("--variants", metavar="MODULE:NAME", help="a mapping name -> KiteRTOSettings to import")
    ap.add_argument("--scheduler", metavar="ADDRESS", help="a running Dask scheduler (default: a LocalCluster)")
    ap.add_argument("--workers", type=int, default=os.cpu_count() or 1, help="LocalCluster worker processes")
    ap.add_argument("--retries", type=int, default=2, help="times a task that raises is run again")
    ap.add_argument("--cache-dir", default=None, help="finished runs (default: the kite_rto cache's campaign folder)")
    ap.add_argument("--out", default="runs/campaign", help="output directory")
    ap.add_argument("--dry-run", action="store_true", help="print what would run and what is cached, run nothing")
    ap.add_argument("--no-progress", action="store_true", help="no progress bar")
    return ap


def build_campaign(args) -> Campaign:
    """The :class:`Campaign` of parsed ``args`` (ValueError naming a bad value)."""
    variants = {GMA: KiteRTOSettings()}
    if args.variants:
        variants.update(load_variants(args.variants))
    for text in args.variant:
        name, settings = parse_variant(text)
        variants[name] = settings
    methods = tuple(m.strip() for m in args.methods.split(",") if m.strip())
    if args.seeds < 1 or args.first_seed < 0:
        raise ValueError(f"--seeds {args.seeds} --first-seed {args.first_seed}: expected >= 1 and >= 0")
    return Campaign(scenarios=tuple(select_scenarios(args.scenarios)),
                    seeds=tuple(range(args.first_seed, args.first_seed + args.seeds)), methods=methods,
                    variants=tuple(variants.items()), n_iter=args.iters, budget=args.budget, flight=args.flight)


def write_outputs(out: Path, campaign: Campaign, result: CampaignRun) -> str:
    """Write ``results.csv``, ``results.manifest.json``, ``wall.csv``, ``summary.md`` and (with results)
    ``campaign.png`` to ``out``; return the summary, computed from the table and manifest read back."""
    out.mkdir(parents=True, exist_ok=True)
    write_table(out / "results.csv", result.results)
    write_manifest(manifest_path(out / "results.csv"), campaign_manifest(campaign, result, library_versions()))
    write_wall_times(out / "wall.csv", result.results)
    rows = read_table(out / "results.csv")
    text = summarize(rows, plan_of([read_manifest(manifest_path(out / "results.csv"))]))
    (out / "summary.md").write_text(text + "\n")
    if rows:
        plot_campaign(out / "campaign.png", rows)
    return text


@contextmanager
def _client(scheduler: str | None, workers: int):
    from distributed import Client, LocalCluster
    if scheduler:
        with Client(scheduler) as client:
            yield client
        return
    with LocalCluster(n_workers=workers, threads_per_worker=1, processes=True, dashboard_address=None) as cluster, \
            Client(cluster) as client:
        yield client


def main(argv=None) -> int:
    args = _parser().parse_args(argv)
    try:
        campaign = build_campaign(args)
        if args.workers < 1 or args.retries < 0:
            raise ValueError(f"--workers {args.workers} --retries {args.retries}: expected >= 1 and >= 0")
    except ValueError as exc:
        print(f"kite_campaign: {exc}", file=sys.stderr)
        return 2
    t0 = time.perf_counter()
    cache = ResultCache(args.cache_dir or cache_dir("campaign"))
    to_run, cached = pending(campaign.tasks(), cache)
    runs = sum(t.store for t in to_run)
    variants = ", ".join(name for name, _ in campaign.variants)
    print(f"kite_campaign: {len(campaign.scenarios)} scenarios x {len(campaign.seeds)} seeds, methods "
          f"{', '.join(campaign.methods)} (GMA variants: {variants}), "
          + (f"{campaign.n_iter} iterations, baseline budget {campaign.budget:g}x" if campaign.flight is None else
             f"fixed flights of {campaign.flight:g} s") + f"; code {campaign.code}; cache {cache.directory}: {len(cached)} runs cached, "
          f"{runs} to run", flush=True)
    if args.dry_run:
        for t in to_run:
            print(f"  would run {t.key}")
        return 0
    if to_run:
        where = args.scheduler or f"a LocalCluster of {args.workers} workers"
        print(f"kite_campaign: running on {where}", flush=True)
        try:
            with _client(args.scheduler, args.workers) as client:
                result = run_campaign(campaign, cache, client, retries=args.retries, progress=not args.no_progress)
        except KeyboardInterrupt:
            done = len(pending(campaign.tasks(), cache)[1])
            print(f"kite_campaign: interrupted; {done} runs are in the cache, run the same command to continue",
                  file=sys.stderr)
            return 130
    else:
        result = run_campaign(campaign, cache, None, progress=False)
    out = Path(args.out)
    text = write_outputs(out, campaign, result)
    print(text)
    for oracle in result.execution.transient.values():
        print(f"kite_campaign: oracle of {oracle['scenario']}: {oracle['tension_kn']:.1f} kN "
              f"({oracle['wall_s']:.1f} s on its worker, 0 when read from its cache)")
    for key, err in sorted(result.failed.items()):
        print(f"kite_campaign: FAILED {key}: {err}", file=sys.stderr)
    planned = len(campaign.scenarios) * len(campaign.seeds) * len(campaign.table_methods())
    print(f"kite_campaign: {len(result.results)} of {planned} planned results ({len(result.execution.submitted)} "
          f"tasks run now), {len(result.failed)} tasks failed ({len(result.failed_runs)} of the table's runs); wrote "
          f"{out}/results.csv, results.manifest.json, wall.csv, summary.md{', campaign.png' if result.results else ''}"
          f"; wall time {time.perf_counter() - t0:.0f} s")
    return 1 if result.failed else 0


if __name__ == "__main__":
    raise SystemExit(main())
