"""Tracker-like corruption of observed histories: what a user's tracker gives instead of a dataset's smoothed tracks.

Used three ways, so that each sees the same corruption: training windows (``data.augment_*``), the noisy-track
evaluation (``training.evaluate --noise``) and the prior study (``training.studies.prior --velocity``).
"""

from __future__ import annotations

from typing import Any

import numpy as np
import numpy.typing as npt

Arr = npt.NDArray[Any]


def tracker_noise(
    positions_m: Arr, mask: Arr, sigma_m: float, drop: float, rng: np.random.Generator
) -> tuple[Arr, Arr]:
    """``positions_m (N, T, 2)`` (world metres) with isotropic Gaussian noise of ``sigma_m`` added to every valid
    step, and ``mask (N, T)`` with a share ``drop`` of each agent's valid steps before the last one dropped at
    random (the last observed step, the agent's current position, is kept so that the agent stays in the frame at
    t_obs). Returns new arrays; the inputs are not changed."""
    if not (np.isfinite(sigma_m) and sigma_m >= 0):
        raise ValueError(f"sigma_m must be a non-negative number of metres, got {sigma_m}")
    if not (0.0 <= drop < 1.0):
        raise ValueError(f"drop must be a share in [0, 1), got {drop}")
    pos = np.array(positions_m, dtype=np.float64, copy=True)
    keep = np.array(mask, dtype=bool, copy=True)
    if sigma_m > 0:
        pos = np.where(keep[..., None], pos + rng.normal(0.0, sigma_m, pos.shape), pos)
    if drop > 0 and keep.size:
        last = keep.shape[1] - 1 - np.argmax(keep[:, ::-1], axis=1)
        before_last = np.arange(keep.shape[1])[None, :] < last[:, None]
        keep &= ~(before_last & (rng.random(keep.shape) < drop))
    return pos, keep


def held_still(positions_m: Arr, mask: Arr, within_m: float) -> Arr:
    """``positions_m (N, T, 2)`` with every agent whose valid positions all lie within ``within_m`` of its last valid
    one given that position at every valid step: a tracker holding a static object's box where it is, rather than a
    dataset's annotation jitter. Other agents, invalid steps and ``mask`` are unchanged. Returns a new array."""
    if not (np.isfinite(within_m) and within_m > 0):
        raise ValueError(f"within_m must be a positive number of metres, got {within_m}")
    pos = np.array(positions_m, dtype=np.float64, copy=True)
    keep = np.asarray(mask, dtype=bool)
    if not keep.size:
        return pos
    last = keep.shape[1] - 1 - np.argmax(keep[:, ::-1], axis=1)  # (N,) the last valid step (0 if none)
    now = pos[np.arange(len(pos)), last]  # (N, 2)
    spread = np.where(keep, np.linalg.norm(pos - now[:, None], axis=-1), 0.0).max(axis=1)
    hold = keep.any(axis=1) & (spread < within_m)
    pos[hold] = np.where(keep[hold][..., None], now[hold][:, None], pos[hold])
    return pos
