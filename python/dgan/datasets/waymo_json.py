"""Waymo Open Motion scenarios in GPUDrive / Nocturne JSON (``objects`` and ``roads``)."""

from __future__ import annotations

import gzip
import json
import os
from collections import Counter
from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import Any, Final

import numpy as np

from dgan.datasets.scenario import (
    BIKE_LANE_WIDTH_M,
    MEDIAN_WIDTH_M,
    Arr,
    Element,
    Scenario,
    _Tracks,
    _xy,
    widen,
)
from dgan.exceptions import InvalidFrameError

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
        if cls not in ("vehicle", "pedestrian", "cyclist"):  # not a contract copy: GPUDrive's object types
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
