"""The campaign's summary (no flight): the criteria per subset, a table with failed or missing runs or mixed code
versions (said in the first line, counted per scenario, no criterion decided), the manifest beside a table,
``campaign_summary`` of tables read back, and ``kite_campaign`` with a task that raises on an in-process cluster:
its summary names the failures and ``campaign_summary`` gives it again to the byte."""
from contextlib import contextmanager
from dataclasses import replace
from pathlib import Path
from types import SimpleNamespace

import numpy as np
import pytest

from kite_rto.campaign import tasks
from kite_rto.campaign.manifest import manifest_path, plan_of, read_manifest, write_manifest
from kite_rto.campaign.methods import Flown
from kite_rto.campaign.plan import Campaign
from kite_rto.campaign.scenarios import scenario
from kite_rto.campaign.tables import read_table
from kite_rto.rto.flight_yield import Segment
from kite_rto.campaign.results import write_table
from kite_rto.campaign.summary import decided, summarize
from kite_rto.campaign.version import code_version
from kite_rto.rto import judge
from kite_rto.tools import campaign as cli
from kite_rto.tools import campaign_summary

from campaign_rows import manifest, plan_of_rows, row


def _criteria(text: str) -> dict:
    return {line.split(" | ")[0].lstrip("| "): line for line in text.splitlines() if line.startswith("|")}


def test_the_summary_evaluates_the_done_when_criteria_per_subset():
    rows = [row("a", 0, "gma", 99.5, 300.0), row("a", 1, "gma", 99.2, 500.0, held=5),
            row("a", 0, "nelder-mead", 99.1, 1500.0, budget=1200.0), row("a", 1, "nelder-mead", 95.0, None),
            row("b", 0, "gma", 98.0, 700.0, held=None, low=95.0, below=1, tuning=False),
            row("b", 1, "gma", 99.6, 900.0, tuning=False),
            row("b", 0, "nelder-mead", 99.3, 1400.0, tuning=False), row("b", 1, "nelder-mead", 99.0, 1800.0,
                                                                         tuning=False)]
    text = summarize(rows, plan_of_rows(rows))
    assert text.startswith("# Scenario campaign: 2 scenarios x 2 seeds, methods gma, nelder-mead; all 8 planned "
                           "runs present, code version 0123456789ab\n")
    assert decided(rows, plan_of_rows(rows)) and "Failed or missing" not in text
    lines = _criteria(text)
    assert "| a | yes | 100 | 2 | 99.20 | 99.35 | 0 | 110.0 | 1/2 | 400 |" in text
    assert "| b | no | 100 | 2 | 98.00 | 98.80 | 1 | 95.0 | 1/2 | 800 |" in text
    assert lines["every run ends >= 99 % of its oracle"].endswith(
        "| 3/4 (NOT met) | 2/2 (met) | 1/2 (NOT met) |")
    assert lines["no iterate below h_min - 2 m"].endswith(
        "| 1/4 runs below (NOT met) | 0/2 runs below (met) | 1/2 runs below (NOT met) |")
    assert lines[">= 99 % held from iteration 3 on in >= 90 % of runs"].endswith(
        "| 2/4 = 50 % (NOT met) | 1/2 = 50 % (NOT met) | 1/2 = 50 % (NOT met) |")
    assert lines["median flight time to 99 % <= 600 s"].endswith("| 600 s (met) | 400 s (met) | 800 s (NOT met) |")
    # Nelder-Mead over GMA per seed: a 5.0 and inf (not reached): median inf; b 2.0 and 2.0: median 2.0;
    # over scenarios: median(inf, 2.0) = inf, i.e. above the budget factor
    assert "| median ratio over scenarios | | >4 |" in text
    assert "| nelder-mead | 4 | 0 | 2 | 1 | 1 |" in text        # per-seed ratios 5.0, inf, 2.0, 2.0
    assert lines["best model-free baseline needs >= 3x GMA's time to 99 % (median over scenarios)"].endswith(
        "| nelder-mead >4 (met) | nelder-mead >4 (met) | nelder-mead 2.0 (NOT met) |")


def test_the_summary_names_the_environment_and_flags_oracles_from_different_caches():
    rows = [row("a", 0, "gma", 99.5, 300.0), replace(row("a", 1, "gma", 99.2, 500.0), oracle_kn=601.25),
            row("b", 0, "gma", 99.6, 900.0, tuning=False)]
    env = summarize(rows, plan_of_rows(rows)).split("## Environment", 1)[1]
    assert "- plan: 10 GMA iterations, the baselines' budget 4x GMA's time to 99 %" in env
    assert "- code version 0123456789ab: 3 runs; numpy 2.4.6, hipersim absent" in env
    assert "| a | 600.000, 601.250 (rows from different oracle caches) |" in env
    assert "| b | 600.000 |" in env


def test_the_summary_counts_per_seed_over_the_scenarios():
    late = replace(row("a", 1, "gma", 99.2, 1500.0, held=3), reach_index=3)     # at 99 % from iterate 3 on
    rows = [row("a", 0, "gma", 99.5, 300.0), row("b", 0, "gma", 98.0, 700.0, held=None), late,
            row("b", 1, "gma", 97.0, None, held=None), row("a", 1, "nelder-mead", 99.1, 900.0, budget=1200.0)]
    text = summarize(rows, plan_of_rows(rows))
    assert "## gma: per seed" in text
    assert "| 0 | 2 | 2/2 | 1/2 | 1 | 500 |" in text
    assert "| 1 | 2 | 0/2 | 1/2 | 1 | never |" in text


def test_a_table_with_failed_and_missing_runs_says_so_first_and_decides_no_criterion():
    rows = [row(sc, seed, m, 99.5, 300.0) for sc in "ab" for seed in (0, 1) for m in ("gma", "nelder-mead")
            if (sc, seed) == ("a", 0) or (sc, seed) == ("a", 1) or (sc, seed, m) == ("b", 1, "gma")]
    plan = plan_of([manifest("ab", (0, 1), ("gma", "nelder-mead"), failed=[
        ("b", 0, "gma", "KilledWorker: Attempted to run task 'gma-b-s0' on 1 different workers\nall died"),
        ("b", 0, "nelder-mead", "KilledWorker: Attempted to run task 'gma-b-s0' on 1 different workers")])])
    text = summarize(rows, plan)
    head = text.splitlines()[:12]
    assert head[0] == ("# Scenario campaign INCOMPLETE, no criterion decided: 2 of 8 planned runs failed, 1 missing; "
                       "2 scenarios x 2 seeds, methods gma, nelder-mead; code version 0123456789ab")
    assert head[2:] == ["## Failed or missing runs", "", "| scenario | planned | present | failed | missing |",
                        "|---|---|---|---|---|", "| b | 4 | 1 | 2 | 1 |", "",
                        "- b seed 0 gma: failed: KilledWorker: Attempted to run task 'gma-b-s0' on 1 different workers",
                        "- b seed 0 nelder-mead: failed: KilledWorker: Attempted to run task 'gma-b-s0' on 1 "
                        "different workers",
                        "- b seed 1 nelder-mead: missing (not in the table, no failure recorded)", ""]
    assert "(met)" not in text and "NOT met" not in text and not decided(rows, plan)
    assert _criteria(text)["every run ends >= 99 % of its oracle"].endswith(
        "| 3/3 (not decided) | 3/3 (not decided) | - |")


def test_rows_of_two_code_versions_are_flagged_first_and_decide_no_criterion():
    rows = [row("a", 0, "gma", 99.5, 300.0, code="aaaaaaaaaaaa"), row("a", 1, "gma", 99.2, 500.0, code="bbbbbbbbbbbb")]
    plan = plan_of([manifest("a", (0,), ("gma",), code="aaaaaaaaaaaa"), manifest("a", (1,), ("gma",),
                                                                                   code="bbbbbbbbbbbb")])
    text = summarize(rows, plan)
    assert text.splitlines()[0] == ("# Scenario campaign MIXED CODE VERSIONS, no criterion decided: code versions "
                                    "aaaaaaaaaaaa (1 runs), bbbbbbbbbbbb (1 runs); 1 scenarios x 2 seeds, methods gma")
    assert "(met)" not in text and "Failed or missing" not in text and not decided(rows, plan)
    assert "- code version bbbbbbbbbbbb: 1 runs; numpy 2.4.6" in text


def test_a_plan_refuses_rows_it_did_not_plan_and_tables_of_other_plans():
    plan = plan_of([manifest("a", (0,), ("gma",), failed=[("a", 0, "gma", "RuntimeError: x")])])
    with pytest.raises(ValueError, match="scenario 'a', seed 1, method 'gma' is not a run its manifest planned"):
        summarize([row("a", 1, "gma", 99.5, 300.0)], plan)
    with pytest.raises(ValueError, match="'gma' is in the table and recorded as failed"):
        summarize([row("a", 0, "gma", 99.5, 300.0)], plan)
    with pytest.raises(ValueError, match="planned with budget 3, 4: expected one value"):
        plan_of([manifest("a", (0,), ("gma",)), manifest("a", (1,), ("gma",), budget=3.0)])


def test_a_manifest_reads_back_and_a_bad_one_is_refused_naming_the_field(tmp_path):
    m = manifest("ab", (0, 1), ("gma", "bayes-opt"), failed=[("b", 1, "bayes-opt", "ValueError: no lap")])
    path = manifest_path(tmp_path / "results.csv")
    assert path.name == "results.manifest.json"
    write_manifest(path, m)
    assert read_manifest(path) == m
    path.write_text(path.read_text().replace('"n_iter": 10', '"n_iter": 0'))
    with pytest.raises(ValueError, match=r"results.manifest.json: n_iter = 0: expected an integer >= 1"):
        read_manifest(path)
    write_manifest(path, replace(m, failed=(("c", 0, "gma", "x"),)))
    with pytest.raises(ValueError, match="failed run scenario 'c', seed 0, method 'gma': expected a planned run"):
        read_manifest(path)


def _table(path, rows, m):
    write_table(path, rows)
    write_manifest(manifest_path(path), m)


def test_campaign_summary_merges_tables_and_refuses_a_run_in_two(tmp_path, capsys):
    _table(tmp_path / "a.csv", [row("a", 0, "gma", 99.5, 300.0), row("a", 0, "bayes-opt", 99.1, 600.0)],
           manifest("a", (0,), ("gma", "bayes-opt")))
    _table(tmp_path / "b.csv", [row("a", 1, "gma", 99.2, 500.0), row("a", 1, "bayes-opt", 98.0, None)],
           manifest("a", (1,), ("gma", "bayes-opt")))
    assert campaign_summary.main([str(tmp_path / "a.csv"), str(tmp_path / "b.csv"), "--out",
                                  str(tmp_path / "s.md")]) == 0
    text = (tmp_path / "s.md").read_text()
    assert text.startswith("# Scenario campaign: 1 scenarios x 2 seeds, methods gma, bayes-opt; all 4 planned runs")
    assert "| a | yes | 100 | 2 | 99.20 | 99.35 | 0 | 110.0 | 2/2 | 400 |" in text
    assert "| bayes-opt | 2 | 0 | 1 | 0 | 1 |" in text             # per-seed ratios 600 / 300 = 2 and not reached
    capsys.readouterr()
    assert campaign_summary.main([str(tmp_path / "a.csv"), str(tmp_path / "a.csv")]) == 2
    err = capsys.readouterr().err
    assert "scenario 'a', seed 0, method 'gma'" in err and "a.csv holds it and" in err
    assert campaign_summary.main([str(tmp_path / "missing.csv")]) == 2
    write_table(tmp_path / "bare.csv", [row("a", 0, "gma", 99.5, 300.0)])
    assert campaign_summary.main([str(tmp_path / "bare.csv")]) == 2
    err = capsys.readouterr().err
    assert "no manifest" in err and "bare.manifest.json" in err
    _table(tmp_path / "c.csv", [row("a", 2, "gma", 99.5, 300.0)], manifest("a", (2,), ("gma", "bayes-opt")))
    assert campaign_summary.main([str(tmp_path / "c.csv")]) == 1     # its bayes-opt run is missing
    assert "INCOMPLETE" in capsys.readouterr().out.splitlines()[0]


def _fake_flight(monkeypatch):
    """Oracle, flights and the judge's plant closed-form; GMA on high_floor raises. GMA flies 0.5 for 400 s, then
    0.6 (600 kN, the oracle) to the end of its flight (800 s, or the fixed flight); a baseline flies 0.5 (500 kN)."""
    def fly_gma(scenario, seed, n_iter, settings, flight=None):
        if scenario.name == "high_floor":
            raise RuntimeError(f"no lap on {scenario.name}")
        end = flight or 800.0
        return Flown(iterates=np.array([[0.5, 0.8, 0.5], [0.6, 0.8, 0.5]]), times=np.array([0.0, 400.0]),
                     flight_time=end, experiments=8, crashes=0,
                     segments=(Segment(0.0, 400.0, (0.5, 0.8, 0.5)), Segment(400.0, end, (0.6, 0.8, 0.5))))
    monkeypatch.setattr(tasks, "find_oracle", lambda plant, box, h_min: SimpleNamespace(tension_kn=600.0,
                                                                                        c=[0.6, 0.8, 0.5]))
    monkeypatch.setattr(tasks, "fly_gma", fly_gma)
    monkeypatch.setattr(tasks, "fly_baseline", lambda method, sc, seed, settings, budget, stop: Flown(
        iterates=np.array([[0.5, 0.8, 0.5]]), times=np.array([0.0]), flight_time=budget, experiments=4, crashes=0,
        segments=(Segment(0.0, budget, (0.5, 0.8, 0.5)),)))
    monkeypatch.setattr(judge, "plant_performance", lambda plant, c: (1000.0 * c[0], 120.0))
    monkeypatch.setattr(tasks, "plant_performance", lambda plant, c: (1000.0 * c[0], 120.0))


@contextmanager
def _in_process_client(scheduler, workers):
    from distributed import Client, LocalCluster
    with LocalCluster(n_workers=1, threads_per_worker=1, processes=False, dashboard_address=None) as cluster, \
            Client(cluster) as client:
        yield client


def test_kite_campaign_with_a_task_that_raises_names_it_and_decides_no_criterion(tmp_path, monkeypatch, capsys):
    _fake_flight(monkeypatch)
    monkeypatch.setattr(cli, "_client", _in_process_client)
    out = tmp_path / "out"
    assert cli.main(["--scenarios", "default,high_floor", "--seeds", "1", "--methods", "gma,model-only", "--iters",
                     "1", "--retries", "0", "--cache-dir", str(tmp_path / "cache"), "--out", str(out)]) == 1
    captured = capsys.readouterr()
    bar = captured.err.replace("\r", "\n").splitlines()
    assert any("4/6" in line and "failed=2" in line for line in bar), captured.err     # not 6/6
    assert "2 of 4 planned results (6 tasks run now), 2 tasks failed (2 of the table's runs)" in captured.out
    summary = (out / "summary.md").read_text()
    assert summary.splitlines()[0] == (
        "# Scenario campaign INCOMPLETE, no criterion decided: 2 of 4 planned runs failed, 0 missing; 2 scenarios x 1 "
        f"seeds, methods gma, model-only; code version {code_version()}")
    assert "| high_floor | 2 | 0 | 2 | 0 |" in summary
    assert "- high_floor seed 0 gma: failed: RuntimeError: no lap on high_floor" in summary
    assert "- high_floor seed 0 model-only: failed: RuntimeError: no lap on high_floor" in summary
    assert "(met)" not in summary and "NOT met" not in summary
    assert [f[:3] for f in read_manifest(out / "results.manifest.json").failed] == [
        ("high_floor", 0, "gma"), ("high_floor", 0, "model-only")]
    assert campaign_summary.main([str(out / "results.csv"), "--out", str(tmp_path / "again.md")]) == 1
    assert (tmp_path / "again.md").read_bytes() == (out / "summary.md").read_bytes()


def test_every_committed_table_gives_its_committed_summary(tmp_path):
    """benchmarks/results/<name>/ (README there): the summary recomputed from the table and its manifest is the
    committed one to the byte, and it decides its criteria (every planned run present, one code version)."""
    results = Path(__file__).resolve().parents[2] / "benchmarks" / "results"
    assert (results / "README.md").is_file()
    for table in sorted(results.glob("*/results.csv")):
        assert manifest_path(table).is_file() and (table.parent / "summary.md").is_file(), table.parent
        assert campaign_summary.main([str(table), "--out", str(tmp_path / "summary.md")]) == 0, table
        assert (tmp_path / "summary.md").read_bytes() == (table.parent / "summary.md").read_bytes(), table


def test_a_campaign_of_fixed_flights_judges_every_method_by_its_yield(tmp_path, monkeypatch, capsys):
    """Every method flies 2000 s: GMA 400 s at 500 kN then 1600 s at the oracle's 600 kN (yield 96.67 %), the
    baseline 500 kN throughout (83.33 %): its loss is 5x GMA's. The yield columns are in the table, the
    flight in the manifest, and the summary decides the yield criteria."""
    _fake_flight(monkeypatch)
    monkeypatch.setattr(cli, "_client", _in_process_client)
    out = tmp_path / "out"
    assert cli.main(["--scenarios", "default", "--seeds", "1", "--methods", "gma,nelder-mead", "--flight",
                     "2000", "--retries", "0", "--cache-dir", str(tmp_path / "cache"), "--out", str(out)]) == 0
    assert "fixed flights of 2000 s" in capsys.readouterr().out
    rows = read_table(out / "results.csv")
    assert [(r.method, r.yield_percent, r.below_floor_s, r.budget_s) for r in rows] == [
        ("gma", 96.667, 0.0, None), ("nelder-mead", 83.333, 0.0, 2000.0)]
    assert read_manifest(manifest_path(out / "results.csv")).flight == 2000.0
    summary = (out / "summary.md").read_text()
    assert "## Yield of the whole flight (2000 s each, learning included)" in summary
    assert "| default | yes | 96.67 (96.67) | 83.33 (83.33) |" in summary
    assert "| GMA's yield: median >= 99.0 % of the oracle's energy | 96.67 % (NOT met) | 96.67 % (NOT met) | - |" \
        in summary
    assert ("| best model-free method's yield loss >= 3x GMA's (median over scenarios) | nelder-mead 5.0x (met) | "
            "nelder-mead 5.0x (met) | - |") in summary
    assert "Baselines: time to 99 %" not in summary
    with pytest.raises(ValueError, match="Campaign.flight = -1: expected a flight time > 0 s or None"):
        Campaign(scenarios=(scenario("default"),), seeds=(0,), flight=-1)
