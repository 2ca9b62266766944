"""ETH/UCY in the Social-GAN layout → windows of 8 observed and 12 future steps → the engine's network inputs.

Every start frame gives a window; every agent seen at t_obs is in the frame (neighbours with partial histories
included) and the agents present at all 20 steps are the targets. As in Social-GAN, a window is kept when it has at
least two targets. Inputs come from :func:`dgan.preprocess` (the Rust engine), with each scene's colourised semantic
mask as the raster map, and futures in each agent's frame from :func:`dgan.to_agent_frame`.
"""

from __future__ import annotations

import hashlib
import json
from collections.abc import Iterator, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
import numpy.typing as npt

import dgan
from dgan.scenes import scene_raster_map

#: Frame ids step by 10 between 0.4 s steps in the Social-GAN files.
FRAME_STEP = 10
#: Which scene map each Social-GAN file is recorded on.
FILE_SCENES = {
    "biwi_eth": "eth",
    "biwi_hotel": "hotel",
    "students001": "univ",
    "students003": "univ",
    "uni_examples": "univ",
    "crowds_zara01": "zara1",
    "crowds_zara02": "zara2",
    "crowds_zara03": "zara2",
}

Arr = npt.NDArray[Any]


def scene_of(path: Path) -> str:
    for prefix, scene in FILE_SCENES.items():
        if path.name.startswith(prefix):
            return scene
    raise ValueError(f"unknown ETH/UCY file {path.name}")


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
    class_index: Arr  # (A,) i64
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

    def batch(self, windows: Sequence[int], flip: Arr | None = None) -> dict[str, Arr]:
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


def mirror(batch: dict[str, Arr], agents: Arr, edges: Arr) -> None:
    """Mirrors the selected agents' inputs and futures across their x axis (y → -y), in place.

    Valid because every input is agent-centric: y coordinates, lateral velocities, yaw rates and the sines of
    relative headings change sign; map crops flip left-right about the agent's column (the crop must be symmetric
    about it: ``width_px == 2 * agent_col + 1``).
    """
    batch["trajectory"][agents, :, 1] *= -1
    batch["future"][agents, :, 1] *= -1
    batch["state"][agents, 2] *= -1  # yaw rate
    batch["state"][agents, 4] *= -1  # motion sin
    for col in (1, 3, 5):  # dy, dvy, heading sin
        batch["edge_features"][edges, col] *= -1
    if "map" in batch:
        batch["map"][agents] = batch["map"][agents][..., ::-1]


def read_file(path: Path) -> Arr:
    rows = np.loadtxt(path, ndmin=2)
    return rows[np.lexsort((rows[:, 1], rows[:, 0]))]


def iter_windows(rows: Arr, t_obs: int, t_f: int, min_targets: int = 2) -> Iterator[tuple[float, Arr, Arr, Arr, Arr]]:
    """Each kept window as ``(t_obs frame, ids (N,), positions (N, T_obs + T_f, 2), mask (N, T), target (N,))``."""
    frames = np.unique(rows[:, 0])
    by_frame = {f: rows[rows[:, 0] == f] for f in frames}
    total = t_obs + t_f
    for f0 in frames:
        steps = [f0 + k * FRAME_STEP for k in range(total)]
        now = steps[t_obs - 1]
        if now not in by_frame:
            continue
        ids = np.unique(by_frame[now][:, 1])
        pos = np.full((len(ids), total, 2), np.nan)
        mask = np.zeros((len(ids), total), dtype=bool)
        for k, f in enumerate(steps):
            r = by_frame.get(f)
            if r is None:
                continue
            hit = np.isin(r[:, 1], ids)
            idx = np.searchsorted(ids, r[hit, 1])
            pos[idx, k] = r[hit, 2:4]
            mask[idx, k] = True
        target = mask.all(axis=1)
        if target.sum() >= min_targets:
            yield float(now), ids, pos, mask, np.asarray(target)


def build_windows(
    files: Sequence[Path], maps_root: Path | None, spec: dgan.InputSpec, progress: bool = True
) -> Windows:
    """Preprocesses every window of ``files`` through the engine."""
    from tqdm import tqdm

    parts: dict[str, list[Arr]] = {k: [] for k in Windows.__dataclass_fields__ if k not in ("files",)}
    agent_ptr, edge_ptr = [0], [0]
    cls_index = list(spec.classes).index("pedestrian")
    maps = {}
    for fi, path in enumerate(files):
        scene = scene_of(path)
        if spec.map is not None and maps_root is not None and scene not in maps:
            maps[scene] = scene_raster_map(scene, maps_root / scene)
        rows = read_file(path)
        windows = list(iter_windows(rows, spec.t_obs, spec.t_f))
        for now, ids, pos, mask, target in tqdm(windows, desc=path.name, disable=not progress, leave=False):
            obs_mask = mask[:, : spec.t_obs]
            frame = dgan.Frame(pos[:, : spec.t_obs], mask=obs_mask, ids=ids.astype(np.int64), map=maps.get(scene))
            x = dgan.preprocess(frame, spec)
            fut = np.where(mask[:, spec.t_obs :, None], pos[:, spec.t_obs :], 0.0)
            future = dgan.to_agent_frame(fut, x["origin"], x["heading"])
            n = len(ids)
            for key in ("trajectory", "trajectory_mask", "state", "edge_index", "edge_features", "origin", "heading"):
                parts[key].append(x[key])
            if "map" in x:
                parts["map"].append(np.round(x["map"] * 255).astype(np.uint8))
            parts["future"].append(future.astype(np.float32))
            parts["target"].append(target)
            parts["class_index"].append(np.full(n, cls_index, np.int64))
            parts["window_file"].append(np.array([fi]))
            parts["window_frame"].append(np.array([now]))
            agent_ptr.append(agent_ptr[-1] + n)
            edge_ptr.append(edge_ptr[-1] + len(x["edge_index"]))
    cat = {k: np.concatenate(v) for k, v in parts.items() if v and k not in ("agent_ptr", "edge_ptr")}
    return Windows(
        map=cat.pop("map", None),
        agent_ptr=np.array(agent_ptr),
        edge_ptr=np.array(edge_ptr),
        files=[str(f) for f in files],
        **cat,
    )


def split_files(data_root: Path, scene: str, split: str) -> list[Path]:
    """The Social-GAN files of a leave-one-scene-out fold: ``train``/``val`` hold the other scenes, ``test`` the
    held-out one."""
    folder = data_root / "eth_ucy" / "datasets" / scene / split
    files = sorted(folder.glob("*.txt"))
    if not files:
        raise FileNotFoundError(f"no ETH/UCY files in {folder}; set data.root to the folder holding eth_ucy/")
    return files


def cached_windows(
    data_root: Path, scene: str, split: str, spec: dgan.InputSpec, cache_dir: Path, progress: bool = True
) -> Windows:
    """``build_windows`` for one split of one fold, cached under ``cache_dir`` by content."""
    files = split_files(data_root, scene, split)
    key = hashlib.sha256(
        json.dumps([spec.to_json(), [(f.name, f.stat().st_size) for f in files], "v1"]).encode()
    ).hexdigest()[:16]
    path = cache_dir / f"ethucy_{scene}_{split}_{key}.npz"
    if path.is_file():
        return Windows.load(path)
    maps_root = data_root / "eth_ucy_scene_maps" / "semantic_masks"
    w = build_windows(files, maps_root if spec.map is not None else None, spec, progress)
    cache_dir.mkdir(parents=True, exist_ok=True)
    w.save(path)
    return w
