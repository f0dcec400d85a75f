"""Generalized Modifier Adaptation (GMA): a generic real-time optimization core.

Plant and model may have different inputs: the plant takes setpoints ``c``, the model takes ``u`` and
predicts the controlled variables ``y(u)``. With ``y(u) = u`` this is standard Modifier Adaptation.
The core knows nothing about kites and never imports ``rclpy``. See ``docs/gma.md``.

The iteration (:class:`GMA`) is small; optional mechanisms take part at named points of it
(:mod:`~kite_rto.gma.mechanism`), each configured by its own settings object in :class:`GMASettings`
(``None`` = off): :class:`ModifierFilter`, :class:`NoiseFilter`, :class:`TrustRegion`, :class:`SafeStep`,
:class:`Undo`, :class:`BoundHold`, :class:`ModelSecant`, :class:`Settle`.
"""
from .bound_hold import BoundHold, bound_side
from .directional import DirectionalGradient, PrivilegedDirections, lagrangian_gradient, privileged_directions
from .gma import GMA
from .gradients import (FiniteDifferenceGradient, GradientEstimate, GradientEstimator, LeastSquaresGradient,
                        PlantPoint)
from .mechanism import Iteration, Mechanism
from .model_secant import ModelSecant
from .modifier_filter import ModifierFilter, NoiseFilter
from .modifiers import Decision, ModelRealization, Modifiers
from .offline import run_offline
from .problem import ModelProblem
from .records import ExperimentRequest, ExperimentResult, History, IterationRecord
from .robust_bounds import BoundActivity, model_optimum, robust_bounds
from .safe_step import SafeStep
from .settle import Settle
from .settings import MECHANISMS, GMASettings, ModelSettings
from .store import HistoryStore, StoreError
from .trust_region import TrustRegion
from .undo import Undo

__all__ = ["HistoryStore", "StoreError",
           "ModelProblem", "GMASettings", "ModelSettings", "MECHANISMS", "GMA", "ModelRealization", "Modifiers",
           "Decision", "Mechanism", "Iteration",
           "ModifierFilter", "NoiseFilter", "TrustRegion", "SafeStep", "Undo", "BoundHold", "ModelSecant", "Settle",
           "GradientEstimator", "GradientEstimate", "PlantPoint", "FiniteDifferenceGradient", "LeastSquaresGradient",
           "DirectionalGradient", "PrivilegedDirections", "privileged_directions", "lagrangian_gradient",
           "ExperimentRequest", "ExperimentResult", "IterationRecord", "History", "run_offline",
           "BoundActivity", "robust_bounds", "bound_side", "model_optimum"]
