"""training.top_mean: the top-mean power kept by its rule, its way into the contract, and the engine's mean."""

from __future__ import annotations

import shutil
from pathlib import Path

import numpy as np
import pytest
import torch
from test_calibrate import _apollo_checkpoint
from test_training import assert_parity, real_frames

import dgan
from training.checkpoint import update_checkpoint
from training.export import export_checkpoint, load_checkpoint
from training.losses import decode_torch
from training.top_mean import (
    CALIBRATION_BOUND,
    MAX_MIN20_RISE,
    MIN_GAIN,
    MIN_TARGETS,
    POWERS,
    Errors,
    choose_power,
    class_powers,
    fit_top_mean,
)


def powered(best: tuple[float, float], at: float = 4.0) -> dict[float, dict[str, tuple[float, float, int]]]:
    """Every power at (1, 2) m except ``at``, at ``best``."""
    return {p: {"pedestrian": (*(best if p == at else (1.0, 2.0)), MIN_TARGETS)} for p in POWERS}


def test_the_power_of_lowest_ade_is_kept_where_it_gains_enough() -> None:
    plain = {"pedestrian": (1.0, 2.0, MIN_TARGETS)}
    assert choose_power(plain, powered((0.98, 1.99)), "pedestrian") == 4.0
    assert choose_power(plain, powered((0.98, 1.99)), "cyclist") == 0.0, "a class without targets"


@pytest.mark.parametrize(
    ("targets", "best", "why"),
    [
        (MIN_TARGETS - 1, (0.9, 1.8), "too few targets"),
        (MIN_TARGETS, (1.0 - MIN_GAIN / 2, 1.9), "a gain under the bound"),
        (MIN_TARGETS, (0.9, 2.01), "FDE rises"),
    ],
)
def test_no_power_is_kept_otherwise(targets: int, best: tuple[float, float], why: str) -> None:
    assert choose_power({"pedestrian": (1.0, 2.0, targets)}, powered(best), "pedestrian") == 0.0, why


def test_class_powers_are_every_power_within_the_class_clauses_best_first() -> None:
    plain = {"pedestrian": (1.0, 2.0, MIN_TARGETS)}
    powered = {1.0: (1.2, 2.1), 2.0: (0.98, 1.99), 4.0: (0.97, 2.01), 8.0: (0.99, 1.9)}
    errors = {p: {"pedestrian": (*e, MIN_TARGETS)} for p, e in powered.items()}
    assert class_powers(plain, errors, "pedestrian") == [2.0, 8.0], "4 raises FDE, 1 raises ADE"
    assert choose_power(plain, errors, "pedestrian") == 0.0, "the best ADE (4) raises FDE"


@pytest.mark.parametrize(
    ("min20", "worst_bin", "own_bin", "keeps"),
    [
        ((1.0 + MAX_MIN20_RISE, 2.0), CALIBRATION_BOUND, 0.05, True),
        ((1.0, 2.0 * (1.0 + 2 * MAX_MIN20_RISE)), 0.05, 0.05, False),
        ((1.0, 2.0), CALIBRATION_BOUND + 0.01, 0.05, False),
        ((1.0, 2.0), 0.15, 0.15, True),
    ],
)
def test_a_power_keeps_the_model_within_best_of_20_and_calibration_bounds(
    min20: tuple[float, float], worst_bin: float, own_bin: float, keeps: bool
) -> None:
    plain = Errors({}, (1.0, 2.0), own_bin)
    assert Errors({}, min20, worst_bin).keeps(plain) == keeps


def test_decode_torch_averages_the_modes_of_the_classes_with_a_power() -> None:
    anchors = torch.tensor([[[1.0, 0.0]], [[0.0, 1.0]], [[2.0, 2.0]]])
    class_of = torch.tensor([0, 0, 1])
    offsets = torch.full((2, 3, 1, 2), 0.5)
    class_logits = torch.tensor([[2.0, 0.0], [0.0, 2.0]])  # agent 0 most probably class 0, agent 1 class 1
    anchor_logits = torch.tensor([[0.0, 1.0, 0.0], [1.0, 0.0, 0.0]])
    prior = torch.tensor([[[0.25, 0.0]], [[0.0, 0.5]]])
    args = (class_logits, anchor_logits, offsets, anchors, class_of, prior)
    plain, p = decode_torch(*args)
    mean, q = decode_torch(*args, top_mean=torch.tensor([2.0, 0.0]))
    assert torch.equal(p, q)
    assert torch.equal(mean[:, 1:], plain[:, 1:])
    assert torch.equal(mean[1], plain[1]), "class 1 has no power"
    w = p[0] ** 2
    torch.testing.assert_close(mean[0, 0], (w[:, None, None] * plain[0]).sum(0) / w.sum())
    held, _ = decode_torch(*args, still=torch.tensor([True, False]), top_mean=torch.tensor([2.0, 0.0]))
    assert held[0, 0].tolist() == [[0.25, 0.0]], "a still agent keeps its prior"


@pytest.mark.slow
def test_the_power_is_fitted_on_validation_by_the_engine_stored_and_exported(tmp_path: Path) -> None:
    ckpt = _apollo_checkpoint(tmp_path / "net.pt", "", 4, 0)
    fit = fit_top_mean(ckpt)
    assert fit.classes == list(dgan.CLASSES)
    assert set(fit.powered) == set(POWERS)
    by_class = {p: e.by_class for p, e in fit.powered.items()}
    for c, kept in zip(fit.classes, fit.power, strict=True):
        tried = [(p, ok) for k, p, ok in fit.trials if k == c]
        # The class's candidates best first, up to the first that keeps the model's bounds (or all of them).
        assert [p for p, _ in tried] == class_powers(fit.plain.by_class, by_class, c)[: len(tried)]
        assert [p for p, ok in tried if ok] == ([kept] if kept else [])
    assert torch.load(ckpt, weights_only=False)["top_mean_power"] == fit.power
    assert "targets" in str(fit)
    # Powers in the checkpoint reach the contract; the engine matches PyTorch's decoding with them.
    shutil.copy(ckpt, tmp_path / "plain.pt")
    update_checkpoint(tmp_path / "plain.pt", top_mean_power=[0.0, 0.0, 0.0])
    update_checkpoint(ckpt, top_mean_power=[1.0, 2.0, 0.0])
    path = export_checkpoint(ckpt, tmp_path / "mean.onnx", "mean")
    averaged = dgan.Predictor(path)
    assert averaged.contract["top_mean_power"] == {dgan.CLASSES[0]: 1.0, dgan.CLASSES[1]: 2.0}
    model, spec, anchors, class_of, _, cal = load_checkpoint(ckpt)
    assert_parity(model, spec, anchors, class_of, path, cal)
    # The most probable mode is the p^β-weighted mean of every mode as decoded without a power.
    plain = dgan.Predictor(export_checkpoint(tmp_path / "plain.pt", tmp_path / "plain.onnx", "plain"))
    frame = real_frames(spec)[0]
    a, b = averaged.predict(frame), plain.predict(frame, modes=plain.num_modes)
    np.testing.assert_array_equal(a.probabilities, b.probabilities)
    np.testing.assert_array_equal(a.trajectories[:, 1:], b.trajectories[:, 1:])
    beta = np.array([1.0, 2.0, 0.0])[b.class_probabilities.argmax(axis=1)]
    assert (beta > 0).any()
    w = (b.probabilities / b.probabilities[:, :1]) ** beta[:, None]
    mean = np.einsum("nk,nktd->ntd", w / w.sum(axis=1, keepdims=True), b.trajectories)
    want = np.where((beta > 0)[:, None, None], mean, b.trajectories[:, 0])
    np.testing.assert_allclose(a.trajectories[:, 0], want, atol=1e-9)
