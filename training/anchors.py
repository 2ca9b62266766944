"""Anchors: k-means (scikit-learn) of agent-centric ground-truth futures, per class."""

from __future__ import annotations

from typing import Any

import numpy as np
import numpy.typing as npt

Arr = npt.NDArray[Any]


def kmeans_anchors(futures: Arr, k: int, seed: int = 0) -> Arr:
    """``(k, T_f, 2)`` cluster centres of ``futures (N, T_f, 2)`` under the summed squared distance of the paper."""
    from sklearn.cluster import KMeans

    if len(futures) < k:
        raise ValueError(f"{len(futures)} futures cannot make {k} anchors")
    flat = futures.reshape(len(futures), -1).astype(np.float64)
    km = KMeans(n_clusters=k, n_init=4, random_state=seed).fit(flat)
    centres: Arr = km.cluster_centers_.reshape(k, *futures.shape[1:])
    # Order by final distance travelled, so anchor indices read from slow to fast.
    order = np.argsort(np.linalg.norm(centres[:, -1], axis=1), kind="stable")
    return centres[order]
