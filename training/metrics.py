"""Trajectory metrics: small pure numpy functions. Predictions are ``(N, M, T, 2)`` with modes sorted by probability
(most probable first), ground truth ``(N, T, 2)``, probabilities ``(N, M)``. Units follow the inputs."""

from __future__ import annotations

from typing import Any

import numpy as np
import numpy.typing as npt

Arr = npt.NDArray[Any]


def displacement(pred: Arr, gt: Arr) -> Arr:
    """``(N, M, T)`` Euclidean error of every mode at every step."""
    out: Arr = np.linalg.norm(pred - gt[:, None], axis=-1)
    return out


def ade_fde_top1(pred: Arr, gt: Arr) -> tuple[Arr, Arr]:
    """Per-agent ADE and FDE of the most probable mode (mode 0)."""
    d = displacement(pred[:, :1], gt)[:, 0]
    return d.mean(axis=1), d[:, -1]


def min_ade_fde(pred: Arr, gt: Arr, k: int) -> tuple[Arr, Arr]:
    """Per-agent minADE_k and minFDE_k over the ``k`` most probable modes; each minimum is taken separately."""
    d = displacement(pred[:, :k], gt)
    return d.mean(axis=2).min(axis=1), d[:, :, -1].min(axis=1)


def brier_min_fde(pred: Arr, gt: Arr, prob: Arr, k: int) -> Arr:
    """Per-agent Brier-minFDE_k (Argoverse): FDE of the mode with the smallest FDE among the top ``k``, plus
    ``(1 - p)²`` of that mode's probability."""
    fde = displacement(pred[:, :k], gt)[:, :, -1]
    best = fde.argmin(axis=1)
    rows = np.arange(len(pred))
    out: Arr = fde[rows, best] + (1.0 - prob[rows, best]) ** 2
    return out


def constant_velocity(trajectory: Arr, mask: Arr, t_f: int, window: int = 1) -> Arr:
    """``(N, 1, T_f, 2)``: each agent keeps a constant velocity (zero with one observed step). ``window`` = 1: the
    velocity of its last two observed steps; ``window`` = k > 1: its mean velocity over the last k steps (from the
    earliest observed step among them; the last two steps when none is)."""
    n = len(trajectory)
    out = np.zeros((n, 1, t_f, 2))
    for i in range(n):
        idx = np.flatnonzero(mask[i])
        if len(idx) < 2:
            out[i, 0] = trajectory[i, idx[-1]]
            continue
        inside = idx[idx >= idx[-1] - window]
        first = inside[0] if window > 1 and len(inside) > 1 else idx[-2]
        v = (trajectory[i, idx[-1]] - trajectory[i, first]) / (idx[-1] - first)
        out[i, 0] = trajectory[i, idx[-1]] + v * np.arange(1, t_f + 1)[:, None]
    return out


def constant_velocity_variants(trajectory: Arr, mask: Arr, t_f: int, dt_s: float) -> dict[str, Arr]:
    """The two constant-velocity baselines every accuracy table carries: ``last2`` (the last two observed steps)
    and ``mean1s`` (the mean velocity over the last second, ``max(2, round(1 / dt))`` steps)."""
    return {
        "last2": constant_velocity(trajectory, mask, t_f),
        "mean1s": constant_velocity(trajectory, mask, t_f, max(2, round(1.0 / dt_s))),
    }
