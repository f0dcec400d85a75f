"""The campaign summary of several results tables together (e.g. seeds run in separate campaigns).

Usage: ``python -m kite_rto.tools.campaign_summary A/results.csv B/results.csv [--budget 4] [--out summary.md]``

Reads each table (:func:`~kite_rto.campaign.tables.read_table`), refuses a scenario x seed x method that two
tables both hold (exit 2, naming both files: which one to keep is the user's choice, not this tool's), and prints
:func:`~kite_rto.campaign.summary.summarize` of the rows in the order given (and writes it to ``--out``). Its
*Environment* section lists each scenario's oracle values and flags a scenario whose rows carry more than one; the
code and library versions are not in the tables, so it names neither.
"""
from __future__ import annotations

import argparse
import sys
from pathlib import Path

from ..campaign.tables import read_table
from ..campaign.summary import summarize

__all__ = ["main", "merged_rows"]


def merged_rows(paths) -> list:
    """The rows of the tables at ``paths``, in order. Raises ValueError naming the scenario, seed, method and both
    files when two tables hold the same run."""
    rows, where = [], {}
    for path in paths:
        for r in read_table(path):
            key = (r.scenario, r.seed, r.method)
            if key in where:
                raise ValueError(f"scenario {r.scenario!r}, seed {r.seed}, method {r.method!r} is in both {where[key]} "
                                 f"and {path}: expected each run in one table only")
            where[key] = path
            rows.append(r)
    return rows


def _parser() -> argparse.ArgumentParser:
    p = argparse.ArgumentParser(prog="python -m kite_rto.tools.campaign_summary", description=__doc__.split("\n\n")[0])
    p.add_argument("tables", nargs="+", help="results.csv files written by kite_campaign")
    p.add_argument("--budget", type=float, default=4.0,
                   help="the baselines' budget factor the campaigns ran with (default 4; only labels '>budget')")
    p.add_argument("--out", help="also write the summary to this file")
    return p


def main(argv=None) -> int:
    args = _parser().parse_args(argv)
    if not args.budget > 0:
        print(f"campaign_summary: --budget = {args.budget!r}: expected > 0", file=sys.stderr)
        return 2
    try:
        rows = merged_rows(args.tables)
    except (OSError, ValueError) as e:
        print(f"campaign_summary: {e}", file=sys.stderr)
        return 2
    if not rows:
        print("campaign_summary: the tables hold no rows", file=sys.stderr)
        return 2
    text = summarize(rows, args.budget)
    if args.out:
        Path(args.out).write_text(text + "\n")
    print(text)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
