"""dgan: multi-modal trajectory prediction with the Dynamic Graph Attention Network.

>>> import dgan
>>> predictor = dgan.Predictor("model.onnx")          # doctest: +SKIP
>>> prediction = predictor.predict(dgan.Frame(positions))  # doctest: +SKIP
"""

from __future__ import annotations

from dgan import contract, demo, evaluation, exceptions, layouts, metrics, models, scenes, series, tables
from dgan._dgan import __version__
from dgan.contract import CLASSES, MAP_ELEMENT_KINDS
from dgan.evaluation import evaluate
from dgan.exceptions import DganError
from dgan.frame import Frame
from dgan.labels import COMMON_CLASS_NAMES
from dgan.maps import RasterMap, VectorMap
from dgan.prediction import Prediction
from dgan.predictor import Predictor, available_execution_providers
from dgan.records import sample_track
from dgan.scenes import scene_map
from dgan.spec import (
    ClassPrior,
    InputSpec,
    MapSpec,
    PriorSpec,
    SceneSpec,
    attention_graph,
    crop_grid,
    kinematic_prior,
    preprocess,
    read_kept,
    scene_raster,
    still_agents,
    to_agent_frame,
    to_world_frame,
)
from dgan.tracker import Tracker
from dgan.viz import plot

__all__ = [
    "CLASSES",
    "COMMON_CLASS_NAMES",
    "MAP_ELEMENT_KINDS",
    "ClassPrior",
    "DganError",
    "Frame",
    "InputSpec",
    "MapSpec",
    "Prediction",
    "Predictor",
    "PriorSpec",
    "RasterMap",
    "SceneSpec",
    "Tracker",
    "VectorMap",
    "__version__",
    "attention_graph",
    "available_execution_providers",
    "contract",
    "crop_grid",
    "demo",
    "evaluate",
    "evaluation",
    "exceptions",
    "kinematic_prior",
    "layouts",
    "metrics",
    "models",
    "plot",
    "preprocess",
    "read_kept",
    "sample_track",
    "scene_map",
    "scene_raster",
    "scenes",
    "series",
    "still_agents",
    "tables",
    "to_agent_frame",
    "to_world_frame",
]
