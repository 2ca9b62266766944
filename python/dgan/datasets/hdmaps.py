"""Driving scenarios with vector HD maps: nuScenes and Waymo in ScenarioNet pickles, Waymo Open Motion in
GPUDrive/Nocturne JSON, and Argoverse 2 (map JSON; scenario parquet and sensor-log feather tracks).

Each reader returns a :class:`Scenario`: every agent's states on the source's time grid and the scene's
:class:`~dgan.frame.VectorMap`. :meth:`Scenario.frame` cuts a :class:`~dgan.frame.Frame` at any step and rate.

How the source map types become the engine's element kinds (``dgan.MAP_ELEMENT_KINDS``), drawn in the paper's colours:

=====================  ==========================================================================================
engine kind            source elements
=====================  ==========================================================================================
``lane_centerline``    lane centre lines (nuScenes lanes and connectors, Waymo lanes of every road type but bike
                       lanes, Argoverse vehicle and bus lane centre lines)
``lane_line_dashed``   broken road lines (white or yellow); Argoverse ``DASHED_*`` lane marks
``lane_line_solid``    solid and double road lines (white or yellow); Argoverse ``SOLID_*``/``DOUBLE_*`` marks
``road_edge``          road boundaries (nuScenes ``boundary_*``, Waymo ``ROAD_EDGE_BOUNDARY``, Argoverse drivable
                       area outlines)
``crosswalk``          crosswalk polygons (Waymo, Argoverse; the nuScenes conversion has none)
``bike_lane``          bike lanes as regions: Waymo's bike-lane centre lines widened to 1.5 m, Argoverse bike lane
                       segments between their two boundaries
``obstacle``           medians (Waymo ``ROAD_EDGE_MEDIAN``, widened to 0.6 m) and static objects (nuScenes traffic
                       cones and barriers, Argoverse ``static`` tracks) as their boxes
=====================  ==========================================================================================

Left out: driveways, stop signs and speed bumps (Waymo), nuScenes lane-area polygons, traffic lights.

Pickles execute code when loaded: read only ScenarioNet files you trust.
"""

from __future__ import annotations

import gzip
import os
from pathlib import Path
from typing import Any

from dgan.datasets import JSON_SUFFIXES, PICKLE_SUFFIXES
from dgan.datasets.argoverse2 import (
    AV2_SCENARIO_CLASSES,
    AV2_SENSOR_CLASSES,
    AV2_SENSOR_STATIC,
    av2_map,
    read_av2_scenario,
    read_av2_sensor_log,
)
from dgan.datasets.scenario import BIKE_LANE_WIDTH_M, MEDIAN_WIDTH_M, Element, Scenario, bird_eye, box, midline, widen
from dgan.datasets.scenarionet import SCENARIONET_CLASSES, SCENARIONET_STATIC, read_scenarionet, scenarionet_map
from dgan.datasets.waymo_json import WAYMO_BROKEN_LINES, WAYMO_INVALID, read_waymo_json, waymo_json_map
from dgan.exceptions import InvalidFrameError

__all__ = [
    "AV2_SCENARIO_CLASSES",
    "AV2_SENSOR_CLASSES",
    "AV2_SENSOR_STATIC",
    "BIKE_LANE_WIDTH_M",
    "MEDIAN_WIDTH_M",
    "SCENARIONET_CLASSES",
    "SCENARIONET_STATIC",
    "WAYMO_BROKEN_LINES",
    "WAYMO_INVALID",
    "Element",
    "Scenario",
    "av2_map",
    "bird_eye",
    "box",
    "midline",
    "read_av2_scenario",
    "read_av2_sensor_log",
    "read_scenario",
    "read_scenarionet",
    "read_waymo_json",
    "scenarionet_map",
    "waymo_json_map",
    "widen",
]


def read_scenario(path: str | os.PathLike[str]) -> Scenario:
    """Any supported source by its path: ``*.pkl``/``*.pkl.gz`` (ScenarioNet, MetaDrive), ``*.json``/``*.json.gz``
    (GPUDrive/Nocturne Waymo, or ScenarioNet's JSON), an Argoverse 2 scenario folder (``scenario_*.parquet``) or
    sensor-log folder (``annotations.feather``)."""
    path = Path(path)
    if path.is_dir():
        if (path / "annotations.feather").is_file():
            return read_av2_sensor_log(path)
        return read_av2_scenario(path)
    name = path.name.lower()
    if name.endswith(PICKLE_SUFFIXES):
        return read_scenarionet(path)
    if name.endswith(JSON_SUFFIXES):
        return read_waymo_json(path) if _is_gpudrive(path) else read_scenarionet(path)
    raise InvalidFrameError(
        f"unknown scenario format: {path} (expected .pkl[.gz], .json[.gz] or an Argoverse 2 folder)"
    )


def _is_gpudrive(path: Path) -> bool:
    """Whether a JSON scenario is GPUDrive/Nocturne's (``objects`` and ``roads``) rather than ScenarioNet's."""
    opener: Any = gzip.open if path.name.lower().endswith(".gz") else open
    try:
        with opener(path, "rt") as fh:
            head = fh.read(1 << 16)
    except (OSError, EOFError, UnicodeDecodeError):
        return True  # the GPUDrive reader reports what is wrong with the file
    return '"objects"' in head or ('"map_features"' not in head and '"tracks"' not in head)
