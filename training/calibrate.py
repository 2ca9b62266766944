"""Calibration of the mode probabilities: one temperature T of the anchor logits, p(k | c) = softmax(logits / T),
fitted on a validation split. The event is the best mode (the mode closest to the ground truth by ADE, which the
reliability diagram of :mod:`training.evaluate` counts). Two proper scores are minimised over a grid of T: the best
mode's negative log-likelihood and the Brier score of the best-mode indicator (which weighs the probable modes more);
of the two temperatures, the one whose validation reliability is closer in the bins the must-show checks (p ≥ 0.3,
at least 30 modes: :func:`training.metrics.worst_gap`) is kept. The engine applies it in decoding (contract 2).
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass, replace
from pathlib import Path
from typing import Any

import numpy as np
import torch

import dgan
from training.config import Config
from training.data.arrays import Windows
from training.losses import mode_probabilities
from training.metrics import worst_gap

#: The temperatures tried, log-spaced.
GRID = np.exp(np.linspace(np.log(0.05), np.log(20.0), 121))


@torch.no_grad()
def best_mode_logits(
    model: torch.nn.Module, w: Windows, spec: dgan.InputSpec, anchors: torch.Tensor, batch: int = 64
) -> tuple[torch.Tensor, torch.Tensor, torch.Tensor]:
    """For every target of ``w``: class logits, anchor logits and the index of its best mode (smallest ADE)."""
    from training.data.batches import forward_inputs, prepared_batch, windows_with_targets

    model.eval()
    cls, anc, best = [], [], []
    keep = windows_with_targets(w)
    for start in range(0, len(keep), batch):
        b = prepared_batch(w, keep[start : start + batch], spec)
        cl, al, off = model(*forward_inputs(b))
        t = b["target"]
        modes = anchors.unsqueeze(0) + off[t] + b["prior"][t].unsqueeze(1)
        ade = torch.linalg.norm(modes - b["future"][t].unsqueeze(1), dim=-1).mean(-1)
        cls.append(cl[t])
        anc.append(al[t])
        best.append(ade.argmin(dim=1))
    return torch.cat(cls), torch.cat(anc), torch.cat(best)


def best_mode_log_loss(p: torch.Tensor, best: torch.Tensor) -> float:
    """Mean −log p(best mode) of mode probabilities ``p (N, K)``."""
    return float(-torch.log(p[torch.arange(len(best)), best].clamp_min(1e-12)).mean())


def best_mode_brier(p: torch.Tensor, best: torch.Tensor) -> float:
    """Mean Brier score Σ_k (p_k − [k is the best mode])² of mode probabilities ``p (N, K)``."""
    hit = torch.zeros_like(p)
    hit[torch.arange(len(best)), best] = 1.0
    return float(((p - hit) ** 2).sum(dim=1).mean())


def best_mode_reliability(p: torch.Tensor, best: torch.Tensor) -> dict[str, Any]:
    """The reliability bins (``training.evaluate.calibration``) of mode probabilities ``p (N, K)`` against the event
    'this mode is the best'."""
    from training.evaluate import calibration

    hit = torch.zeros_like(p, dtype=torch.bool)
    hit[torch.arange(len(best)), best] = True
    return calibration(p.double().numpy().ravel(), hit.numpy().ravel())


def reliability_gap(p: torch.Tensor, best: torch.Tensor) -> float:
    """The worst |frequency − probability| of a checked reliability bin (``training.metrics.worst_gap``); infinite
    when no bin qualifies, so that a temperature cannot pass by leaving no mode at p ≥ 0.3."""
    gap, at = worst_gap(best_mode_reliability(p, best))
    return gap if at == at else float("inf")


@dataclass(frozen=True)
class TemperatureFit:
    """The kept temperature, the score it minimised (``"nll"`` or ``"brier"``), the validation best-mode NLL at
    T = 1 and at it, the worst checked reliability gap on validation at T = 1 and at it, the number of targets it
    was fitted on and of validation splits they came from (``folds`` > 1: cross-fitted)."""

    temperature: float
    objective: str
    nll_before: float
    nll_after: float
    gap_before: float
    gap_after: float
    targets: int = 0
    folds: int = 1

    def __str__(self) -> str:
        where = "validation" if self.folds == 1 else f"{self.folds} validation folds"
        return (
            f"temperature {self.temperature:.3f} (by {self.objective}; {self.targets} targets of {where}): "
            f"best-mode NLL {self.nll_before:.4f} -> {self.nll_after:.4f}, worst reliability gap "
            f"{self.gap_before:.3f} -> {self.gap_after:.3f}"
        )


def fit_temperature(
    model: torch.nn.Module, w: Windows, spec: dgan.InputSpec, anchors: torch.Tensor, class_of: torch.Tensor
) -> TemperatureFit:
    """The temperature of smallest best-mode NLL on ``w`` and the one of smallest Brier score; keeps the one whose
    worst checked reliability gap on ``w`` is smaller (the NLL's on a tie)."""
    cl, al, best = best_mode_logits(model, w, spec, anchors)
    return choose_temperature(cl, al, best, class_of)


def choose_temperature(
    cl: torch.Tensor, al: torch.Tensor, best: torch.Tensor, class_of: torch.Tensor
) -> TemperatureFit:
    """:func:`fit_temperature` given class logits ``cl (N, C)``, anchor logits ``al (N, K)``, the best modes
    ``best (N,)`` and each anchor's class ``class_of (K,)``."""
    nll, brier = [], []
    for t in GRID:
        p = mode_probabilities(cl, al, class_of, float(t))
        nll.append(best_mode_log_loss(p, best))
        brier.append(best_mode_brier(p, best))
    candidates = {"nll": int(np.argmin(nll)), "brier": int(np.argmin(brier))}
    gaps = {
        k: reliability_gap(mode_probabilities(cl, al, class_of, float(GRID[i])), best) for k, i in candidates.items()
    }
    objective = "brier" if gaps["brier"] < gaps["nll"] else "nll"
    i = candidates[objective]
    at_one = mode_probabilities(cl, al, class_of, 1.0)
    return TemperatureFit(
        float(GRID[i]),
        objective,
        best_mode_log_loss(at_one, best),
        nll[i],
        reliability_gap(at_one, best),
        gaps[objective],
        len(best),
    )


#: ``train.calibration_split``: which validation windows the temperature is fitted on (:func:`calibration_config`).
CALIBRATION_SPLITS = ("all", "own")


def calibration_config(cfg: Config) -> Config:
    """The configuration whose validation split the temperature is fitted on: ``cfg`` itself
    (``train.calibration_split = "all"``), or ``cfg`` without its ``data.extra_sources`` ("own": the configuration's
    own dataset's validation windows alone). Raises a ValueError naming the choices for any other value."""
    split = cfg.train.calibration_split
    if split not in CALIBRATION_SPLITS:
        raise ValueError(f"train.calibration_split must be 'all' or 'own', got {split!r}")
    if split == "own" and cfg.data.extra_sources:
        return replace(cfg, data=replace(cfg.data, extra_sources=""))
    return cfg


def validation_logits(
    path: Path, data_root: Path | None = None, progress: bool = False
) -> tuple[torch.Tensor, torch.Tensor, torch.Tensor, torch.Tensor]:
    """:func:`best_mode_logits` of the checkpoint at ``path`` on its configuration's validation split (under
    ``data_root`` if given; the windows :func:`calibration_config` names), and the class of each of its anchors."""
    from training.data.splits import split_windows
    from training.export import load_checkpoint

    model, spec, anchors, class_of, cfg, _ = load_checkpoint(path)
    if data_root is not None:
        cfg = replace(cfg, data=replace(cfg.data, root=str(data_root)))
    val = split_windows(calibration_config(cfg), spec, "val", progress)
    cl, al, best = best_mode_logits(model, val, spec, torch.from_numpy(anchors).float())
    return cl, al, best, torch.from_numpy(class_of).long()


def calibrate_checkpoint(
    path: Path, data_root: Path | None = None, progress: bool = False, folds: Sequence[Path] = ()
) -> TemperatureFit:
    """Fits the temperature of the checkpoint at ``path`` (one run's or an ensemble's, ``training.ensemble``) on its
    configuration's validation split (under ``data_root`` if given) and stores it there.

    ``folds``: checkpoints of the same configuration trained with other validation splits (cross-fitting,
    ``data.val_recordings``); their predictions on their own validation splits join the fit, which then sees every
    fold's validation data instead of one split's."""
    from training.checkpoint import update_checkpoint

    cl, al, best, class_of = validation_logits(path, data_root, progress)
    parts = [(cl, al, best)]
    for fold in folds:
        fold_cl, fold_al, fold_best, fold_class_of = validation_logits(fold, data_root, progress)
        if not torch.equal(fold_class_of, class_of):
            raise ValueError(f"{fold}: its anchors' classes differ from {path}'s; folds must share a configuration")
        parts.append((fold_cl, fold_al, fold_best))
    cl, al, best = (torch.cat(x) for x in zip(*parts, strict=True))
    found = replace(choose_temperature(cl, al, best, class_of), folds=len(parts))
    update_checkpoint(path, temperature=found.temperature)
    return found
