"""training.metrics against hand-computed cases."""

from __future__ import annotations

import numpy as np
import pytest

from training import metrics


def test_top1_and_min_over_k() -> None:
    gt = np.array([[[0.0, 0.0], [0.0, 2.0]]])  # one agent, two steps
    pred = np.array([[[[3.0, 0.0], [3.0, 2.0]], [[0.0, 0.0], [0.0, 1.0]], [[0.0, 1.0], [0.0, 2.0]]]])
    ade, fde = metrics.ade_fde_top1(pred, gt)
    assert ade.tolist() == [3.0]
    assert fde.tolist() == [3.0]
    # Mode 1: errors (0, 1); mode 2: errors (1, 0). minADE = 0.5, minFDE = 0 (each minimum taken on its own).
    made, mfde = metrics.min_ade_fde(pred, gt, 3)
    assert made.tolist() == [0.5]
    assert mfde.tolist() == [0.0]
    made2, mfde2 = metrics.min_ade_fde(pred, gt, 2)
    assert made2.tolist() == [0.5]
    assert mfde2.tolist() == [1.0]


def test_brier_min_fde() -> None:
    gt = np.array([[[0.0, 0.0], [0.0, 2.0]]])
    pred = np.array([[[[0.0, 0.0], [0.0, 1.0]], [[0.0, 0.0], [0.0, 2.5]]]])
    prob = np.array([[0.8, 0.2]])
    # Best FDE is mode 1 (0.5) with p = 0.2: 0.5 + 0.8² = 1.14.
    assert metrics.brier_min_fde(pred, gt, prob, 2) == pytest.approx([1.14])


def test_constant_velocity_uses_the_last_two_observed_steps() -> None:
    traj = np.array([[[0.0, 0.0], [9.0, 9.0], [1.0, 0.0], [2.0, 0.0]]])
    mask = np.array([[True, False, True, True]])
    cv = metrics.constant_velocity(traj, mask, 3)
    np.testing.assert_allclose(cv[0, 0], [[3.0, 0.0], [4.0, 0.0], [5.0, 0.0]])
    gap = np.array([[True, False, False, True]])
    np.testing.assert_allclose(metrics.constant_velocity(traj, gap, 1)[0, 0], [[2.0 + 2.0 / 3, 0.0]])
    single = np.array([[False, False, False, True]])
    np.testing.assert_allclose(metrics.constant_velocity(traj, single, 2)[0, 0], [[2.0, 0.0], [2.0, 0.0]])
