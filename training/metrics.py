"""Trajectory metrics: the package's own :mod:`dgan.metrics` (one implementation for users and training)."""

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
    "ade_fde_top1",
    "brier_min_fde",
    "constant_velocity",
    "constant_velocity_variants",
    "displacement",
    "min_ade_fde",
    "miss_rate",
]
