"""dgan.metrics (also training.metrics) against hand-computed cases."""

from __future__ import annotations

import numpy as np
import pytest

from dgan import exceptions as exc
from dgan import metrics


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


def test_constant_velocity_over_the_last_second() -> None:
    # Steps of 0.5 s: x = 0, 1, 3, 6 (speeding up); the last second is two steps: (6 - 1) / 2 = 2.5 per step.
    traj = np.array([[[0.0, 0.0], [1.0, 0.0], [3.0, 0.0], [6.0, 0.0]]])
    mask = np.ones((1, 4), dtype=bool)
    v = metrics.constant_velocity_variants(traj, mask, 2, 0.5)
    assert v["last2"][0, 0, :, 0].tolist() == [9.0, 12.0]
    assert v["mean1s"][0, 0, :, 0].tolist() == [8.5, 11.0]
    # A missing step inside the window: from the earliest observed one (3 steps back: step 0, 6 m in 3 steps).
    mask[0, 1] = False
    assert metrics.constant_velocity(traj, mask, 1, 3)[0, 0, 0, 0] == pytest.approx(6.0 + 2.0)
    assert metrics.constant_velocity(traj, mask, 1, 2)[0, 0, 0, 0] == pytest.approx(6.0 + 3.0)


def test_untempered_probabilities_invert_the_temperature() -> None:
    import dgan
    from training.evaluate import untempered

    rng = np.random.default_rng(0)
    logits = rng.normal(size=(3, 5))
    classes = np.array([0, 0, 0, 1, 1])
    pc = np.array([[0.7, 0.3]] * 3)

    def probs(t: float) -> np.ndarray:
        out = np.zeros_like(logits)
        for c in (0, 1):
            e = np.exp(logits[:, classes == c] / t)
            out[:, classes == c] = pc[:, [c]] * e / e.sum(axis=1, keepdims=True)
        return out

    pred = dgan.Prediction(
        np.arange(3), np.zeros((3, 5, 1, 2)), probs(2.0), pc, np.tile(classes, (3, 1)), np.zeros((0, 2), np.int64), ()
    )
    np.testing.assert_allclose(untempered(pred, 2.0), probs(1.0), rtol=1e-9)


def test_miss_rate_and_summary() -> None:
    gt = np.array([[[0.0, 0.0], [0.0, 4.0]], [[0.0, 0.0], [0.0, 1.0]]])
    pred = np.array(
        [
            [[[0.0, 0.0], [0.0, 1.0]], [[0.0, 0.0], [0.0, 3.0]]],  # ends 3 m and 1 m off
            [[[0.0, 0.0], [3.0, 1.0]], [[0.0, 0.0], [0.0, 4.5]]],  # ends 3 m and 3.5 m off
        ]
    )
    prob = np.array([[0.6, 0.4], [0.5, 0.5]])
    assert metrics.miss_rate(pred, gt, k=2).tolist() == [0.0, 1.0]
    assert metrics.miss_rate(pred, gt, k=1).tolist() == [1.0, 1.0]
    s = metrics.summary(pred, gt, prob, ks=(1, 2))
    assert s["ade"] == pytest.approx((1.5 + 1.5) / 2)
    assert s["fde"] == pytest.approx(3.0)
    assert s["min_fde_2"] == pytest.approx((1.0 + 3.0) / 2)
    assert s["miss_rate_2"] == pytest.approx(0.5)
    assert s["brier_min_fde_2"] == pytest.approx((1.0 + 0.6**2 + 3.0 + 0.5**2) / 2)


def test_metrics_refuse_bad_shapes() -> None:
    with pytest.raises(exc.InvalidFrameError, match=r"\(N, M, T, 2\)"):
        metrics.ade(np.zeros((2, 12, 2)), np.zeros((2, 12, 2)))
    with pytest.raises(exc.InvalidFrameError, match="ground truth"):
        metrics.ade(np.zeros((2, 3, 12, 2)), np.zeros((2, 8, 2)))
    with pytest.raises(exc.InvalidFrameError, match="k must be"):
        metrics.min_ade(np.zeros((2, 3, 12, 2)), np.zeros((2, 12, 2)), k=0)
    with pytest.raises(exc.InvalidFrameError, match="probabilities"):
        metrics.brier_min_fde(np.zeros((2, 3, 12, 2)), np.zeros((2, 12, 2)), np.zeros((2, 2)), k=3)


def test_bad_ground_truth_masks_and_histories_are_clear_errors() -> None:
    gt = np.zeros((2, 3, 2))
    gt[1, 1, 0] = np.nan
    with pytest.raises(exc.InvalidFrameError, match=r"ground truth holds NaN .* row 1"):
        metrics.summary(np.zeros((2, 2, 3, 2)), gt)
    with pytest.raises(exc.InvalidFrameError, match=r"mask must have shape \(N, T\) = \(2, 4\), got \(2, 3\)"):
        metrics.constant_velocity(np.zeros((2, 4, 2)), np.ones((2, 3), bool), 3)
    mask = np.ones((2, 4), bool)
    mask[1] = False
    with pytest.raises(exc.InvalidFrameError, match=r"1 agent.* no observed step, e.g. row 1"):
        metrics.constant_velocity(np.zeros((2, 4, 2)), mask, 3)


def test_untempered_probabilities_invert_speed_and_class_temperatures() -> None:
    import torch

    import dgan
    from training.evaluate import untempered
    from training.losses import Calibration, mode_probabilities

    g = torch.Generator().manual_seed(0)
    cl, al = torch.randn(4, 2, generator=g, dtype=torch.float64), torch.randn(4, 5, generator=g, dtype=torch.float64)
    classes = torch.tensor([0, 0, 0, 1, 1])
    speed = np.array([0.0, 0.5, 3.0, 12.0])
    cal = Calibration(0.7, 0.5, 2.0)
    p = mode_probabilities(cl, al, classes, cal.at_speed(torch.from_numpy(speed)), cal.class_temperature)
    pc = torch.softmax(cl / cal.class_temperature, dim=1).numpy()
    mode_classes = np.tile(classes.numpy(), (4, 1))
    edges = np.zeros((0, 2), np.int64)
    pred = dgan.Prediction(np.arange(4), np.zeros((4, 5, 1, 2)), p.numpy(), pc, mode_classes, edges, ())
    np.testing.assert_allclose(untempered(pred, cal, speed), mode_probabilities(cl, al, classes).numpy(), rtol=1e-9)
    with pytest.raises(ValueError, match="prior speeds"):
        untempered(pred, cal)
