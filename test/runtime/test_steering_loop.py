"""SteeringLoop without DDS: the controller node's join, timeline, restart and optimizer sync, on a fake clock."""
import math
import re
from types import SimpleNamespace

import numpy as np
import pytest

from kite_rto.flight.controller import ControllerSettings, PathController
from kite_rto.flight.path import DEFAULT_SETPOINTS, Setpoints
from kite_rto.runtime.plan import Mode, Plan
from kite_rto.runtime.sample_join import Place, Timeline
from kite_rto.runtime.setpoint_inbox import SUMMARY_PERIOD
from kite_rto.runtime.sources import SOURCE_QUIET, Publisher, SourceWatch, node_name, parse_source
from kite_rto.runtime.steering_loop import (PATH_PERIOD, PLANT_QUIET, SETPOINTS_WAIT, SYNC_ABSENT, SYNC_NAMES,
                                           SteeringLoop)
from kite_rto.kite.params import ParameterError
from kite_rto.kite.params import KiteParams
from kite_rto.kite.model import shared_model
from kite_rto.kite.plant import KitePlant, PlantConfig

DT_NS = 20_000_000
NAMES = ["theta", "phi", "psi"]
NEW = Setpoints.from_degrees(33.0, 46.0, 7.0).as_array().tolist()


class Log:
    """Logger stand-in: keeps (level, text)."""

    def __init__(self):
        self.lines = []

    def info(self, text, **_):
        self.lines.append(("info", text))

    def warning(self, text, **_):
        self.lines.append(("warning", text))

    def count(self, needle):
        return sum(needle in text for _, text in self.lines)


class Rig:
    """A SteeringLoop with recorded answers, a fake wall clock, and plant samples to feed it."""

    def __init__(self, sync=False, optimizer=True, **kwargs):
        self.now = 100.0
        self.answers, self.log, self.paths = [], Log(), []
        self.optimizer_alive = int(optimizer)          # publishers of /rto/sync in the graph
        self.plants = 1                                # publishers of /kite/state in the graph
        self.loop = SteeringLoop(KiteParams(), ControllerSettings(), DEFAULT_SETPOINTS,
                                 answer=lambda s, d: self.answers.append((s, d)), lap=lambda s, lap: None,
                                 path=lambda: self.paths.append(self.loop.controller.setpoints),
                                 logger=self.log, sync=sync, setpoint_sources=lambda: int(optimizer),
                                 sync_sources=lambda: self.optimizer_alive, state_sources=lambda: self.plants,
                                 clock=lambda: self.now, **kwargs)
        self.plant = KitePlant(PlantConfig(), seed=0)
        self.samples = []
        for _ in range(40):
            self.samples.append(self.plant.measure())
            self.plant.step(0.0)
        self.now += SETPOINTS_WAIT                     # past the start-up wait for setpoints

    def state(self, k, stamp=None):
        m = self.samples[k]
        self.loop.state_sample(k * DT_NS if stamp is None else stamp, NAMES, [m.theta, m.phi, m.psi],
                               [m.theta_dot, m.phi_dot, m.psi_dot])

    def wind(self, k, stamp=None):
        self.loop.wind_reading(k * DT_NS if stamp is None else stamp, self.samples[k].wind_ref)

    def sample(self, k, stamp=None):
        self.wind(k, stamp)
        self.state(k, stamp)

    def reference(self, ks, c=DEFAULT_SETPOINTS):
        """Commands of a fresh PathController fed samples ``ks`` (the pure runner's answers)."""
        ctrl = PathController(shared_model(), KiteParams(), c, ControllerSettings())
        out = []
        for i, k in enumerate(ks):
            m = self.samples[k]
            out.append(ctrl.command(_meas(i * DT_NS, m)))
        return out


def _meas(stamp, m, wind_ref=None):
    """The controller's measurement of plant sample ``m`` stamped ``stamp`` (ns)."""
    return SimpleNamespace(t=stamp * 1e-9, theta=m.theta, phi=m.phi, psi=m.psi, theta_dot=m.theta_dot,
                           phi_dot=m.phi_dot, psi_dot=m.psi_dot, wind_ref=m.wind_ref if wind_ref is None else wind_ref)


def test_in_order_samples_are_answered_like_the_pure_controller():
    rig = Rig()
    for k in range(10):
        rig.sample(k)
    assert [s for s, _ in rig.answers] == [k * DT_NS for k in range(10)]
    assert [d for _, d in rig.answers] == rig.reference(range(10))         # bit for bit
    rig.state(9)                                                            # re-published: the same answer
    assert rig.answers[-1] == rig.answers[-2] and len(rig.answers) == 11
    assert not rig.loop.reject.counts


def test_waits_during_start_up_for_setpoints():
    rig = Rig()
    rig.now -= SETPOINTS_WAIT                                               # just started, optimizer known
    rig.sample(0)
    assert rig.answers == [] and rig.log.count("waiting for the setpoints") == 1
    rig.loop.setpoints_message(["theta_0", "A_phi", "A_theta"], NEW)
    rig.sample(0)
    assert len(rig.answers) == 1 and rig.loop.controller.setpoints.as_array().tolist() == NEW


def test_a_sample_waits_for_the_anemometer_reading_of_its_stamp():
    rig = Rig()
    rig.sample(0)
    rig.state(1)                                        # state before its wind reading: not answered yet
    assert len(rig.answers) == 1
    rig.wind(1)
    assert [s for s, _ in rig.answers] == [0, DT_NS]
    rig.state(2)                                        # its wind reading is lost ...
    rig.sample(3)                                       # ... the next sample releases it with the previous reading
    assert [s for s, _ in rig.answers] == [0, DT_NS, 2 * DT_NS, 3 * DT_NS]
    ref = PathController(shared_model(), KiteParams(), DEFAULT_SETPOINTS, ControllerSettings())
    winds = [rig.samples[0].wind_ref, rig.samples[1].wind_ref, rig.samples[1].wind_ref, rig.samples[3].wind_ref]
    expected = [ref.command(_meas(k * DT_NS, rig.samples[k], w)) for k, w in enumerate(winds)]
    assert [d for _, d in rig.answers] == expected


def test_restart_is_accepted_only_when_continued():
    rig = Rig()
    for k in range(10):
        rig.sample(k)
    flying = rig.loop.controller
    rig.sample(0, stamp=2 * DT_NS)                      # stamped before the last sample: a candidate only
    assert rig.answers[-1][0] == 2 * DT_NS              # answered (a restarted lockstep plant waits for it) ...
    assert rig.loop.controller is flying                # ... by a fresh controller, not the flying one
    rig.sample(10)                                      # the old timeline goes on: the candidate was junk
    assert rig.loop.controller is flying and rig.log.count("jumped back") == 0
    assert rig.loop.reject.counts == {"state stamp": 1}
    assert [d for _, d in rig.answers[:10]] + [rig.answers[11][1]] == rig.reference(range(11))
    rig.sample(0, stamp=0)                              # a restarted plant's first sample ...
    fresh_answer = rig.answers[-1]
    rig.sample(0, stamp=0)                              # ... re-published: the same answer
    assert rig.answers[-1] == fresh_answer
    rig.sample(1, stamp=DT_NS)                          # ... and its second: the restart is confirmed
    assert rig.loop.controller is not flying and rig.log.count("jumped back") == 1
    assert rig.loop.timeline.last == DT_NS
    assert [fresh_answer[1], rig.answers[-1][1]] == rig.reference([0, 1])   # the new plant, a new controller


def test_junk_off_the_timeline_is_rejected():
    rig = Rig()
    for k in range(5):
        rig.sample(k)
    rig.state(0, stamp=300 * 10**9)                     # future state, no wind with its stamp
    rig.sample(5)                                       # the timeline goes on: rejected
    assert rig.loop.reject.counts == {"state stamp": 1}
    rig.sample(0, stamp=400 * 10**9)                    # complete future sample: a candidate, not answered
    assert rig.answers[-1][0] == 5 * DT_NS
    rig.sample(6)
    assert rig.loop.reject.counts == {"state stamp": 2} and rig.log.count("jumped forward") == 0
    rig.loop.tension_reading(6 * DT_NS + 2 * 10**9, 5e5)   # readings far from the timeline are rejected
    rig.loop.position_reading(500 * 10**9, (300.0, 0.0, 200.0))
    rig.loop.wind_reading(7 * DT_NS, math.nan)
    assert rig.loop.reject.counts == {"state stamp": 2, "tension stamp": 1, "position stamp": 1, "wind": 1}
    assert [s for s, _ in rig.answers] == [k * DT_NS for k in range(7)]
    assert [d for _, d in rig.answers] == rig.reference(range(7))


def test_lost_samples_move_the_timeline_forward_when_continued():
    rig = Rig()
    rig.sample(0)
    far = 5 * 10**9
    rig.sample(1, stamp=far)                            # a complete sample 5 s on: a candidate
    rig.sample(2, stamp=far + DT_NS)                    # continued: samples were lost
    assert rig.log.count("jumped forward") == 1 and rig.loop.timeline.last == far + DT_NS
    assert [s for s, _ in rig.answers] == [0, far + DT_NS]


def plan(c, updates, number, mode=Mode.EACH, max_duration=0.0):
    """A /rto/sync message's values: the plan ``number`` with setpoints ``c`` (an experiment plan ends after
    ``max_duration`` s, flying no lap in these 40 samples)."""
    end = (1, 0.0, 0, max_duration) if mode is Mode.EXPERIMENT else ()
    return Plan(tuple(c), updates, number, mode, *end).values()


def test_sync_applies_the_optimizer_setpoints_at_the_stamped_sample():
    rig = Rig(sync=True)
    rig.loop.setpoints_message(["theta_0", "A_phi", "A_theta"], DEFAULT_SETPOINTS.as_array().tolist())
    rig.loop.sync_message(0, SYNC_NAMES, plan(DEFAULT_SETPOINTS.as_array(), 1, 1))   # before its sample
    rig.sample(0)
    assert len(rig.answers) == 1
    rig.loop.setpoints_message(["theta_0", "A_phi", "A_theta"], NEW)    # not applied yet: synchronized
    assert rig.loop.controller.setpoints == DEFAULT_SETPOINTS
    rig.sample(1)
    assert len(rig.answers) == 1                                        # held for its sync message
    rig.loop.sync_message(DT_NS, SYNC_NAMES, plan(NEW, 2, 2))
    assert len(rig.answers) == 2 and rig.loop.controller.setpoints.as_array().tolist() == NEW
    ref = PathController(shared_model(), KiteParams(), DEFAULT_SETPOINTS, ControllerSettings())
    expected = [ref.command(_meas(0, rig.samples[0]))]
    ref.set_setpoints(NEW)
    expected.append(ref.command(_meas(DT_NS, rig.samples[1])))
    assert [d for _, d in rig.answers] == expected
    rig.loop.sync_message(DT_NS, ["theta_0"], [1.0])                     # malformed: rejected
    assert rig.loop.reject.counts == {"sync": 1}


@pytest.mark.parametrize("optimizer", [True, False], ids=["optimizer-stalls", "no-optimizer"])
def test_before_any_sync_a_held_sample_waits_while_an_optimizer_is_in_the_graph(optimizer):
    """Before the first sync message, however long an optimizer in the graph takes, the sample waits; once none
    has been in the graph for SYNC_ABSENT s (no optimizer at all) it is answered with the latest setpoints, and
    unsynchronized samples are answered at once until a sync message arrives."""
    rig = Rig(sync=True, optimizer=optimizer)
    rig.loop.setpoints_message(["theta_0", "A_phi", "A_theta"], NEW)
    rig.sample(0)
    assert rig.answers == []
    if optimizer:                                      # in the graph: waits an hour of wall time, and says so
        for _ in range(60):
            rig.now += 60.0
            rig.loop.watchdog()
        assert rig.answers == [] and rig.log.count("waiting") >= 1
        rig.optimizer_alive = 0                        # it left the graph (exited, or killed and dropped by DDS)
        rig.now += SYNC_ABSENT / 2
        rig.loop.watchdog()
        assert rig.answers == []                       # not yet SYNC_ABSENT without an optimizer
    rig.now += SYNC_ABSENT + 0.5
    rig.loop.watchdog()
    assert len(rig.answers) == 1 and rig.loop.controller.setpoints.as_array().tolist() == NEW
    assert rig.log.count("no optimizer in the graph") == 1
    rig.sample(1)                                      # unsynchronized: answered at once
    assert len(rig.answers) == 2 and not rig.loop.synchronized()
    rig.loop.sync_message(2 * DT_NS, SYNC_NAMES, plan(NEW, 1, 1))   # the optimizer is back
    assert rig.loop.synchronized() and rig.log.count("/rto/sync is back: answering") == 1
    rig.sample(2)
    assert len(rig.answers) == 3
    np.testing.assert_array_equal([s for s, _ in rig.answers], [0, DT_NS, 2 * DT_NS])


def test_timeline_rule_shared_by_both_joins():
    """Off the timeline only a continued candidate moves it; the old timeline going on drops the candidate."""
    tl = Timeline()
    assert tl.place(5 * DT_NS).place is Place.NEXT                 # the first sample, wherever it lies
    tl.last = 5 * DT_NS
    assert tl.place(6 * DT_NS) == (Place.NEXT, None, None)
    assert tl.place(5 * DT_NS + 2 * 10**9) == (Place.CANDIDATE, None, None)          # far future
    assert tl.place(5 * DT_NS + 2 * 10**9) == (Place.REPEATED, None, None)
    assert tl.place(2 * DT_NS) == (Place.CANDIDATE, 5 * DT_NS + 2 * 10**9, None)     # replaces the first
    assert tl.place(3 * DT_NS) == (Place.RESTART, None, 2 * DT_NS)                   # continued: restart
    tl.last = 3 * DT_NS
    assert tl.place(3 * DT_NS + 3 * 10**9).place is Place.CANDIDATE
    assert tl.place(3 * DT_NS + 3 * 10**9 + DT_NS) == (Place.JUMP, None, 3 * DT_NS + 3 * 10**9)
    tl.last = 10 * DT_NS
    assert tl.place(DT_NS).place is Place.CANDIDATE
    assert tl.place(11 * DT_NS) == (Place.NEXT, DT_NS, None) and tl.candidate is None   # junk dropped


def test_after_the_first_sync_a_sample_waits_for_its_own_whatever_the_graph_shows():
    """Once the optimizer has synchronized the loop, a held sample is never released on wall time or graph state
    (a restarted optimizer picks it up): what the kite flies cannot depend on how fast the optimizer is."""
    rig = Rig(sync=True, optimizer=True)
    rig.sample(0)
    rig.loop.sync_message(0, SYNC_NAMES, plan(NEW, 1, 1))
    assert len(rig.answers) == 1
    rig.sample(1)
    rig.optimizer_alive = 0                            # the graph shows no optimizer (killed, or a discovery hiccup)
    for _ in range(60):
        rig.now += 60.0
        rig.loop.watchdog()
    assert len(rig.answers) == 1 and rig.loop.synchronized() and rig.log.count("waiting") >= 1
    rig.loop.sync_message(DT_NS, SYNC_NAMES, plan(NEW, 1, 1))      # the optimizer (restarted) processes it
    assert [s for s, _ in rig.answers] == [0, DT_NS]


def _setpoints(rig, c):
    rig.loop.setpoints_message(["A_theta", "theta_0", "A_phi"], [c[2], c[0], c[1]])    # any order of names


def test_a_burst_of_setpoints_between_two_samples_applies_only_the_latest_at_the_sample():
    """A flood between two samples costs cheap checks only: the latest valid setpoints are applied once, at the next
    sample; the answers are those of a controller switched to them at that sample; logging is one line, then a
    summary per period."""
    rig = Rig()
    rig.sample(0)
    burst = [Setpoints.from_degrees(31.0 + 0.4 * i, 45.0 + 0.5 * i, 7.0).as_array().tolist() for i in range(20)]
    calls = []
    set_setpoints = rig.loop.controller.set_setpoints
    rig.loop.controller.set_setpoints = lambda c: calls.append(list(c)) or set_setpoints(c)
    for i, c in enumerate(burst):
        _setpoints(rig, c)
        if i == 7:
            rig.loop.setpoints_message(["theta_0", "A_phi"], [0.6, 0.8])             # malformed: rejected at once
            _setpoints(rig, [0.6, 1.5, 0.12])                                        # outside the box: rejected
    assert calls == [] and rig.loop.controller.setpoints == DEFAULT_SETPOINTS       # nothing applied yet
    assert rig.loop.inbox.received == 22 and rig.loop.reject.counts == {"setpoints": 1, "setpoints value": 1}
    rig.sample(1)
    assert calls == [burst[-1]]                                                       # one change: the latest
    assert rig.loop.controller.setpoints.as_array().tolist() == burst[-1]
    ref = PathController(shared_model(), KiteParams(), DEFAULT_SETPOINTS, ControllerSettings())
    expected = [ref.command(_meas(0, rig.samples[0]))]
    ref.set_setpoints(burst[-1])
    expected.append(ref.command(_meas(DT_NS, rig.samples[1])))
    assert [d for _, d in rig.answers] == expected                                   # bit for bit
    assert rig.paths == [rig.loop.controller.setpoints]                              # published after the answer
    rig.sample(2)
    assert len(calls) == 1                                                            # nothing new: nothing applied
    for k in range(3, 30):                                                            # a flood: 2 per sample
        _setpoints(rig, burst[k % 2])
        _setpoints(rig, burst[(k + 1) % 2])
        rig.now += 0.2
        rig.sample(k)
    assert len(calls) == 1 + 27 and rig.loop.inbox.applied == 28
    assert rig.log.count("new setpoints") <= 2 + 27 * 0.2 / SUMMARY_PERIOD            # throttled, not per message
    summary = [t for _, t in rig.log.lines if "setpoint messages in the last" in t]
    assert summary and re.search(r"\d+ setpoint messages in the last [\d.]+ s, applied \d+", summary[0])
    assert len(rig.paths) <= 2 + 27 * 0.2 / PATH_PERIOD                               # path throttled too


def test_setpoints_are_ignored_while_a_node_other_than_the_source_publishes():
    pubs = [Publisher("/optimizer", "01"), Publisher("/intruder", "02")]
    matched = [2]                                               # writers the subscription is matched with
    rig = Rig(setpoint_source="/optimizer", setpoint_publishers=lambda: pubs, setpoint_matched=lambda: matched[0])
    rig.sample(0)
    _setpoints(rig, NEW)
    _setpoints(rig, NEW)
    rig.sample(1)
    assert rig.loop.controller.setpoints == DEFAULT_SETPOINTS and rig.loop.inbox.ignored == 2
    assert rig.loop.inbox.refresh and rig.log.count("ignoring /rto/setpoints") == 1
    assert "/intruder (gid 02)" in [t for _, t in rig.log.lines if "ignoring" in t][0]
    pubs.pop()                                                  # the graph lists the source alone, but a second
    _setpoints(rig, NEW)                                        # writer is matched: not in the graph yet
    rig.sample(2)
    assert rig.loop.controller.setpoints == DEFAULT_SETPOINTS
    assert rig.loop.inbox.guard.others() == "1 not in the graph yet"
    matched[0] = 1                                              # the source alone ...
    _setpoints(rig, NEW)
    rig.sample(3)                                               # ... but another one was seen less than 1 s ago
    assert rig.loop.controller.setpoints == DEFAULT_SETPOINTS and not rig.loop.inbox.guard.clean()
    assert rig.log.count("less than 1 s before") == 0           # warnings throttled (one per period)
    rig.now += SOURCE_QUIET
    assert rig.loop.inbox.guard.clean()                         # the node subscribes again: the latched value
    _setpoints(rig, NEW)
    rig.sample(4)
    assert rig.loop.controller.setpoints.as_array().tolist() == NEW
    matched[0] = 2                                              # a hit-and-run writer: matched when its message
    _setpoints(rig, DEFAULT_SETPOINTS.as_array().tolist())      # arrives, gone from DDS before the sample
    matched[0] = 1
    rig.sample(5)
    assert rig.loop.controller.setpoints.as_array().tolist() == NEW
    assert parse_source("optimizer") == "/optimizer" and parse_source("*") is None
    with pytest.raises(ParameterError, match="setpoint_source = 'bad name'"):
        parse_source("bad name")


def test_a_second_plant_is_ignored_while_the_first_flies_and_a_restart_still_works():
    """Two publishers of /kite/state: samples off the timeline are another plant's while the timeline served is
    alive; once it has been silent PLANT_QUIET s (its plant killed, still listed by DDS) the restart is taken."""
    rig = Rig()
    for k in range(20, 30):
        rig.sample(k)
    flying = rig.loop.controller
    rig.plants = 2                                      # a second plant joined the domain
    for k in range(0, 6):                               # its samples interleave with the first plant's
        rig.sample(k)
        rig.sample(30 + k)
        rig.now += 0.02
    assert rig.loop.controller is flying and rig.log.count("jumped back") == 0
    assert [s for s, _ in rig.answers] == [k * DT_NS for k in range(20, 36)]     # only the first kite answered
    assert rig.loop.reject.counts["other plant"] == 6
    rig.now += PLANT_QUIET                              # the first plant is gone (killed: DDS still lists it)
    rig.sample(6)
    rig.sample(7)
    assert rig.loop.controller is not flying and rig.log.count("jumped back") == 1
    assert rig.loop.timeline.last == 7 * DT_NS


def test_source_watch_names_every_publisher_throttled():
    log, now = Log(), [0.0]
    watch = SourceWatch(log, clock=lambda: now[0], period=10.0)
    a, b, c = Publisher("/plant", "aa"), Publisher("/plant", "bb"), Publisher("/plant", "cc")
    watch.update("/kite/state", [a], "two plants")
    assert log.lines == []
    for _ in range(10):                                 # 5 s of looks every 0.5 s: one warning
        watch.update("/kite/state", [a, b], "two plants")
        now[0] += 0.5
    assert log.count("2 publishers of /kite/state: /plant (gid aa), /plant (gid bb): two plants") == 1
    watch.update("/kite/state", [a, b, c], "two plants")            # a new one: at once
    now[0] += 10.0
    watch.update("/kite/state", [a, b, c], "two plants")            # the same, a period later: again
    assert log.count("3 publishers of /kite/state") == 2
    watch.update("/kite/state", [b], "two plants")
    assert log.count("/kite/state has one publisher again: /plant (gid bb)") == 1
    unnamed = Publisher(node_name("_NODE_NAME_UNKNOWN_", "_NODE_NAMESPACE_UNKNOWN_"), "dd")
    watch.update("/kite/state", [b, unnamed], "two plants")         # the graph knows the writer, not its node
    watch.update("/kite/state", [b, Publisher("/plant", "dd")], "two plants")     # ... then its name: at once
    assert log.count("<node not known yet> (gid dd)") == 1 and log.count("/plant (gid bb), /plant (gid dd)") == 1
