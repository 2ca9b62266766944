"""Preprocessed windows as the network takes them, concatenated into arrays (:class:`Windows`, built by
:mod:`training.data.windows` and cached by :mod:`training.data.cache`): batches of windows as one graph, mirroring, and
several window sets as one (:func:`concat_windows`)."""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass
from typing import Any, Final

import numpy as np
import numpy.typing as npt

from dgan.contract import EDGE_FEATURES, EDGE_MIRRORED, STATE_FEATURES, STATE_MIRRORED

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
    # (A,) bool: the agent's frame had no map (a dataset without one, for a model whose map is optional); None: none
    map_absent: Arr | None = None
    # (A,) bool: the agent's window is a noisy copy (data.augment_noise, training.data.augment); None: none is
    noisy: Arr | None = None
    # (A, 3, H_t, W_t) u8: the same agents' crops drawn to a distillation teacher's geometry where it differs from the
    # student's (training.step.teacher_crops); None: the teacher takes the student's
    teacher_map: Arr | None = None
    # (W, 3, S, S) u8: each window's scene raster (data.map_scene_px, dgan.scene_raster); None: none
    scene: Arr | None = None
    # (A, gh, gw, 2) f32: where each agent's crop blocks lie in its window's scene raster (dgan.crop_grid)
    scene_grid: Arr | None = None

    @property
    def num_windows(self) -> int:
        return len(self.agent_ptr) - 1

    @property
    def num_targets(self) -> int:
        return int(self.target.sum())

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
        if self.map_absent is not None:
            out["map_absent"] = self.map_absent[a_idx]
        if self.noisy is not None:
            out["noisy"] = self.noisy[a_idx]
        if self.teacher_map is not None:
            out["teacher_map"] = self.teacher_map[a_idx].astype(np.float32) / 255.0
        if self.scene is not None and self.scene_grid is not None:
            # A scene model's inputs as the engine gives them (contract 12): the windows' rasters as ``map``, their
            # agents' grids padded to the window with the most, each agent's slot; the crops stay for a teacher.
            if "map" in out:
                out["crops"] = out.pop("map")
            out["map"] = self.scene[w].astype(np.float32) / 255.0
            out["map_grid"], out["map_slot"] = padded_grids(self.scene_grid[a_idx], n_agents)
        if flip is not None and flip.any():
            mirror(out, np.repeat(flip, n_agents), np.repeat(flip, n_edges))
            if "map_grid" in out:  # the scene flipped left-right, and its agents' grids with it (columns reversed)
                out["map"][flip] = out["map"][flip][..., ::-1]
                out["map_grid"][flip] = out["map_grid"][flip][:, :, :, ::-1] * np.array([-1.0, 1.0], np.float32)
        return out


#: The columns of the state and edge features that mirroring negates (the engine's, ``dgan.contract``).
STATE_MIRROR_COLUMNS: Final = tuple(STATE_FEATURES.index(c) for c in STATE_MIRRORED)
EDGE_MIRROR_COLUMNS: Final = tuple(EDGE_FEATURES.index(c) for c in EDGE_MIRRORED)


def padded_grids(grids: Arr, per_window: Arr) -> tuple[Arr, Arr]:
    """Agents' crop grids ``(A, gh, gw, 2)``, ``per_window[w]`` of them to window w in order, as the engine lays them
    out (contract 12): ``(W, M, gh, gw, 2)``, padded with zeros to the window with the most agents M, and each agent's
    row of it flattened ``(A,)``."""
    most = int(per_window.max()) if len(per_window) else 0
    window = np.repeat(np.arange(len(per_window)), per_window)
    slot = np.arange(len(grids)) - np.repeat(np.cumsum(per_window) - per_window, per_window)
    out = np.zeros((len(per_window), most, *grids.shape[1:]), np.float32)
    out[window, slot] = grids
    return out, (window * most + slot).astype(np.int64)


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
    # A scene model's ``map`` is its windows' rasters, mirrored with their grids (:meth:`Windows.batch`).
    for key in ("crops", "teacher_map") if "map_grid" in batch else ("map", "teacher_map"):
        if key in batch:
            batch[key][agents] = batch[key][agents][..., ::-1]


def concat_windows(parts: Sequence[Windows]) -> Windows:
    """Several window sets as one: agent and edge pointers and file indices shifted, files listed in order (one set
    is returned as it is). Their maps must all be present or all absent."""
    if not parts:
        raise ValueError("concat_windows needs at least one window set")
    if len(parts) == 1:
        return parts[0]
    if len({p.map is None for p in parts}) > 1:
        raise ValueError("window sets with and without map crops cannot be concatenated")
    if len({p.scene is None for p in parts}) > 1:
        raise ValueError("window sets with and without scene rasters cannot be concatenated")
    if any(p.teacher_map is not None for p in parts):
        raise ValueError("a teacher's crops are added to the concatenated windows (training.step.teacher_crops)")
    agent_ptr, edge_ptr, window_file = [np.zeros(1, np.int64)], [np.zeros(1, np.int64)], []
    agents = edges = files = 0
    for p in parts:
        agent_ptr.append(p.agent_ptr[1:] + agents)
        edge_ptr.append(p.edge_ptr[1:] + edges)
        window_file.append(p.window_file + files)
        agents, edges, files = agents + int(p.agent_ptr[-1]), edges + int(p.edge_ptr[-1]), files + len(p.files)
    rows = [*("trajectory", "trajectory_mask", "state", "edge_index", "edge_features", "future", "target")]
    rows += ["class_index", "origin", "heading", "window_frame"]
    absent, noisy = (_flags(parts, name) for name in ("map_absent", "noisy"))
    return Windows(
        map=None if parts[0].map is None else np.concatenate([p.map for p in parts if p.map is not None]),
        scene=None if parts[0].scene is None else np.concatenate([p.scene for p in parts if p.scene is not None]),
        scene_grid=None
        if parts[0].scene_grid is None
        else np.concatenate([p.scene_grid for p in parts if p.scene_grid is not None]),
        map_absent=absent,
        noisy=noisy,
        agent_ptr=np.concatenate(agent_ptr),
        edge_ptr=np.concatenate(edge_ptr),
        window_file=np.concatenate(window_file),
        files=[f for p in parts for f in p.files],
        **{k: np.concatenate([getattr(p, k) for p in parts]) for k in rows},
    )


def _flags(parts: Sequence[Windows], name: str) -> Arr | None:
    """The per-agent flag ``name`` of several window sets concatenated (false for a set without it); None if none
    has it."""
    flags: list[Arr | None] = [getattr(p, name) for p in parts]
    if all(f is None for f in flags):
        return None
    return np.concatenate(
        [np.zeros(int(p.agent_ptr[-1]), bool) if f is None else f for p, f in zip(parts, flags, strict=True)]
    )
