"""Trajectory metrics, the ones of the standard protocols (ETH/UCY, Argoverse): numpy only, used by ``training/``.

Predictions are ``(N, M, T, 2)`` with modes sorted by probability (most probable first), as
:class:`~dgan.Prediction` gives them; ground truth ``(N, T, 2)``; probabilities ``(N, M)``. Every function returns
per-agent values in the inputs' unit; average them yourself (:func:`summary` does it for a prediction).

>>> import numpy as np
>>> pred = np.zeros((1, 2, 3, 2)); pred[0, 1, :, 0] = 1.0
>>> gt = np.ones((1, 3, 2)) * [1.0, 0.0]
>>> ade(pred, gt), min_ade(pred, gt, k=2)
(array([1.]), array([0.]))
"""

from __future__ import annotations

from typing import Any

import numpy as np
import numpy.typing as npt

from dgan.exceptions import InvalidFrameError

Arr = npt.NDArray[Any]

__all__ = [
    "ade",
    "ade_fde_top1",
    "brier_min_fde",
    "constant_velocity",
    "constant_velocity_variants",
    "displacement",
    "fde",
    "min_ade",
    "min_ade_fde",
    "min_fde",
    "miss_rate",
    "summary",
]


def _finite(name: str, a: Arr, axes: tuple[int, ...]) -> None:
    bad = ~np.all(np.isfinite(a), axis=axes)
    if np.any(bad):
        rows = np.flatnonzero(bad)
        raise InvalidFrameError(
            f"{name} holds NaN or infinite values for {rows.size} agent(s), e.g. row {rows[0]}: score only the agents "
            "with a full ground truth (select them first; a NaN would silently make the mean NaN)"
        )


def _check(pred: Arr, gt: Arr) -> tuple[Arr, Arr]:
    p, g = np.asarray(pred, dtype=np.float64), np.asarray(gt, dtype=np.float64)
    if p.ndim != 4 or p.shape[-1] != 2:
        raise InvalidFrameError(f"predictions must have shape (N, M, T, 2), got {p.shape}")
    if g.shape != (p.shape[0], p.shape[2], 2):
        raise InvalidFrameError(
            f"ground truth must have shape (N, T, 2) = {(p.shape[0], p.shape[2], 2)}, got {g.shape}"
        )
    _finite("the ground truth", g, (1, 2))
    _finite("the predictions", p, (1, 2, 3))
    return p, g


def _k(k: int, m: int) -> int:
    if isinstance(k, bool) or not isinstance(k, (int, np.integer)) or k < 1:
        raise InvalidFrameError(f"k must be a positive integer, got {k!r}")
    return min(int(k), m)


def displacement(pred: Arr, gt: Arr) -> Arr:
    """``(N, M, T)`` Euclidean error of every mode at every step."""
    p, g = _check(pred, gt)
    out: Arr = np.linalg.norm(p - g[:, None], axis=-1)
    return out


def ade_fde_top1(pred: Arr, gt: Arr) -> tuple[Arr, Arr]:
    """Per-agent ADE and FDE of the most probable mode (mode 0)."""
    d = displacement(np.asarray(pred)[:, :1], gt)[:, 0]
    return d.mean(axis=1), d[:, -1]


def ade(pred: Arr, gt: Arr) -> Arr:
    """Per-agent average displacement error of the most probable mode."""
    return ade_fde_top1(pred, gt)[0]


def fde(pred: Arr, gt: Arr) -> Arr:
    """Per-agent final displacement error of the most probable mode."""
    return ade_fde_top1(pred, gt)[1]


def min_ade_fde(pred: Arr, gt: Arr, k: int) -> tuple[Arr, Arr]:
    """Per-agent minADE_k and minFDE_k over the ``k`` most probable modes; each minimum is taken separately."""
    d = displacement(np.asarray(pred)[:, : _k(k, np.shape(pred)[1])], gt)
    return d.mean(axis=2).min(axis=1), d[:, :, -1].min(axis=1)


def min_ade(pred: Arr, gt: Arr, k: int) -> Arr:
    """Per-agent minADE_k."""
    return min_ade_fde(pred, gt, k)[0]


def min_fde(pred: Arr, gt: Arr, k: int) -> Arr:
    """Per-agent minFDE_k."""
    return min_ade_fde(pred, gt, k)[1]


def brier_min_fde(pred: Arr, gt: Arr, prob: Arr, k: int) -> Arr:
    """Per-agent Brier-minFDE_k (Argoverse): FDE of the mode with the smallest FDE among the top ``k``, plus
    ``(1 - p)²`` of that mode's probability."""
    p = np.asarray(prob, dtype=np.float64)
    if p.shape != np.shape(pred)[:2]:
        raise InvalidFrameError(f"probabilities must have shape (N, M) = {np.shape(pred)[:2]}, got {p.shape}")
    fde_k = displacement(np.asarray(pred)[:, : _k(k, p.shape[1])], gt)[:, :, -1]
    best = fde_k.argmin(axis=1)
    rows = np.arange(len(fde_k))
    out: Arr = fde_k[rows, best] + (1.0 - p[rows, best]) ** 2
    return out


def miss_rate(pred: Arr, gt: Arr, k: int, threshold: float = 2.0) -> Arr:
    """Per-agent miss (1.0) or hit (0.0): whether every one of the top ``k`` modes ends farther than ``threshold``
    from the true end point (Argoverse's miss rate at 2 m)."""
    return (min_fde(pred, gt, k) > threshold).astype(np.float64)


def summary(pred: Arr, gt: Arr, prob: Arr | None = None, ks: tuple[int, ...] = (1, 5, 20)) -> dict[str, float]:
    """Mean metrics over agents: ``ade``, ``fde``, and for each ``k`` in ``ks`` up to the modes given ``min_ade_k``,
    ``min_fde_k``, ``miss_rate_k`` and (with probabilities) ``brier_min_fde_k``."""
    out = {"ade": float(ade(pred, gt).mean()), "fde": float(fde(pred, gt).mean())}
    for k in ks:
        if k > np.shape(pred)[1] or k == 1:
            continue
        a, f = min_ade_fde(pred, gt, k)
        out[f"min_ade_{k}"], out[f"min_fde_{k}"] = float(a.mean()), float(f.mean())
        out[f"miss_rate_{k}"] = float(miss_rate(pred, gt, k).mean())
        if prob is not None:
            out[f"brier_min_fde_{k}"] = float(brier_min_fde(pred, gt, prob, k).mean())
    return out


def constant_velocity(trajectory: Arr, mask: Arr, t_f: int, window: int = 1) -> Arr:
    """``(N, 1, T_f, 2)``: each agent keeps a constant velocity (zero with one observed step). ``window`` = 1: the
    velocity of its last two observed steps; ``window`` = k > 1: its mean velocity over the last k steps (from the
    earliest observed step among them; the last two steps when none is).

    Raises:
        InvalidFrameError: shapes that disagree (``trajectory`` ``(N, T, 2)``, ``mask`` ``(N, T)``), an agent without
            an observed step, a non-finite observed position.
    """
    trajectory, mask = np.asarray(trajectory, dtype=np.float64), np.asarray(mask)
    if trajectory.ndim != 3 or trajectory.shape[-1] != 2:
        raise InvalidFrameError(f"trajectory must have shape (N, T, 2), got {trajectory.shape}")
    if mask.shape != trajectory.shape[:2]:
        raise InvalidFrameError(f"mask must have shape (N, T) = {trajectory.shape[:2]}, got {mask.shape}")
    mask = mask.astype(bool)
    empty = np.flatnonzero(~mask.any(axis=1))
    if empty.size:
        raise InvalidFrameError(f"{empty.size} agent(s) have no observed step, e.g. row {empty[0]}")
    if not np.all(np.isfinite(trajectory[mask])):
        raise InvalidFrameError("the trajectory holds NaN or infinite values at observed steps")
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
