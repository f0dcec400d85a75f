"""The campaign summary of one or several results tables read back (e.g. seeds run in separate campaigns).

Usage: ``python -m kite_rto.tools.campaign_summary A/results.csv [B/results.csv ...] [--out summary.md]``

Reads each table (:func:`~kite_rto.campaign.tables.read_table`) and the manifest ``kite_campaign`` wrote beside it
(``results.manifest.json``: the planned runs, the failed ones, the budget, the code and library versions), refuses
a scenario x seed x method that two tables both hold or one holds and another records as failed (exit 2, naming
the files: which one to keep is the user's choice, not this tool's), and prints
:func:`~kite_rto.campaign.summary.summarize` of the rows in the order given (and writes it to ``--out``). Of one
campaign's table and manifest it gives that campaign's ``summary.md`` to the byte. Exit code 0; 1 when the summary
decides no criterion (a planned run failed or is missing, or the rows are of several code versions); 2 on a table
or manifest that does not read, or tables of different plans.
"""
from __future__ import annotations

import argparse
import sys
from pathlib import Path

from ..campaign.manifest import manifest_path, plan_of, read_manifest
from ..campaign.summary import decided, summarize
from ..campaign.tables import read_table

__all__ = ["main", "merged_rows"]


def merged_rows(paths) -> tuple:
    """``(rows, manifests)`` of the tables at ``paths`` and the manifests beside them, in order. Raises OSError for
    a missing file, ValueError naming the scenario, seed, method and both files when two tables hold the same run,
    or the table whose rows its manifest did not plan."""
    rows, manifests, where = [], [], {}
    for path in paths:
        try:
            manifest = read_manifest(manifest_path(path))
        except FileNotFoundError:
            raise ValueError(f"{path}: no manifest {manifest_path(path)} beside it: expected the one kite_campaign "
                             "writes with the table (without it the planned and failed runs are unknown)") from None
        table = read_table(path)
        plan_of([manifest]).check(table, str(path))
        claimed = [((r.scenario, r.seed, r.method), "holds") for r in table]
        claimed += [((sc, seed, m), "records as failed") for sc, seed, m, _ in manifest.failed]
        for run, how in claimed:
            if run in where:
                raise ValueError(f"scenario {run[0]!r}, seed {run[1]}, method {run[2]!r}: {where[run]} and {path} "
                                 f"{how} it: expected each run in one table only")
            where[run] = f"{path} {how} it"
        rows += table
        manifests.append(manifest)
    return rows, manifests


def _parser() -> argparse.ArgumentParser:
    p = argparse.ArgumentParser(prog="python -m kite_rto.tools.campaign_summary", description=__doc__.split("\n\n")[0])
    p.add_argument("tables", nargs="+", help="results.csv files written by kite_campaign (manifests beside them)")
    p.add_argument("--out", help="also write the summary to this file")
    return p


def main(argv=None) -> int:
    args = _parser().parse_args(argv)
    try:
        rows, manifests = merged_rows(args.tables)
        plan = plan_of(manifests)
        text = summarize(rows, plan)
    except (OSError, ValueError) as e:
        print(f"campaign_summary: {e}", file=sys.stderr)
        return 2
    if args.out:
        Path(args.out).write_text(text + "\n")
    print(text)
    return 0 if decided(rows, plan) else 1


if __name__ == "__main__":
    raise SystemExit(main())
