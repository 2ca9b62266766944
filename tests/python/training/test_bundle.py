"""training.release.bundle: the model card's words follow the training configuration."""

from __future__ import annotations

import json
from pathlib import Path
from typing import Any

import pytest

pytest.importorskip("torch")

from training.release.bundle import check_folds
from training.release.cards import (
    classification_words,
    contract_line,
    denoise_words,
    distill_words,
    extra_data_line,
    extra_licence_line,
    fitted_where,
    restated,
    temperature_words,
)
from training.release.multiclass_card import joint_words


def cfg(**data: Any) -> dict[str, Any]:
    return {"data": data, "train": {}}


def test_extra_pedestrians_are_named_with_their_licence() -> None:
    assert extra_data_line(cfg()) == extra_licence_line(cfg()) == ""
    line = extra_data_line(cfg(extra_pedestrians="sdd", extra_stride=2))
    assert "Stanford Drone's 30 training videos" in line
    assert "divisible by 2" in line
    assert "anchors" not in line
    assert "fitted on ETH/UCY's windows alone" in extra_data_line(cfg(extra_pedestrians="sdd", extra_in_anchors=False))
    assert "CC BY-NC-SA 3.0" in extra_licence_line(cfg(extra_pedestrians="sdd"))


def test_faster_copies_are_named() -> None:
    plain = {"data": {"prior": "none"}, "train": {}, "model": {}}
    assert "faster copies" not in contract_line(plain, {})
    fast = {"data": {"prior": "none", "augment_speed": "1.5,2"}, "train": {}, "model": {}}
    assert "every agent 1.5 and 2 times as fast over the same map" in contract_line(fast, {})


def test_the_classification_target_is_named() -> None:
    assert classification_words(cfg()) == "the paper's hierarchical classification"
    best = {"data": {}, "train": {"cls_target": "best_mode"}}
    assert "decoded mode closest to the future" in classification_words(best)


def test_what_a_student_learned_from_its_teacher_is_named() -> None:
    assert distill_words("eth", cfg()) == ""
    student = {"data": {}, "train": {"distill": "x.pt", "distill_weight": 1.0}}
    words = distill_words("eth", student)
    assert "most probable mode of a consensus of runs" in words
    assert "teachers/eth.pt" in words
    assert "offsets only" not in words
    soft = {"data": {}, "train": {**student["train"], "distill_soft": 0.5}}
    assert "its mode probabilities (weight 0.5)" in distill_words("eth", soft)
    offsets = {"data": {}, "train": {**student["train"], "distill_classifier": False}}
    assert "its offsets only: the mode probabilities learned from the data alone" in distill_words("eth", offsets)
    both = {"data": {}, "train": {**offsets["train"], "distill_soft": 0.5}}
    assert "mode (its offsets only) and its mode probabilities (weight 0.5) of" in distill_words("eth", both)
    wider = {"data": {}, "model": {"head_dim": 512}, "train": student["train"]}
    assert "consensus of runs whose heads' layers are 256 wide (this one's 512)" in distill_words("hotel", wider)
    assert "wide" not in words
    # A second stage (training.release.retrain.KEPT_STAGE) names the crop model it was taught by, and that file.
    second = {"data": {}, "train": {"distill": "training/checkpoints/teachers/sdd_crop.pt", "distill_weight": 1.0}}
    kept = distill_words("sdd", second)
    assert "the crop model it replaced" in kept
    assert "`training/checkpoints/teachers/sdd_crop.pt`" in kept
    assert "consensus" not in kept


def test_a_cross_fitted_temperature_is_named() -> None:
    assert fitted_where(cfg()) == "fitted on validation"
    assert fitted_where(cfg(), " for the consensus") == "fitted for the consensus on validation"
    folds = {"data": {}, "train": {"calibration_folds": "9050,9055;9051,9054"}}
    assert fitted_where(folds).startswith("cross-fitted on 3 validation folds (its validation split and 2 more")


def test_the_fold_runs_must_hold_out_the_declared_splits(tmp_path: Path) -> None:
    def run(name: str, val: str) -> Path:
        folder = tmp_path / name
        folder.mkdir()
        (folder / "config.json").write_text(json.dumps({"config": {"data": {"val_recordings": val}}}))
        return folder

    declared = {"data": {}, "train": {"calibration_folds": "9050,9055;9051,9054"}}
    a, b = [run("a", "9050,9055")], [run("b", "9051,9054")]
    check_folds(declared, [b, a])
    check_folds(cfg(), [])
    with pytest.raises(ValueError, match="pass --calibration-fold"):
        check_folds(declared, [a])
    with pytest.raises(ValueError, match="declares the validation splits none"):
        check_folds(cfg(), [a])


def test_other_sources_and_where_the_temperature_was_fitted_are_named() -> None:
    assert joint_words(cfg()) == ""
    joint = {"data": {"extra_sources": "ethucy_5hz:3"}, "train": {}}
    words = joint_words(joint)
    assert "`ethucy_5hz:3`" in words
    assert "non-commercial research use only" in words
    assert fitted_where(joint) == "fitted on validation"
    own = {"data": joint["data"], "train": {"calibration_split": "own"}}
    assert fitted_where(own) == "fitted on validation scenes alone, not the other sources' (`train.calibration_split`)"
    # Without other sources every validation window is the model's own: nothing to say.
    assert fitted_where({"data": {}, "train": {"calibration_split": "own"}}) == "fitted on validation"


def test_the_card_names_contract_9s_temperatures() -> None:
    assert temperature_words({"temperature": 1.349}) == "the temperature 1.35"
    words = temperature_words({"temperature": 0.733, "temperature_speed_exponent": 0.956, "class_temperature": 7.104})
    assert words.startswith("the temperature 0.73 × (1 + speed in m/s)^0.96 with a class temperature of 7.10")
    assert "`train.calibration" in words


def test_a_card_restated_with_a_denoising_gate() -> None:
    assert denoise_words(cfg()) == ""
    assert "0.1 m or more" in denoise_words(cfg(denoise_gate_m=0.1))
    card = (
        "  One class. The network refines a rollout. Mode probabilities at the temperature 1.73 fitted on validation.\n"
        "- **Test metrics** (engine, world metres, 602 windows, 2253 agents):\n\n"
        "| | top-1 ADE | top-1 FDE | minADE5 | minFDE5 | minADE20 | minFDE20 | Brier-minFDE20 |\n"
        "|---|---|---|---|---|---|---|---|\n"
        "| DGAN | 0.365 | 0.790 | 0.257 | 0.526 | 0.224 | 0.435 | 1.031 |\n"
        "| DGAN without the map | 0.395 | 0.854 | 0.273 | 0.558 | 0.231 | 0.451 | 1.066 |\n"
        "| constant velocity (last2) | 0.431 | 0.960 | | | | | |\n"
    )
    keys = ("ade", "fde", "min_ade5", "min_fde5", "min_ade20", "min_fde20", "brier_min_fde20")
    metrics: dict[str, Any] = {k: 0.1 * i for i, k in enumerate(keys, 1)}
    metrics.update(windows=600, agents=2000, cv_variant="mean1s", cv_ade=0.5, cv_fde=1.0)
    metrics["without_map"] = {k: 1.0 + 0.1 * i for i, k in enumerate(keys, 1)}
    out = restated(card, metrics, cfg(denoise_gate_m=0.1))
    assert "(engine, world metres, 600 windows, 2000 agents):" in out
    assert "| DGAN | 0.100 | 0.200 | 0.300 | 0.400 | 0.500 | 0.600 | 0.700 |" in out
    assert "| DGAN without the map | 1.100 | 1.200 |" in out
    assert "| constant velocity (mean1s) | 0.500 | 1.000 |" in out
    assert "rollout. The engine first smooths histories" in out
    assert "`denoise_gate_m`" in out
    assert restated(out, metrics, cfg(denoise_gate_m=0.1)) == out  # the sentence once
    assert "smooths" not in restated(card, metrics, cfg())


def test_a_bad_denoising_gate_is_refused_before_the_checkpoint_is_touched() -> None:
    from dgan.exceptions import InvalidSpecError
    from training.release.bundle import CHECKPOINTS, redenoise

    before = (CHECKPOINTS / "zara1.pt").read_bytes()
    for bad in (-0.1, float("nan"), 1e3):
        with pytest.raises(InvalidSpecError, match="denoise_gate_m"):
            redenoise("zara1", bad)
    assert (CHECKPOINTS / "zara1.pt").read_bytes() == before


def test_neighbor_groups_export_the_same_predictions(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    """``--neighbor-groups`` sets ``model.neighbor_groups`` in a copy of the checkpoint and exports it again: the
    graph splits its neighbours by degree (a ScatterND) and the engine's predictions are those of the bundled file, to
    float rounding."""
    import shutil

    import numpy as np
    import onnx
    import torch

    import dgan
    from dgan.demo import scene_for
    from training.release import bundle

    shutil.copy(bundle.CHECKPOINTS / "apolloscape.pt", tmp_path / "apolloscape.pt")
    monkeypatch.setattr(bundle, "CHECKPOINTS", tmp_path)
    monkeypatch.setattr(bundle, "MODELS", tmp_path)
    path = bundle.regroup("apolloscape", True)
    assert path == tmp_path / "apolloscape.onnx"
    assert "ScatterND" in {n.op_type for n in onnx.load(str(path)).graph.node}
    kept = torch.load(tmp_path / "apolloscape.pt", weights_only=False)
    for held in kept.get("members", [kept]):  # a consensus of one keeps it in its member
        assert held["config"]["model"]["neighbor_groups"] is True
    frame = scene_for(dgan.Predictor("apolloscape").spec).frame
    a, b = dgan.Predictor("apolloscape").predict(frame), dgan.Predictor(path).predict(frame)
    # The same arithmetic; the heads' batched products over a group of a few receivers may round otherwise than over
    # every agent (1.4e-6 m on this scene; `hdmap`'s scenes bit-identical).
    np.testing.assert_allclose(a.trajectories, b.trajectories, rtol=0, atol=1e-5)
    np.testing.assert_allclose(a.probabilities, b.probabilities, rtol=0, atol=1e-6)


def test_neighbor_groups_take_on_or_off(monkeypatch: pytest.MonkeyPatch, capsys: pytest.CaptureFixture[str]) -> None:
    import sys

    from training.release import bundle

    monkeypatch.setattr(sys, "argv", ["bundle", "--neighbor-groups", "hdmap", "yes"])
    with pytest.raises(SystemExit) as exit_info:
        bundle.main()
    assert exit_info.value.code == 2
    assert "--neighbor-groups takes on or off, got 'yes'" in capsys.readouterr().err


def test_map_classes_refit_a_temperature_per_class_and_export_the_bundled_hdmap_again(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    """``--map-classes``: the kept checkpoint's model.map_classes and train.calibration = "per_class" are set, the
    temperatures refitted on validation and the model exported again; done on the bundled `hdmap`'s own checkpoint
    (already so), it gives the bundled file's predictions back. A consensus is refused."""
    import shutil

    import numpy as np
    import torch
    from conftest import shared_data

    import dgan
    from dgan.demo import scene_for
    from training.release import bundle

    root = shared_data("waymo_motion_samples")
    shutil.copy(bundle.CHECKPOINTS / "hdmap.pt", tmp_path / "hdmap.pt")
    shutil.copy(bundle.CHECKPOINTS / "zara2.pt", tmp_path / "zara2.pt")
    monkeypatch.setattr(bundle, "CHECKPOINTS", tmp_path)
    monkeypatch.setattr(bundle, "MODELS", tmp_path)
    path = bundle.regate("hdmap", "cyclist,pedestrian", root)
    kept = torch.load(tmp_path / "hdmap.pt", weights_only=False)
    assert (kept["config"]["model"]["map_classes"], kept["config"]["train"]["calibration"]) == (
        "cyclist,pedestrian",
        "per_class",
    )
    assert len(kept["anchor_logit_scale"]) == 30
    frame = scene_for(dgan.Predictor("hdmap").spec).frame
    a, b = dgan.Predictor("hdmap").predict(frame), dgan.Predictor(path).predict(frame)
    np.testing.assert_allclose(a.trajectories, b.trajectories, rtol=0, atol=1e-5)
    np.testing.assert_allclose(a.probabilities, b.probabilities, rtol=0, atol=1e-6)
    spec = dgan.Predictor(path).spec
    assert spec.map is not None
    assert spec.map.classes == ("cyclist", "pedestrian")  # contract 11: the engine draws their crops alone
    before = (tmp_path / "zara2.pt").read_bytes()
    with pytest.raises(ValueError, match="consensus"):
        bundle.regate("zara2", "pedestrian", root)
    assert (tmp_path / "zara2.pt").read_bytes() == before  # refused before anything is written
