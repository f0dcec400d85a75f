"""The real-time plant's pacer (kite_rto/runtime/pace.py) and the shipped DDS profile's lookup (no DDS)."""
import os

import pytest

from kite_rto.runtime.pace import PaceSettings, RealtimePacer
from kite_rto.nodes import dds_profile

DT = 0.02


def run(pacer, steps, wall_per_step=None, lag=None, t=0.0):
    """``steps`` steps ``wall_per_step`` s apart (None: at the pacer's rate), one command of ``lag`` samples per
    step; the changes and the last wall time."""
    changes = []
    for _ in range(steps):
        t += DT / pacer.rate if wall_per_step is None else wall_per_step
        if lag is not None:
            pacer.command(lag)
        c = pacer.step(t)
        if c is not None:
            changes.append(c)
    return changes, t


def test_a_lag_above_the_bound_lowers_the_rate_at_once_and_it_comes_back():
    p = RealtimePacer(DT, 100.0, 0.0)
    changes, t = run(p, 50, DT / 100.0, lag=30)              # one lag window: 30 samples late
    assert len(changes) == 1 and changes[0].slower and changes[0].lag == 30
    assert changes[0].rate == pytest.approx(100.0 * 0.25) and p.rate == changes[0].rate
    assert "cannot hold rate_factor 100: steering commands arrive 30 samples (0.60 s simulated)" in \
        changes[0].message(DT, first=True)
    changes, t = run(p, 99000, lag=2, t=t)                  # holding well: raised step by step to the request
    assert [c.slower for c in changes] == [False] * len(changes) and p.rate == 100.0
    assert "back at rate_factor 100" in changes[-1].message(DT, first=False)


def test_a_small_lag_or_too_few_commands_change_nothing():
    p = RealtimePacer(DT, 50.0, 0.0)
    assert run(p, 500, DT / 50.0, lag=10)[0] == []           # at the bound: fine
    assert run(p, 500, DT / 50.0, lag=None)[0] == [] and p.rate == 50.0


def test_real_time_is_the_floor_a_too_slow_loop_there_is_only_reported():
    p = RealtimePacer(DT, 1.0, 0.0)
    changes, _ = run(p, 50, DT, lag=40)
    assert len(changes) == 1 and changes[0].rate == 1.0 == p.rate and changes[0].slower
    assert "already at 1x, the lowest it slows down to" in changes[0].message(DT, first=True)
    p = RealtimePacer(DT, 4.0, 0.0)
    run(p, 500, DT / 4.0, lag=40)
    assert p.rate == 1.0 and p.floor == 1.0


def test_a_plant_behind_its_schedule_is_reported_not_slowed():
    p = RealtimePacer(DT, 100.0, 0.0)
    changes, _ = run(p, 5000, DT / 40.0)                      # it steps at 40x only
    assert changes and all(c.achieved == pytest.approx(40.0) and c.rate == 100.0 for c in changes)
    assert "the plant steps at only 40.0x; it runs as fast as it can" in changes[0].message(DT, first=True)


def test_a_new_request_starts_again():
    p = RealtimePacer(DT, 100.0, 0.0)
    run(p, 50, DT / 100.0, lag=30)
    p.request(20.0, 1.0)
    assert p.rate == 20.0 == p.requested


@pytest.mark.parametrize("bad", [{"max_lag": 0.5}, {"behind": 1.0}, {"speed_up": 1.0}, {"lag_window": 0}])
def test_pace_settings_are_checked(bad):
    with pytest.raises(ValueError, match=next(iter(bad))):
        PaceSettings(**bad)


def test_shipped_profile_is_set_unless_the_user_chose(tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)
    path = dds_profile.shipped_profile()
    assert path is not None and path.name == "fastdds_profile.xml" and "<heartbeatPeriod>" in path.read_text()
    env = {}
    assert dds_profile.use_shipped_profile(env) == (str(path), "shipped with kite_rto")
    assert env == {name: str(path) for name in dds_profile.PROFILE_ENV}
    env = {"FASTRTPS_DEFAULT_PROFILES_FILE": "/mine.xml"}
    assert dds_profile.use_shipped_profile(env)[0] == "/mine.xml" and "FASTDDS_DEFAULT_PROFILES_FILE" not in env
    env = {"KITE_RTO_DDS_PROFILE": "none"}
    assert dds_profile.use_shipped_profile(env)[0] is None and env == {"KITE_RTO_DDS_PROFILE": "none"}
    (tmp_path / "DEFAULT_FASTRTPS_PROFILES.xml").write_text("<dds/>")
    env = {}
    assert "working directory" in dds_profile.use_shipped_profile(env)[1] and env == {}
    assert os.environ.get("KITE_RTO_DDS_PROFILE") != "set by a test"


def test_a_controller_that_answers_few_samples_lowers_the_rate():
    p = RealtimePacer(DT, 100.0, 0.0)
    changes = []
    t = 0.0
    for k in range(50):                                       # one command every 5 samples, each fresh
        t += DT / 100.0
        if k % 5 == 0:
            p.command(1)
        c = p.step(t)
        if c is not None:
            changes.append(c)
    assert len(changes) == 1 and changes[0].answered == pytest.approx(0.2) and changes[0].lag is None
    assert changes[0].rate == pytest.approx(100.0 * 0.25) and changes[0].slower
    assert "the controller answered only 20 % of the samples; slowing down to 25.0x" in \
        changes[0].message(DT, first=True)
