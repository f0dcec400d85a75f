"""Read a campaign's results table back (:func:`read_table`, the inverse of
:func:`~kite_rto.campaign.results.write_table`), e.g. to summarize campaigns run separately together
(``python -m kite_rto.tools.campaign_summary``).

Apart from :mod:`.results` on purpose: reading decides no run's numbers, so it is not part of the code version
(:mod:`.version`) and changing it leaves every cached run valid.
"""
from __future__ import annotations

import csv
import json
import math

from .results import OPTIONAL_COLUMNS, TABLE_COLUMNS, RunResult

__all__ = ["read_table"]

_INTS = ("seed", "reach_index", "held_from", "below_floor", "experiments", "crashes")
_FLOATS = ("h_min", "t99_s", "final_percent", "lowest_altitude", "flight_time_s", "budget_s", "oracle_kn",
           "yield_percent", "below_floor_s")


def _parse(name: str, text: str):
    """One cell of the table as the :class:`~kite_rto.campaign.results.RunResult` field ``name`` holds it (the
    other fields, ``times_s``, ``percent`` and ``altitude``, are JSON lists)."""
    if name in ("scenario", "method", "message", "code_version"):
        return text
    if name == "tuning":
        if text not in ("True", "False"):
            raise ValueError(f"expected True or False, got {text!r}")
        return text == "True"
    if text == "":
        return None
    if name in _INTS:
        return int(text)
    if name in _FLOATS:
        return float(text)
    values = json.loads(text)
    if not isinstance(values, list):
        raise ValueError(f"expected a JSON list, got {text!r}")
    return tuple(None if v is None else float(v) for v in values)


def read_table(path) -> list:
    """The :class:`~kite_rto.campaign.results.RunResult` rows of a table ``write_table`` wrote, in its order;
    ``wall_s`` (not in the table) is NaN. Raises ValueError naming the file, line and column of a cell that does
    not parse, or the columns when they are not :data:`~kite_rto.campaign.results.TABLE_COLUMNS`."""
    with open(path, newline="") as f:
        reader = csv.DictReader(f)
        columns = tuple(reader.fieldnames or ())
        older = tuple(c for c in TABLE_COLUMNS if c not in OPTIONAL_COLUMNS)      # a table without fixed flights
        if columns not in (TABLE_COLUMNS, older):
            hint = ("; without code_version it cannot name the code its runs were computed with: run its campaign "
                    "again" if set(older) - set(columns) == {"code_version"} else "")
            raise ValueError(f"{path}: columns {reader.fieldnames} differ from a campaign table's "
                             f"{list(TABLE_COLUMNS)}{hint}")
        rows = []
        for line, cells in enumerate(reader, start=2):
            values = {}
            for name in columns:
                try:
                    values[name] = _parse(name, cells[name])
                except (ValueError, TypeError) as e:
                    raise ValueError(f"{path}, line {line}, column {name} = {cells[name]!r}: {e}") from None
            rows.append(RunResult(**values, wall_s=math.nan))
    return rows
