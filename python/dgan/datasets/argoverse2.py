"""Argoverse 2: motion-forecasting scenario folders (``scenario_*.parquet``, ``log_map_archive_*.json``) and sensor
logs (``annotations.feather``, ``city_SE3_egovehicle.feather``, the log's map)."""

from __future__ import annotations

import json
import os
from pathlib import Path
from typing import Any, Final

import numpy as np

from dgan.datasets.scenario import (
    Arr,
    Element,
    Scenario,
    _Tracks,
    _xy,
    box,
    midline,
)
from dgan.exceptions import InvalidFrameError, InvalidMapError

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
