"""SteeringLoop without DDS: the controller node's join, timeline, restart and optimizer sync, on a fake clock."""
import math
from types import SimpleNamespace

import numpy as np
import pytest

from kite_rto.flight.controller import ControllerSettings, PathController
from kite_rto.flight.path import DEFAULT_SETPOINTS, Setpoints
from kite_rto.flight.sample_join import Place, Timeline
from kite_rto.flight.steering_loop import SETPOINTS_WAIT, SYNC_ABSENT, SYNC_NAMES, SteeringLoop
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

    def __init__(self, sync=False, optimizer=True):
        self.now = 100.0
        self.answers, self.log = [], Log()
        self.optimizer_alive = int(optimizer)          # publishers of /rto/sync in the graph
        self.loop = SteeringLoop(KiteParams(), ControllerSettings(), DEFAULT_SETPOINTS,
                                 answer=lambda s, d: self.answers.append((s, d)), lap=lambda s, lap: None,
                                 path=lambda: None, logger=self.log, sync=sync,
                                 setpoint_sources=lambda: int(optimizer), sync_sources=lambda: self.optimizer_alive,
                                 clock=lambda: self.now)
        self.plant = KitePlant(PlantConfig(), seed=0)
        self.samples = []
        for _ in range(20):
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


def test_sync_applies_the_optimizer_setpoints_at_the_stamped_sample():
    rig = Rig(sync=True)
    rig.loop.setpoints_message(["theta_0", "A_phi", "A_theta"], DEFAULT_SETPOINTS.as_array().tolist())
    rig.loop.sync_message(0, SYNC_NAMES, [*DEFAULT_SETPOINTS.as_array(), 1.0])   # sync before its sample
    rig.sample(0)
    assert len(rig.answers) == 1
    rig.loop.setpoints_message(["theta_0", "A_phi", "A_theta"], NEW)    # not applied yet: synchronized
    assert rig.loop.controller.setpoints == DEFAULT_SETPOINTS
    rig.sample(1)
    assert len(rig.answers) == 1                                        # held for its sync message
    rig.loop.sync_message(DT_NS, SYNC_NAMES, [*NEW, 2.0])
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
    rig.loop.sync_message(2 * DT_NS, SYNC_NAMES, [*NEW, 1.0])       # the optimizer is back
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
    rig.loop.sync_message(0, SYNC_NAMES, [*NEW, 1.0])
    assert len(rig.answers) == 1
    rig.sample(1)
    rig.optimizer_alive = 0                            # the graph shows no optimizer (killed, or a discovery hiccup)
    for _ in range(60):
        rig.now += 60.0
        rig.loop.watchdog()
    assert len(rig.answers) == 1 and rig.loop.synchronized() and rig.log.count("waiting") >= 1
    rig.loop.sync_message(DT_NS, SYNC_NAMES, [*NEW, 1.0])          # the optimizer (restarted) processes it
    assert [s for s, _ in rig.answers] == [0, DT_NS]
