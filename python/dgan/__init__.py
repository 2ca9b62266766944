"""dgan: multi-modal trajectory prediction with the Dynamic Graph Attention Network.

>>> import dgan
>>> predictor = dgan.Predictor("model.onnx")          # doctest: +SKIP
>>> prediction = predictor.predict(dgan.Frame(positions))  # doctest: +SKIP
"""

from __future__ import annotations

from dgan import demo, exceptions, io, metrics, models, scenes
from dgan._dgan import __version__
from dgan.exceptions import DganError
from dgan.frame import CLASSES, MAP_ELEMENT_KINDS, Frame, RasterMap, VectorMap
from dgan.predictor import Prediction, Predictor, available_execution_providers
from dgan.scenes import scene_map
from dgan.spec import (
    InputSpec,
    MapSpec,
    PriorSpec,
    attention_graph,
    kinematic_prior,
    preprocess,
    to_agent_frame,
    to_world_frame,
)
from dgan.tracker import Tracker
from dgan.viz import plot

__all__ = [
    "CLASSES",
    "MAP_ELEMENT_KINDS",
    "DganError",
    "Frame",
    "InputSpec",
    "MapSpec",
    "Prediction",
    "Predictor",
    "PriorSpec",
    "RasterMap",
    "Tracker",
    "VectorMap",
    "__version__",
    "attention_graph",
    "available_execution_providers",
    "demo",
    "exceptions",
    "io",
    "kinematic_prior",
    "metrics",
    "models",
    "plot",
    "preprocess",
    "scene_map",
    "scenes",
    "to_agent_frame",
    "to_world_frame",
]
