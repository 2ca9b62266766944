"""What every dataset reader gives: a :class:`Recording` (rows in world metres with per-row labels) of a dataset
whose time base, protocol and labels are its :class:`DatasetInfo`; and what a training split is made of: the
:class:`WindowSet` parts a configuration asks for, each :class:`Located` by the registry before it is cached."""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, replace
from pathlib import Path
from typing import Any

import numpy as np
import numpy.typing as npt

import dgan
from dgan._values import checked_shift

Arr = npt.NDArray[Any]


@dataclass(frozen=True)
class DatasetInfo:
    """A dataset's time base, protocol and labels."""

    name: str
    dt_s: float
    t_obs: int
    t_f: int
    labels: tuple[str, ...]  # the dataset's own labels, in code order
    label_class: tuple[str, ...]  # the engine class of each label
    scored: tuple[bool, ...]  # whether agents with the label can be targets
    unit: str  # the unit errors are reported in: "m" or "px"
    min_targets: int  # a window needs at least this many targets
    has_map: bool
    min_move_m: float = 0.0  # a target must move more than this over the window (first to last point)

    @property
    def classes(self) -> tuple[str, ...]:
        """The model's classes, in the engine's canonical order, among those of the scored labels."""
        used = {c for c, s in zip(self.label_class, self.scored, strict=True) if s}
        return tuple(c for c in dgan.CLASSES if c in used)


@dataclass
class Recording:
    """One recording's rows, sorted by (step, agent). Steps are integer time indices ``dt_s`` apart."""

    name: str
    step: Arr  # (R,) int64
    agent: Arr  # (R,) int64
    xy: Arr  # (R, 2) f64, world metres
    label: Arr  # (R,) int64 into DatasetInfo.labels
    heading: Arr | None = None  # (R,) radians
    length: Arr | None = None  # (R,) metres
    width: Arr | None = None  # (R,) metres
    unit_m: float = 1.0  # metres per reporting unit
    map: dgan.RasterMap | dgan.VectorMap | None = None
    now_steps: Arr | None = None  # the steps a window may end at (all if None)

    @classmethod
    def sorted(cls, **kw: Any) -> Recording:
        rec = cls(**kw)
        order = np.lexsort((rec.agent, rec.step))
        for k in ("step", "agent", "xy", "label", "heading", "length", "width"):
            v = getattr(rec, k)
            if v is not None:
                setattr(rec, k, v[order])
        return rec


def moved(rec: Recording, shift_m: npt.ArrayLike) -> Recording:
    """``rec`` with every world coordinate, its rows' and its map's, moved by ``shift_m`` (2,) metres: the same
    recording under another origin (``training.evaluate --origin``; docs/model-contract.md, *The map's grid and the
    world's origin*)."""
    shift = checked_shift("shift_m", shift_m, ValueError)
    return replace(rec, xy=rec.xy + shift, map=None if rec.map is None else rec.map.moved(shift))


@dataclass(frozen=True)
class WindowSet:
    """One part of a split as the window cache keys it: ``split`` of ``dataset`` (``fold``: the held-out ETH/UCY
    scene, or ApolloScape's validation recordings) with windows ending every ``stride`` steps, its observed histories
    corrupted as a tracker would with ``noise = (sigma_m, drop)`` or, with ``hold`` (metres), its still agents held
    where they are (:func:`training.data.augment.held_still`), or with ``speed`` its agents sped up; or, with
    ``pedestrians``, the training pedestrians of the source ``dataset`` for an ETH/UCY model."""

    dataset: str
    split: str
    fold: str = ""
    stride: int = 1
    noise: tuple[float, float] = (0.0, 0.0)
    pedestrians: bool = False
    hold: float = 0.0
    #: With ``hold``: the whole window (history and future) of each agent that stays within ``hold`` metres held.
    hold_future: bool = False
    #: Each recording resampled onto steps ``speed`` times as long and read on the dataset's grid: every agent
    #: ``speed`` times as fast (``data.augment_speed``).
    speed: float = 1.0


@dataclass(frozen=True)
class Located:
    """A :class:`WindowSet` found on disk: its source ``files`` (what its cache key holds), the dataset whose
    protocol its windows follow, and ``read``, which reads its recordings (called only when the windows are not
    cached)."""

    part: WindowSet
    files: list[Path]
    info: DatasetInfo
    read: Callable[[], list[Recording]]
