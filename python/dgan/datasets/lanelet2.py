"""Lanelet2 maps (OSM XML: INTERACTION, Autoware and much of the HD-map tooling) and INTERACTION track files.

:func:`lanelet2_map` reads a ``.osm`` Lanelet2 map into a :class:`~dgan.VectorMap`:

=====================  ==========================================================================================
engine kind            Lanelet2 elements
=====================  ==========================================================================================
``lane_centerline``    every lanelet but crosswalks, bicycle lanes and walkways: the line midway between its left
                       and right bounds
``lane_line_dashed``   ``line_thin`` / ``line_thick`` ways of subtype ``dashed``
``lane_line_solid``    ``line_thin`` / ``line_thick`` ways of the other subtypes (``solid``, ``solid_solid``, ...)
``road_edge``          ``road_border``, ``curbstone``, ``guard_rail``, ``wall``, ``fence`` and ``barrier`` ways
``crosswalk``          lanelets of subtype ``crosswalk``: the region between their bounds
``bike_lane``          lanelets of subtype ``bicycle_lane``: the region between their bounds
``obstacle``           areas (multipolygons) of subtype ``keepout``, ``building``, ``vegetation`` or ``parking``
=====================  ==========================================================================================

``virtual`` ways (bounds without paint) are not drawn; every other way or relation type that is not drawn (stop
lines, traffic signs, regulatory elements, walkways ...) is named in a :class:`~dgan.exceptions.DatasetWarning`
with its count.

Positions: nodes with ``local_x`` / ``local_y`` tags (Autoware maps) are taken as metres as they are; otherwise
latitude and longitude are projected as Lanelet2's ``UtmProjector`` does: the UTM zone of ``origin``, relative to
``origin`` (INTERACTION's maps use the origin (0, 0)); ``projection="local"`` takes a tangent plane at ``origin``
instead (no pyproj needed; within 0.2% of UTM over a few kilometres near the zone's centre).
"""

from __future__ import annotations

import os
import re
import xml.etree.ElementTree as ET
from collections import Counter
from pathlib import Path
from typing import Any, Final

import numpy as np
import numpy.typing as npt

from dgan.datasets.argoverse2 import _long_rows
from dgan.datasets.scenario import Element, Scenario, _Tracks, midline, resample, warn_unmapped
from dgan.exceptions import InvalidFrameError, InvalidMapError
from dgan.maps import VectorMap

Arr = npt.NDArray[Any]

LINE_EDGES: Final = frozenset({"road_border", "curbstone", "guard_rail", "wall", "fence", "barrier"})
AREA_OBSTACLES: Final = frozenset({"keepout", "building", "vegetation", "parking"})
#: WGS84 equatorial radius, metres (the tangent-plane projection).
EARTH_RADIUS_M: Final = 6_378_137.0
#: INTERACTION agent types → engine classes.
INTERACTION_CLASSES: Final = {
    "car": "vehicle",
    "truck": "vehicle",
    "bus": "vehicle",
    "pedestrian": "pedestrian",
    "pedestrian/bicycle": "pedestrian",
    "bicycle": "cyclist",
}


def _projector(origin: tuple[float, float], projection: str) -> Any:
    """lat, lon arrays → x, y metres relative to ``origin`` = (lat, lon)."""
    lat0, lon0 = (float(v) for v in origin)
    if projection == "local":

        def local(lat: Arr, lon: Arr) -> tuple[Arr, Arr]:
            x = EARTH_RADIUS_M * np.cos(np.radians(lat0)) * np.radians(lon - lon0)
            return x, EARTH_RADIUS_M * np.radians(lat - lat0)

        return local
    if projection != "utm":
        raise InvalidMapError(f"projection must be 'utm' or 'local', got {projection!r}")
    try:
        from pyproj import Transformer
    except ImportError:
        raise InvalidMapError(
            "projecting a Lanelet2 map to UTM needs pyproj (pip install 'dgan[lanelet2]'), or pass projection='local'"
        ) from None
    zone = int((lon0 + 180.0) // 6.0) % 60 + 1
    epsg = (32600 if lat0 >= 0 else 32700) + zone
    to_utm = Transformer.from_crs("EPSG:4326", f"EPSG:{epsg}", always_xy=True)
    x0, y0 = to_utm.transform(lon0, lat0)

    def utm(lat: Arr, lon: Arr) -> tuple[Arr, Arr]:
        x, y = to_utm.transform(lon, lat)
        return np.asarray(x) - x0, np.asarray(y) - y0

    return utm


def _nodes(root: ET.Element, origin: tuple[float, float], projection: str) -> dict[str, Arr]:
    """Node id → ``(2,)`` metres."""
    ids, lat, lon, local = [], [], [], []
    for n in root.iter("node"):
        tags = {t.get("k"): t.get("v") for t in n.iter("tag")}
        ids.append(n.get("id", ""))
        lat.append(float(n.get("lat", "nan")))
        lon.append(float(n.get("lon", "nan")))
        local.append((float(tags.get("local_x") or "nan"), float(tags.get("local_y") or "nan")))
    loc = np.asarray(local, dtype=np.float64).reshape(-1, 2)
    if len(ids) and np.isfinite(loc).all():
        xy = loc
    else:
        x, y = _projector(origin, projection)(np.asarray(lat), np.asarray(lon))
        xy = np.c_[x, y]
    return dict(zip(ids, xy, strict=True))


def _tags(el: ET.Element) -> dict[str, str]:
    return {str(t.get("k")): str(t.get("v")) for t in el.iter("tag")}


def _aligned(left: Arr, right: Arr) -> Arr:
    """``right`` pointing the way ``left`` does (Lanelet2 bounds may be stored in either direction)."""
    same = np.linalg.norm(left[0] - right[0]) + np.linalg.norm(left[-1] - right[-1])
    flipped = np.linalg.norm(left[0] - right[-1]) + np.linalg.norm(left[-1] - right[0])
    return right[::-1] if flipped < same else right


def _way_element(tags: dict[str, str], pts: Arr) -> Element | str | None:
    """A way's element, None for one not drawn on purpose, or the name of its type when it is not mapped."""
    kind, sub = tags.get("type", ""), tags.get("subtype", "")
    if kind in ("line_thin", "line_thick"):
        return ("lane_line_dashed" if sub == "dashed" else "lane_line_solid", pts)
    if kind in LINE_EDGES:
        return ("road_edge", pts)
    if kind in ("virtual", ""):
        return None  # a bound without paint, or a way that only shapes a relation
    return f"way {kind}"


def _relation_elements(root: ET.Element, ways: dict[str, Arr], unmapped: Counter[str]) -> list[Element]:
    out: list[Element] = []
    for rel in root.iter("relation"):
        tags = _tags(rel)
        kind, sub = tags.get("type", ""), tags.get("subtype", "")
        members = {m.get("role"): ways.get(str(m.get("ref"))) for m in rel.iter("member") if m.get("type") == "way"}
        if kind == "lanelet":
            left, right = members.get("left"), members.get("right")
            if left is None or right is None:
                unmapped["lanelet without both bounds"] += 1
                continue
            right = _aligned(left, right)
            if sub in ("crosswalk", "bicycle_lane"):
                n = max(len(left), len(right), 2)
                poly = np.vstack([resample(left, n), resample(right, n)[::-1]])
                out.append(("crosswalk" if sub == "crosswalk" else "bike_lane", poly))
            elif sub == "walkway":
                unmapped["lanelet walkway"] += 1
            else:
                out.append(("lane_centerline", midline(left, right)))
        elif kind == "multipolygon" and sub in AREA_OBSTACLES and (outer := members.get("outer")) is not None:
            out.append(("obstacle", outer))
        else:
            unmapped[f"{kind or 'relation'} {sub}".strip()] += 1
    return out


def lanelet2_map(
    path: str | os.PathLike[str], origin: tuple[float, float] = (0.0, 0.0), *, projection: str = "utm"
) -> VectorMap:
    """A Lanelet2 OSM map as a vector map in metres (see the module's table).

    Args:
        origin: (latitude, longitude) of the map's projection origin, as given to Lanelet2's ``UtmProjector``
            ((0, 0) for INTERACTION).
        projection: ``"utm"`` (Lanelet2's, needs pyproj) or ``"local"`` (a tangent plane at ``origin``).

    Raises:
        InvalidMapError: a file that is not a readable Lanelet2 OSM map.
    """
    path = Path(path)
    try:
        root = ET.parse(path).getroot()
    except (OSError, ET.ParseError) as e:
        raise InvalidMapError(f"cannot read Lanelet2 map {path}: {e}") from None
    if root.tag != "osm":
        raise InvalidMapError(f"{path} is not an OSM file (root <{root.tag}>)")
    nodes = _nodes(root, origin, projection)
    ways: dict[str, Arr] = {}
    elements: list[Element] = []
    unmapped: Counter[str] = Counter()
    for way in root.iter("way"):
        refs = [nodes.get(str(nd.get("ref"))) for nd in way.iter("nd")]
        if any(r is None for r in refs) or len(refs) < 2:
            unmapped["way with missing nodes"] += 1
            continue
        pts = np.asarray(refs, dtype=np.float64)
        ways[str(way.get("id"))] = pts
        element = _way_element(_tags(way), pts)
        if isinstance(element, str):
            unmapped[element] += 1
        elif element is not None:
            elements.append(element)
    elements += _relation_elements(root, ways, unmapped)
    warn_unmapped(path, unmapped)
    if not elements:
        raise InvalidMapError(f"{path}: no lanelet, line or border that dgan draws")
    return VectorMap(elements)


#: INTERACTION's pedestrian track ids (``P1``, ``P2``, ...) as the engine's integer ids: this offset plus their
#: number, so that they never meet a vehicle's id when a recording's two track files are read as one scene.
PEDESTRIAN_ID_OFFSET: Final = 1_000_000

#: An INTERACTION recording's track file: ``vehicle_tracks_007.csv`` or ``pedestrian_tracks_007.csv``.
_TRACK_FILE: Final = re.compile(r"^(vehicle|pedestrian)_tracks_(\w+)\.csv$")


def interaction_companion(tracks_csv: str | os.PathLike[str]) -> Path | None:
    """The other track file of the same INTERACTION recording beside ``tracks_csv`` (``pedestrian_tracks_007.csv``
    for ``vehicle_tracks_007.csv`` and the other way round), or None where there is none: INTERACTION keeps a
    recording's pedestrians and cyclists apart from its vehicles, on the same frames."""
    path = Path(tracks_csv)
    m = _TRACK_FILE.match(path.name)
    if m is None:
        return None
    other = path.with_name(f"{'pedestrian' if m[1] == 'vehicle' else 'vehicle'}_tracks_{m[2]}.csv")
    return other if other.is_file() else None


def read_interaction(
    tracks_csv: str | os.PathLike[str],
    map_osm: str | os.PathLike[str] | None = None,
    origin: tuple[float, float] = (0.0, 0.0),
    companion: bool = True,
) -> Scenario:
    """An INTERACTION track file (``vehicle_tracks_*.csv`` or ``pedestrian_tracks_*.csv``: ``track_id, frame_id,
    timestamp_ms, agent_type, x, y[, vx, vy, psi_rad, length, width]``, 10 Hz) with its Lanelet2 map. With
    ``companion``, the recording's other track file beside it (:func:`interaction_companion`) joins it: one scene of
    every agent, on the recording's frames. Pedestrian ids ``P<n>`` become :data:`PEDESTRIAN_ID_OFFSET` + n."""
    path = Path(tracks_csv)
    other = interaction_companion(path) if companion else None
    rows = _track_rows(path) + ([] if other is None else _track_rows(other))
    try:
        num = {k: np.array([float(r.get(k) or "nan") for r in rows]) for k in ("x", "y", "psi_rad", "length", "width")}
    except ValueError as e:
        raise InvalidFrameError(f"{path}: {e} (x, y, psi_rad, length and width must be numbers)") from None
    labels = np.array([INTERACTION_CLASSES.get(r["agent_type"], "") for r in rows], dtype=object)
    unknown = sorted({r["agent_type"] for r in rows} - INTERACTION_CLASSES.keys())
    if unknown:
        raise InvalidFrameError(f"{path}: agent types {unknown} have no engine class")
    frame = np.array([r["frame_id"] for r in rows])
    track = np.array([r["track_id"] for r in rows])
    step = frame - frame.min()
    tracks = _Tracks()
    xy = np.c_[num["x"], num["y"]]
    sizes = (num["psi_rad"], num["length"], num["width"])
    _long_rows(tracks, track, step, int(step.max()) + 1, labels, xy, *sizes, unknown_heading=np.nan)
    elements = [] if map_osm is None else lanelet2_map(map_osm, origin).elements()
    return tracks.scenario(path, path.stem, "interaction", 0.1, elements)


def _track_rows(path: Path) -> list[dict[str, Any]]:
    """An INTERACTION track file's rows, their ``frame_id`` and ``track_id`` as integers (``P<n>``, a pedestrian's,
    as :data:`PEDESTRIAN_ID_OFFSET` + n)."""
    import csv

    try:
        with path.open(newline="") as f:
            rows: list[dict[str, Any]] = list(csv.DictReader(f))
    except (OSError, UnicodeDecodeError, csv.Error) as e:
        raise InvalidFrameError(f"cannot read INTERACTION tracks {path}: {e}") from None
    need = {"track_id", "frame_id", "agent_type", "x", "y"}
    if not rows or not need <= rows[0].keys():
        raise InvalidFrameError(f"{path}: not an INTERACTION track file (needs {sorted(need)})")
    for k, r in enumerate(rows, 2):
        track_id, frame_id = str(r["track_id"]).strip(), str(r["frame_id"]).strip()
        number = track_id[1:] if track_id[:1] == "P" else track_id
        if not (number.isdigit() and frame_id.isdigit()):
            raise InvalidFrameError(
                f"{path}, line {k}: track_id {track_id!r} must be a whole number (P and one for a pedestrian) and "
                f"frame_id {frame_id!r} a whole number"
            )
        r["track_id"] = int(number) + (PEDESTRIAN_ID_OFFSET if number != track_id else 0)
        r["frame_id"] = int(frame_id)
    return rows
