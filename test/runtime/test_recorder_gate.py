"""The lockstep plant's wait for lossless recorders (kite_rto.runtime.recorder_gate), on a counted clock."""
from kite_rto.runtime.recorder_gate import WINDOW_SAMPLES, RecorderGate

from storage_flight import Log

DT = 20_000_000                 # ns per sample
W = WINDOW_SAMPLES * DT


def gate(timeout=10.0, present=("/rec",)):
    t = [0.0]
    g = RecorderGate(W, timeout, clock=lambda: t[0], log=Log(), recorders=lambda: set(present))
    return g, t


def test_without_a_recorder_every_sample_goes():
    g, _ = gate()
    assert all(g.may_publish(k * DT) for k in range(0, 10 * WINDOW_SAMPLES, 97)) and g.waits == 0


def test_a_sample_waits_until_the_recorder_is_within_the_window():
    g, t = gate()
    g.ack("/rec", 0, 0)
    assert g.may_publish(W)                                   # exactly one window ahead: goes
    assert not g.may_publish(W + DT) and g.waits == 1         # one sample more: waits
    t[0] = 9.0
    assert not g.may_publish(W + DT)                          # still within the timeout: waits, however long
    g.ack("/rec", DT, W)
    assert g.may_publish(W + DT) and g.waits == 1 and not g.log.lines


def test_the_slowest_of_several_recorders_sets_the_pace():
    g, _ = gate(present=("/a", "/b"))
    g.ack("/a", 5 * W, 0)
    g.ack("/b", 0, 0)
    assert not g.may_publish(W + DT)
    g.ack("/b", W, 0)
    assert g.may_publish(2 * W)


def test_a_recorder_that_left_the_graph_is_not_waited_for():
    present = {"/rec"}
    g = RecorderGate(W, 10.0, clock=lambda: 0.0, log=Log(), recorders=lambda: set(present))
    g.ack("/rec", 0, 0)
    assert not g.may_publish(2 * W)
    present.clear()
    assert g.may_publish(2 * W) and "/rec" not in g.acked
    assert g.log.lines == [("info", "lossless recorder /rec left the graph: not waited for any more")]


def test_a_stopped_recorder_is_left_behind_after_the_timeout_and_waited_for_again_once_caught_up():
    g, t = gate(timeout=30.0)
    g.ack("/rec", 0, 0)
    assert not g.may_publish(2 * W)
    t[0] = 29.9
    assert not g.may_publish(2 * W)
    t[0] = 30.0
    assert g.may_publish(2 * W)                               # the loop goes on without it, and says so
    kind, text = g.log.lines[-1]
    assert kind == "warning" and "/rec" in text and "after 30 s of waiting" in text and "going on" in text
    assert g.may_publish(5 * W)                               # not waited for while it is behind
    g.ack("/rec", 5 * W - DT, 5 * W)                          # caught up: waited for again
    assert "caught up" in g.log.lines[-1][1]
    t[0] = 31.0
    assert not g.may_publish(6 * W + DT)
