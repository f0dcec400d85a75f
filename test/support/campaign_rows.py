"""Campaign result rows and plans made up for the summary's and the tables' tests (no flight)."""
from kite_rto.campaign.manifest import Manifest, Plan
from kite_rto.campaign.results import RunResult

LIBRARIES = {"numpy": "2.4.6", "hipersim": "absent"}


def row(sc, seed, method, final, t99, held=1, low=110.0, below=0, tuning=True, budget=None, code="0123456789ab"):
    """A judged run on scenario ``sc`` (h_min 100 m, oracle 600 kN) ending at ``final`` % with time to 99 % ``t99``."""
    return RunResult(scenario=sc, tuning=tuning, h_min=100.0, seed=seed, method=method,
                     reach_index=None if t99 is None else 1, t99_s=t99, held_from=held, times_s=(0.0, 300.0),
                     percent=(90.0, final), altitude=(130.0, low), final_percent=final, lowest_altitude=low,
                     below_floor=below, flight_time_s=3000.0, experiments=30, crashes=0, budget_s=budget,
                     oracle_kn=600.0, message="", code_version=code, wall_s=12.5)


def plan_of_rows(rows, budget=4.0) -> Plan:
    """The plan whose runs are exactly ``rows``' (complete), computed with their first row's code version."""
    return Plan(runs=tuple((r.scenario, r.seed, r.method) for r in rows), failed={}, n_iter=10, budget=budget,
                versions={rows[0].code_version: dict(LIBRARIES)})


def manifest(scenarios, seeds, methods, failed=(), code="0123456789ab", budget=4.0) -> Manifest:
    """A campaign's manifest of ``scenarios`` x ``seeds`` x ``methods`` with the ``failed`` runs."""
    return Manifest(scenarios=tuple(scenarios), seeds=tuple(seeds), methods=tuple(methods), n_iter=10,
                    budget=budget, code_version=code, libraries=dict(LIBRARIES), failed=tuple(failed))
