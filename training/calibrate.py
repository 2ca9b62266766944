"""Calibration of the mode probabilities: one temperature T of the anchor logits, p(k | c) = softmax(logits / T),
fitted on a validation split by the likelihood of the best mode (the mode closest to the ground truth by ADE, the
event the reliability diagram of :mod:`training.evaluate` counts). The engine applies it in decoding (contract 2).
"""

from __future__ import annotations

import numpy as np
import torch

import dgan
from training.data import Windows
from training.loss import mode_probabilities

#: The temperatures tried, log-spaced.
GRID = np.exp(np.linspace(np.log(0.05), np.log(20.0), 121))


@torch.no_grad()
def best_mode_logits(
    model: torch.nn.Module, w: Windows, spec: dgan.InputSpec, anchors: torch.Tensor, batch: int = 64
) -> tuple[torch.Tensor, torch.Tensor, torch.Tensor]:
    """For every target of ``w``: class logits, anchor logits and the index of its best mode (smallest ADE)."""
    from training.train import forward_inputs, prepared_batch, windows_with_targets

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


def best_mode_nll(
    class_logits: torch.Tensor,
    anchor_logits: torch.Tensor,
    best: torch.Tensor,
    class_of: torch.Tensor,
    temperature: float,
) -> float:
    """Mean −log p(best mode) at one temperature."""
    p = mode_probabilities(class_logits, anchor_logits, class_of, temperature)
    return float(-torch.log(p[torch.arange(len(best)), best].clamp_min(1e-12)).mean())


def fit_temperature(
    model: torch.nn.Module, w: Windows, spec: dgan.InputSpec, anchors: torch.Tensor, class_of: torch.Tensor
) -> tuple[float, float, float]:
    """The temperature of smallest best-mode NLL on ``w``; also the NLL at T = 1 and at the fitted T."""
    cl, al, best = best_mode_logits(model, w, spec, anchors)
    nll = [best_mode_nll(cl, al, best, class_of, float(t)) for t in GRID]
    i = int(np.argmin(nll))
    return float(GRID[i]), best_mode_nll(cl, al, best, class_of, 1.0), float(nll[i])
