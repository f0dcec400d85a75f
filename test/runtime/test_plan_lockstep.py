"""The plan handshake (kite_rto.runtime.plan) end to end without DDS: the controller waits only where a decision is
due, the optimizer works behind it at its own pace, and the graph flies the pure runner's run bit for bit."""
import numpy as np
import pytest

from kite_rto.kite.plant import PlantConfig
from kite_rto.rto.experiment import ExperimentSpec
from kite_rto.rto.runner import run_rto
from kite_rto.rto.settings import KiteRTOSettings
from kite_rto.runtime.plan import MAX_LEAD, PROGRESS_EVERY
from kite_rto.tools.compare_pure import compare_histories

from lockstep_graph import LockstepGraph

SETTINGS = KiteRTOSettings(experiment=ExperimentSpec(n_laps=1, settle_laps=0))


@pytest.mark.parametrize("pace", [0, 1], ids=["optimizer-keeps-up", "optimizer-behind"])
def test_lockstep_graph_flies_the_pure_runners_run(tmp_path, pace):
    config = PlantConfig()
    graph = LockstepGraph(tmp_path / "rto.sqlite", SETTINGS, config, seed=3, n_iter=1, pace=pace).fly()
    pure = run_rto(config, seed=3, n_iter=1, settings=SETTINGS)
    diffs = compare_histories(graph.gma.history, pure.history)
    assert not diffs, diffs[:20]
    np.testing.assert_array_equal([e.outcome.cost for e in graph.run.session.experiments],
                                  [e.outcome.cost for e in pure.experiments])
    samples = graph.plant.k
    n_exp = len(pure.experiments)
    assert graph.sync_messages < samples / 50, (graph.sync_messages, samples)   # not one per sample
    assert graph.sync_messages >= n_exp
    assert graph.log.text("warning") == "" and graph.opt_log.text("warning") == ""
    if pace:            # fell behind as far as the controller lets it (the last report at most PROGRESS_EVERY back)
        assert MAX_LEAD - PROGRESS_EVERY < graph.max_backlog <= MAX_LEAD + 1, graph.max_backlog
