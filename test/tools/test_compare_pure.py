"""kite_rto.tools.compare_pure: a database the pure runner wrote compares equal; a changed cost or gradient does
not."""
import numpy as np

from kite_rto.rto.runner import run_rto
from kite_rto.kite.plant import PlantConfig
from kite_rto.gma import HistoryStore
from kite_rto.tools.compare_pure import compare_histories, main


def test_pure_database_compares_identical_and_a_changed_cost_is_found(tmp_path, capsys):
    res = run_rto(PlantConfig(), seed=2, n_iter=1)
    db = tmp_path / "rto.sqlite"
    store = HistoryStore(str(db))
    store.save_history(res.history)
    store.close()
    assert main(["--db", str(db), "--seed", "2"]) == 0
    assert "bit for bit: 4 experiments" in capsys.readouterr().out     # one iteration: nominal + 3 directions
    other = HistoryStore(str(db)).load()
    other.experiments[1][1].cost = float(np.nextafter(other.experiments[1][1].cost, 0.0))   # one ulp
    diff = compare_histories(other, res.history)
    assert diff == [f"experiment k0-1-perturbation: result.cost: graph {other.experiments[1][1].cost!r}, "
                    f"pure {res.history.experiments[1][1].cost!r}"]
    other.iterations[0].grad_cost[2] += 1e-12                               # a field compare_pure never printed
    assert compare_histories(other, res.history)[1].startswith("iteration 0.grad_cost[2]: graph")
    assert main(["--db", str(tmp_path / "missing.sqlite")]) == 2
