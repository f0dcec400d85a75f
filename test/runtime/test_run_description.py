"""The run's description in the optimizer's database: stored with a new run's start, again with the plant's
configuration when the plant publishes it (a failed write keeps it and does not hold the run), bad configurations
rejected; the plant's configuration as JSON and back; a resumed run's stored description."""
from dataclasses import replace

import pytest

from kite_rto.gma import HistoryStore
from kite_rto.kite.plant import PLANT_PARAMS, PlantConfig
from kite_rto.rto.experiment import ExperimentSpec
from kite_rto.rto.run import RUN_KEY, RunDescription
from kite_rto.rto.settings import KiteRTOSettings
from kite_rto.runtime.run_description import plant_from_json, plant_json, stored_description
from kite_rto.runtime.store_fault import DiskFull

from storage_flight import DT, TICK, Flight, compare, sample

PLANT = PlantConfig(params=replace(PLANT_PARAMS, w_ref=9.0))
SETTINGS = KiteRTOSettings(experiment=ExperimentSpec(h_min=115.0))


def fly(f: Flight, config_at: int | None = None, text: str = "") -> list:
    """Flight.fly with the plant's configuration ``text`` handed to the run at sample ``config_at``; returns what
    :meth:`OptimizerRun.plant_config` returned."""
    got = []
    f.run.begin()
    for n in range(2000):
        if f.run.done:
            break
        if n == config_at:
            got.append(f.run.plant_config(text))
        f.clock += 0.1
        f.run.on_sample(sample(f.t))
        if n % TICK == 0:
            f.run.tick()
        f.t += DT
    f.store.close()
    return got


def stored_run(db):
    store = HistoryStore(db)
    try:
        return store.load().meta.get(RUN_KEY)
    finally:
        store.close()


@pytest.fixture(scope="module")
def reference(tmp_path_factory):
    db = tmp_path_factory.mktemp("reference") / "rto.sqlite"
    Flight(db).fly()
    store = HistoryStore(db)
    try:
        return store.load()
    finally:
        store.close()


def test_the_plants_configuration_is_stored_with_the_description(tmp_path, reference):
    db = tmp_path / "rto.sqlite"
    f = Flight(db, description=RunDescription(SETTINGS))
    got = fly(f, config_at=15, text=plant_json(PLANT))
    assert f.finished and got == [RunDescription(SETTINGS, PLANT)]
    assert RunDescription.from_dict(stored_run(db)) == RunDescription(SETTINGS, PLANT)
    assert "now names the plant's configuration" in f.log.text("info")
    c = compare(db, reference)
    assert c["lost"] == c["duplicated"] == c["extra"] == 0 and c["dc"] < 1e-6, c


def test_a_failed_write_of_the_description_keeps_it_and_the_run_goes_on(tmp_path, reference):
    """The description's own write (the store's second 'start' write) fails: the run neither holds nor mismeasures;
    the description is written at the next try (alone, or with the next experiment, whichever comes first)."""
    db = tmp_path / "rto.sqlite"
    f = Flight(db, fault=DiskFull("start", 2, attempts=1), description=RunDescription(SETTINGS))
    got = fly(f, config_at=15, text=plant_json(PLANT))
    assert f.finished and not f.storage_lost and got == [RunDescription(SETTINGS, PLANT)]
    assert f.unsafe == 0 and f.mismeasured == 0
    errors = f.log.text("error")
    assert errors.count("database or disk is full: run data (run) kept in memory") == 1, errors
    assert "Holding" not in f.log.text(), f.log.text()
    assert "run data (run) stored in" in f.log.text("info")
    assert RunDescription.from_dict(stored_run(db)).plant == PLANT
    c = compare(db, reference)
    assert c["lost"] == c["duplicated"] == c["extra"] == 0 and c["dc"] < 1e-6, c


@pytest.mark.parametrize("text, why", [
    ("not json", "rejected plant configuration 'not json': not JSON (Expecting value"),
    ('{"dt": "x"}', """rejected plant configuration '{"dt": "x"}': not a PlantConfig (PlantConfig.dt = 'x': """
                    "expected a number)"),
    ('{"rotor": 1}', "not a PlantConfig (PlantConfig: unknown fields ['rotor']"),
    ("[1, 2]", "not a PlantConfig (PlantConfig: expected a dict of its fields, got [1, 2])"),
])
def test_a_bad_configuration_is_rejected_and_the_run_goes_on(tmp_path, reference, text, why):
    db = tmp_path / "rto.sqlite"
    f = Flight(db, description=RunDescription(SETTINGS))
    got = fly(f, config_at=15, text=text)
    assert f.finished and got == [None]
    assert why in f.log.text("warning"), f.log.text("warning")
    assert RunDescription.from_dict(stored_run(db)) == RunDescription(SETTINGS)       # as stored at the start


def test_the_configuration_round_trips_and_a_resumed_run_keeps_its_description():
    assert plant_from_json(plant_json(PLANT)) == PLANT
    long = "x" * 500
    with pytest.raises(ValueError, match=r"'x{120}\.\.\.': not JSON"):
        plant_from_json(long)
    run = RunDescription(SETTINGS, PLANT)
    assert stored_description({RUN_KEY: run.to_dict()}, KiteRTOSettings()) == (run, "")
    fresh, note = stored_description({}, SETTINGS)
    assert fresh == RunDescription(SETTINGS) and "holds no run description" in note
    bad, note = stored_description({RUN_KEY: {"settings": {"altitude": 1}}}, SETTINGS)
    assert bad == RunDescription(SETTINGS) and "cannot be read (KiteRTOSettings: unknown fields ['altitude']" in note
