"""A source's scene as every agent's states on its own grid and its vector map (:class:`Scenario`), the geometry
the readers share, and a bird's-eye picture drawn by the engine (:func:`bird_eye`)."""

from __future__ import annotations

import warnings
from collections import Counter
from collections.abc import Iterable, Mapping, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Final

import numpy as np
import numpy.typing as npt

from dgan.contract import MAP_KINDS
from dgan.exceptions import DatasetWarning, InvalidFrameError, InvalidMapError
from dgan.frame import Frame
from dgan.maps import VectorMap

Arr = npt.NDArray[Any]


Element = tuple[str, Arr]


#: Width a bike lane's centre line is widened to, metres.
BIKE_LANE_WIDTH_M: Final = 1.5


#: Width a median's edge line is widened to, metres.
MEDIAN_WIDTH_M: Final = 0.6


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

    def records(self) -> dict[str, Arr]:
        """Every valid state as one row of a long table that :meth:`dgan.Frame.from_records`, :func:`dgan.evaluate`
        and :func:`dgan.series.frames` read (with ``time_unit=1``, the scenario's map as ``map=``): ``agent_id``,
        ``time`` (seconds from the scenario's first step), ``x``, ``y``, ``class`` (the engine's), ``heading``,
        ``length`` and ``width`` (NaN where unknown); rows by agent, then time."""
        agent, step = np.nonzero(self.valid)
        return {
            "agent_id": self.ids[agent],
            "time": np.round(step * self.dt_s, 9),  # 0.1 · 3 is 0.30000000000000004
            "x": self.positions[agent, step, 0],
            "y": self.positions[agent, step, 1],
            "class": np.asarray(self.labels, dtype=object)[agent],
            "heading": self.heading[agent, step],
            "length": self.length[agent, step],
            "width": self.width[agent, step],
        }

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


#: The element kinds drawn as filled polygons (the others are polylines).
POLYGON_KINDS: Final = frozenset(k.name for k in MAP_KINDS if k.polygon)


def _usable(elements: Iterable[Element]) -> list[Element]:
    """Drops degenerate elements (too few distinct points for their kind) rather than rejecting the whole map."""
    out = []
    for kind, pts in elements:
        need = 3 if kind in POLYGON_KINDS else 2
        if len(pts) >= need and np.isfinite(pts).all():
            out.append((kind, pts))
    return out


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
