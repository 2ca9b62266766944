"""Windows as the network takes them: a configuration's splits (:func:`load_windows`), and batches of windows as
one graph with the engine's kinematic prior and map dropout (:func:`prepared_batch`)."""

from __future__ import annotations

from pathlib import Path
from typing import Any

import numpy as np
import torch

import dgan
from dgan.contract import EDGE_LIST_INPUTS
from training.config import Config
from training.data.datasets import pedestrian_sources
from training.data.windows import Windows, cached_pedestrian_windows, cached_windows, concat_windows


def load_windows(cfg: Config, spec: dgan.InputSpec, split: str, progress: bool) -> Windows:
    """A split's cached windows; for training, with the pedestrians of ``data.extra_pedestrians`` (ETH/UCY only)."""
    return concat_windows(load_window_parts(cfg, spec, split, progress))


def load_window_parts(cfg: Config, spec: dgan.InputSpec, split: str, progress: bool) -> list[Windows]:
    """A split's cached windows of the dataset itself, then (for training) those of each ``data.extra_pedestrians``
    source."""
    d = cfg.data
    fold = {"ethucy": d.scene, "apolloscape": d.val_recordings}.get(d.dataset, "")
    if d.val_recordings and d.dataset != "apolloscape":
        raise ValueError(f"data.val_recordings is for ApolloScape, not {d.dataset!r}")
    cache, root = Path(d.cache_dir).expanduser(), Path(d.root).expanduser()
    sources = pedestrian_sources(d.extra_pedestrians)
    if sources and d.dataset != "ethucy":
        raise ValueError(f"data.extra_pedestrians is for the ETH/UCY models, not {d.dataset!r}")
    own = cached_windows(d.dataset, root, split, spec, cache, fold, d.window_stride, progress)
    if split != "train":
        return [own]
    noisy = [
        cached_windows(d.dataset, root, split, spec, cache, fold, d.window_stride, progress, (sigma, d.augment_drop))
        for sigma in augment_sigmas(d.augment_noise)
    ]
    extra = [cached_pedestrian_windows(s, root, spec, cache, d.extra_stride, progress) for s in sources]
    return [own, *noisy, *extra]


def augment_sigmas(declared: str) -> list[float]:
    """The noise levels of ``data.augment_noise`` (comma-separated metres; "" = none)."""
    try:
        sigmas = [float(x) for x in declared.split(",") if x.strip()]
    except ValueError:
        raise ValueError(f"data.augment_noise must be comma-separated metres, got {declared!r}") from None
    if any(not (0.0 < x <= 5.0) for x in sigmas):
        raise ValueError(f"data.augment_noise must hold noise levels in (0, 5] metres, got {declared!r}")
    return sigmas


def restrict_targets(w: Windows, spec: dgan.InputSpec, target_class: str) -> None:
    """For a per-class run: only that class's agents stay targets (the others remain neighbours)."""
    if target_class not in spec.classes:
        raise ValueError(f"data.target_class {target_class!r} is not among the classes {spec.classes}")
    w.target &= w.class_index == list(spec.classes).index(target_class)


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
    """The network inputs present in a batch, in ``DGAN.forward``'s order."""
    return [b[k] for k in INPUTS if k in b]


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
    from ``rng``, the trainer's seeded generator)."""
    b = w.batch(idx, flip)
    b["prior"] = dgan.kinematic_prior(b["trajectory"], b["trajectory_mask"], b["state"], spec)
    if spec.map is not None and spec.map.optional:
        present = np.ones(len(b["state"]), dtype=np.float32)
        if drop > 0:
            if rng is None:
                raise ValueError("map dropout needs the trainer's random generator (rng)")
            gone = rng.random(len(present)) < drop
            present[gone] = 0.0
            b["map"][gone] = 0.0
        b["map_present"] = present
    return to_tensors(b)
