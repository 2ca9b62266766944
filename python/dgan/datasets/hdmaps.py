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
import json
import os
import pickle
import warnings
from collections import Counter
from collections.abc import Iterable, Mapping, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Final

import numpy as np
import numpy.typing as npt

from dgan.exceptions import DatasetWarning, InvalidFrameError, InvalidMapError
from dgan.frame import Frame, VectorMap

Arr = npt.NDArray[Any]
Element = tuple[str, Arr]

#: Width a bike lane's centre line is widened to, metres.
BIKE_LANE_WIDTH_M: Final = 1.5
#: Width a median's edge line is widened to, metres.
MEDIAN_WIDTH_M: Final = 0.6

#: ScenarioNet (MetaDrive) agent types → engine classes; other types (cones, barriers) are static obstacles.
SCENARIONET_CLASSES: Final = {"VEHICLE": "vehicle", "CYCLIST": "cyclist", "PEDESTRIAN": "pedestrian"}
SCENARIONET_STATIC: Final = frozenset({"TRAFFIC_CONE", "TRAFFIC_BARRIER"})
#: Argoverse 2 motion-forecasting object types → engine classes (``static`` and ``background`` are not agents).
AV2_SCENARIO_CLASSES: Final = {
    "vehicle": "vehicle",
    "bus": "vehicle",
    "motorcyclist": "cyclist",
    "cyclist": "cyclist",
    "riderless_bicycle": "cyclist",
    "pedestrian": "pedestrian",
}
#: Argoverse 2 sensor-log cuboid categories → engine classes; other categories (signs, bollards, cones ...) are
#: static obstacles.
AV2_SENSOR_CLASSES: Final = {
    "REGULAR_VEHICLE": "vehicle",
    "LARGE_VEHICLE": "vehicle",
    "BUS": "vehicle",
    "BOX_TRUCK": "vehicle",
    "TRUCK": "vehicle",
    "TRUCK_CAB": "vehicle",
    "VEHICULAR_TRAILER": "vehicle",
    "ARTICULATED_BUS": "vehicle",
    "SCHOOL_BUS": "vehicle",
    "MESSAGE_BOARD_TRAILER": "vehicle",
    "RAILED_VEHICLE": "vehicle",
    "BICYCLE": "cyclist",
    "BICYCLIST": "cyclist",
    "MOTORCYCLE": "cyclist",
    "MOTORCYCLIST": "cyclist",
    "WHEELED_RIDER": "cyclist",
    "PEDESTRIAN": "pedestrian",
    "STROLLER": "pedestrian",
    "WHEELCHAIR": "pedestrian",
    "OFFICIAL_SIGNALER": "pedestrian",
}
AV2_SENSOR_STATIC: Final = frozenset({"BOLLARD", "CONSTRUCTION_BARREL", "CONSTRUCTION_CONE"})


@dataclass
class Scenario:
    """Agents' states on a regular time grid (``dt_s`` apart) and the scene's vector map, in world metres.

    ``keyframe_every``: only every n-th step holds a real annotation (5 for nuScenes, whose 2 Hz annotations the
    converter interpolated to 10 Hz); the steps between are linear interpolations.
    """

    name: str
    source: str  # "nuscenes", "waymo" or "argoverse2"
    dt_s: float
    ids: Arr  # (N,) i64
    labels: list[str]  # (N,) engine class
    positions: Arr  # (N, T, 2) f64, NaN where invalid
    valid: Arr  # (N, T) bool
    heading: Arr  # (N, T) f64 radians
    length: Arr  # (N, T) f64 metres
    width: Arr  # (N, T) f64 metres
    map: VectorMap
    keyframe_every: int = 1

    @property
    def num_steps(self) -> int:
        return int(self.positions.shape[1])

    def frame(self, now: int, t_obs: int, every: int = 1) -> Frame:
        """The frame at step ``now``: ``t_obs`` steps ``every`` source steps apart, ending at ``now``, with every
        agent valid at ``now``."""
        if not 0 <= now < self.num_steps:
            raise InvalidFrameError(f"step {now} is outside the scenario's 0..{self.num_steps - 1}")
        steps = now - every * np.arange(t_obs - 1, -1, -1)
        inside = steps >= 0
        agents = np.flatnonzero(self.valid[:, now])
        if len(agents) == 0:
            raise InvalidFrameError(f"no agent is valid at step {now} of {self.name}")
        cols = np.where(inside, steps, 0)
        mask = self.valid[np.ix_(agents, cols)] & inside
        return Frame(
            np.where(mask[..., None], self.positions[np.ix_(agents, cols)], np.nan),
            mask=mask,
            classes=[self.labels[i] for i in agents],
            ids=self.ids[agents],
            headings=self.heading[agents, now],
            lengths=self.length[agents, now],
            widths=self.width[agents, now],
            map=self.map,
        )


def _xy(points: Any, what: str) -> Arr:
    """Point lists ``[{x, y, ...}]`` or arrays ``(P, ≥2)`` → ``(P, 2)`` float64."""
    if isinstance(points, list) and points and isinstance(points[0], Mapping):
        arr = np.array([[p["x"], p["y"]] for p in points], dtype=np.float64)
    else:
        arr = np.asarray(points, dtype=np.float64)
    if arr.ndim != 2 or arr.shape[1] < 2:
        raise InvalidMapError(f"{what}: points must have shape (P, 2) or (P, 3), got {arr.shape}")
    return np.ascontiguousarray(arr[:, :2])


def widen(polyline: Arr, width_m: float) -> Arr:
    """The polygon of a polyline widened to ``width_m`` (offset half each side along the vertex normals)."""
    p = np.asarray(polyline, dtype=np.float64)
    keep = np.r_[True, np.linalg.norm(np.diff(p, axis=0), axis=1) > 1e-6]
    p = p[keep]
    if len(p) < 2:
        return p
    seg = np.diff(p, axis=0)
    seg /= np.linalg.norm(seg, axis=1, keepdims=True)
    tangent = np.vstack([seg[:1], seg[:-1] + seg[1:], seg[-1:]])
    tangent /= np.maximum(np.linalg.norm(tangent, axis=1, keepdims=True), 1e-9)
    normal = np.c_[-tangent[:, 1], tangent[:, 0]] * (width_m / 2)
    return np.vstack([p + normal, (p - normal)[::-1]])


def resample(polyline: Arr, n: int) -> Arr:
    """``n`` points evenly spaced by arc length along a polyline."""
    p = np.asarray(polyline, dtype=np.float64)
    s = np.r_[0.0, np.cumsum(np.linalg.norm(np.diff(p, axis=0), axis=1))]
    if s[-1] <= 0:
        return np.repeat(p[:1], n, axis=0)
    t = np.linspace(0.0, s[-1], n)
    out: Arr = np.c_[np.interp(t, s, p[:, 0]), np.interp(t, s, p[:, 1])]
    return out


def midline(left: Arr, right: Arr, n: int = 20) -> Arr:
    """The centre line between a lane's left and right boundaries (both resampled to ``n`` points)."""
    out: Arr = (resample(left, n) + resample(right, n)) / 2
    return out


def box(centre: Arr, heading: float, length: float, width: float) -> Arr:
    """The four corners of an oriented box."""
    c, s = np.cos(heading), np.sin(heading)
    half = np.array([[1, 1], [-1, 1], [-1, -1], [1, -1]]) * [length / 2, width / 2]
    out: Arr = np.asarray(centre, dtype=np.float64)[:2] + half @ np.array([[c, s], [-s, c]])
    return out


class _Tracks:
    """Per-agent state arrays, gathered one agent at a time, and the :class:`Scenario` they make."""

    def __init__(self) -> None:
        self.ids: list[int] = []
        self.labels: list[str] = []
        self.cols: dict[str, list[Arr]] = {k: [] for k in ("positions", "valid", "heading", "length", "width")}
        self.sizeless = 0  # agents with a length or width given but not a positive number where valid
        self.unmapped: Counter[str] = Counter()  # map element types not drawn

    def add(self, agent: int, label: str, xy: Arr, valid: Arr, heading: Arr, length: Arr, width: Arr) -> None:
        """One agent's ``(T, 2)`` positions (anything where invalid), ``(T,)`` validity, heading and size. A size
        that is not a positive number (a box of zero size) is unknown: NaN, the class default in a frame."""
        self.ids.append(agent)
        self.labels.append(label)
        sizes, sizeless = [], False
        for size in (length, width):
            size = np.asarray(size, dtype=np.float64)
            sizeless |= bool(np.any(valid & ~np.isnan(size) & ~(np.isfinite(size) & (size > 0))))  # given, not a size
            sizes.append(np.where(np.isfinite(size) & (size > 0), size, np.nan))
        self.sizeless += sizeless
        values = (np.where(valid[:, None], xy, np.nan), valid, heading, *sizes)
        for col, value in zip(self.cols.values(), values, strict=True):
            col.append(value)

    def scenario(
        self, path: Path, name: str, source: str, dt_s: float, elements: list[Element], keyframe_every: int = 1
    ) -> Scenario:
        if not self.ids:
            raise InvalidFrameError(f"{path}: no vehicle, cyclist or pedestrian tracks")
        if self.sizeless:
            warnings.warn(
                f"{path.name}: {self.sizeless} agent(s) have a box of zero, negative or infinite size; their class "
                "default is used",
                DatasetWarning,
                stacklevel=3,
            )
        warn_unmapped(path, self.unmapped)
        col = {k: np.stack(v) for k, v in self.cols.items()}
        return Scenario(
            name=name,
            source=source,
            dt_s=dt_s,
            ids=np.array(self.ids, np.int64),
            labels=self.labels,
            positions=col["positions"],
            valid=col["valid"],
            heading=col["heading"],
            length=col["length"],
            width=col["width"],
            map=VectorMap(_usable(elements)),
            keyframe_every=keyframe_every,
        )


def warn_unmapped(path: Path, unmapped: Counter[str]) -> None:
    """Warns (:class:`~dgan.exceptions.DatasetWarning`) of the map element types a reader did not draw, with their
    counts."""
    if unmapped:
        listed = ", ".join(f"{kind} ×{n}" for kind, n in unmapped.most_common())
        warnings.warn(f"{path.name}: map elements not drawn (no engine kind): {listed}", DatasetWarning, stacklevel=4)


def _usable(elements: Iterable[Element]) -> list[Element]:
    """Drops degenerate elements (too few distinct points for their kind) rather than rejecting the whole map."""
    out = []
    for kind, pts in elements:
        need = 3 if kind in ("crosswalk", "bike_lane", "obstacle") else 2
        if len(pts) >= need and np.isfinite(pts).all():
            out.append((kind, pts))
    return out


# ---- ScenarioNet (nuScenes, Waymo) -----------------------------------------------------------------------------------


#: Older or other spellings of ScenarioNet / MetaDrive map types, by the name this reader knows.
SCENARIONET_TYPE_ALIASES: Final = {
    "CROSS_WALK": "CROSSWALK",
    "ROAD_EDGE_SIDEWALK": "ROAD_EDGE_BOUNDARY",
    "BOUNDARY_LINE": "ROAD_EDGE_BOUNDARY",
}


def scenarionet_map(features: Mapping[str, Mapping[str, Any]], unmapped: Counter[str] | None = None) -> list[Element]:
    """ScenarioNet ``map_features`` → engine elements (see the module's table); the types not drawn are counted in
    ``unmapped``."""
    out: list[Element] = []
    for key, f in features.items():
        kind = str(f.get("type", "")).upper()
        kind = SCENARIONET_TYPE_ALIASES.get(kind, kind)
        if key.startswith("boundary_") or kind == "ROAD_EDGE_BOUNDARY":  # nuScenes keys its road edges boundary_<n>
            out.append(("road_edge", _xy(f["polyline"], key)))
        elif kind == "ROAD_EDGE_MEDIAN":
            out.append(("obstacle", widen(_xy(f["polyline"], key), MEDIAN_WIDTH_M)))
        elif kind == "LANE_BIKE_LANE":
            out.append(("bike_lane", widen(_xy(f["polyline"], key), BIKE_LANE_WIDTH_M)))
        elif kind.startswith("LANE_"):
            out.append(("lane_centerline", _xy(f["polyline"], key)))
        elif kind.startswith("ROAD_LINE_"):
            dashed = "BROKEN" in kind
            out.append(("lane_line_dashed" if dashed else "lane_line_solid", _xy(f["polyline"], key)))
        elif kind == "CROSSWALK":
            out.append(("crosswalk", _xy(f.get("polygon", f.get("polyline")), key)))
        elif unmapped is not None:
            unmapped[kind or "(no type)"] += 1
    return out


def _load_scenarionet(path: Path) -> Any:
    """The object of a ScenarioNet / MetaDrive file: a pickle (``.pkl``, ``.pkl.gz``) or JSON (``.json``,
    ``.json.gz``)."""
    name = path.name.lower()
    opener: Any = gzip.open if name.endswith(".gz") else open
    try:
        with opener(path, "rb") as fh:
            if name.endswith((".json", ".json.gz")):
                return json.loads(fh.read())
            return pickle.load(fh)  # ScenarioNet's own format; see the module's note
    except (OSError, pickle.UnpicklingError, EOFError, json.JSONDecodeError, UnicodeDecodeError, ValueError) as e:
        raise InvalidFrameError(f"cannot read ScenarioNet scenario {path}: {e}") from None


def _time_step(d: Mapping[str, Any], meta: Mapping[str, Any], path: Path) -> float:
    """Seconds per step: ``sample_rate``, or the median spacing of ``ts`` (in the metadata or at the top level)."""
    if "sample_rate" in meta:
        return float(meta["sample_rate"])
    ts = meta.get("ts", d.get("ts"))
    if ts is None or np.size(ts) < 2:
        raise InvalidFrameError(f"{path}: no time base (neither metadata.sample_rate nor two timestamps ts)")
    return round(float(np.median(np.diff(np.asarray(ts, dtype=np.float64).ravel()))), 3)


def _sizes(st: Mapping[str, Any], t: int) -> tuple[Arr, Arr]:
    """A track's length and width per step: ``length``/``width`` (``(T,)``, ``(T, 1)`` or one value) or ``size``
    (``(T, ≥2)`` or ``(≥2,)``: length, width[, height]); NaN where the file has none."""
    if "length" in st and "width" in st:
        ln, wd = (np.asarray(st[k], dtype=np.float64).ravel() for k in ("length", "width"))
        return (np.full(t, ln[0]) if ln.size == 1 else ln), (np.full(t, wd[0]) if wd.size == 1 else wd)
    if "size" in st:
        size = np.asarray(st["size"], dtype=np.float64)
        size = np.broadcast_to(size, (t, size.shape[-1])) if size.ndim == 1 else size.reshape(t, -1)
        return size[:, 0].copy(), size[:, 1].copy()
    return np.full(t, np.nan), np.full(t, np.nan)


def read_scenarionet(path: str | os.PathLike[str], source: str | None = None) -> Scenario:
    """A ScenarioNet / MetaDrive scenario (nuScenes, Waymo, ...): a pickle (``.pkl``, ``.pkl.gz``) or its JSON
    (``.json``, ``.json.gz``). Vintages differ: sizes as ``length``/``width``/``height`` or ``size``, timestamps
    ``ts`` in the metadata or at the top level, type names such as ``CROSS_WALK``; map types that are not drawn are
    named in a :class:`~dgan.exceptions.DatasetWarning` with their counts."""
    path = Path(path)
    d = _load_scenarionet(path)
    if not isinstance(d, dict) or not {"tracks", "map_features"} <= d.keys():
        raise InvalidFrameError(f"{path}: not a ScenarioNet scenario (needs tracks and map_features)")
    meta = d.get("metadata") or {}
    src = source or ("nuscenes" if "nuscenes" in str(meta.get("dataset", path.name)).lower() else "waymo")
    dt = _time_step(d, meta, path)
    tracks = _Tracks()
    elements = scenarionet_map(d["map_features"], tracks.unmapped)
    for k, (_tid, tr) in enumerate(sorted(d["tracks"].items(), key=lambda kv: str(kv[0]))):
        st = tr["state"]
        ok = np.asarray(st["valid"]).astype(bool).ravel()
        p = np.asarray(st["position"], dtype=np.float64).reshape(len(ok), -1)[:, :2]
        hd = np.asarray(st["heading"], dtype=np.float64).ravel()
        ln, wd = _sizes(st, len(ok))
        kind = str(tr["type"]).upper()
        if kind in SCENARIONET_STATIC:
            if ok.any():
                t = int(np.flatnonzero(ok)[0])
                size = [x if np.isfinite(x) else 0.3 for x in (ln[t], wd[t])]
                elements.append(("obstacle", box(p[t], hd[t], max(size[0], 0.3), max(size[1], 0.3))))
            continue
        cls = SCENARIONET_CLASSES.get(kind)
        if cls is not None:
            tracks.add(k, cls, p, ok, hd, ln, wd)
    name = str(d.get("id", path.stem))
    return tracks.scenario(path, name, src, dt, elements, keyframe_every=5 if src == "nuscenes" else 1)


# ---- Waymo Open Motion in GPUDrive/Nocturne JSON ---------------------------------------------------------------------

#: WOMD road-line subtypes (``map_element_id``) that are broken lines.
WAYMO_BROKEN_LINES: Final = frozenset({6, 9, 10, 13})
WAYMO_BIKE_LANE: Final = 3
WAYMO_MEDIAN: Final = 16
#: Invalid states hold this sentinel.
WAYMO_INVALID: Final = -10000.0


def waymo_json_map(roads: Sequence[Mapping[str, Any]], unmapped: Counter[str] | None = None) -> list[Element]:
    """GPUDrive ``roads`` → engine elements. Road lines of the older files have no subtype and count as solid. The
    types not drawn (driveways, stop signs, speed bumps) are counted in ``unmapped``."""
    out: list[Element] = []
    for j, r in enumerate(roads):
        kind, sub = r.get("type"), r.get("map_element_id")
        what = f"road {j} ({kind})"
        if kind == "lane":
            pts = _xy(r["geometry"], what)
            out.append(
                ("bike_lane", widen(pts, BIKE_LANE_WIDTH_M)) if sub == WAYMO_BIKE_LANE else ("lane_centerline", pts)
            )
        elif kind == "road_line":
            out.append(
                ("lane_line_dashed" if sub in WAYMO_BROKEN_LINES else "lane_line_solid", _xy(r["geometry"], what))
            )
        elif kind == "road_edge":
            pts = _xy(r["geometry"], what)
            out.append(("obstacle", widen(pts, MEDIAN_WIDTH_M)) if sub == WAYMO_MEDIAN else ("road_edge", pts))
        elif kind == "crosswalk":
            out.append(("crosswalk", _xy(r["geometry"], what)))
        elif unmapped is not None:
            unmapped[str(kind)] += 1
    return out


def _waymo_heading_scale(objects: list[tuple[Arr, Arr, Arr]]) -> float:
    """Radians per unit of a GPUDrive file's headings: exports of this format differ, some in radians, some in
    degrees. The unit is the one whose headings agree with the direction of motion of the agents moving faster than
    2 m/s (median angle); without such agents, degrees where any valid heading exceeds 2π in magnitude."""
    errors: dict[float, list[float]] = {1.0: [], np.pi / 180.0: []}
    largest = 0.0
    for p, ok, hd in objects:
        if ok.any():
            largest = max(largest, float(np.abs(hd[ok]).max()))
        both = ok[1:] & ok[:-1]
        v = (p[1:] - p[:-1])[both] / 0.1
        moving = np.hypot(v[:, 0], v[:, 1]) > 2.0
        motion = np.arctan2(v[moving, 1], v[moving, 0])
        h = hd[1:][both][moving]
        for scale, errs in errors.items():
            errs.extend(np.abs((h * scale - motion + np.pi) % (2 * np.pi) - np.pi).tolist())
    if errors[1.0]:
        return min(errors, key=lambda s: float(np.median(errors[s])))
    return np.pi / 180.0 if largest > 2 * np.pi + 1e-6 else 1.0


def read_waymo_json(path: str | os.PathLike[str]) -> Scenario:
    """A Waymo Open Motion scenario in GPUDrive/Nocturne JSON (``.json`` or ``.json.gz``), 91 steps at 10 Hz; headings
    in radians or degrees, whichever the file holds (:func:`_waymo_heading_scale`)."""
    path = Path(path)
    try:
        opener = gzip.open if path.suffix == ".gz" else open
        with opener(path, "rt") as fh:
            d = json.load(fh)
    except (OSError, EOFError, json.JSONDecodeError, UnicodeDecodeError) as e:
        raise InvalidFrameError(f"cannot read Waymo JSON {path}: {e}") from None
    if not isinstance(d, dict) or "objects" not in d or "roads" not in d:
        raise InvalidFrameError(f"{path}: not a GPUDrive scenario (needs objects and roads)")
    tracks = _Tracks()
    objects = []
    for k, o in enumerate(d["objects"]):
        cls = str(o.get("type", ""))
        if cls not in ("vehicle", "pedestrian", "cyclist"):
            continue
        p = np.array([[q["x"], q["y"]] for q in o["position"]], dtype=np.float64)
        ok = np.asarray(o["valid"], dtype=bool) & (p[:, 0] != WAYMO_INVALID)
        objects.append((k, o, cls, p, ok, np.where(ok, np.asarray(o["heading"], dtype=np.float64), 0.0)))
    to_rad = _waymo_heading_scale([(p, ok, hd) for _, _, _, p, ok, hd in objects])
    for k, o, cls, p, ok, hd in objects:
        t = len(p)
        length, width = (np.full(t, float(o.get(k) if o.get(k) is not None else np.nan)) for k in ("length", "width"))
        tracks.add(int(o.get("id", k)), cls, p, ok, hd * to_rad, length, width)
    name = str(d.get("scenario_id") or d.get("name") or path.name.split(".")[0])
    return tracks.scenario(path, name, "waymo", 0.1, waymo_json_map(d["roads"], tracks.unmapped))


# ---- Argoverse 2 -----------------------------------------------------------------------------------------------------


def _av2_mark(mark: str) -> str | None:
    if mark.startswith("DASHED") or mark.startswith("DASH_"):
        return "lane_line_dashed"
    if mark.startswith(("SOLID", "DOUBLE")):
        return "lane_line_solid"
    return None  # NONE, UNKNOWN


def av2_map(path: str | os.PathLike[str]) -> list[Element]:
    """An Argoverse 2 ``log_map_archive_*.json`` → engine elements: drivable-area outlines as road edges, crossings
    (between their two edges) as crosswalks, bike lanes as regions between their boundaries, other lanes as centre
    lines, painted lane marks as dashed or solid lines."""
    path = Path(path)
    try:
        d = json.loads(path.read_text())
    except (OSError, json.JSONDecodeError, UnicodeDecodeError) as e:
        raise InvalidMapError(f"cannot read Argoverse 2 map {path}: {e}") from None
    if not isinstance(d, dict) or "lane_segments" not in d:
        raise InvalidMapError(f"{path}: not an Argoverse 2 map archive (needs lane_segments)")
    out: list[Element] = []
    for a in d.get("drivable_areas", {}).values():
        ring = _xy(a["area_boundary"], "drivable area")
        out.append(("road_edge", np.vstack([ring, ring[:1]])))
    for c in d.get("pedestrian_crossings", {}).values():
        out.append(("crosswalk", np.vstack([_xy(c["edge1"], "crossing"), _xy(c["edge2"], "crossing")[::-1]])))
    for ls in d["lane_segments"].values():
        left, right = _xy(ls["left_lane_boundary"], "lane"), _xy(ls["right_lane_boundary"], "lane")
        if ls.get("lane_type") == "BIKE":
            out.append(("bike_lane", np.vstack([left, right[::-1]])))
        else:  # the sensor logs' maps carry no centre lines: the midline of the two boundaries, as av2 computes it
            centre = _xy(ls["centerline"], "lane") if "centerline" in ls else midline(left, right)
            out.append(("lane_centerline", centre))
        for side, pts in (("left", left), ("right", right)):
            kind = _av2_mark(str(ls.get(f"{side}_lane_mark_type", "NONE")))
            if kind is not None:
                out.append((kind, pts))
    return out


def _pyarrow() -> Any:
    try:
        import pyarrow.feather
        import pyarrow.parquet
    except ImportError as e:
        raise InvalidFrameError("reading Argoverse 2 tracks needs pyarrow: pip install pyarrow") from e
    return pyarrow


def _long_rows(
    tracks: _Tracks,
    track: Arr,
    step: Arr,
    num_steps: int,
    labels: Arr,
    xy: Arr,
    *cols: Arr,
    unknown_heading: float = 0.0,
) -> None:
    """Adds long rows (track index, step, label, positions, heading, length, width; NaN length and width for the
    class defaults) to ``tracks``, one agent per track index; a NaN heading becomes ``unknown_heading``."""
    for t in np.unique(track):
        rows = track == t
        ok = np.zeros(num_steps, bool)
        ok[step[rows]] = True
        grid = []
        for c in (xy, *cols):
            g = np.full((num_steps, *c.shape[1:]), np.nan)
            g[step[rows]] = c[rows]
            grid.append(g)
        heading, length, width = grid[1:]
        tracks.add(
            int(t),
            str(labels[rows][0]),
            grid[0],
            ok,
            np.where(np.isnan(heading), unknown_heading, heading),
            length,
            width,
        )


def read_av2_scenario(folder: str | os.PathLike[str]) -> Scenario:
    """An Argoverse 2 motion-forecasting scenario folder (``scenario_*.parquet`` and ``log_map_archive_*.json``),
    110 steps at 10 Hz. Object sizes are not in the format: the engine's class defaults apply (NaN sizes)."""
    folder = Path(folder)
    pa = _pyarrow()
    files = sorted(folder.glob("scenario_*.parquet"))
    maps = sorted(folder.glob("log_map_archive_*.json"))
    if not files or not maps:
        raise InvalidFrameError(f"{folder}: needs scenario_*.parquet and log_map_archive_*.json")
    t = pa.parquet.read_table(files[0])
    col = {n: t.column(n).to_numpy(zero_copy_only=False) for n in t.column_names}
    types = col["object_type"].astype(str)
    step = col["timestep"].astype(np.int64)
    num_steps = int(step.max()) + 1
    elements = av2_map(maps[0])
    track_names = col["track_id"].astype(str)
    static = types == "static"
    for name in np.unique(track_names[static]):
        r = np.flatnonzero(track_names == name)[0]
        elements.append(
            ("obstacle", box(np.array([col["position_x"][r], col["position_y"][r]]), col["heading"][r], 4.5, 2.0))
        )
    keep = np.isin(types, list(AV2_SCENARIO_CLASSES))
    _, track = np.unique(track_names[keep], return_inverse=True)
    labels = np.array([AV2_SCENARIO_CLASSES[t] for t in types[keep]])
    xy = np.c_[col["position_x"][keep], col["position_y"][keep]]
    no_size = np.full(len(xy), np.nan)  # the engine's class defaults
    tracks = _Tracks()
    _long_rows(
        tracks, track, step[keep], num_steps, labels, xy, col["heading"][keep].astype(np.float64), no_size, no_size
    )
    return tracks.scenario(folder, folder.name, "argoverse2", 0.1, elements)


def _yaw(qw: Arr, qx: Arr, qy: Arr, qz: Arr) -> Arr:
    out: Arr = np.arctan2(2 * (qw * qz + qx * qy), 1 - 2 * (qy**2 + qz**2))
    return out


def read_av2_sensor_log(folder: str | os.PathLike[str]) -> Scenario:
    """An Argoverse 2 sensor-dataset log folder: ``annotations.feather`` cuboids (ego frame, 10 Hz) composed with
    ``city_SE3_egovehicle.feather`` into the city frame of ``map/log_map_archive_*.json``."""
    folder = Path(folder)
    pa = _pyarrow()
    maps = sorted((folder / "map").glob("log_map_archive_*.json"))
    if not (folder / "annotations.feather").is_file() or not maps:
        raise InvalidFrameError(f"{folder}: needs annotations.feather, city_SE3_egovehicle.feather and map/")

    def table(name: str) -> dict[str, Arr]:
        t = pa.feather.read_table(folder / name)
        return {n: t.column(n).to_numpy(zero_copy_only=False) for n in t.column_names}

    ann, ego = table("annotations.feather"), table("city_SE3_egovehicle.feather")
    times = np.unique(ann["timestamp_ns"])
    step = np.searchsorted(times, ann["timestamp_ns"])
    pose_at = {int(ts): k for k, ts in enumerate(ego["timestamp_ns"])}
    missing = set(times.tolist()) - pose_at.keys()
    if missing:
        raise InvalidFrameError(f"{folder}: {len(missing)} annotation times have no ego pose")
    e = np.array([pose_at[int(ts)] for ts in ann["timestamp_ns"]])
    ego_yaw = _yaw(ego["qw"][e], ego["qx"][e], ego["qy"][e], ego["qz"][e])
    c, s = np.cos(ego_yaw), np.sin(ego_yaw)
    x = ego["tx_m"][e] + c * ann["tx_m"] - s * ann["ty_m"]
    y = ego["ty_m"][e] + s * ann["tx_m"] + c * ann["ty_m"]
    yaw = ego_yaw + _yaw(ann["qw"], ann["qx"], ann["qy"], ann["qz"])
    cats = ann["category"].astype(str)
    elements = av2_map(maps[0])
    uuids = ann["track_uuid"].astype(str)
    for u in np.unique(uuids[np.isin(cats, list(AV2_SENSOR_STATIC))]):
        r = np.flatnonzero(uuids == u)[0]
        elements.append(("obstacle", box(np.array([x[r], y[r]]), yaw[r], ann["length_m"][r], ann["width_m"][r])))
    keep = np.isin(cats, list(AV2_SENSOR_CLASSES))
    _, track = np.unique(uuids[keep], return_inverse=True)
    labels = np.array([AV2_SENSOR_CLASSES[c] for c in cats[keep]])
    tracks = _Tracks()
    sizes = (ann["length_m"][keep].astype(np.float64), ann["width_m"][keep].astype(np.float64))
    _long_rows(tracks, track, step[keep], len(times), labels, np.c_[x, y][keep], yaw[keep], *sizes)
    dt = round(float(np.median(np.diff(times))) * 1e-9, 3)
    return tracks.scenario(folder, folder.name, "argoverse2", dt, elements)


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
    if name.endswith((".pkl", ".pkl.gz")):
        return read_scenarionet(path)
    if name.endswith((".json", ".json.gz")):
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


def bird_eye(
    scenario: Scenario,
    now: int,
    centre: Sequence[float] | None = None,
    extent_m: float = 120.0,
    resolution_m: float = 0.2,
) -> Arr:
    """A north-up ``(H, W, 3)`` uint8 picture of the map and the agents valid at step ``now``, ``extent_m`` a side
    around ``centre`` (the mean agent position if None), drawn by the engine's rasteriser exactly as the network's
    crops are: the crop of a virtual agent at ``centre`` heading north."""
    from dgan.spec import InputSpec, MapSpec, preprocess

    side = round(extent_m / resolution_m)
    if not 1 <= side <= 2048:
        raise InvalidMapError(f"extent_m / resolution_m must give 1..2048 pixels, got {side}")
    frame = scenario.frame(now, 2)
    agents = np.flatnonzero(scenario.valid[:, now])
    pos = frame.positions[:, -1]
    c = np.nanmean(pos, axis=0) if centre is None else np.asarray(centre, dtype=np.float64)
    spec = InputSpec(
        dt_s=scenario.dt_s,
        t_obs=2,
        t_f=1,
        map=MapSpec(side, side, resolution_m, side // 2, side // 2, draw_agents=True),
    )
    view = Frame(  # the agents, and a tiny virtual one at the centre heading north (its crop is the picture)
        np.concatenate([frame.positions, [[c - [0.0, 0.1], c]]]),
        mask=np.vstack([frame.mask, [[True, True]]]),
        classes=[*frame.classes, "pedestrian"],
        ids=np.r_[frame.ids, frame.ids.max() + 1],
        headings=np.r_[scenario.heading[agents, now], np.pi / 2],
        lengths=np.r_[frame.lengths, 1e-3],
        widths=np.r_[frame.widths, 1e-3],
        map=scenario.map,
    )
    crop = preprocess(view, spec)["map"][-1]
    out: Arr = np.round(np.moveaxis(crop, 0, -1) * 255).astype(np.uint8)
    return out
