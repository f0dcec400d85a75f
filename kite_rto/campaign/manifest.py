"""The manifest beside a results table (:class:`Manifest`, ``results.manifest.json`` beside ``results.csv``): what
the campaign planned (scenarios, seeds, the table's methods, GMA iterations, the baselines' budget), which runs
failed and with what error, and the client's code and library versions. With it a table read back knows the runs it
lacks; :func:`plan_of` joins the manifests of tables summarized together into one :class:`Plan`.

Apart from :mod:`.results` on purpose, like :mod:`.tables`: it decides no run's numbers, so it is not part of the
code version. JSON, fields in a fixed order and no wall time: two runs of the same campaign write the same bytes.
"""
from __future__ import annotations

import json
import math
from dataclasses import asdict, dataclass, fields
from pathlib import Path

__all__ = ["Manifest", "Plan", "manifest_path", "write_manifest", "read_manifest", "plan_of"]

_FORMAT = "kite_campaign manifest 1"


@dataclass(frozen=True)
class Manifest:
    """One campaign's plan and outcome beside its table.

    Attributes:
        scenarios: scenario names, in table order.
        seeds: plant seeds.
        methods: the table's method names (GMA variants, then baselines), in row order.
        n_iter: GMA iterations.
        budget: the baselines' flight time over the reference GMA's time to 99 %.
        code_version: the client's code version (every planned run is computed with it).
        libraries: name -> version of the client's numerical libraries.
        failed: ``(scenario, seed, method, error)`` of each planned run that failed, in table order.
        flight: a campaign of fixed flights: their length, s (None: the time-to-99 % campaign; a manifest without
            the field is one).
    """

    scenarios: tuple
    seeds: tuple
    methods: tuple
    n_iter: int
    budget: float
    code_version: str
    libraries: dict
    failed: tuple = ()
    flight: float | None = None

    def runs(self) -> list:
        """The planned ``(scenario, seed, method)`` in table order."""
        return [(sc, seed, m) for sc in self.scenarios for seed in self.seeds for m in self.methods]


def manifest_path(table) -> Path:
    """The manifest beside the table at ``table``: ``results.csv`` -> ``results.manifest.json``."""
    table = Path(table)
    return table.with_name(f"{table.stem}.manifest.json")


def write_manifest(path, manifest: Manifest) -> None:
    """Write ``manifest`` as JSON to ``path``."""
    d = {"format": _FORMAT, **asdict(manifest)}
    d["failed"] = [{"scenario": sc, "seed": seed, "method": m, "error": e} for sc, seed, m, e in manifest.failed]
    if manifest.flight is None:
        del d["flight"]                              # the manifest of a time-to-99 % campaign, as it always was
    Path(path).write_text(json.dumps(d, indent=1, allow_nan=False) + "\n")


def _strings(v) -> bool:
    return isinstance(v, list) and all(isinstance(x, str) for x in v)


def _ints(v) -> bool:
    return isinstance(v, list) and all(isinstance(x, int) and not isinstance(x, bool) for x in v)


_CHECKS = {
    "scenarios": (_strings, "a list of scenario names"),
    "seeds": (_ints, "a list of integer seeds"),
    "methods": (_strings, "a list of method names"),
    "n_iter": (lambda v: isinstance(v, int) and not isinstance(v, bool) and v >= 1, "an integer >= 1"),
    "budget": (lambda v: isinstance(v, (int, float)) and not isinstance(v, bool) and math.isfinite(v) and v > 0,
               "a number > 0"),
    "code_version": (lambda v: isinstance(v, str) and v != "", "a code version"),
    "libraries": (lambda v: isinstance(v, dict) and all(isinstance(x, str) for x in v.values()),
                  "an object of library names and versions"),
    "flight": (lambda v: v is None or (isinstance(v, (int, float)) and not isinstance(v, bool) and math.isfinite(v)
                                       and v > 0), "a flight time > 0 s or null"),
    "failed": (lambda v: isinstance(v, list) and all(
        isinstance(f, dict) and set(f) == {"scenario", "seed", "method", "error"} and isinstance(f["seed"], int)
        and all(isinstance(f[k], str) for k in ("scenario", "method", "error")) for f in v),
               "a list of {scenario, seed, method, error}"),
}


def read_manifest(path) -> Manifest:
    """The :class:`Manifest` :func:`write_manifest` wrote to ``path``. Raises OSError if it is missing, ValueError
    naming the file and the field that is not what a manifest holds."""
    try:
        d = json.loads(Path(path).read_text())
    except ValueError as e:
        raise ValueError(f"{path}: not JSON ({e}): expected a kite_campaign manifest") from None
    if not isinstance(d, dict) or d.get("format") != _FORMAT:
        raise ValueError(f"{path}: format {d.get('format') if isinstance(d, dict) else d!r}: expected {_FORMAT!r}")
    names = [f.name for f in fields(Manifest)]
    d.setdefault("flight", None)                     # written before fixed flights existed
    if sorted(d) != sorted(names + ["format"]):
        raise ValueError(f"{path}: fields {sorted(d)}: expected {sorted(names + ['format'])}")
    for name, (ok, what) in _CHECKS.items():
        if not ok(d[name]):
            raise ValueError(f"{path}: {name} = {d[name]!r}: expected {what}")
    m = Manifest(scenarios=tuple(d["scenarios"]), seeds=tuple(d["seeds"]), methods=tuple(d["methods"]),
                 n_iter=d["n_iter"], budget=float(d["budget"]), code_version=d["code_version"],
                 libraries=d["libraries"],
                 failed=tuple((f["scenario"], f["seed"], f["method"], f["error"]) for f in d["failed"]),
                 flight=d["flight"])
    planned = set(m.runs())
    for sc, seed, method, _ in m.failed:
        if (sc, seed, method) not in planned:
            raise ValueError(f"{path}: failed run scenario {sc!r}, seed {seed}, method {method!r}: expected a "
                             "planned run")
    return m


@dataclass(frozen=True)
class Plan:
    """What tables summarized together planned (:func:`plan_of`).

    Attributes:
        runs: the planned ``(scenario, seed, method)``, each once, in the tables' order.
        failed: ``(scenario, seed, method)`` -> error of the runs that failed.
        n_iter, budget: GMA iterations and the baselines' budget factor (the same in every table).
        versions: code version -> its library versions, of every manifest.
        flight: fixed flights' length, s (the same in every table), or None.
    """

    runs: tuple
    failed: dict
    n_iter: int
    budget: float
    versions: dict
    flight: float | None = None

    def check(self, rows, where: str = "the table") -> None:
        """Raise ValueError naming the first row of ``rows`` (:class:`~kite_rto.campaign.results.RunResult`)
        that is not a planned run or is a run recorded as failed."""
        planned = set(self.runs)
        for r in rows:
            run = (r.scenario, r.seed, r.method)
            if run not in planned:
                raise ValueError(f"{where}: scenario {r.scenario!r}, seed {r.seed}, method {r.method!r} is not a "
                                 "run its manifest planned: expected the manifest written with the table")
            if run in self.failed:
                raise ValueError(f"{where}: scenario {r.scenario!r}, seed {r.seed}, method {r.method!r} is in the "
                                 "table and recorded as failed: expected each run once, finished or failed")


def plan_of(manifests) -> Plan:
    """The :class:`Plan` of tables summarized together. Raises ValueError when their GMA iterations or budgets
    differ (a comparison of one plan is reported, not of several) or when two record the same run as failed."""
    manifests = list(manifests)
    if not manifests:
        raise ValueError("plan_of: no manifest: expected at least one")
    for name in ("n_iter", "budget", "flight"):
        values = sorted({getattr(m, name) for m in manifests}, key=lambda v: (v is not None, v or 0))
        if len(values) > 1:
            raise ValueError(f"the tables were planned with {name} {', '.join('none' if v is None else f'{v:g}' for v in values)}: expected "
                             "one value in all of them")
    runs, failed = {}, {}
    for m in manifests:
        runs.update(dict.fromkeys(m.runs()))
        for sc, seed, method, error in m.failed:
            if (sc, seed, method) in failed:
                raise ValueError(f"scenario {sc!r}, seed {seed}, method {method!r} is recorded as failed in two "
                                 "manifests: expected each run in one table only")
            failed[(sc, seed, method)] = error
    return Plan(runs=tuple(runs), failed=failed, n_iter=manifests[0].n_iter, budget=manifests[0].budget,
                versions={m.code_version: m.libraries for m in manifests}, flight=manifests[0].flight)
