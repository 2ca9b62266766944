"""Trajectory metrics: the package's own :mod:`dgan.metrics` (one implementation for users and training); and the
calibration gap that the temperature and the scorecard check (:func:`worst_gap`)."""

from __future__ import annotations

from typing import Any

import numpy as np

from dgan.metrics import (
    ade_fde_top1,
    brier_min_fde,
    constant_velocity,
    constant_velocity_variants,
    displacement,
    min_ade_fde,
    miss_rate,
)

__all__ = [
    "CHECKED_FROM_P",
    "MIN_BIN_MODES",
    "ade_fde_top1",
    "brier_min_fde",
    "constant_velocity",
    "constant_velocity_variants",
    "displacement",
    "min_ade_fde",
    "miss_rate",
    "worst_gap",
]

#: "Every bin with p ≥ 0.3": the calibration bins checked, and the largest gap allowed there.
CHECKED_FROM_P = 0.3


#: A bin is checked when it holds at least this many modes (fewer make its frequency mostly noise).
MIN_BIN_MODES = 30


def worst_gap(cal: dict[str, Any]) -> tuple[float, float]:
    """The largest |frequency − mean probability| over the bins from p ≥ 0.3 holding at least ``MIN_BIN_MODES``
    modes, and that bin's p (0 and NaN when no bin qualifies)."""
    edges = np.array(cal["edges"])
    count = np.array(cal["count"])
    p, f = np.array(cal["mean_probability"]), np.array(cal["frequency"])
    sel = (edges[:-1] >= CHECKED_FROM_P - 1e-9) & (count >= MIN_BIN_MODES)
    if not sel.any():
        return 0.0, float("nan")
    gap = np.abs(f - p)[sel]
    i = int(np.argmax(gap))
    return float(gap[i]), float(p[sel][i])
