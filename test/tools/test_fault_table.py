"""kite_rto.testing.fault_table: the table of the fault rows, written where the command runs (never next to the
installed package)."""
import json

from kite_rto.testing.fault_table import main

ROW = {"fault": "bad parameter: negative tether length", "injection": "plant --ros-args -p r:=-5.0",
       "outcome": "exit 2", "experiments_lost": 0, "unsafe_setpoints": 0, "passed": True}


def test_table_is_written_to_docs_in_the_working_directory(tmp_path, monkeypatch, capsys):
    rows = tmp_path / "rows"
    rows.mkdir()
    (rows / "test_fault_params.jsonl").write_text(json.dumps(ROW) + "\n")
    (tmp_path / "docs").mkdir()
    monkeypatch.chdir(tmp_path)
    assert main([str(rows), "--wall", "12"]) == 0
    text = (tmp_path / "docs" / "faults.md").read_text()
    assert "| bad parameter: negative tether length | plant --ros-args -p r:=-5.0 | exit 2 | 0 | 0 | yes |" in text
    assert "Result: 1 faults, 1 passed; experiments lost: 0; unsafe setpoints: 0." in text
    assert "wrote docs/faults.md" in capsys.readouterr().out


def test_a_failed_row_fails_the_command_and_is_marked(tmp_path, capsys):
    rows = tmp_path / "rows"
    rows.mkdir()
    (rows / "test_fault_nodes.jsonl").write_text(json.dumps({**ROW, "passed": False, "experiments_lost": 1}) + "\n")
    assert main([str(rows), "--no-write"]) == 1
    out = capsys.readouterr().out
    assert "| **NO** |" in out and "experiments lost: 1" in out
