"""``kite_report`` judges a run against its own plant and floor: the ones stored with it (in the optimizer's database
or in a recording), not the defaults."""
from dataclasses import replace
from types import SimpleNamespace

import numpy as np
import pytest
from diagnostic_msgs.msg import DiagnosticArray, DiagnosticStatus, KeyValue
from rclpy.serialization import serialize_message
from sensor_msgs.msg import JointState
from std_msgs.msg import String

from kite_rto.flight.shape import ShapeBox
from kite_rto.gma import History, HistoryStore
from kite_rto.kite.plant import PLANT_PARAMS, PlantConfig
from kite_rto.nodes import topics as T
from kite_rto.rto import judge as judge_module
from kite_rto.rto.experiment import ExperimentSpec
from kite_rto.rto.run import RUN_KEY, RunDescription
from kite_rto.rto.settings import KiteRTOSettings
from kite_rto.tools import rto_report
from kite_rto.tools.record import RUN_METADATA, TOPICS, McapRecording

PLANT = PlantConfig(params=replace(PLANT_PARAMS, w_ref=9.0))
RUN = RunDescription(KiteRTOSettings(experiment=ExperimentSpec(h_min=115.0)), PLANT)


@pytest.fixture
def judged(monkeypatch):
    """The oracle's and the judge's calls, answered without flying: every point 112 m low, 600 kN."""
    seen = {"oracle": [], "plant": []}

    def oracle(config, box, *, h_min, **kw):
        seen["oracle"].append((config, box, h_min))
        return SimpleNamespace(c=np.zeros(3), c_deg=[0.0] * 3, tension_kn=600.0, min_altitude=115.0, evaluations=1)

    def performance(config, c):
        seen["plant"].append(config)
        return 600.0, 112.0
    monkeypatch.setattr(rto_report, "find_oracle", oracle)
    monkeypatch.setattr(judge_module, "plant_performance", performance)
    return seen


def _database(path, run):
    store = HistoryStore(path)
    box = run.settings.box
    store.save_history(History(c0=0.5 * (box.lower() + box.upper()), meta={} if run is None else {RUN_KEY: run.to_dict()}))
    store.close()


def test_a_run_with_another_plant_and_floor_is_judged_against_them(judged, tmp_path):
    _database(tmp_path / "rto.sqlite", RUN)
    assert rto_report.main(["--db", str(tmp_path / "rto.sqlite"), "--out", str(tmp_path / "report")]) == 0
    assert judged["oracle"] == [(PLANT, RUN.settings.box, 115.0)]
    assert judged["plant"] and all(p == PLANT for p in judged["plant"])
    summary = (tmp_path / "report" / "summary.json").read_text()
    assert '"feasible": false' in summary          # 112 m is below 115 - 2, though above the default 100 - 2


def test_a_run_whose_plant_is_not_stored_is_not_judged(judged, tmp_path, capsys):
    _database(tmp_path / "rto.sqlite", replace(RUN, plant=None))
    assert rto_report.main(["--db", str(tmp_path / "rto.sqlite"), "--out", str(tmp_path / "report")]) == 0
    assert judged["oracle"] == [] and judged["plant"] == []
    assert "not judged: the run's plant is not stored with it" in capsys.readouterr().out


def test_the_description_round_trips_and_names_bad_fields():
    assert RunDescription.from_json(RUN.to_json()) == RUN
    assert RUN.h_min == 115.0 and RunDescription(KiteRTOSettings()).plant is None
    with pytest.raises(ValueError, match=r"KiteRTOSettings: unknown fields \['altitude'\]"):
        RunDescription.from_dict({"settings": {"altitude": "lap"}})
    with pytest.raises(ValueError, match="RunDescription.plant = 'x': expected a PlantConfig or None"):
        RunDescription(KiteRTOSettings(), "x")
    assert ShapeBox() == RUN.settings.box


def _recording(path, run_message=None, run_metadata=None):
    """A recording of one finished iteration as the optimizer publishes it, with the run's description on /rto/run
    and/or in the recorder's metadata record."""
    rec = McapRecording(path)
    for topic in (T.SETPOINTS, T.STATUS, T.RUN):
        rec.add_topic(topic, *TOPICS[topic])
    c = np.radians([[30.0, 42.0, 6.5], [31.0, 44.0, 6.8]])
    rec.write(T.SETPOINTS, serialize_message(JointState(name=["theta_0", "A_phi", "A_theta"], position=list(c[0]))), 1)
    if run_message is not None:
        rec.write(T.RUN, serialize_message(String(data=run_message.to_json())), 2)
    kv = {"iteration": "1", "experiments_done": "2", "experiment": "k1-0-nominal", "measured_cost_kN": "-560.00",
          "measured_constraint_m": "-3.00", "decision": "step",
          "c_next_deg": "(" + ", ".join(f"{v:.2f}" for v in np.degrees(c[1])) + ") deg"}
    st = DiagnosticStatus(name="kite_rto/optimizer", values=[KeyValue(key=k, value=v) for k, v in kv.items()])
    rec.write(T.STATUS, serialize_message(DiagnosticArray(status=[st])), 3)
    if run_metadata is not None:
        rec.add_metadata(RUN_METADATA, {"description": run_metadata.to_json()})
    rec.close()


@pytest.mark.parametrize("where", ["metadata", "message", "both"])
def test_a_recording_is_judged_against_its_own_run(judged, tmp_path, where):
    """The description in the recorder's metadata record, or else on the last /rto/run message (an older message
    that a metadata record contradicts loses)."""
    other = replace(RUN, plant=PlantConfig())
    _recording(tmp_path / "run.mcap", run_message={"metadata": None, "message": RUN, "both": other}[where],
               run_metadata={"metadata": RUN, "message": None, "both": RUN}[where])
    assert rto_report.report_from_mcap(tmp_path / "run.mcap", tmp_path / "report") == 0
    assert judged["oracle"] == [(PLANT, RUN.settings.box, 115.0)]
    assert judged["plant"] and all(p == PLANT for p in judged["plant"])


def test_a_recording_without_a_description_is_not_judged(judged, tmp_path, capsys):
    _recording(tmp_path / "run.mcap")
    assert rto_report.report_from_mcap(tmp_path / "run.mcap", tmp_path / "report") == 0
    assert judged["oracle"] == [] and judged["plant"] == []
    assert "not judged: the run's description is not stored with it" in capsys.readouterr().out

