"""Effort matched to noise (issue #14 item 4): fly an iteration's gradient experiments again while they are noisy.

A perturbation experiment measures the plant's cost change ``f_j - f_0`` from the nominal point ``c_k`` to
``c_j``; its standard error is ``sqrt(s_j^2 + s_0^2)`` (the results' ``cost_std``). When that error is larger than
``noise_ratio`` times the change itself, the difference quotient ``(f_j - f_0) / |c_j - c_0|`` (the directional
derivative the estimator fits) has an uncertain size and maybe sign. :class:`~kite_rto.gma.GMA` then asks for the
nominal and every perturbation experiment of the iteration once more (``purpose = "repeat"``,
``ExperimentRequest.repeat_of``), up to ``GMASettings.max_repeats_noise`` times, and gives the estimator each point
averaged over its flights (:func:`average`): the mean, with standard deviation ``sqrt(sum s_i^2) / n``. Every
point is flown equally often, so each estimator's own standard-error formula shrinks as ``1 / sqrt(n)``.

The decision depends on the finished experiments only, so a resumed run (:mod:`~kite_rto.gma.store`) takes the same
decisions and asks for the same repeats, whether its stored plan already held them or not.
"""
from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Sequence

import numpy as np

from .gradients import PlantPoint
from .records import ExperimentRequest, ExperimentResult

__all__ = ["average", "fold_repeats", "NoiseTest", "noise_test", "repeat_requests"]


def average(points: Sequence[PlantPoint]) -> PlantPoint:
    """One point from repeated measurements at the same setpoints: mean cost and constraints; standard deviations
    ``sqrt(sum s_i^2) / n`` (``None`` unless every point has one). A single point is returned as it is."""
    if len(points) == 0:
        raise ValueError("average: expected at least one plant point")
    if len(points) == 1:
        return points[0]
    n = len(points)
    cost = float(np.mean([p.cost for p in points]))
    g = np.mean([np.asarray(p.constraints, float) for p in points], axis=0)

    def mean_std(stds):
        if any(s is None for s in stds):
            return None
        return np.sqrt(np.sum(np.square(np.asarray(stds, float)), axis=0)) / n

    s_f = mean_std([p.cost_std for p in points])
    s_g = mean_std([p.constraints_std for p in points])
    return PlantPoint(np.asarray(points[0].c, float), cost, g, None if s_f is None else float(s_f), s_g)


def fold_repeats(pairs: Sequence[tuple[ExperimentRequest, ExperimentResult]]
                 ) -> list[tuple[ExperimentRequest, list[ExperimentResult]]]:
    """Group finished experiments with their repeats: ``(request, [its result, the repeats' results...])`` in the
    order of the original requests. A repeat whose original is not among ``pairs`` stands as its own point."""
    groups: dict[str, tuple[ExperimentRequest, list[ExperimentResult]]] = {}
    for q, r in pairs:
        key = q.repeat_of if q.repeat_of in groups else q.request_id
        if key in groups:
            groups[key][1].append(r)
        else:
            groups[key] = (q, [r])
    return list(groups.values())


@dataclass
class NoiseTest:
    """The noise of an iteration's measured cost changes (:func:`noise_test`).

    Attributes:
        change: (m,) ``f_j - f_0`` per perturbation, cost units (averaged points).
        std: (m,) its standard error ``sqrt(s_j^2 + s_0^2)``, cost units.
        ratio: the ``noise_ratio`` it was tested with.
        noisy: some ``std > ratio |change|``.
        flights: how often each point has been flown (the nominal's count).
    """

    change: np.ndarray
    std: np.ndarray
    ratio: float
    noisy: bool
    flights: int

    def describe(self, final: bool = True) -> str:
        """One line for ``IterationRecord.notes``; ``final``: no more repeats follow (``max_repeats_noise``)."""
        rel = [round(float(s / abs(c)), 3) if c != 0 else math.inf for c, s in zip(self.change, self.std)]
        verdict = ("precise enough" if not self.noisy else
                   "still noisy, max_repeats_noise reached" if final else "noisy: flown again")
        return (f"noise test after {self.flights} flight(s) per point: std error / |cost change| = {rel} "
                f"(ratio {self.ratio:g}): {verdict}")


def noise_test(nominal: PlantPoint, perturbations: Sequence[PlantPoint], ratio: float, flights: int
               ) -> NoiseTest | None:
    """Test each perturbation's cost change from ``nominal`` against ``ratio`` times its standard error; ``None``
    when there is nothing to test (no perturbation, or a point without ``cost_std``)."""
    if not perturbations or nominal.cost_std is None or any(p.cost_std is None for p in perturbations):
        return None
    change = np.array([p.cost - nominal.cost for p in perturbations])
    std = np.array([math.hypot(p.cost_std, nominal.cost_std) for p in perturbations])
    return NoiseTest(change, std, float(ratio), bool(np.any(std > ratio * np.abs(change))), int(flights))


def repeat_requests(groups: Sequence[tuple[ExperimentRequest, list[ExperimentResult]]], first_index: int,
                    tag: str) -> list[ExperimentRequest]:
    """One more flight of each of ``groups``' requests: ids ``<tag>-<j>-repeat``, ``j`` from ``first_index``."""
    return [ExperimentRequest(f"{tag}-{first_index + i}-repeat", np.asarray(q.c, float).copy(), "repeat",
                              q.iteration, q.settle_time, q.averaging, repeat_of=q.request_id)
            for i, (q, _) in enumerate(groups)]
