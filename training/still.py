"""The still radius of a model's classes (contract 15), fitted on its validation split.

    python -m training.still CHECKPOINT [--data-root DIR]

An agent whose every observed step is present and within r metres of its last observed position (a still history,
``dgan.still_agents``: the engine's own test) has its most probable mode held at the kinematic prior: the network's
residual over the prior is dropped for that mode alone. For each class, each radius of :data:`RADII` is tried on the
validation targets (the checkpoint's configuration's validation windows, the model's own top mode); the radius with
the lowest class top-1 ADE is kept if its still group holds at least :data:`MIN_STILL` targets, the group's top-1 ADE
falls by at least :data:`MIN_GAIN` and its top-1 FDE does not rise; otherwise the class is never held (0). The result
is stored in the checkpoint as ``still_radius`` (one value per class); exporting it (``training.export``,
``training.release.bundle --reexport``) writes the contract's ``still_radius_m``.
"""

from __future__ import annotations

import argparse
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import torch

import dgan
from dgan.contract import STATE_FEATURES
from training.export import load_checkpoint

#: The radii tried, metres.
RADII = (0.02, 0.05, 0.1, 0.2)
#: The fewest validation targets in a class's still group for a radius to be kept.
MIN_STILL = 30
#: A radius is kept only if holding lowers its still group's top-1 ADE by at least this share.
MIN_GAIN = 0.02


@dataclass(frozen=True)
class StillErrors:
    """Every validation target's class, whether its history is still at each of :data:`RADII` (``dgan.still_agents``)
    and the top-1 ADE and FDE of the model's most probable mode as decoded (``network``) and held at the prior
    (``held``)."""

    klass: np.ndarray
    still: np.ndarray  # (N, len(RADII)) bool
    network: np.ndarray  # (N, 2): ADE, FDE
    held: np.ndarray  # (N, 2)


@torch.no_grad()
def still_errors(path: Path, data_root: Path | None = None, progress: bool = False) -> tuple[StillErrors, list[str]]:
    """:class:`StillErrors` of the checkpoint at ``path`` on its validation split, and its classes."""
    from training.data.batches import INPUTS
    from training.ensemble import validation_top_modes

    ckpt = load_checkpoint(path)
    c = len(ckpt.spec.classes)
    parts: list[tuple[np.ndarray, ...]] = []
    for b, residual in validation_top_modes(ckpt, data_root, progress):
        t = b["target"]
        prior, future = b["prior"][t].double().numpy(), b["future"][t].double().numpy()
        traj, mask, state = (b[k][t].numpy() for k in INPUTS[:3])  # the contract's first three inputs
        still = np.stack([dgan.still_agents(traj, mask, state, [r] * c) for r in RADII], axis=1)
        net = _errors(prior + residual.double().numpy(), future)
        parts.append((state[:, len(STATE_FEATURES) :].argmax(axis=1), still, net, _errors(prior, future)))
    if not parts:
        raise ValueError(f"{path}: no validation targets")
    cols = [np.concatenate(col) for col in zip(*parts, strict=True)]
    return StillErrors(*cols), list(ckpt.spec.classes)


def _errors(pred: np.ndarray, future: np.ndarray) -> np.ndarray:
    d = np.linalg.norm(pred - future, axis=2)
    return np.stack([d.mean(axis=1), d[:, -1]], axis=1)


@dataclass(frozen=True)
class StillFit:
    """Per class: its name, validation targets, and for each radius the still group's size and its top-1 ADE/FDE as
    decoded and held; the radius kept (0: none)."""

    classes: tuple[str, ...]
    targets: tuple[int, ...]
    groups: tuple[tuple[tuple[int, float, float, float, float], ...], ...]
    radius: tuple[float, ...]

    def __str__(self) -> str:
        rows = []
        for c, n, g, r in zip(self.classes, self.targets, self.groups, self.radius, strict=True):
            tried = ", ".join(
                f"{d:g} m: {k} still, ADE {a:.4f} -> {ha:.4f}, FDE {f:.4f} -> {hf:.4f}"
                for d, (k, a, f, ha, hf) in zip(RADII, g, strict=True)
            )
            rows.append(f"{c} ({n} targets; {tried}) -> {r:g}")
        return "still radius on validation: " + "; ".join(rows)


def choose_radius(e: StillErrors, klass: int) -> tuple[float, tuple[tuple[int, float, float, float, float], ...]]:
    """The radius kept for class ``klass`` (0: none) by the rule of this module's docstring, and each radius's still
    group: size, top-1 ADE and FDE as decoded, then held."""
    mine = e.klass == klass
    groups: list[tuple[int, float, float, float, float]] = []
    totals = []
    for i in range(len(RADII)):
        g = mine & e.still[:, i]
        net, held = (e.network[g].mean(axis=0), e.held[g].mean(axis=0)) if g.any() else (np.zeros(2), np.zeros(2))
        groups.append((int(g.sum()), float(net[0]), float(net[1]), float(held[0]), float(held[1])))
        totals.append(e.network[mine & ~g, 0].sum() + e.held[g, 0].sum())
    best = int(np.argmin(totals))  # the first of equals: the smallest radius
    k, ade, fde, held_ade, held_fde = groups[best]
    keep = k >= MIN_STILL and held_ade <= (1 - MIN_GAIN) * ade and held_fde <= fde
    return (RADII[best] if keep else 0.0), tuple(groups)


def fit_still_radius(path: Path, data_root: Path | None = None, progress: bool = False) -> StillFit:
    """Fits each class's still radius of the checkpoint at ``path`` (:func:`choose_radius`) and stores it there as
    ``still_radius``."""
    from training.checkpoint import update_checkpoint

    e, names = still_errors(path, data_root, progress)
    fits = [choose_radius(e, i) for i in range(len(names))]
    radius = [r for r, _ in fits]
    update_checkpoint(path, still_radius=radius)
    targets = tuple(int((e.klass == i).sum()) for i in range(len(names)))
    return StillFit(tuple(names), targets, tuple(g for _, g in fits), tuple(radius))


def main(argv: list[str] | None = None) -> StillFit:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("checkpoint", type=Path)
    ap.add_argument("--data-root", type=Path, help="the data folder for the validation split (the run's own if unset)")
    a = ap.parse_args(argv)
    fit = fit_still_radius(a.checkpoint, a.data_root, progress=True)
    print(fit)
    return fit


if __name__ == "__main__":
    main()
