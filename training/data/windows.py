"""Recordings (:mod:`training.data.datasets`) → windows of T_obs observed and T_f future steps → the engine's network
inputs.

Every step gives a window ending there; every agent seen at t_obs is in the frame (neighbours with partial histories
included) and the agents of a scored label present at all T_obs + T_f consecutive steps are the targets. As in
Social-GAN and Multiclass-SGCN, a window is kept when it has at least ``min_targets`` targets (two). Inputs come from
:func:`dgan.preprocess` (the Rust engine) and futures in each agent's frame from :func:`dgan.to_agent_frame`.
"""

from __future__ import annotations

import hashlib
import json
from collections.abc import Callable, Iterator, Sequence
from dataclasses import dataclass, replace
from pathlib import Path
from typing import Any, Final

import numpy as np
import numpy.typing as npt

import dgan
from dgan.contract import CACHE_KEY, EDGE_FEATURES, EDGE_MIRRORED, STATE_FEATURES, STATE_MIRRORED
from training.data.augment import tracker_noise
from training.data.datasets import DATASETS, pedestrian_recordings, recordings, source_files
from training.data.recording import DatasetInfo, Recording

Arr = npt.NDArray[Any]


@dataclass
class Windows:
    """Preprocessed windows, concatenated: agents of window w are rows ``agent_ptr[w]:agent_ptr[w + 1]`` and its
    directed edges ``edge_ptr[w]:edge_ptr[w + 1]`` (edge indices local to the window)."""

    trajectory: Arr  # (A, T_obs, 2) f32
    trajectory_mask: Arr  # (A, T_obs) f32
    state: Arr  # (A, S) f32
    edge_index: Arr  # (Ed, 2) i64, window-local
    edge_features: Arr  # (Ed, 6) f32
    map: Arr | None  # (A, 3, H, W) u8
    future: Arr  # (A, T_f, 2) f32, agent frame (valid for targets)
    target: Arr  # (A,) bool
    class_index: Arr  # (A,) i64 into the spec's classes
    origin: Arr  # (A, 2) f64 world
    heading: Arr  # (A,) f64 world
    agent_ptr: Arr  # (W + 1,)
    edge_ptr: Arr  # (W + 1,)
    window_file: Arr  # (W,) index into files
    window_frame: Arr  # (W,) t_obs frame id
    files: list[str]

    @property
    def num_windows(self) -> int:
        return len(self.agent_ptr) - 1

    @property
    def num_targets(self) -> int:
        return int(self.target.sum())

    def save(self, path: Path) -> None:
        arrays = {k: v for k, v in self.__dict__.items() if isinstance(v, np.ndarray)}
        np.savez(path, files=np.array(self.files), **arrays)  # type: ignore[arg-type]

    @classmethod
    def load(cls, path: Path) -> Windows:
        with np.load(path, allow_pickle=False) as z:
            d = {k: z[k] for k in z.files}
        d["files"] = [str(f) for f in d["files"]]
        d.setdefault("map", None)
        return cls(**d)

    def batch(self, windows: Sequence[int] | Arr, flip: Arr | None = None) -> dict[str, Arr]:
        """Concatenates windows into one graph; ``flip`` (per window, bool) mirrors left and right."""
        w = np.asarray(windows)
        n_agents = self.agent_ptr[w + 1] - self.agent_ptr[w]
        n_edges = self.edge_ptr[w + 1] - self.edge_ptr[w]
        a_idx = np.concatenate([np.arange(self.agent_ptr[i], self.agent_ptr[i + 1]) for i in w])
        e_idx = np.concatenate([np.arange(self.edge_ptr[i], self.edge_ptr[i + 1]) for i in w])
        # Each window's edge indices shift by the agents of the windows before it in the batch.
        shift = np.repeat(np.cumsum(n_agents) - n_agents, n_edges)
        out = {
            "trajectory": self.trajectory[a_idx].copy(),
            "trajectory_mask": self.trajectory_mask[a_idx],
            "state": self.state[a_idx].copy(),
            "edge_index": self.edge_index[e_idx] + shift[:, None],
            "edge_features": self.edge_features[e_idx].copy(),
            "future": self.future[a_idx].copy(),
            "target": self.target[a_idx],
            "class_index": self.class_index[a_idx],
        }
        if self.map is not None:
            out["map"] = self.map[a_idx].astype(np.float32) / 255.0
        if flip is not None and flip.any():
            mirror(out, np.repeat(flip, n_agents), np.repeat(flip, n_edges))
        return out


#: The columns of the state and edge features that mirroring negates (the engine's, ``dgan.contract``).
STATE_MIRROR_COLUMNS: Final = tuple(STATE_FEATURES.index(c) for c in STATE_MIRRORED)
EDGE_MIRROR_COLUMNS: Final = tuple(EDGE_FEATURES.index(c) for c in EDGE_MIRRORED)


def mirror(batch: dict[str, Arr], agents: Arr, edges: Arr) -> None:
    """Mirrors the selected agents' inputs and futures across their x axis (y → -y), in place.

    Valid because every input is agent-centric: y coordinates, lateral velocities, yaw rates and the sines of
    relative headings change sign; map crops flip left-right about the agent's column (the crop must be symmetric
    about it: ``width_px == 2 * agent_col + 1``).
    """
    batch["trajectory"][agents, :, 1] *= -1
    batch["future"][agents, :, 1] *= -1
    for col in STATE_MIRROR_COLUMNS:
        batch["state"][agents, col] *= -1
    for col in EDGE_MIRROR_COLUMNS:
        batch["edge_features"][edges, col] *= -1
    if "map" in batch:
        batch["map"][agents] = batch["map"][agents][..., ::-1]


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


def build_windows(
    recs: Sequence[Recording],
    info: DatasetInfo,
    spec: dgan.InputSpec,
    stride: int = 1,
    progress: bool = True,
    noise: tuple[float, float] = (0.0, 0.0),
) -> Windows:
    """Preprocesses every window of ``recs`` through the engine; ``noise = (sigma_m, drop)`` first corrupts the
    observed histories as a tracker would (:func:`training.data.augment.tracker_noise`, seeded by the recording's
    order), the futures staying as recorded."""
    from tqdm import tqdm

    parts: dict[str, list[Arr]] = {k: [] for k in Windows.__dataclass_fields__ if k not in ("files",)}
    agent_ptr, edge_ptr = [0], [0]
    class_of_label = np.array([list(spec.classes).index(c) for c in info.label_class])
    for fi, rec in enumerate(recs):
        windows = list(iter_windows(rec, info, spec.t_obs, spec.t_f, stride))
        rng = np.random.default_rng(fi)
        for w in tqdm(windows, desc=rec.name, disable=not progress, leave=False):
            if noise != (0.0, 0.0):
                w = noisy_window(w, spec.t_obs, noise, rng)
            x = dgan.preprocess(w.frame(info, spec.t_obs, with_map=spec.map is not None), spec)
            fut = np.where(w.mask[:, spec.t_obs :, None], w.positions[:, spec.t_obs :], 0.0)
            future = dgan.to_agent_frame(fut, x["origin"], x["heading"])
            n = len(w.ids)
            for key in ("trajectory", "trajectory_mask", "state", "edge_index", "edge_features", "origin", "heading"):
                parts[key].append(x[key])
            if "map" in x:
                parts["map"].append(np.round(x["map"] * 255).astype(np.uint8))
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


def noisy_window(w: Window, t_obs: int, noise: tuple[float, float], rng: np.random.Generator) -> Window:
    """``w`` with its observed steps corrupted by :func:`training.data.augment.tracker_noise` (``noise = (sigma_m,
    drop)``); the future steps and the targets stay as they were."""
    pos, keep = tracker_noise(w.positions[:, :t_obs], w.mask[:, :t_obs], *noise, rng)
    return replace(
        w,
        positions=np.concatenate([pos, w.positions[:, t_obs:]], axis=1),
        mask=np.concatenate([keep, w.mask[:, t_obs:]], axis=1),
    )


def concat_windows(parts: Sequence[Windows]) -> Windows:
    """Several window sets as one: agent and edge pointers and file indices shifted, files listed in order (one set
    is returned as it is). Their maps must all be present or all absent."""
    if not parts:
        raise ValueError("concat_windows needs at least one window set")
    if len(parts) == 1:
        return parts[0]
    if len({p.map is None for p in parts}) > 1:
        raise ValueError("window sets with and without map crops cannot be concatenated")
    agent_ptr, edge_ptr, window_file = [np.zeros(1, np.int64)], [np.zeros(1, np.int64)], []
    agents = edges = files = 0
    for p in parts:
        agent_ptr.append(p.agent_ptr[1:] + agents)
        edge_ptr.append(p.edge_ptr[1:] + edges)
        window_file.append(p.window_file + files)
        agents, edges, files = agents + int(p.agent_ptr[-1]), edges + int(p.edge_ptr[-1]), files + len(p.files)
    rows = [*("trajectory", "trajectory_mask", "state", "edge_index", "edge_features", "future", "target")]
    rows += ["class_index", "origin", "heading", "window_frame"]
    return Windows(
        map=None if parts[0].map is None else np.concatenate([p.map for p in parts if p.map is not None]),
        agent_ptr=np.concatenate(agent_ptr),
        edge_ptr=np.concatenate(edge_ptr),
        window_file=np.concatenate(window_file),
        files=[f for p in parts for f in p.files],
        **{k: np.concatenate([getattr(p, k) for p in parts]) for k in rows},
    )


def _cached(
    cache_dir: Path,
    stem: str,
    spec: dgan.InputSpec,
    files: list[Path],
    stride: int,
    version: str,
    build: Callable[[], Windows],
) -> Windows:
    """The windows cached under ``cache_dir`` by content (the spec, the source files' names and sizes, the stride,
    the builder's ``version`` and the engine's raster and preprocessing versions: ``dgan.contract.CACHE_KEY``),
    built by ``build()`` and saved when absent."""
    files_key = [(f.name, f.stat().st_size) for f in files]
    key = hashlib.sha256(json.dumps([spec.to_json(), files_key, stride, version, CACHE_KEY]).encode()).hexdigest()[:16]
    path = cache_dir / f"{stem}_{key}.npz"
    if path.is_file():
        return Windows.load(path)
    w = build()
    cache_dir.mkdir(parents=True, exist_ok=True)
    w.save(path)
    return w


def cached_pedestrian_windows(
    source: str, data_root: Path, spec: dgan.InputSpec, cache_dir: Path, stride: int = 3, progress: bool = True
) -> Windows:
    """The windows of ``source``'s training pedestrians for an ETH/UCY model (``pedestrian_recordings``, at the
    model's time base), cached under ``cache_dir`` by content."""

    def build() -> Windows:
        recs = pedestrian_recordings(source, data_root, spec.dt_s)
        return build_windows(recs, DATASETS["ethucy"], spec, stride, progress)

    files = source_files(source, data_root, "train")
    return _cached(cache_dir, f"pedestrians_{source}", spec, files, stride, "pedestrians-v1", build)


def cached_windows(
    dataset: str,
    data_root: Path,
    split: str,
    spec: dgan.InputSpec,
    cache_dir: Path,
    fold: str = "",
    stride: int = 1,
    progress: bool = True,
    noise: tuple[float, float] = (0.0, 0.0),
) -> Windows:
    """``build_windows`` for one split of a dataset (``fold``: the held-out ETH/UCY scene; ``noise``: tracker-like
    histories), cached under ``cache_dir`` by content."""

    def build() -> Windows:
        recs = recordings(dataset, data_root, split, fold, with_map=spec.map is not None)
        return build_windows(recs, DATASETS[dataset], spec, stride, progress, noise)

    files = source_files(dataset, data_root, split, fold)
    info = DATASETS[dataset]
    # v8: every fully observed agent is a target (hdmap dropped those moving under 1 m before).
    version = f"v8-move{info.min_move_m:g}" + (f"-noise{noise[0]:g}-drop{noise[1]:g}" if noise != (0.0, 0.0) else "")
    stem = f"{dataset}{'_' + fold if fold else ''}_{split}"
    return _cached(cache_dir, stem, spec, files, stride, version, build)
