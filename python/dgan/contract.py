"""What the engine owns about the model contract, derived from ``dgan._dgan.CONTRACT`` (``dgan-core``): nothing in
the package, training or tests types these lists again (a test fails on a new literal copy).

Attributes:
    VERSION: the contract version exporters write; ``SUPPORTED_VERSIONS`` those the engine reads.
    RASTER_VERSION, PREPROCESS_VERSION: what a crop and the features hold; written into every exported model and
        into the training window-cache key (:data:`CACHE_KEY`).
    CLASSES: the agent classes by canonical integer code; ``CLASS_SIZES_M`` their default (length, width).
    MAP_KINDS: the vector-map element kinds in drawing order, each a :class:`MapKind`; ``MAP_ELEMENT_KINDS`` their
        names.
    STATE_FEATURES, EDGE_FEATURES: the columns of the traffic-state vector (a one-hot class follows them) and of
        each edge.
    EDGE_LIST_INPUTS, PADDED_INPUTS: the network inputs of each graph layout, in the contract's order (a model
        takes those its spec needs); ``OUTPUTS`` the network outputs.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass
from typing import Final

from dgan import _dgan

_C: Final = _dgan.CONTRACT


@dataclass(frozen=True)
class MapKind:
    """A vector-map element kind as the rasteriser draws it."""

    name: str
    polygon: bool
    colour: tuple[int, int, int]
    #: Line width in metres (None for a filled polygon).
    width_m: float | None


VERSION: Final[int] = _C["version"]
SUPPORTED_VERSIONS: Final[tuple[int, ...]] = tuple(_C["supported_versions"])
RASTER_VERSION: Final[int] = _C["raster_version"]
PREPROCESS_VERSION: Final[int] = _C["preprocess_version"]
METADATA_KEY: Final[str] = _C["metadata_key"]
CLASSES: Final[tuple[str, ...]] = tuple(_C["classes"])
CLASS_SIZES_M: Final[dict[str, tuple[float, float]]] = dict(_C["class_sizes_m"])
MAP_KINDS: Final[tuple[MapKind, ...]] = tuple(MapKind(**k) for k in _C["map_kinds"])
MAP_ELEMENT_KINDS: Final[tuple[str, ...]] = tuple(k.name for k in MAP_KINDS)
AGENT_COLOUR: Final[tuple[int, int, int]] = tuple(_C["agent_colour"])
STATE_FEATURES: Final[tuple[str, ...]] = tuple(_C["state_features"])
EDGE_FEATURES: Final[tuple[str, ...]] = tuple(_C["edge_features"])
#: The state and edge columns that change sign when a scene is mirrored across the agents' x axes (y → −y).
STATE_MIRRORED: Final[tuple[str, ...]] = tuple(_C["state_mirrored"])
EDGE_MIRRORED: Final[tuple[str, ...]] = tuple(_C["edge_mirrored"])
EDGE_LIST_INPUTS: Final[tuple[str, ...]] = tuple(_C["inputs"]["edge_list"])
PADDED_INPUTS: Final[tuple[str, ...]] = tuple(_C["inputs"]["padded"])
#: A scene model's inputs after ``map_present`` (contract 12): where its agents read the frame's raster.
SCENE_GRID_INPUTS: Final[tuple[str, ...]] = EDGE_LIST_INPUTS[EDGE_LIST_INPUTS.index("map_present") + 1 :]
#: A scene model's inputs after ``map_present`` when its features are kept with the map (contract 13): the kept
#: rows and where each agent reads them.
KEPT_INPUTS: Final[tuple[str, ...]] = tuple(_C["inputs"]["kept"][_C["inputs"]["kept"].index("map_present") + 1 :])
OUTPUTS: Final[tuple[str, ...]] = tuple(_C["outputs"])
#: The output of a model with kept features (contract 13): the features of the tiles a call computed.
KEPT_OUTPUT: Final[str] = _C["kept_output"]
#: Keys what the engine's preprocessing produces, for caches of its output.
CACHE_KEY: Final = f"contract{VERSION}-raster{RASTER_VERSION}-preprocess{PREPROCESS_VERSION}"


def state_width(classes: Sequence[str]) -> int:
    """Width of the traffic-state vector of a model of these classes: the state features and a one-hot class."""
    return len(STATE_FEATURES) + len(classes)


def map_kind(name: str) -> MapKind:
    """The :class:`MapKind` called ``name`` (KeyError for none)."""
    for kind in MAP_KINDS:
        if kind.name == name:
            return kind
    raise KeyError(f"unknown map element kind {name!r}; known kinds: {', '.join(MAP_ELEMENT_KINDS)}")
