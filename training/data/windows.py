"""Recordings (read by :mod:`training.data.datasets`) → windows of T_obs observed and T_f future steps → the
engine's network inputs (:class:`~training.data.arrays.Windows`).

Every step gives a window ending there; every agent seen at t_obs is in the frame (neighbours with partial histories
included) and the agents of a scored label present at all T_obs + T_f consecutive steps are the targets. As in
Social-GAN and Multiclass-SGCN, a window is kept when it has at least ``min_targets`` targets (two). Inputs come from
:func:`dgan.preprocess` (the Rust engine) and futures in each agent's frame from :func:`dgan.to_agent_frame`.
"""

from __future__ import annotations

from collections.abc import Iterator, Sequence
from dataclasses import dataclass, replace
from typing import Any

import numpy as np
import numpy.typing as npt

import dgan
from training.data.arrays import Windows
from training.data.augment import held_still, tracker_noise
from training.data.recording import DatasetInfo, Recording
from training.modules.scene import SCENE_TRAIN_PX

Arr = npt.NDArray[Any]


#: A target that moves less than this many metres from its first observed to its last true position stands (every
#: moving / standing split: evaluation, the velocity study).
STANDING_M = 1.0


@dataclass
class Window:
    """One window of a recording: the agents seen at t_obs, their positions over all T_obs + T_f steps (NaN where
    absent) and which of them are targets."""

    recording: Recording
    now: int  # the step of t_obs
    ids: Arr  # (N,) i64
    positions: Arr  # (N, T_obs + T_f, 2) world metres
    mask: Arr  # (N, T_obs + T_f) bool
    target: Arr  # (N,) bool
    label: Arr  # (N,) i64, at t_obs
    heading: Arr | None  # (N,) at t_obs
    length: Arr | None
    width: Arr | None

    def moving(self) -> Arr:
        """``(n_targets,)`` whether each target moves at least :data:`STANDING_M` from its first to its last
        position."""
        t = self.target
        moved: Arr = np.linalg.norm(self.positions[t, -1] - self.positions[t, 0], axis=1) >= STANDING_M
        return moved

    def frame(self, info: DatasetInfo, t_obs: int, with_map: bool = True) -> dgan.Frame:
        return dgan.Frame(
            self.positions[:, :t_obs],
            mask=self.mask[:, :t_obs],
            classes=[info.label_class[k] for k in self.label],
            ids=self.ids,
            headings=self.heading,
            lengths=self.length,
            widths=self.width,
            map=self.recording.map if with_map else None,
        )


def iter_windows(
    rec: Recording, info: DatasetInfo, t_obs: int, t_f: int, stride: int = 1, min_targets: int | None = None
) -> Iterator[Window]:
    """Every window of ``rec`` ending at a step divisible by ``stride`` with at least ``min_targets`` targets: agents
    of a scored label present at all ``t_obs + t_f`` consecutive steps."""
    need = info.min_targets if min_targets is None else min_targets
    steps, first = np.unique(rec.step, return_index=True)
    bounds = dict(
        zip(steps.tolist(), zip(first.tolist(), [*first[1:].tolist(), len(rec.step)], strict=True), strict=True)
    )
    scored = np.array(info.scored)
    total = t_obs + t_f
    allowed = None if rec.now_steps is None else set(rec.now_steps.tolist())
    for now in steps.tolist():
        if now % stride or (allowed is not None and now not in allowed):
            continue
        lo, hi = bounds[now]
        ids, at = np.unique(rec.agent[lo:hi], return_index=True)
        n = len(ids)
        pos = np.full((n, total, 2), np.nan)
        mask = np.zeros((n, total), dtype=bool)
        for k in range(total):
            b = bounds.get(now - (t_obs - 1) + k)
            if b is None:
                continue
            agents = rec.agent[b[0] : b[1]]
            idx = np.minimum(np.searchsorted(ids, agents), n - 1)
            hit = ids[idx] == agents
            pos[idx[hit], k] = rec.xy[b[0] : b[1]][hit]
            mask[idx[hit], k] = True
        rows = lo + at
        label = rec.label[rows]
        target = mask.all(axis=1) & scored[label]
        if info.min_move_m > 0:
            target &= np.linalg.norm(pos[:, -1] - pos[:, 0], axis=1) > info.min_move_m
        if target.sum() < need:
            continue

        def at_now(col: Arr | None, rows: Arr = rows) -> Arr | None:
            return None if col is None else col[rows]

        yield Window(
            rec, now, ids, pos, mask, target, label, at_now(rec.heading), at_now(rec.length), at_now(rec.width)
        )


def held_window(w: Window, t_obs: int, hold: float, whole: bool) -> Window:
    """``w`` with its still agents held where they are (:func:`training.data.augment.held_still`): over the observed
    steps, the futures staying as recorded, or (``whole``) over the whole window, history and future."""
    if whole:
        return replace(w, positions=held_still(w.positions, w.mask, hold))
    obs = held_still(w.positions[:, :t_obs], w.mask[:, :t_obs], hold)
    return replace(w, positions=np.concatenate([obs, w.positions[:, t_obs:]], axis=1))


def build_windows(
    recs: Sequence[Recording],
    info: DatasetInfo,
    spec: dgan.InputSpec,
    stride: int = 1,
    progress: bool = True,
    noise: tuple[float, float] = (0.0, 0.0),
    hold: float = 0.0,
    scene_px: int = SCENE_TRAIN_PX,
    hold_future: bool = False,
) -> Windows:
    """Preprocesses every window of ``recs`` through the engine; ``noise = (sigma_m, drop)`` first corrupts the
    observed histories as a tracker would (:func:`training.data.augment.tracker_noise`, seeded by the recording's
    order), ``hold`` (metres) holds their still agents where they are (:func:`training.data.augment.held_still`), the
    futures staying as recorded (``hold_future``: the agents still over the whole window held throughout). A scene
    model's windows (``spec.map.scene``, contract 12) also hold their scene rasters of ``scene_px`` a side and their
    agents' grids (:func:`scene_inputs`), beside the agents' crops that a teacher reads."""
    from tqdm import tqdm

    parts: dict[str, list[Arr]] = {k: [] for k in Windows.__dataclass_fields__ if k not in ("files",)}
    agent_ptr, edge_ptr = [0], [0]
    class_of_label = np.array([list(spec.classes).index(c) for c in info.label_class])
    scene = spec.map.scene if spec.map is not None else None
    crops = spec if scene is None or spec.map is None else replace(spec, map=replace(spec.map, scene=None))
    # A dataset without maps, for a model whose map is optional: its agents' crops are flagged absent, as the engine
    # flags a frame without a map (another source's pedestrians for an ETH/UCY model keep the flag present).
    flag_absent = spec.map is not None and spec.map.optional and not info.has_map
    for fi, rec in enumerate(recs):
        windows = list(iter_windows(rec, info, spec.t_obs, spec.t_f, stride))
        rng, turns = np.random.default_rng(fi), np.random.default_rng([fi, 1])
        for w in tqdm(windows, desc=rec.name, disable=not progress, leave=False):
            if noise != (0.0, 0.0):
                w = noisy_window(w, spec.t_obs, noise, rng)
            if hold > 0:
                w = held_window(w, spec.t_obs, hold, hold_future)
            frame = w.frame(info, spec.t_obs, with_map=spec.map is not None)
            x = dgan.preprocess(frame, crops)
            if scene is not None:
                turn = float(turns.uniform(-np.pi, np.pi))
                scene_raster, grid = scene_inputs(frame, crops, x, scene_px, scene.stride, turn)
                parts["scene"].append(scene_raster[None])
                parts["scene_grid"].append(grid)
            fut = np.where(w.mask[:, spec.t_obs :, None], w.positions[:, spec.t_obs :], 0.0)
            future = dgan.to_agent_frame(fut, x["origin"], x["heading"])
            n = len(w.ids)
            for key in ("trajectory", "trajectory_mask", "state", "edge_index", "edge_features", "origin", "heading"):
                parts[key].append(x[key])
            if "map" in x:
                parts["map"].append(np.round(x["map"] * 255).astype(np.uint8))
            if flag_absent:
                parts["map_absent"].append(np.ones(n, bool))
            parts["future"].append(future.astype(np.float32))
            parts["target"].append(w.target)
            parts["class_index"].append(class_of_label[w.label])
            parts["window_file"].append(np.array([fi]))
            parts["window_frame"].append(np.array([w.now]))
            agent_ptr.append(agent_ptr[-1] + n)
            edge_ptr.append(edge_ptr[-1] + len(x["edge_index"]))
    cat = {k: np.concatenate(v) for k, v in parts.items() if v and k not in ("agent_ptr", "edge_ptr")}
    return Windows(
        map=cat.pop("map", None),
        agent_ptr=np.array(agent_ptr),
        edge_ptr=np.array(edge_ptr),
        files=[r.name for r in recs],
        **cat,
    )


def scene_inputs(
    frame: dgan.Frame, spec: dgan.InputSpec, x: dict[str, Arr], size_px: int, stride: int, heading: float
) -> tuple[Arr, Arr]:
    """A window's scene raster ``(3, S, S)`` u8 (S = ``size_px``), centred on its agents' mean position and turned to
    ``heading`` (the CNN learns the map whichever way the scene lies; the engine's lie north up, each holding a group
    of crops), and each agent's crop grid in it ``(N, gh, gw, 2)``."""
    centre = x["origin"].mean(axis=0) if len(x["origin"]) else np.zeros(2)
    raster = dgan.scene_raster(frame, spec, size_px, centre, heading)
    grid = dgan.crop_grid(x["origin"], x["heading"], spec, stride, size_px, centre, heading)
    return np.round(raster * 255).astype(np.uint8), grid


def noisy_window(w: Window, t_obs: int, noise: tuple[float, float], rng: np.random.Generator) -> Window:
    """``w`` with its observed steps corrupted by :func:`training.data.augment.tracker_noise` (``noise = (sigma_m,
    drop)``); the future steps and the targets stay as they were."""
    pos, keep = tracker_noise(w.positions[:, :t_obs], w.mask[:, :t_obs], *noise, rng)
    return replace(
        w,
        positions=np.concatenate([pos, w.positions[:, t_obs:]], axis=1),
        mask=np.concatenate([keep, w.mask[:, t_obs:]], axis=1),
    )
