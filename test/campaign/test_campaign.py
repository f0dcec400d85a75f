"""The scenario campaign: task keys, variants, the results table and the summary's criteria (fast, no flight), and
one slow end-to-end run of ``kite_campaign`` (one scenario, one seed, model-only and GMA with one iteration)."""
import csv
import json
import math
from dataclasses import replace

import pytest

from kite_rto.campaign.plan import Campaign
from kite_rto.campaign.results import TABLE_COLUMNS, RunResult, write_table
from kite_rto.campaign.tables import read_table
from kite_rto.campaign.scenarios import scenario
from kite_rto.campaign.summary import summarize
from kite_rto.campaign.tasks import baseline_budget
from kite_rto.campaign.variants import parse_variant
from kite_rto.campaign.version import check_code_version, code_version
from kite_rto.rto.settings import KiteRTOSettings
from kite_rto.tools import campaign as cli
from kite_rto.tools import campaign_summary

TWO = (scenario("default"), scenario("high_floor"))


def _keys(**changes):
    c = Campaign(**{"scenarios": TWO, "seeds": (0, 1), "code": "tag", **changes})
    return {(t.fn.__name__, t.args[0].name if t.fn.__name__ == "oracle_task" else
             (t.args[0].scenario.name, t.args[0].seed, t.args[0].method)): t for t in c.tasks()}


def test_task_keys_follow_exactly_what_decides_a_run():
    base = _keys()
    assert _keys().keys() == base.keys() and [t.key for t in _keys().values()] == [t.key for t in base.values()]
    assert len(base) == 2 + 2 * 2 * 5                     # an oracle per scenario, 5 methods per scenario and seed
    for (fn, what), t in base.items():
        if fn == "baseline_task":
            sc, seed, _ = what
            assert t.deps == (base[("oracle_task", sc)].key, base[("gma_task", (sc, seed, "gma"))].key)
            assert t.args[0].settings.experiment.h_min == scenario(sc).h_min
        assert t.store == (fn != "oracle_task")
    budget = _keys(budget=3.0)
    for k, t in base.items():
        assert (budget[k].key == t.key) == (k[0] != "baseline_task")
    iters = _keys(n_iter=5)
    assert all((iters[k].key == t.key) == (k[0] == "oracle_task") for k, t in base.items())
    tag = _keys(code="other")
    assert all(tag[k].key != t.key for k, t in base.items())
    varied = _keys(variants=(("gma", KiteRTOSettings()), parse_variant("bo4=gma.backoff=4.0")))
    assert varied[("gma_task", ("default", 0, "bo4"))].key != base[("gma_task", ("default", 0, "gma"))].key
    assert all(varied[k].key == t.key for k, t in base.items())          # adding a variant changes no other key
    moved = _keys(variants=(("gma", KiteRTOSettings().with_gma(backoff=4.0)),))
    assert all((moved[k].key == t.key) == (k[0] == "oracle_task") for k, t in base.items())


def test_baselines_alone_still_fly_the_reference_gma_for_their_budget():
    keys = _keys(methods=("nelder-mead",))
    assert sorted({k[0] for k in keys}) == ["baseline_task", "gma_task", "oracle_task"]
    assert baseline_budget(4.0, {"t99_s": 300.0, "flight_time_s": 3000.0}) == 1200.0
    assert baseline_budget(4.0, {"t99_s": None, "flight_time_s": 3000.0}) == 12000.0


@pytest.mark.parametrize("changes, match", [
    ({"variants": (("sc", KiteRTOSettings()),)}, "expected one named 'gma'"),
    ({"methods": ("gma", "random-search")}, "expected some of"),
    ({"variants": (("gma", KiteRTOSettings()), ("model-only", KiteRTOSettings()))}, "not a baseline's name"),
    ({"variants": (("gma", KiteRTOSettings()), ("a-b", KiteRTOSettings()))}, "'a-b'"),
    ({"n_iter": 0}, "n_iter = 0"),
    ({"budget": 0.0}, "budget = 0.0"),
    ({"seeds": (0, 0)}, "must not repeat"),
])
def test_a_bad_campaign_is_refused_naming_the_value(changes, match):
    with pytest.raises(ValueError, match=match):
        Campaign(**{"scenarios": TWO, "seeds": (0,), "code": "tag", **changes})


def test_variants_change_the_named_fields_and_refuse_unknown_ones():
    name, s = parse_variant("v=fd_step=(0.3, 0.3, 0.3),gma.structure_check_every=3,gradient=central")
    assert name == "v" and s.fd_step == (0.3, 0.3, 0.3) and s.gma.structure_check_every == 3
    assert s.gradient == "central" and s.gma.backoff == KiteRTOSettings().gma.backoff
    assert parse_variant("plain") == ("plain", KiteRTOSettings())
    with pytest.raises(ValueError, match="has no field 'nope'"):
        parse_variant("v=gma.nope=1")
    with pytest.raises(ValueError, match="n_laps = 0"):
        parse_variant("v=experiment.n_laps=0")
    with pytest.raises(ValueError, match="not FIELD=VALUE"):
        parse_variant("v=gma.backoff")


def test_a_worker_running_other_code_refuses_the_task():
    check_code_version(code_version())
    with pytest.raises(RuntimeError, match="install the same kite_rto"):
        check_code_version("000000000000")


def _row(sc, seed, method, final, t99, held=1, low=110.0, below=0, tuning=True, budget=None):
    return RunResult(scenario=sc, tuning=tuning, h_min=100.0, seed=seed, method=method,
                     reach_index=None if t99 is None else 1, t99_s=t99, held_from=held, times_s=(0.0, 300.0),
                     percent=(90.0, final), altitude=(130.0, low), final_percent=final, lowest_altitude=low,
                     below_floor=below, flight_time_s=3000.0, experiments=30, crashes=0, budget_s=budget,
                     oracle_kn=600.0, message="", wall_s=12.5)


def test_the_summary_evaluates_the_done_when_criteria_per_subset():
    rows = [_row("a", 0, "gma", 99.5, 300.0), _row("a", 1, "gma", 99.2, 500.0, held=5),
            _row("a", 0, "nelder-mead", 99.1, 1500.0, budget=1200.0), _row("a", 1, "nelder-mead", 95.0, None),
            _row("b", 0, "gma", 98.0, 700.0, held=None, low=95.0, below=1, tuning=False),
            _row("b", 1, "gma", 99.6, 900.0, tuning=False),
            _row("b", 0, "nelder-mead", 99.3, 1400.0, tuning=False), _row("b", 1, "nelder-mead", 99.0, 1800.0,
                                                                           tuning=False)]
    text = summarize(rows, budget=4.0)
    lines = {line.split(" | ")[0].lstrip("| "): line for line in text.splitlines() if line.startswith("|")}
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
    rows = [_row("a", 0, "gma", 99.5, 300.0), replace(_row("a", 1, "gma", 99.2, 500.0), oracle_kn=601.25),
            _row("b", 0, "gma", 99.6, 900.0, tuning=False)]
    text = summarize(rows, budget=4.0, code="0123456789ab", libraries={"numpy": "2.4.6", "hipersim": "absent"})
    env = text.split("## Environment", 1)[1]
    assert "- code version 0123456789ab" in env and "- numpy 2.4.6, hipersim absent" in env
    assert "| a | 600.000, 601.250 (rows from different oracle caches) |" in env
    assert "| b | 600.000 |" in env
    assert "code version" not in summarize(rows, budget=4.0)


def test_the_summary_counts_per_seed_over_the_scenarios():
    late = replace(_row("a", 1, "gma", 99.2, 1500.0, held=3), reach_index=3)     # at 99 % from iterate 3 on
    rows = [_row("a", 0, "gma", 99.5, 300.0), _row("b", 0, "gma", 98.0, 700.0, held=None), late,
            _row("b", 1, "gma", 97.0, None, held=None), _row("a", 1, "nelder-mead", 99.1, 900.0, budget=1200.0)]
    text = summarize(rows, budget=4.0)
    assert "## gma: per seed" in text
    assert "| 0 | 2 | 2/2 | 1/2 | 1 | 500 |" in text
    assert "| 1 | 2 | 0/2 | 1/2 | 1 | never |" in text


def test_the_table_holds_every_field_but_wall_time_in_campaign_order(tmp_path):
    rows = [_row("a", 0, "gma", 99.5, 300.0), _row("a", 0, "model-only", 90.0, None, held=None, budget=1200.0)]
    rows[1] = replace(rows[1], altitude=(None,), lowest_altitude=None, percent=(0.0,), times_s=(0.0,))
    assert RunResult.from_dict(json.loads(json.dumps(rows[1].to_dict()))) == rows[1]
    write_table(tmp_path / "t.csv", rows)
    table = list(csv.DictReader(open(tmp_path / "t.csv")))
    assert tuple(table[0]) == TABLE_COLUMNS and "wall_s" not in TABLE_COLUMNS
    assert [r["method"] for r in table] == ["gma", "model-only"]
    assert json.loads(table[0]["percent"]) == [90.0, 99.5] and table[0]["budget_s"] == ""
    assert json.loads(table[1]["altitude"]) == [None] and table[1]["lowest_altitude"] == ""


def test_a_table_reads_back_as_the_rows_it_was_written_from(tmp_path):
    crash = replace(_row("a", 0, "model-only", 90.0, None, held=None, budget=1200.0), altitude=(None,),
                    lowest_altitude=None, percent=(0.0,), times_s=(0.0,), message="stopped: no lap")
    rows = [_row("a", 0, "gma", 99.5, 300.0), crash, _row("b", 3, "gma", 98.25, None, held=None, tuning=False)]
    write_table(tmp_path / "t.csv", rows)
    back = read_table(tmp_path / "t.csv")
    assert all(math.isnan(r.wall_s) for r in back)
    assert [replace(r, wall_s=w.wall_s) for r, w in zip(back, rows)] == rows
    assert summarize(back, budget=4.0) == summarize(rows, budget=4.0)
    text = (tmp_path / "t.csv").read_text().replace(",98.25,", ",98.x,")
    (tmp_path / "bad.csv").write_text(text)
    with pytest.raises(ValueError, match=r"bad.csv, line 4, column final_percent = '98.x'"):
        read_table(tmp_path / "bad.csv")
    (tmp_path / "cols.csv").write_text("scenario,seed\na,0\n")
    with pytest.raises(ValueError, match="columns"):
        read_table(tmp_path / "cols.csv")


def test_campaign_summary_merges_tables_and_refuses_a_run_in_two(tmp_path, capsys):
    write_table(tmp_path / "a.csv", [_row("a", 0, "gma", 99.5, 300.0), _row("a", 0, "bayes-opt", 99.1, 600.0)])
    write_table(tmp_path / "b.csv", [_row("a", 1, "gma", 99.2, 500.0), _row("a", 1, "bayes-opt", 98.0, None)])
    assert campaign_summary.main([str(tmp_path / "a.csv"), str(tmp_path / "b.csv"), "--out",
                                  str(tmp_path / "s.md")]) == 0
    text = (tmp_path / "s.md").read_text()
    assert "| a | yes | 100 | 2 | 99.20 | 99.35 | 0 | 110.0 | 2/2 | 400 |" in text
    assert "| bayes-opt | 2 | 0 | 1 | 0 | 1 |" in text             # per-seed ratios 600 / 300 = 2 and not reached
    capsys.readouterr()
    assert campaign_summary.main([str(tmp_path / "a.csv"), str(tmp_path / "a.csv")]) == 2
    err = capsys.readouterr().err
    assert "scenario 'a', seed 0, method 'gma' is in both" in err and "a.csv" in err
    assert campaign_summary.main([str(tmp_path / "missing.csv")]) == 2


@pytest.mark.slow
def test_kite_campaign_end_to_end_and_from_its_cache(tmp_path, capsys):
    args = ["--scenarios", "default", "--seeds", "1", "--methods", "gma,model-only", "--iters", "1", "--workers",
            "1", "--cache-dir", str(tmp_path / "cache"), "--no-progress"]
    assert cli.main(args + ["--out", str(tmp_path / "one")]) == 0
    first = capsys.readouterr().out
    assert "2 results (3 tasks run now), 0 failed" in first
    table = list(csv.DictReader(open(tmp_path / "one" / "results.csv")))
    assert [(r["scenario"], r["seed"], r["method"]) for r in table] == [("default", "0", "gma"),
                                                                          ("default", "0", "model-only")]
    gma, mo = table
    assert len(json.loads(gma["percent"])) == 2
    assert int(gma["experiments"]) == KiteRTOSettings().experiments_per_iteration()   # nominal + 3 directions
    assert json.loads(gma["percent"])[0] == json.loads(mo["percent"])[0]         # both start at the model optimum
    assert float(mo["budget_s"]) == 4.0 * (float(gma["t99_s"]) if gma["t99_s"] else float(gma["flight_time_s"]))
    assert math.isclose(float(gma["final_percent"]), json.loads(gma["percent"])[-1])
    for name in ("summary.md", "campaign.png", "wall.csv"):
        assert (tmp_path / "one" / name).stat().st_size > 0
    assert sorted(p.name for p in (tmp_path / "cache").iterdir()) == sorted(
        f"{t.key}.json" for t in cli.build_campaign(cli._parser().parse_args(args)).tasks() if t.store)
    assert cli.main(args + ["--out", str(tmp_path / "two")]) == 0
    assert "2 results (0 tasks run now), 0 failed" in capsys.readouterr().out
    assert (tmp_path / "two" / "results.csv").read_bytes() == (tmp_path / "one" / "results.csv").read_bytes()
