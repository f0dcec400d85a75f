"""The campaign's summary in markdown (:func:`summarize`) of a table's rows and the :class:`~.manifest.Plan` they
belong to. Its first line says whether every planned run is present and computed with one code version; if not (a
run failed, is missing, or rows of several code versions are mixed) it says so, a section counts the absent runs per
scenario and names them, and no criterion is marked met or not met. Then per scenario and GMA variant, per seed (a
seed is the same turbulence box in every scenario with the same Mann length scale and anisotropy, so outcomes
correlate by seed), then the campaign's criteria over all runs and over the tuning and report subsets, then
the baselines' time to 99 % over GMA's (a campaign of fixed flights: the yield of the whole flight per scenario and
method, and its criteria, instead), and last the environment: the plan, the code versions with their rows and
numerical libraries, and each scenario's oracle (its cache is rebuilt per environment, and a criterion decided by a
run near 99 % can move with it; a scenario whose rows carry more than one oracle value was merged from different
caches).

Times to 99 % of runs that never reach it count as infinite in medians ("never" when the median is). A baseline's
per-seed ratio is its time to 99 % over the reference GMA run's on the same seed (seeds where GMA did not reach
are left out); when the baseline did not reach within its budget the ratio is only known to exceed the budget
factor, and counts as infinite (shown as ``>budget``).
"""
from __future__ import annotations

import math

import numpy as np

from ..rto.judge import ALTITUDE_TOLERANCE_M, REACH_PERCENT
from .manifest import Plan
from .methods import BASELINES, GMA

__all__ = ["summarize", "decided", "CRITERIA"]

MODEL_FREE = ("nelder-mead", "fd-ascent", "bayes-opt")
CRITERIA = {
    "final": f"every run ends >= {REACH_PERCENT:g} % of its oracle",
    "floor": f"no iterate below h_min - {ALTITUDE_TOLERANCE_M:g} m",
    "held": ">= 99 % held from iteration 3 on in >= 90 % of runs",
    "t99": "median flight time to 99 % <= 600 s",
    "baseline": "best model-free baseline needs >= 3x GMA's time to 99 % (median over scenarios)",
}
"""The criteria one campaign's table decides: where every run ends, how low it flies, how long 99 % holds, how soon
it is reached, and how GMA compares with the best model-free method."""


def _t(r) -> float:
    return math.inf if r.t99_s is None else r.t99_s


def _median(values) -> float:
    return float(np.median(values)) if len(values) else math.nan


def _fmt_t(v: float) -> str:
    return "never" if v == math.inf else ("-" if math.isnan(v) else f"{v:.0f}")


def _fmt_ratio(v: float, budget: float) -> str:
    return f">{budget:g}" if v == math.inf else ("-" if math.isnan(v) else f"{v:.1f}")


def _held3(r) -> bool:
    return r.held_from is not None and r.held_from <= 3


def _ratios(rows, method: str, ref: str) -> dict:
    """scenario -> the per-seed ratios of ``method``'s time to 99 % over ``ref``'s."""
    gma = {(r.scenario, r.seed): _t(r) for r in rows if r.method == ref}
    out = {}
    for r in rows:
        tg = gma.get((r.scenario, r.seed), math.inf)
        if r.method == method and math.isfinite(tg):
            out.setdefault(r.scenario, []).append(_t(r) / tg if tg > 0 else (1.0 if _t(r) == 0 else math.inf))
    return out


def _best_baseline(rows) -> tuple:
    """``(name, median over scenarios of the per-scenario median ratio)`` of the model-free baseline with the
    smallest such median; ``(None, nan)`` without model-free baselines."""
    best = (None, math.nan)
    for m in MODEL_FREE:
        per = [_median(v) for v in _ratios(rows, m, GMA).values()]
        if per and (best[0] is None or _median(per) < best[1]):
            best = (m, _median(per))
    return best


def _criteria(gma_rows, all_rows, budget: float) -> dict:
    n = len(gma_rows)
    final = sum(r.final_percent >= REACH_PERCENT for r in gma_rows)
    floor = sum(r.below_floor > 0 for r in gma_rows)
    held = sum(_held3(r) for r in gma_rows)
    med = _median([_t(r) for r in gma_rows])
    name, ratio = _best_baseline(all_rows)
    return {
        "final": (f"{final}/{n}", final == n),
        "floor": (f"{floor}/{n} runs below", floor == 0),
        "held": (f"{held}/{n} = {100 * held / n:.0f} %" if n else "-", n > 0 and held >= 0.9 * n),
        "t99": (_fmt_t(med) + (" s" if math.isfinite(med) else ""), med <= 600.0),
        "baseline": ((f"{name} {_fmt_ratio(ratio, budget)}", ratio >= 3.0) if name else
                     ("no model-free baseline", None)),
    }


YIELD_CRITERIA = {
    "median": "GMA's yield: median >= 99.0 % of the oracle's energy",
    "worst": "GMA's yield: worst run >= 98.0 %",
    "below": "GMA: no flight time below h_min - 2 m",
    "loss": "best model-free method's yield loss >= 3x GMA's (median over scenarios)",
}
"""The criteria a campaign of fixed flights decides: the energy of the whole flight, learning included."""


def _loss_ratio(rows, method: str, ref: str) -> float:
    """Median over scenarios of ``method``'s median yield loss (100 - yield) over ``ref``'s."""
    per = []
    for sc in dict.fromkeys(r.scenario for r in rows):
        mine = [100.0 - r.yield_percent for r in rows if r.scenario == sc and r.method == method]
        theirs = [100.0 - r.yield_percent for r in rows if r.scenario == sc and r.method == ref]
        if mine and theirs:
            a, b = _median(mine), _median(theirs)
            per.append(a / b if b > 0 else (1.0 if a <= 0 else math.inf))
    return _median(per)


def _yield_section(rows, complete: bool) -> list:
    """Per scenario and method: median and worst yield and the longest time below the floor; then the criteria per
    GMA variant over all, tuning and report scenarios."""
    rows = [r for r in rows if r.yield_percent is not None]
    if not rows:
        return []
    methods = list(dict.fromkeys(r.method for r in rows))
    out = ["| scenario | tuning | " + " | ".join(methods) + " |", "|---|---|" + "---|" * len(methods)]
    for sc in dict.fromkeys(r.scenario for r in rows):
        cells = []
        for m in methods:
            ys = [r.yield_percent for r in rows if r.scenario == sc and r.method == m]
            below = max((r.below_floor_s or 0.0 for r in rows if r.scenario == sc and r.method == m), default=0.0)
            cells.append("-" if not ys else f"{_median(ys):.2f} ({min(ys):.2f})" + (f", {below:.0f} s low" if below
                                                                                     else ""))
        tuning = next(r.tuning for r in rows if r.scenario == sc)
        out.append(f"| {sc} | {'yes' if tuning else ''} | " + " | ".join(cells) + " |")
    out += ["", "Cells: median yield % of the oracle's energy over the seeds (worst); the longest flight time on "
            "setpoints judged below h_min - 2 m, when any.", ""]
    subsets = {"all": lambda r: True, "tuning": lambda r: r.tuning, "report": lambda r: not r.tuning}
    for v in (m for m in methods if m not in BASELINES):
        out += [f"**{v}**", "", "| criterion | all | tuning | report |", "|---|---|---|---|"]
        for c, text in YIELD_CRITERIA.items():
            cells = []
            for f in subsets.values():
                mine = [r for r in rows if r.method == v and f(r)]
                sub = [r for r in rows if f(r)]
                if not mine:
                    cells.append("-")
                    continue
                ys = [r.yield_percent for r in mine]
                if c == "median":
                    cells.append(_verdict(f"{_median(ys):.2f} %", _median(ys) >= 99.0, complete))
                elif c == "worst":
                    cells.append(_verdict(f"{min(ys):.2f} %", min(ys) >= 98.0, complete))
                elif c == "below":
                    low = sum((r.below_floor_s or 0.0) > 0 for r in mine)
                    cells.append(_verdict(f"{low}/{len(mine)} runs", low == 0, complete))
                else:
                    ratios = {m: _loss_ratio(sub, m, v) for m in MODEL_FREE if any(r.method == m for r in sub)}
                    if not ratios:
                        cells.append("no model-free method")
                        continue
                    best = min(ratios, key=ratios.get)
                    cells.append(_verdict(f"{best} {ratios[best]:.1f}x", ratios[best] >= 3.0, complete))
            out.append(f"| {text} | " + " | ".join(cells) + " |")
        out.append("")
    return out


def _verdict(value: str, met, complete: bool) -> str:
    if met is None:
        return value
    return f"{value} ({'met' if met else 'NOT met'})" if complete else f"{value} (not decided)"


def _scenario_table(rows, variant: str) -> list:
    lines = ["| scenario | tuning | h_min m | runs | final % min | final % median | runs < 99 % | lowest alt m | "
             "held from <= 3 | median t99 s |", "|---|---|---|---|---|---|---|---|---|---|"]
    for sc in dict.fromkeys(r.scenario for r in rows):
        rs = [r for r in rows if r.scenario == sc and r.method == variant]
        if not rs:
            continue
        fin = [r.final_percent for r in rs]
        alts = [r.lowest_altitude for r in rs]
        low = "crash" if any(a is None for a in alts) else f"{min(alts):.1f}"
        lines.append(f"| {sc} | {'yes' if rs[0].tuning else 'no'} | {rs[0].h_min:g} | {len(rs)} | {min(fin):.2f} | "
                     f"{_median(fin):.2f} | {sum(f < REACH_PERCENT for f in fin)} | {low} | "
                     f"{sum(_held3(r) for r in rs)}/{len(rs)} | {_fmt_t(_median([_t(r) for r in rs]))} |")
    return lines


def _seed_table(rows, variant: str) -> list:
    lines = ["| seed | runs | at 99 % by iterate 1 | held from <= 3 | runs < 99 % | median t99 s |",
             "|---|---|---|---|---|---|"]
    for seed in sorted({r.seed for r in rows if r.method == variant}):
        rs = [r for r in rows if r.seed == seed and r.method == variant]
        early = sum(r.reach_index is not None and r.reach_index <= 1 for r in rs)
        lines.append(f"| {seed} | {len(rs)} | {early}/{len(rs)} | {sum(_held3(r) for r in rs)}/{len(rs)} | "
                     f"{sum(r.final_percent < REACH_PERCENT for r in rs)} | {_fmt_t(_median([_t(r) for r in rs]))} |")
    return lines


def _baseline_table(rows, budget: float) -> list:
    methods = [m for m in BASELINES if any(r.method == m for r in rows)]
    if not methods:
        return []
    lines = ["| scenario | GMA median t99 s | " + " | ".join(f"{m}: median t99 s (ratio)" for m in methods) + " |",
             "|---|---|" + "---|" * len(methods)]
    ratios = {m: _ratios(rows, m, GMA) for m in methods}
    for sc in dict.fromkeys(r.scenario for r in rows):
        cells = []
        for m in methods:
            t = _median([_t(r) for r in rows if r.scenario == sc and r.method == m])
            cells.append(f"{_fmt_t(t)} ({_fmt_ratio(_median(ratios[m].get(sc, [])), budget)})")
        tg = _median([_t(r) for r in rows if r.scenario == sc and r.method == GMA])
        lines.append(f"| {sc} | {_fmt_t(tg)} | " + " | ".join(cells) + " |")
    overall = [_fmt_ratio(_median([_median(v) for v in ratios[m].values()]), budget) for m in methods]
    lines.append("| median ratio over scenarios | | " + " | ".join(overall) + " |")
    lines += ["", "Per-seed ratios over all scenarios (runs where GMA reached 99 %):", "",
              "| method | runs | < 1 (reached first) | 1 to < 3 | >= 3 | not within the budget |",
              "|---|---|---|---|---|---|"]
    for m in methods:
        v = np.array([x for xs in ratios[m].values() for x in xs], dtype=float)
        lines.append(f"| {m} | {len(v)} | {int(np.sum(v < 1))} | {int(np.sum((v >= 1) & (v < 3)))} | "
                     f"{int(np.sum((v >= 3) & np.isfinite(v)))} | {int(np.sum(~np.isfinite(v)))} |")
    return lines


def _missing(rows, plan: Plan) -> list:
    """The planned runs neither in ``rows`` nor recorded as failed, in plan order."""
    present = {(r.scenario, r.seed, r.method) for r in rows}
    return [run for run in plan.runs if run not in present and run not in plan.failed]


def decided(rows, plan: Plan) -> bool:
    """True if the summary of ``rows`` decides its criteria: every run ``plan`` planned is in ``rows`` and all
    were computed with one code version."""
    return not plan.failed and not _missing(rows, plan) and len(_versions(rows, plan)) == 1


def _versions(rows, plan: Plan) -> dict:
    """Code version -> rows computed with it: the rows' versions in order, then the manifests' without rows."""
    out = {}
    for r in rows:
        out[r.code_version] = out.get(r.code_version, 0) + 1
    return {**out, **{v: 0 for v in plan.versions if v not in out}}


def _environment(rows, plan: Plan, versions: dict) -> list:
    lines = [f"- plan: {plan.n_iter} GMA iterations, the baselines' budget {plan.budget:g}x GMA's time to 99 %"
             if plan.flight is None else f"- plan: fixed flights of {plan.flight:g} s for every method"]
    for v, n in versions.items():
        libraries = plan.versions.get(v)
        lines.append(f"- code version {v}: {n} runs; " + (", ".join(f"{k} {x}" for k, x in libraries.items())
                                                         if libraries else "libraries not in any manifest"))
    lines += ["", "| scenario | oracle kN |", "|---|---|"]
    for sc in dict.fromkeys(r.scenario for r in rows):
        values = sorted({r.oracle_kn for r in rows if r.scenario == sc})
        note = "" if len(values) == 1 else " (rows from different oracle caches)"
        lines.append(f"| {sc} | {', '.join(f'{v:.3f}' for v in values)}{note} |")
    return lines


def _headline(plan: Plan, versions: dict, missing: list) -> str:
    """The first line: the planned grid, its absent runs and code versions, and, unless every planned run is
    present and all were computed with one code version, that no criterion is decided."""
    n_failed = len(plan.failed)
    grid = (f"{len(dict.fromkeys(sc for sc, _, _ in plan.runs))} scenarios x "
            f"{len(dict.fromkeys(s for _, s, _ in plan.runs))} seeds, methods "
            f"{', '.join(dict.fromkeys(m for _, _, m in plan.runs))}")
    problems, details = [], []
    if n_failed or missing:
        problems.append("INCOMPLETE")
        details.append(f"{n_failed} of {len(plan.runs)} planned runs failed, {len(missing)} missing")
    if len(versions) > 1:
        problems.append("MIXED CODE VERSIONS")
        details.append("code versions " + ", ".join(f"{v} ({n} runs)" for v, n in versions.items()))
    if not problems:
        return (f"# Scenario campaign: {grid}; all {len(plan.runs)} planned runs present, code version "
                f"{next(iter(versions))}")
    version = "" if len(versions) > 1 else f"; code version {next(iter(versions))}"
    return (f"# Scenario campaign {' and '.join(problems)}, no criterion decided: {'; '.join(details)}; "
            f"{grid}{version}")


def _absent(plan: Plan, missing: list) -> list:
    """The failed and missing runs, counted per scenario, then each named (an error's first line)."""
    lines = ["| scenario | planned | present | failed | missing |", "|---|---|---|---|---|"]
    absent = [*plan.failed, *missing]
    for sc in dict.fromkeys(sc for sc, _, _ in absent):
        planned = sum(run[0] == sc for run in plan.runs)
        failed = sum(run[0] == sc for run in plan.failed)
        gone = sum(run[0] == sc for run in missing)
        lines.append(f"| {sc} | {planned} | {planned - failed - gone} | {failed} | {gone} |")
    lines.append("")
    for run in plan.runs:
        if run in plan.failed:
            error = (plan.failed[run].splitlines() or [""])[0]
            lines.append(f"- {run[0]} seed {run[1]} {run[2]}: failed: "
                         f"{error if len(error) <= 200 else error[:200] + ' ...'}")
        elif run in missing:
            lines.append(f"- {run[0]} seed {run[1]} {run[2]}: missing (not in the table, no failure recorded)")
    return lines


def summarize(rows, plan: Plan) -> str:
    """The markdown summary of ``rows`` (:class:`~kite_rto.campaign.results.RunResult`, campaign order) of the
    runs ``plan`` (:func:`~kite_rto.campaign.manifest.plan_of` their manifests) planned. Raises ValueError naming a
    row that is not a planned run or was recorded as failed."""
    plan.check(rows)
    missing, versions, complete = _missing(rows, plan), _versions(rows, plan), decided(rows, plan)
    budget = plan.budget
    variants = list(dict.fromkeys(r.method for r in rows if r.method not in BASELINES))
    out = [_headline(plan, versions, missing), ""]
    if plan.failed or missing:
        out += ["## Failed or missing runs", ""] + _absent(plan, missing) + [""]
    for v in variants:
        out += [f"## {v}: per scenario", ""] + _scenario_table(rows, v) + [""]
        out += [f"## {v}: per seed (the same turbulence in most scenarios)", ""] + _seed_table(rows, v) + [""]
        subsets = {"all": lambda r: True, "tuning": lambda r: r.tuning, "report": lambda r: not r.tuning}
        cols = {k: _criteria([r for r in rows if r.method == v and f(r)], [r for r in rows if f(r)], budget)
                for k, f in subsets.items()}
        out += [f"## {v}: criteria", "", "| criterion | all | tuning | report |",
                "|---|---|---|---|"]
        for c, text in CRITERIA.items():
            if c == "baseline" and (v != GMA or plan.flight is not None):
                continue
            cells = [_verdict(*cols[k][c], complete) if any(r.method == v and f(r) for r in rows) else "-"
                     for k, f in subsets.items()]
            out.append(f"| {text} | " + " | ".join(cells) + " |")
        out.append("")
    if plan.flight is not None:
        out += [f"## Yield of the whole flight ({plan.flight:g} s each, learning included)", ""]
        out += _yield_section(rows, complete)
    base = _baseline_table(rows, budget) if plan.flight is None else []
    if base:
        out += [f"## Baselines: time to 99 % over GMA's (budget {budget:g}x GMA's)", ""] + base + [""]
    extra = [v for v in variants if v != GMA]
    if extra and any(r.scenario == "default" for r in rows):
        g = _median([_t(r) for r in rows if r.scenario == "default" and r.method == GMA])
        out += ["## GMA variants on the default plant: extra flight time to 99 % over gma's", ""]
        for v in extra:
            m = _median([_t(r) for r in rows if r.scenario == "default" and r.method == v])
            rel = "-" if not (math.isfinite(m) and math.isfinite(g) and g > 0) else f"{100 * (m / g - 1):+.0f} %"
            out.append(f"- {v}: median t99 {_fmt_t(m)} s vs {_fmt_t(g)} s: {rel}")
        out.append("")
    out += ["## Environment", ""] + _environment(rows, plan, versions) + [""]
    return "\n".join(out)
