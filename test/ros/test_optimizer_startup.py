"""The optimizer answers its services and says what it is building from the first second of its start-up.

The start-up work is held on an event the test controls (not timed), so the verdict does not depend on how fast the
machine builds: while GMA is being made, ``get_parameters`` answers, ``/rto/status`` says ``starting: ...`` and no
setpoints are out; once released, the first setpoints follow. GMA's NLPs are created lazily: ahead of need on a
worker thread, or on first use by whichever thread needs them first, exactly once.
"""
import threading

import pytest
from diagnostic_msgs.msg import DiagnosticArray
from rcl_interfaces.srv import GetParameters
from rclpy.parameter import Parameter
from sensor_msgs.msg import JointState

import kite_rto.nodes.optimizer_node as optimizer_node
from kite_rto.gma import GMA
from kite_rto.nodes.interface import LATCHED, RELIABLE_10
from kite_rto.rto.builder import make_gma
from kite_rto.rto.settings import KiteRTOSettings

from rosutil import Probe

pytestmark = pytest.mark.ros


def test_parameters_and_status_answer_while_the_optimizer_builds(tmp_path, monkeypatch):
    release, building = threading.Event(), threading.Event()

    def held_make_gma(*args, **kwargs):
        building.set()
        assert release.wait(300), "the test never released the start-up"
        return make_gma(*args, **kwargs)

    monkeypatch.setattr(optimizer_node, "make_gma", held_make_gma)
    probe = Probe("startup_probe")
    phases, setpoints = [], []
    probe.node.create_subscription(DiagnosticArray, "/rto/status", lambda m: phases.append(m.status[0].message),
                                   RELIABLE_10)
    probe.node.create_subscription(JointState, "/rto/setpoints", setpoints.append, LATCHED)
    client = probe.node.create_client(GetParameters, "/optimizer/get_parameters")
    node = optimizer_node.OptimizerNode(parameter_overrides=_overrides(db=str(tmp_path / "rto.sqlite")))
    probe.executor.add_node(node)
    try:
        assert building.wait(300)
        assert probe.spin_until(client.service_is_ready, 60.0)
        future = client.call_async(GetParameters.Request(names=["n_iter", "db"]))
        assert probe.spin_until(future.done, 60.0), "get_parameters did not answer during the start-up"
        assert [v.integer_value for v in future.result().values[:1]] == [10]
        assert probe.spin_until(lambda: any(p.startswith("starting") for p in phases), 60.0)
        assert not setpoints and node.run is None
        assert all(p.startswith("starting") for p in phases), phases
        release.set()
        assert probe.spin_until(lambda: setpoints, 300.0), "no setpoints after the start-up was released"
        assert node.run is not None
        assert node.wait_until_started(0)
    finally:
        release.set()
        node._builder.join(300)     # its NLP build must not overlap the next test's CasADi work (not thread-safe)
        probe.executor.remove_node(node)
        node.destroy_node()
    try:        # destroyed, it leaves no lifecycle service behind for a later optimizer's clients to find
        lifecycle = {"/optimizer/get_state", "/optimizer/change_state"}
        assert probe.spin_until(lambda: not lifecycle & {s for s, _ in probe.node.get_service_names_and_types()},
                                60.0), "the destroyed optimizer left its lifecycle services on the graph"
    finally:
        probe.close()


def _overrides(**values):
    return [Parameter(k, value=v) for k, v in values.items()]


def test_gma_creates_its_nlps_once_on_first_use():
    gma = make_gma(KiteRTOSettings())
    assert isinstance(gma, GMA) and not gma._nlps.built, "the NLPs were built before anything needed them"
    first = gma.next_request()                     # the first experiment needs no NLP
    assert first is not None and not gma._nlps.built
    got = []
    threads = [threading.Thread(target=lambda: got.append((gma.realization_nlp, gma.modified_nlp)))
               for _ in range(3)]
    for t in threads:
        t.start()
    gma.prepare()
    for t in threads:
        t.join()
    assert gma._nlps.built
    assert all(r is gma.realization_nlp and m is gma.modified_nlp for r, m in got)
