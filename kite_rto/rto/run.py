"""A GMA run on the kite, described once (:class:`RunDescription`): the settings every part of the run takes its
values from, and the simulated plant it flew, stored with the run and read back to judge it.

The model problem, GMA, the baselines, the oracle and the judge all take their values from it: the experiment
spec (h_min, laps, settling), the effort schedule, the box, the OCP options. The optimizer stores it in its
database (meta key :data:`RUN_KEY`) and publishes it, so recordings hold it too; the report judges a run against
its own plant and floor.
"""
from __future__ import annotations

import json
from dataclasses import dataclass

from ..gma.plain import from_plain, to_plain
from ..kite.plant import PlantConfig
from .settings import KiteRTOSettings

__all__ = ["RunDescription", "RUN_KEY"]

RUN_KEY = "run"
"""Meta key of the run's :class:`RunDescription` in the optimizer's database."""


@dataclass(frozen=True)
class RunDescription:
    """A run of GMA on the kite.

    Attributes:
        settings: the optimizer's :class:`~kite_rto.rto.settings.KiteRTOSettings`.
        plant: the simulated plant it flew (:class:`~kite_rto.kite.plant.PlantConfig`); ``None`` when not known (a
            real plant, or a plant that did not say): such a run cannot be judged on a deterministic plant.
    """

    settings: KiteRTOSettings
    plant: PlantConfig | None = None

    def __post_init__(self):
        if not isinstance(self.settings, KiteRTOSettings):
            raise ValueError(f"RunDescription.settings = {self.settings!r}: expected a KiteRTOSettings")
        if self.plant is not None and not isinstance(self.plant, PlantConfig):
            raise ValueError(f"RunDescription.plant = {self.plant!r}: expected a PlantConfig or None")

    @property
    def h_min(self) -> float:
        """The run's minimum altitude, m (its experiment's)."""
        return self.settings.experiment.h_min

    def to_dict(self) -> dict:
        """Plain JSON data (:func:`~kite_rto.gma.plain.to_plain`)."""
        return to_plain(self)

    @classmethod
    def from_dict(cls, data: dict) -> "RunDescription":
        """Inverse of :meth:`to_dict`; ``ValueError`` names an unknown or bad field."""
        return from_plain(cls, data)

    def to_json(self) -> str:
        return json.dumps(self.to_dict(), allow_nan=False, sort_keys=True)

    @classmethod
    def from_json(cls, text: str) -> "RunDescription":
        try:
            data = json.loads(text)
        except json.JSONDecodeError as err:
            raise ValueError(f"RunDescription: not JSON ({err})") from None
        return cls.from_dict(data)
