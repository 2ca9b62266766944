"""Batches of windows as one graph, as the network takes them, with the engine's kinematic prior and map dropout
(:func:`prepared_batch`); a configuration's windows come from :mod:`training.data.splits`."""

from __future__ import annotations

from typing import Any

import numpy as np
import torch

import dgan
from dgan.contract import EDGE_LIST_INPUTS
from training.data.arrays import Windows


def windows_with_targets(w: Windows) -> np.ndarray:
    """Indices of the windows that hold at least one target."""
    counts = np.add.reduceat(w.target.astype(np.int64), w.agent_ptr[:-1]) if len(w.target) else np.zeros(0)
    empty = w.agent_ptr[1:] == w.agent_ptr[:-1]  # reduceat repeats the next value for empty slices
    return np.flatnonzero((counts > 0) & ~empty)


def to_tensors(batch: dict[str, Any]) -> dict[str, torch.Tensor]:
    return {k: torch.from_numpy(np.ascontiguousarray(v)) for k, v in batch.items()}


#: The contract's network inputs, in the order of ``DGAN.forward``.
INPUTS = EDGE_LIST_INPUTS


def forward_inputs(b: dict[str, Any]) -> list[Any]:
    """The network inputs present in a batch, in ``DGAN.forward``'s order (a scene model's ``map``, ``map_grid`` and
    ``map_slot`` as the engine gives them, contract 12)."""
    if "map_grid" in b:  # a scene model whose map is not optional: map_present is None in its place
        return [b.get(k) for k in INPUTS if k in b or k == "map_present"]
    return [b[k] for k in INPUTS if k in b]


def batch_prior(b: dict[str, Any], spec: dgan.InputSpec, rows: Any = slice(None)) -> np.ndarray:
    """The engine's kinematic prior ``(N, T_f, 2)`` under ``spec`` of a batch's agents (``rows`` of them; arrays or
    CPU tensors)."""
    traj, mask, state = (np.asarray(b[k][rows]) for k in INPUTS[:3])  # the prior's inputs lead the contract's
    return dgan.kinematic_prior(traj, mask, state, spec)


def prepared_batch(
    w: Windows,
    idx: np.ndarray,
    spec: dgan.InputSpec,
    flip: np.ndarray | None = None,
    drop: float = 0.0,
    rng: np.random.Generator | None = None,
) -> dict[str, torch.Tensor]:
    """Windows ``idx`` as one graph with the engine's kinematic prior (``prior``, after mirroring) and, for a model
    whose map is optional, ``map_present``: 1, or 0 for the share ``drop`` of agents whose crop is blanked (drawn
    from ``rng``, the trainer's seeded generator) and for the agents of windows without a map (``map_absent``)."""
    b = w.batch(idx, flip)
    b["prior"] = batch_prior(b, spec)
    if spec.map is not None and spec.map.optional:
        present = np.ones(len(b["state"]), dtype=np.float32)
        if "map_absent" in b:  # windows of a dataset without maps: a blank crop, flagged absent as the engine does
            present[b.pop("map_absent")] = 0.0
        if drop > 0:
            if rng is None:
                raise ValueError("map dropout needs the trainer's random generator (rng)")
            gone = rng.random(len(present)) < drop
            present[gone] = 0.0
            # Crops blanked (a scene model's raster is every agent's: its features are gated by map_present).
            for key in ("crops", "teacher_map") if "map_grid" in b else ("map", "teacher_map"):
                if key in b:  # the teacher sees the agent without its map too
                    b[key][gone] = 0.0
        b["map_present"] = present
    return to_tensors(b)
