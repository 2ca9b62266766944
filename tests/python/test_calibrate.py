"""training.calibrate: the two proper scores, the reliability gap that chooses between their temperatures, and the
choice itself on best modes drawn at a known temperature."""

from __future__ import annotations

import math

import pytest
import torch

from training.calibrate import best_mode_brier, choose_temperature, reliability_gap


def test_the_brier_score_of_the_best_mode_indicator() -> None:
    p = torch.tensor([[1.0, 0.0], [0.5, 0.5], [0.2, 0.8]])
    best = torch.tensor([0, 1, 0])
    # 0; 0.25 + 0.25; 0.64 + 0.64
    assert best_mode_brier(p, best) == pytest.approx((0.0 + 0.5 + 1.28) / 3)


def test_the_reliability_gap_of_the_checked_bins() -> None:
    # 40 modes at p = 0.75 that are the best 30 times: frequency 0.75, no gap; then 20 of 40: gap 0.25.
    p = torch.tensor([[0.75, 0.25]] * 40)
    assert reliability_gap(p, torch.tensor([0] * 30 + [1] * 10)) == pytest.approx(0.0, abs=1e-9)
    assert reliability_gap(p, torch.tensor([0] * 20 + [1] * 20)) == pytest.approx(0.25)
    # Fewer than 30 modes at p >= 0.3 in every bin: no bin is checked, and the gap counts as infinite, so that a
    # temperature cannot pass by leaving no probable mode.
    assert math.isinf(reliability_gap(torch.tensor([[0.75, 0.25]] * 10), torch.zeros(10, dtype=torch.long)))


def test_best_modes_drawn_at_a_temperature_give_it_back() -> None:
    g = torch.Generator().manual_seed(0)
    n, k, true_t = 20000, 6, 2.0
    cl = torch.zeros(n, 1)
    al = 3.0 * torch.randn(n, k, generator=g)
    best = torch.multinomial(torch.softmax(al / true_t, dim=1), 1, generator=g).squeeze(1)
    fit = choose_temperature(cl, al, best, torch.zeros(k, dtype=torch.long))
    assert fit.objective in ("nll", "brier")
    assert fit.temperature == pytest.approx(true_t, rel=0.1)
    assert fit.nll_after < fit.nll_before  # the logits at T = 1 are overconfident
    assert fit.gap_after < 0.05 < fit.gap_before
    assert "temperature" in str(fit)
