"""ScenarioNet / MetaDrive scenarios (``.pkl``, ``.pkl.gz``, ``.json``, ``.json.gz``): agents and map features."""

from __future__ import annotations

import gzip
import json
import os
import pickle
from collections import Counter
from collections.abc import Mapping
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
    box,
    widen,
)
from dgan.exceptions import InvalidFrameError

#: ScenarioNet (MetaDrive) agent types → engine classes; other types (cones, barriers) are static obstacles.
SCENARIONET_CLASSES: Final = {"VEHICLE": "vehicle", "CYCLIST": "cyclist", "PEDESTRIAN": "pedestrian"}


SCENARIONET_STATIC: Final = frozenset({"TRAFFIC_CONE", "TRAFFIC_BARRIER"})


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
