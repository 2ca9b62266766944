"""Anchors: k-means (scikit-learn) of agent-centric ground-truth futures' residuals from the prior, per class."""

from __future__ import annotations

from typing import Any

import numpy as np
import numpy.typing as npt

import dgan
from training.config import Config
from training.data.arrays import Windows

Arr = npt.NDArray[Any]


def kmeans_anchors(futures: Arr, k: int, seed: int = 0, zero: bool = False, rounds: int = 20) -> Arr:
    """``(k, T_f, 2)`` cluster centres of ``futures (N, T_f, 2)`` under the summed squared distance of the paper.

    ``zero``: one centre is held at the origin (for residual futures: the kinematic prior itself) and the other k − 1
    are fitted around it (scikit-learn's k-means for k − 1 centres, then ``rounds`` Lloyd steps with the origin
    fixed)."""
    from sklearn.cluster import KMeans

    if len(futures) < k:
        raise ValueError(f"{len(futures)} futures cannot make {k} anchors")
    flat = futures.reshape(len(futures), -1).astype(np.float64)
    free = k - 1 if zero else k
    fitted = KMeans(n_clusters=free, n_init=4, random_state=seed).fit(flat).cluster_centers_ if free else flat[:0]
    if zero:
        fitted = np.concatenate([np.zeros((1, flat.shape[1])), fitted])
        for _ in range(rounds):
            nearest = ((flat[:, None, :] - fitted[None]) ** 2).sum(-1).argmin(1)
            for j in range(1, k):
                if (nearest == j).any():
                    fitted[j] = flat[nearest == j].mean(0)
    centres: Arr = fitted.reshape(k, *futures.shape[1:])
    # Order by final distance travelled, so anchor indices read from slow to fast.
    order = np.argsort(np.linalg.norm(centres[:, -1], axis=1), kind="stable")
    return centres[order]


def anchor_windows(cfg: Config, parts: list[Windows], train: Windows) -> Windows:
    """The training windows whose futures the anchors are fitted on: all of ``train`` (the concatenation of
    ``parts``), or with ``data.extra_in_anchors`` false the dataset's own windows ``parts[0]`` alone."""
    return train if cfg.data.extra_in_anchors else parts[0]


def residual_futures(w: Windows, spec: dgan.InputSpec) -> np.ndarray:
    """``(A, T_f, 2)`` every agent's future minus its kinematic prior (agent frame): what the anchors model."""
    prior = dgan.kinematic_prior(w.trajectory, w.trajectory_mask, w.state, spec)
    out: np.ndarray = w.future - prior
    return out


def fit_anchors(cfg: Config, train: Windows, spec: dgan.InputSpec, num_classes: int) -> tuple[np.ndarray, np.ndarray]:
    """K_c k-means anchors of the residuals from the prior for every class (from all of its targets, also in a
    per-class run, so that the model contract holds) and the class of each anchor."""
    out = []
    residual = residual_futures(train, spec)
    for c in range(num_classes):
        fut = residual[train.target & (train.class_index == c)]
        if cfg.train.mirror:
            flipped = fut.copy()
            flipped[..., 1] *= -1
            fut = np.concatenate([fut, flipped])
        k, seed = cfg.train.anchors_per_class, cfg.train.seed
        out.append(kmeans_anchors(fut, k, seed, cfg.train.zero_anchor).astype(np.float32))
    class_of = np.repeat(np.arange(num_classes), cfg.train.anchors_per_class)
    return np.concatenate(out), class_of
