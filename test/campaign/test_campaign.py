"""The scenario campaign: task keys, variants and the results table (fast, no flight), and one slow end-to-end run of
``kite_campaign`` (one scenario, one seed, model-only and GMA with one iteration). The summary:
test_campaign_summary.py."""
import csv
import json
import math
from dataclasses import replace

import pytest

from kite_rto.campaign.plan import Campaign
from kite_rto.campaign.results import OPTIONAL_COLUMNS, TABLE_COLUMNS, RunResult, write_table
from kite_rto.campaign.tables import read_table
from kite_rto.campaign.scenarios import scenario
from kite_rto.campaign.summary import summarize
from kite_rto.campaign.tasks import baseline_budget
from kite_rto.campaign.variants import parse_variant
from kite_rto.campaign.version import check_code_version, code_version
from kite_rto.rto.settings import KiteRTOSettings
from kite_rto.tools import campaign as cli
from kite_rto.tools import campaign_summary

from campaign_rows import plan_of_rows, row

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
    name, s = parse_variant("v=fd_step=(0.3, 0.3, 0.3),gma.trust_region.radius=0.4,gradient=central")
    assert name == "v" and s.fd_step == (0.3, 0.3, 0.3) and s.gma.trust_region.radius == 0.4
    assert s.gma.trust_region.min_radius == KiteRTOSettings().gma.trust_region.min_radius
    assert s.gradient == "central" and s.gma.backoff == KiteRTOSettings().gma.backoff
    off = parse_variant("v=gma.undo=None,gma.model_secant=None")[1].gma
    assert off.undo is None and off.model_secant is None and off.bound_hold is not None
    on = parse_variant("v=gma.undo.sigma=2.5", replace(KiteRTOSettings(), gma=off))[1].gma
    assert on.undo.sigma == 2.5                     # a mechanism that was off: on with its defaults, then changed
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


def test_the_table_holds_every_field_but_wall_time_in_campaign_order(tmp_path):
    rows = [row("a", 0, "gma", 99.5, 300.0), row("a", 0, "model-only", 90.0, None, held=None, budget=1200.0)]
    rows[1] = replace(rows[1], altitude=(None,), lowest_altitude=None, percent=(0.0,), times_s=(0.0,))
    assert RunResult.from_dict(json.loads(json.dumps(rows[1].to_dict()))) == rows[1]
    write_table(tmp_path / "t.csv", rows)
    table = list(csv.DictReader(open(tmp_path / "t.csv")))
    # without fixed flights, the table it always was; with them, the yield columns too
    assert tuple(table[0]) == tuple(c for c in TABLE_COLUMNS if c not in OPTIONAL_COLUMNS)
    assert "wall_s" not in TABLE_COLUMNS and TABLE_COLUMNS[-2:] == OPTIONAL_COLUMNS
    flights = [replace(r, yield_percent=98.5 - i, below_floor_s=0.0) for i, r in enumerate(rows)]
    write_table(tmp_path / "f.csv", flights)
    assert tuple(next(csv.reader(open(tmp_path / "f.csv")))) == TABLE_COLUMNS
    assert [(r.yield_percent, r.below_floor_s) for r in read_table(tmp_path / "f.csv")] == [(98.5, 0.0), (97.5, 0.0)]
    assert [r["method"] for r in table] == ["gma", "model-only"]
    assert json.loads(table[0]["percent"]) == [90.0, 99.5] and table[0]["budget_s"] == ""
    assert json.loads(table[1]["altitude"]) == [None] and table[1]["lowest_altitude"] == ""
    assert table[0]["code_version"] == "0123456789ab"                 # each row names the code it was computed with


def test_a_table_reads_back_as_the_rows_it_was_written_from(tmp_path):
    crash = replace(row("a", 0, "model-only", 90.0, None, held=None, budget=1200.0), altitude=(None,),
                    lowest_altitude=None, percent=(0.0,), times_s=(0.0,), message="stopped: no lap")
    rows = [row("a", 0, "gma", 99.5, 300.0), crash, row("b", 3, "gma", 98.25, None, held=None, tuning=False)]
    write_table(tmp_path / "t.csv", rows)
    back = read_table(tmp_path / "t.csv")
    assert all(math.isnan(r.wall_s) for r in back)
    assert [replace(r, wall_s=w.wall_s) for r, w in zip(back, rows)] == rows
    assert summarize(back, plan_of_rows(rows)) == summarize(rows, plan_of_rows(rows))
    text = (tmp_path / "t.csv").read_text().replace(",98.25,", ",98.x,")
    (tmp_path / "bad.csv").write_text(text)
    with pytest.raises(ValueError, match=r"bad.csv, line 4, column final_percent = '98.x'"):
        read_table(tmp_path / "bad.csv")
    (tmp_path / "cols.csv").write_text("scenario,seed\na,0\n")
    with pytest.raises(ValueError, match="columns") as refused:
        read_table(tmp_path / "cols.csv")
    assert "without code_version" not in str(refused.value)
    with open(tmp_path / "t.csv") as f:                                  # a table from before the code_version column
        old = [",".join(line.rstrip("\n").split(",")[:-1]) for line in f]
    (tmp_path / "old.csv").write_text("\n".join(old) + "\n")
    with pytest.raises(ValueError, match="without code_version it cannot name the code"):
        read_table(tmp_path / "old.csv")


@pytest.mark.slow
def test_kite_campaign_end_to_end_and_from_its_cache(tmp_path, capsys):
    args = ["--scenarios", "default", "--seeds", "1", "--methods", "gma,model-only", "--iters", "1", "--workers",
            "1", "--cache-dir", str(tmp_path / "cache"), "--no-progress"]
    assert cli.main(args + ["--out", str(tmp_path / "one")]) == 0
    first = capsys.readouterr().out
    assert "2 of 2 planned results (3 tasks run now), 0 tasks failed (0 of the table's runs)" in first
    table = list(csv.DictReader(open(tmp_path / "one" / "results.csv")))
    assert [(r["scenario"], r["seed"], r["method"]) for r in table] == [("default", "0", "gma"),
                                                                          ("default", "0", "model-only")]
    gma, mo = table
    assert len(json.loads(gma["percent"])) == 2
    assert int(gma["experiments"]) == KiteRTOSettings().experiments_per_iteration()   # nominal + 3 directions
    assert json.loads(gma["percent"])[0] == json.loads(mo["percent"])[0]         # both start at the model optimum
    assert float(mo["budget_s"]) == 4.0 * (float(gma["t99_s"]) if gma["t99_s"] else float(gma["flight_time_s"]))
    assert math.isclose(float(gma["final_percent"]), json.loads(gma["percent"])[-1])
    assert {r["code_version"] for r in table} == {code_version()}
    for name in ("summary.md", "campaign.png", "wall.csv"):
        assert (tmp_path / "one" / name).stat().st_size > 0
    summary = (tmp_path / "one" / "summary.md").read_text()
    assert summary.startswith(f"# Scenario campaign: 1 scenarios x 1 seeds, methods gma, model-only; all 2 planned "
                              f"runs present, code version {code_version()}\n")
    assert campaign_summary.main([str(tmp_path / "one" / "results.csv"), "--out", str(tmp_path / "again.md")]) == 0
    assert (tmp_path / "again.md").read_bytes() == (tmp_path / "one" / "summary.md").read_bytes()
    assert sorted(p.name for p in (tmp_path / "cache").iterdir()) == sorted(
        f"{t.key}.json" for t in cli.build_campaign(cli._parser().parse_args(args)).tasks() if t.store)
    assert cli.main(args + ["--out", str(tmp_path / "two")]) == 0
    assert "2 of 2 planned results (0 tasks run now), 0 tasks failed" in capsys.readouterr().out
    for name in ("results.csv", "results.manifest.json", "summary.md"):
        assert (tmp_path / "two" / name).read_bytes() == (tmp_path / "one" / name).read_bytes()
