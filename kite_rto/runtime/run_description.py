"""The run's description (:class:`~kite_rto.rto.run.RunDescription`) between the nodes and in the optimizer's
database: the plant's configuration as JSON (what the plant publishes on ``kite/plant_config``:
:func:`plant_json`, read back by :func:`plant_from_json`) and the description a run's database holds
(:func:`stored_description`, meta key :data:`~kite_rto.rto.run.RUN_KEY`).
"""
from __future__ import annotations

import json

from ..gma.plain import from_plain, to_plain
from ..kite.plant import PlantConfig
from ..rto.run import RUN_KEY, RunDescription

__all__ = ["plant_json", "plant_from_json", "stored_description"]

_EXCERPT = 120
"""Characters of a bad message quoted in its rejection."""


def plant_json(config: PlantConfig) -> str:
    """``config`` as JSON text (:func:`~kite_rto.gma.plain.to_plain`: nested dicts, tuples as lists, infinities as
    ``"inf"``)."""
    return json.dumps(to_plain(config), allow_nan=False, sort_keys=True)


def plant_from_json(text: str) -> PlantConfig:
    """The :class:`PlantConfig` that :func:`plant_json` wrote; ``ValueError`` quoting the text and naming what is
    wrong (not JSON, an unknown field, a bad value)."""
    quoted = repr(text if len(text) <= _EXCERPT else text[:_EXCERPT] + "...")
    try:
        data = json.loads(text)
    except json.JSONDecodeError as err:
        raise ValueError(f"{quoted}: not JSON ({err}); expected a PlantConfig as JSON") from None
    try:
        return from_plain(PlantConfig, data)
    except (ValueError, TypeError, AttributeError) as err:
        raise ValueError(f"{quoted}: not a PlantConfig ({err})") from None


def stored_description(meta: dict, settings) -> tuple[RunDescription, str]:
    """The description stored in a run's ``meta`` (a database's, :data:`RUN_KEY`), and a note for the log ("" when
    it was there and readable); without one, ``RunDescription(settings)`` (the plant not known) and a note."""
    data = meta.get(RUN_KEY)
    if data is None:
        return RunDescription(settings), ("the stored run holds no run description (made by an older version): "
                                          "its plant is known once the plant publishes its configuration")
    try:
        return RunDescription.from_dict(data), ""
    except (ValueError, TypeError, AttributeError) as err:
        return RunDescription(settings), (f"the stored run description cannot be read ({err}): replaced by this "
                                          "optimizer's settings, its plant known once the plant publishes its "
                                          "configuration")
