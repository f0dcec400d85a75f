"""Parameters that must agree between a node and the plant it serves, checked against what the plant says.

A controller whose ``dt`` or tether length ``r`` differs from the plant's flies on with a wrong dead-time
compensation and a wrong path geometry (tracking several times worse) without anything failing. The plant
announces its parameters through its standard ``get_parameters`` service; :class:`PlantAgreement` asks every
node that publishes ``/kite/state`` once, as soon as it appears, and logs one line per finding:

* an **error** for each parameter that must be equal (``dt``, ``r``, ``z_ref``), naming both values and the fix;
* one **info** line listing the model parameters that differ from the simulated plant's (``E``, ``g_s``,
  ``shear``, ...): expected, since the plant stands for the real kite the model only approximates.
"""
from __future__ import annotations

import math

from rcl_interfaces.msg import ParameterType
from rcl_interfaces.srv import GetParameters
from rclpy.clock import Clock, ClockType

from .topics import STATE

__all__ = ["PlantAgreement", "MUST_AGREE", "compare"]

MUST_AGREE = ("dt", "r", "z_ref")
"""Parameters a controller and the plant must share: sample time (s), tether length (m), anemometer height (m)."""


def _value(p):
    """A float (or None) from an rcl_interfaces/ParameterValue."""
    if p.type == ParameterType.PARAMETER_DOUBLE:
        return p.double_value
    if p.type == ParameterType.PARAMETER_INTEGER:
        return float(p.integer_value)
    return None


def compare(mine: dict, theirs: dict, must_agree=MUST_AGREE) -> tuple[list[str], list[str]]:
    """(names that must agree but differ, model names that differ) between two name -> float dicts."""
    def differs(name):
        a, b = mine.get(name), theirs.get(name)
        return a is not None and b is not None and not math.isclose(a, b, rel_tol=1e-9, abs_tol=1e-12)
    bad = [n for n in must_agree if differs(n)]
    model = [n for n in mine if n not in must_agree and differs(n)]
    return bad, model


class PlantAgreement:
    """Asks each plant (publisher of ``/kite/state``) for its parameters once and logs disagreements.

    Args:
        node: the rclpy node (its logger, graph queries and a client per plant).
        mine: this node's values by plant parameter name (floats), e.g. ``{"dt": 0.02, "r": 400.0, "E": 5.0}``.
        units: unit per name, for the messages.
        period: wall seconds between looks at the graph.
    """

    def __init__(self, node, mine: dict, units: dict | None = None, period: float = 1.0):
        self.node, self.mine, self.units = node, dict(mine), dict(units or {})
        self.asked: dict[str, object] = {}        # plant node's full name -> client
        self.findings: dict[str, tuple[list[str], list[str]]] = {}
        self._timer = node.create_timer(period, self._look, clock=Clock(clock_type=ClockType.STEADY_TIME))

    def _look(self) -> None:
        for info in self.node.get_publishers_info_by_topic(STATE):
            ns = info.node_namespace.rstrip("/")
            full = f"{ns}/{info.node_name}"
            if full in self.asked or info.node_name.startswith("_"):
                continue
            client = self.node.create_client(GetParameters, f"{full}/get_parameters")
            self.asked[full] = client
            self._ask(full, client, tries=20)

    def _ask(self, full: str, client, tries: int) -> None:
        if not client.service_is_ready():
            if tries > 0:           # the plant's services are discovered a little after its topics
                t = self.node.create_timer(0.5, lambda: (self.node.destroy_timer(t), self._ask(full, client,
                                                                                              tries - 1)),
                                           clock=Clock(clock_type=ClockType.STEADY_TIME))
            return
        names = list(self.mine)
        future = client.call_async(GetParameters.Request(names=names))
        future.add_done_callback(lambda f: self._answer(full, names, f))

    def _answer(self, full: str, names: list, future) -> None:
        res = future.result()
        if res is None:
            return
        theirs = {n: _value(v) for n, v in zip(names, res.values)}
        bad, model = compare(self.mine, theirs)
        self.findings[full] = (bad, model)
        log = self.node.get_logger()
        for n in bad:
            u = f" {self.units[n]}" if self.units.get(n) else ""
            log.error(f"parameter {n} = {self.mine[n]:g}{u} differs from plant {full}'s {n} = {theirs[n]:g}{u}: they "
                      f"must be equal (restart {self.node.get_name()} with -p {n}:={theirs[n]:g})")
        if model:
            log.info("model parameters differ from the simulated plant's (expected: the plant stands for the real "
                     "kite): " + ", ".join(f"{n} {self.mine[n]:g} (plant {theirs[n]:g})" for n in model))
        if not bad:
            log.info(f"plant {full}: {', '.join(f'{n} = {theirs[n]:g}' for n in MUST_AGREE if n in theirs)} agree")
