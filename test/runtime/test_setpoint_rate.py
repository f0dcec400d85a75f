"""SetpointRate and the steering loop without DDS: setpoints that change faster than the path can follow are warned
about once per interval of flight, naming the publisher and the rate; the optimizer's stream never is."""
import re

import pytest

from kite_rto.flight.controller import ControllerSettings
from kite_rto.flight.path import DEFAULT_SETPOINTS, Setpoints
from kite_rto.kite.params import KiteParams
from kite_rto.kite.plant import KitePlant, PlantConfig
from kite_rto.runtime.setpoint_rate import RATE_LIMIT, RATE_PERIOD, RATE_WINDOW, SetpointRate
from kite_rto.runtime.sources import UNKNOWN_NODE, Publisher
from kite_rto.runtime.steering_loop import SETPOINTS_WAIT, SteeringLoop

A = Setpoints.from_degrees(33.0, 46.0, 7.0).as_array().tolist()
B = Setpoints.from_degrees(35.0, 52.0, 8.0).as_array().tolist()
INTRUDER = [Publisher("/intruder", "0a")]
WARNING = re.compile(r"changed /rto/setpoints (\d+) times in ([\d.]+) s of flight up to t = ([\d.]+) s "
                     r"\(([\d.]+) changes per s of flight")


class Log:
    def __init__(self):
        self.warnings = []

    def info(self, text, **_):
        pass

    def warning(self, text, **_):
        self.warnings.append(text)


class Stream:
    """A SetpointRate fed a stream: ``hz`` messages per s of flight, 50 Hz samples, wall = flight / ``speed``."""

    def __init__(self, publishers=INTRUDER, source=None):
        self.log, self.wall = Log(), 1000.0
        self.rate = SetpointRate(self.log, lambda: publishers, source, clock=lambda: self.wall)
        self.t = 0.0

    def fly(self, seconds, hz=0.0, values=lambda i: A if i % 2 else B, speed=1.0):
        """``seconds`` of flight; messages spread evenly, ``values(i)`` the i-th one's."""
        sent, i = 0.0, 0
        for _ in range(round(seconds * 50)):
            sent += hz / 50
            while i < int(sent):
                self.rate.message(values(i))
                i += 1
            self.t += 0.02
            self.wall += 0.02 / speed
            self.rate.flight(self.t)

    def parsed(self):
        return [tuple(map(float, WARNING.search(w).groups())) for w in self.log.warnings]


def test_a_500_hz_stream_is_warned_once_per_interval_naming_its_node_and_rate():
    s = Stream()
    s.fly(5.0)
    s.fly(35.0, hz=500.0)
    s.fly(30.0)
    found = s.parsed()
    assert len(found) == 4                                  # 35 s of changes: intervals of 10 s from the first
    assert all("/intruder (gid 0a)" in w and "setpoint_source" in w for w in s.log.warnings)
    assert sum(n for n, *_ in found) == s.rate.changes == 35 * 500
    ends = [t for _, _, t, _ in found]
    assert all(b - a >= RATE_PERIOD for a, b in zip(ends, ends[1:]))     # at most one per interval
    assert [round(r) for _, _, _, r in found[:3]] == [500, 500, 500]
    assert f"expected at most {RATE_LIMIT}" in s.log.warnings[0]


def test_republished_identical_setpoints_are_not_changes():
    s = Stream()
    s.fly(60.0, hz=500.0, values=lambda i: A)
    assert s.rate.changes == 1 and not s.log.warnings


@pytest.mark.parametrize("every", [20.0, 30.0, 120.0])
def test_the_optimizers_stream_is_never_warned_about(every):
    """One change per experiment (a lap at the very least, about 20 s), republished now and then."""
    s = Stream(publishers=[Publisher("/optimizer", "01")])
    for k in range(30):
        s.rate.message(A if k % 2 else B)
        s.rate.message(A if k % 2 else B)                  # the same again (e.g. a resubscription): not a change
        s.fly(every)
    s.rate.message(B)                                       # a person sets them by hand a few times in a row
    s.fly(1.0)
    s.rate.message(A)
    s.fly(1.0)
    s.rate.message(B)
    s.fly(60.0)
    assert s.rate.changes == 33 and not s.log.warnings


def test_the_limit_is_the_changes_within_a_window_of_flight():
    s = Stream()
    for k in range(RATE_LIMIT):
        s.rate.message(A if k % 2 else B)
        s.fly(RATE_WINDOW / RATE_LIMIT - 0.5)
    s.fly(30.0)
    assert not s.log.warnings                               # at the limit: can be flown
    for k in range(RATE_LIMIT + 1):
        s.rate.message(A if k % 2 else B)
        s.fly(RATE_WINDOW / (RATE_LIMIT + 1) - 0.5)
    s.fly(30.0)
    assert len(s.log.warnings) == 1 and "up to 7 within 60 s of flight" in s.log.warnings[0]


def test_a_fast_simulation_warns_once_per_interval_of_flight_and_of_wall_time():
    """Lockstep at 20 times real time: an interval stays open until RATE_PERIOD wall s have passed too; every
    change is reported."""
    s = Stream()
    s.fly(420.0, hz=25.0, speed=20.0)
    found = s.parsed()
    assert len(found) == 3 and [round(t) for _, _, t, _ in found] == [10, 210, 410]
    assert [round(r) for *_, r in found] == [25, 25, 25]
    s.fly(300.0, speed=20.0)                                # the rest is reported once the wall time allows
    assert len(s.parsed()) == 4 and s.parsed()[-1][1] == 200.0
    assert sum(n for n, *_ in s.parsed()) == s.rate.changes == 420 * 25


def test_the_warning_names_every_publisher_or_none_and_the_source():
    pubs = [Publisher("/optimizer", "01"), Publisher("/intruder", "0a")]
    s = Stream(publishers=pubs, source="/optimizer")
    s.fly(12.0, hz=100.0)
    assert "one of /optimizer (gid 01), /intruder (gid 0a) (a message does not tell its sender)" in \
        s.log.warnings[0]
    assert "setpoint_source is /optimizer: only its setpoints apply" in s.log.warnings[0]
    s.fly(20.0)                                             # the interval after it closes, with its warning
    pubs.clear()
    s.fly(12.0, hz=100.0)
    assert len(s.log.warnings) == 3 and "a publisher not seen in the graph changed" in s.log.warnings[2]


def test_the_publisher_is_named_as_seen_while_the_changes_arrived():
    """The graph does not know the node's name at first, and the node has left when the interval closes."""
    pubs = [Publisher(UNKNOWN_NODE, "0a")]
    s = Stream(publishers=pubs)
    s.fly(0.4, hz=500.0)
    pubs[0] = INTRUDER[0]                                   # discovery learnt its name
    s.fly(7.6, hz=500.0)
    pubs.clear()                                            # the node left
    s.fly(5.0)
    assert len(s.log.warnings) == 1 and "/intruder (gid 0a) changed" in s.log.warnings[0]


@pytest.mark.parametrize("restart", [True, False])
def test_a_flight_time_going_back_starts_the_count_anew(restart):
    s = Stream()
    s.rate.message(A)                                       # before the first sample: counted at it
    s.fly(5.0, hz=1.0)                                      # B, A, B, A, B: 6 changes
    if restart:
        s.t = 0.0                                           # the plant restarted
    s.fly(20.0, hz=0.1)                                     # B (no change), A
    assert s.rate.changes == 7 and len(s.log.warnings) == (0 if restart else 1)


def test_the_loop_answers_every_sample_of_a_flood_and_warns():
    """SteeringLoop fed a 500 Hz stream of valid, alternating setpoints from one node for 12 s of flight: every
    sample is answered, the setpoints are applied at sample boundaries, one warning names the node and the rate."""
    log, wall = Log(), [1000.0]
    answers = []
    loop = SteeringLoop(KiteParams(), ControllerSettings(), DEFAULT_SETPOINTS,
                        answer=lambda s, d: answers.append((s, d)), lap=lambda s, lap: None, path=lambda: None,
                        logger=log, setpoint_sources=lambda: 1, setpoint_publishers=lambda: INTRUDER,
                        clock=lambda: wall[0])
    wall[0] += SETPOINTS_WAIT
    plant = KitePlant(PlantConfig(), seed=0)
    names = list(Setpoints.names())
    for k in range(600):
        for i in range(10):
            loop.setpoints_message(names, A if (10 * k + i) % 2 else B)
        m = plant.measure()
        loop.wind_reading(k * 20_000_000, m.wind_ref)
        loop.state_sample(k * 20_000_000, ["theta", "phi", "psi"], [m.theta, m.phi, m.psi],
                          [m.theta_dot, m.phi_dot, m.psi_dot])
        plant.step(answers[-1][1] if answers else 0.0)
        wall[0] += 0.02
    assert [s for s, _ in answers] == [k * 20_000_000 for k in range(600)]
    assert loop.inbox.received == 6000 and loop.inbox.rate.changes == 6000
    rate = [w for w in log.warnings if "faster than the path can follow" in w]
    assert len(rate) == 1                                   # 10 before each of the samples 0 to 500 (t = 10 s)
    assert "/intruder (gid 0a) changed /rto/setpoints 5010 times in 10.0 s of flight up to t = 10.0 s (501.0 " \
           "changes per s of flight" in rate[0]
