"""Anchors: k-means (scikit-learn) of agent-centric ground-truth futures, per class."""

from __future__ import annotations

from typing import Any

import numpy as np
import numpy.typing as npt

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
