"""A campaign (:class:`Campaign`: scenarios x seeds x methods, GMA variants, budget) as executor tasks, and its run
(:func:`run_campaign`).

Task keys are deterministic: ``<method>-<scenario>-s<seed>-<hash>``, the hash over the scenario's plant and h_min,
the seed, the method, the variant's settings (repr, with the scenario's h_min), the iterations, the code version
and, for a baseline, the budget and the reference GMA run's key. Each scenario's oracle is an unstored task
(``find_oracle`` caches it on disk itself) that every run of the scenario depends on; each baseline depends on the
reference GMA run (the variant named ``gma``) of its scenario and seed.
"""
from __future__ import annotations

import hashlib
import re
from dataclasses import dataclass, field, replace

from ..rto.settings import KiteRTOSettings
from .executor import Execution, ResultCache, Task, execute
from .manifest import Manifest
from .methods import BASELINES, GMA, METHODS, scenario_settings
from .results import RunResult
from .tasks import RunSpec, baseline_task, gma_task, oracle_task
from .version import code_version

__all__ = ["Campaign", "CampaignRun", "run_campaign", "campaign_manifest"]

_NAME = re.compile(r"^[A-Za-z0-9][A-Za-z0-9_.]*$")


def _digest(*parts) -> str:
    return hashlib.sha1(repr(parts).encode()).hexdigest()[:12]


@dataclass(frozen=True)
class Campaign:
    """Scenarios x seeds x methods.

    Attributes:
        scenarios: the :class:`~kite_rto.campaign.scenarios.Scenario` s, in table order.
        seeds: plant seeds.
        methods: names from :data:`~kite_rto.campaign.methods.METHODS`; ``gma`` stands for every GMA variant.
        variants: ``(name, KiteRTOSettings)`` pairs, the GMA variants (their h_min is replaced by each
            scenario's); must hold ``gma``, the reference whose time to 99 % sets the baselines' budget (default:
            just ``gma`` with :class:`KiteRTOSettings` defaults). Names: letters, digits, ``_`` and ``.``.
        n_iter: GMA iterations (>= 1).
        budget: a baseline's flight time over the reference GMA's time to 99 % on the same scenario and seed (> 0).
        code: the code-version tag (default: :func:`~kite_rto.campaign.version.code_version`).
        flight: fixed flights: every method flies this long (s, > 0) and is judged by the yield of the flight (GMA
            iterates as long as it holds, ``n_iter`` and ``budget`` are unused, a baseline flies it all); None: the
            time-to-99 % campaign.
    """

    scenarios: tuple
    seeds: tuple
    methods: tuple = METHODS
    variants: tuple = ((GMA, KiteRTOSettings()),)
    n_iter: int = 10
    budget: float = 4.0
    code: str = field(default_factory=code_version)
    flight: float | None = None

    def __post_init__(self):
        n = type(self).__name__
        object.__setattr__(self, "variants", tuple(dict(self.variants).items()))
        if not self.scenarios or not self.seeds:
            raise ValueError(f"{n}: expected at least one scenario and one seed")
        bad = [m for m in self.methods if m not in METHODS]
        if bad or not self.methods:
            raise ValueError(f"{n}.methods = {self.methods!r}: expected some of {', '.join(METHODS)}")
        names = [v for v, _ in self.variants]
        if GMA not in names:
            raise ValueError(f"{n}.variants {names}: expected one named {GMA!r} (the reference for the budget)")
        for v, s in self.variants:
            if not _NAME.match(v) or v in BASELINES:
                raise ValueError(f"{n}: GMA variant name {v!r}: expected letters, digits, '_' or '.', not a "
                                 f"baseline's name ({', '.join(BASELINES)})")
            if not isinstance(s, KiteRTOSettings):
                raise ValueError(f"{n}: GMA variant {v!r} = {s!r}: expected a KiteRTOSettings")
        if isinstance(self.n_iter, bool) or not isinstance(self.n_iter, int) or self.n_iter < 1:
            raise ValueError(f"{n}.n_iter = {self.n_iter!r}: expected an integer >= 1")
        if not self.budget > 0:
            raise ValueError(f"{n}.budget = {self.budget!r}: expected > 0")
        if self.flight is not None and not (isinstance(self.flight, (int, float)) and 0 < self.flight < float("inf")):
            raise ValueError(f"{n}.flight = {self.flight!r}: expected a flight time > 0 s or None")
        if len({s.name for s in self.scenarios}) != len(self.scenarios) or len(set(self.seeds)) != len(self.seeds):
            raise ValueError(f"{n}: scenarios and seeds must not repeat")

    def table_methods(self) -> tuple:
        """The method names of the table's rows, in row order: every GMA variant if ``gma`` is among the methods,
        then the baselines among them."""
        variants = tuple(v for v, _ in self.variants) if GMA in self.methods else ()
        return variants + tuple(m for m in BASELINES if m in self.methods)

    def _gma_spec(self, scenario, seed, name) -> RunSpec:
        settings = scenario_settings(dict(self.variants)[name], scenario)
        return RunSpec(scenario, int(seed), name, settings, self.n_iter, self.budget, self.code, self.flight)

    def _flight_key(self) -> tuple:
        """What a fixed flight adds to a run's key (nothing without one: the keys of earlier campaigns stand)."""
        return () if self.flight is None else ("flight", float(self.flight))

    def tasks(self) -> list:
        """The executor's :class:`~kite_rto.campaign.executor.Task` s, dependencies first."""
        out = []
        ref = dict(self.variants)[GMA]
        for sc in self.scenarios:
            ok = f"oracle-{sc.name}-{_digest(sc.plant, sc.h_min, ref.box, self.code)}"
            out.append(Task(ok, oracle_task, (sc, ref.box, self.code), store=False))
            for seed in self.seeds:
                gma_keys = {}
                run_gma = GMA in self.methods
                for name, _ in self.variants:
                    if not run_gma and (name != GMA or self.flight is not None):     # the reference only for
                        continue                                                      # the baselines' budget
                    spec = self._gma_spec(sc, seed, name)
                    key = f"{name}-{sc.name}-s{seed}-" + _digest(sc.name, sc.plant, sc.h_min, spec.seed, name,
                                                                 repr(spec.settings), spec.n_iter, self.code,
                                                                 *self._flight_key())
                    gma_keys[name] = key
                    out.append(Task(key, gma_task, (spec,), deps=(ok,)))
                for method in (m for m in BASELINES if m in self.methods):
                    spec = replace(self._gma_spec(sc, seed, GMA), method=method)
                    if self.flight is None:
                        key = f"{method}-{sc.name}-s{seed}-" + _digest(sc.name, sc.plant, sc.h_min, spec.seed,
                                                                       method, repr(spec.settings), spec.n_iter,
                                                                       self.budget, gma_keys[GMA], self.code)
                        out.append(Task(key, baseline_task, (spec,), deps=(ok, gma_keys[GMA])))
                    else:                        # a fixed flight: no reference run, no budget
                        key = f"{method}-{sc.name}-s{seed}-" + _digest(sc.name, sc.plant, sc.h_min, spec.seed,
                                                                       method, repr(spec.settings), self.code,
                                                                       *self._flight_key())
                        out.append(Task(key, baseline_task, (spec,), deps=(ok,)))
        return out


@dataclass
class CampaignRun:
    """A campaign's outcome: ``results`` (:class:`RunResult` in campaign order: scenario, seed, GMA variants,
    baselines), ``failed`` (task key -> error), ``failed_runs`` (``(scenario, seed, method, error)`` of the table's
    runs among them, in campaign order) and the executor's :class:`Execution`."""

    results: list
    failed: dict
    failed_runs: tuple
    execution: Execution


def run_campaign(campaign: Campaign, cache: ResultCache, client=None, retries: int = 2,
                 progress: bool = True) -> CampaignRun:
    """Run what ``cache`` does not hold yet on ``client`` (None: everything must be cached) and collect the
    results. A GMA run without baselines appears in the table only if ``gma`` is among the methods."""
    tasks = campaign.tasks()
    ex = execute(tasks, cache, client, retries=retries, progress=progress)
    tuning = {s.name: s.tuning for s in campaign.scenarios}
    in_table = set(campaign.table_methods())
    results, failed = [], []
    for t in tasks:
        if t.store and t.key in ex.results:
            r = RunResult.from_dict(ex.results[t.key])
            if r.method in in_table:
                results.append(replace(r, tuning=tuning[r.scenario]))
        elif t.store and t.key in ex.failed and t.args[0].method in in_table:
            spec = t.args[0]
            failed.append((spec.scenario.name, spec.seed, spec.method, ex.failed[t.key]))
    return CampaignRun(results=results, failed=dict(ex.failed), failed_runs=tuple(failed), execution=ex)


def campaign_manifest(campaign: Campaign, run: CampaignRun, libraries: dict) -> Manifest:
    """The :class:`~kite_rto.campaign.manifest.Manifest` of ``campaign`` after ``run``, with the client's
    ``libraries`` (name -> version)."""
    return Manifest(scenarios=tuple(s.name for s in campaign.scenarios), seeds=tuple(int(s) for s in campaign.seeds),
                    methods=campaign.table_methods(), n_iter=campaign.n_iter, budget=float(campaign.budget),
                    code_version=campaign.code, libraries=dict(libraries), failed=run.failed_runs,
                    flight=None if campaign.flight is None else float(campaign.flight))
