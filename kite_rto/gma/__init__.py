"""Generalized Modifier Adaptation (GMA): a generic real-time optimization core.

Plant and model may have different inputs: the plant takes setpoints ``c``, the model takes ``u`` and
predicts the controlled variables ``y(u)``. With ``y(u) = u`` this is standard Modifier Adaptation.
The core knows nothing about kites and never imports ``rclpy``. See ``docs/gma.md``.
"""
from .directional import DirectionalGradient, PrivilegedDirections, lagrangian_gradient, privileged_directions
from .gma import GMA
from .effort import NoiseTest, noise_test
from .gradients import (FiniteDifferenceGradient, GradientEstimate, GradientEstimator, LeastSquaresGradient,
                        PlantPoint)
from .modifiers import Decision, ModelRealization, Modifiers
from .kkt import KKTTest, kkt_test
from .offline import run_offline
from .problem import ModelProblem
from .records import ExperimentRequest, ExperimentResult, History, IterationRecord
from .settings import GMASettings
from .store import HistoryStore, StoreError
from .structure import (BoundActivity, StructureTest, bound_side, excluded_directions, model_optimum,
                        robust_bounds, structure_plan, structure_test)

__all__ = ["HistoryStore", "StoreError",
           "ModelProblem", "GMASettings", "GMA", "ModelRealization", "Modifiers", "Decision",
           "GradientEstimator", "GradientEstimate", "PlantPoint", "FiniteDifferenceGradient", "LeastSquaresGradient",
           "DirectionalGradient", "PrivilegedDirections", "privileged_directions", "lagrangian_gradient",
           "ExperimentRequest", "ExperimentResult", "IterationRecord", "History", "run_offline",
           "BoundActivity", "robust_bounds", "bound_side", "model_optimum", "excluded_directions", "structure_plan",
           "StructureTest", "structure_test", "KKTTest", "kkt_test", "NoiseTest", "noise_test"]
