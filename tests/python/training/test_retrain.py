"""training.release.retrain: what a student changes of its configuration gives the bundled student's settings, so
that retraining reproduces the bundled models."""

from __future__ import annotations

from pathlib import Path

import pytest
import torch

import dgan
from training.config import Config
from training.release.bundle import DECODING_KEYS, check_decoding, decoding_lines
from training.release.retrain import (
    DECODING,
    DISTILLED,
    DISTILLED_SCENES,
    KEPT_SEED,
    KEPT_STAGE,
    SCENE_STUDENT_ARGS,
    STUDENT_ARGS,
    STUDENT_SEED,
    TOP_SCALED,
)
from training.train import parse_args

ROOT = Path(__file__).resolve().parents[3]
CHECKPOINTS = ROOT / "training" / "checkpoints"


def _students() -> list[tuple[str, str, tuple[str, ...]]]:
    """(bundled name, configuration file, the student's extra arguments) of every distilled bundled model."""
    out = [(ds, f"{ds}.toml", KEPT_STAGE.get(ds, STUDENT_ARGS.get(ds, ()))) for ds in DISTILLED]
    return out + [(s, f"ethucy_{s}.toml", SCENE_STUDENT_ARGS.get(s, ())) for s in DISTILLED_SCENES]


@pytest.mark.parametrize(("name", "toml", "args"), _students())
def test_a_students_arguments_give_the_bundled_students_settings(
    name: str, toml: str, args: tuple[str, ...], tmp_path: Path
) -> None:
    _, cfg = parse_args(["--config", str(ROOT / "training" / "configs" / toml), "--out", str(tmp_path), *args])
    ckpt = torch.load(CHECKPOINTS / f"{name}.pt", weights_only=False)
    if name in TOP_SCALED:  # one network kept as a consensus of one, for its top-mode scale
        assert len(ckpt["members"]) == 1, f"{name} is bundled as one network"
        assert len(ckpt["top_scale"]) == len(dgan.Predictor(name).classes)
        ckpt = ckpt["members"][0]
    else:
        assert "members" not in ckpt, f"{name} is bundled as one network"
    seed = KEPT_SEED.get(name, STUDENT_SEED.get(name, 0))
    assert ckpt["config"]["train"]["seed"] == seed, f"{name}: the student's seed"
    kept = Config.from_dict({"name": name, **{k: ckpt["config"][k] for k in ("data", "model", "train")}})
    changed = [tuple(a.split("=")[0].split(".")) for a in args if a != "--set"]
    for section, key in [*changed, ("model", "head_dim"), ("model", "map_res_blocks"), ("train", "calibration")]:
        want = getattr(getattr(kept, section), key)
        assert getattr(getattr(cfg, section), key) == want, f"{name}: {section}.{key}"


def test_hotels_student_is_wider_and_folds_an_entropy_temperature() -> None:
    kept = torch.load(CHECKPOINTS / "hotel.pt", weights_only=False)
    assert kept["config"]["model"]["head_dim"] == 512
    _, b = kept["anchor_entropy_temperature"]
    assert b > 0  # spread distributions flattened, peaked ones sharpened
    assert kept.get("anchor_logit_scale") is None


@pytest.mark.parametrize("name", dgan.models.list())
def test_retraining_declares_the_bundled_models_decoding(name: str) -> None:
    """What the engine's decoding adds to a bundled network (chosen on validation once it was trained) is what a
    retrained model gets (``training.release.retrain.DECODING``); a consensus's top-mode scale is fitted anew."""
    ckpt = torch.load(CHECKPOINTS / f"{name}.pt", weights_only=False)
    for key in DECODING_KEYS:
        if key == "top_scale" and "members" in ckpt:
            continue
        assert ckpt.get(key) == DECODING.get(name, {}).get(key), f"{name}: {key}"


def test_a_cards_decoding_lines_name_each_class_with_its_value() -> None:
    classes = dgan.Predictor("hdmap").classes  # vehicle, cyclist, pedestrian
    text = decoding_lines(classes, {"top_scale": [0.75, 1.0, 1.0], "still_radius": [0.0, 0.02, 0.05]})
    lines = text.splitlines()
    assert len(lines) == 2
    assert text.endswith("\n")
    assert lines[0].startswith("- **Top-mode scale** (contract 14")
    assert lines[0].endswith(": vehicle 0.75.")
    assert lines[1].endswith(": cyclist 0.02 m, pedestrian 0.05 m.")


def test_bundling_refuses_unknown_decoding_and_a_consensus_given_a_top_mode_scale() -> None:
    with pytest.raises(ValueError, match="must be among top_scale, still_radius, top_mean_power, got temperature"):
        check_decoding("sdd", {"temperature": [1.0]}, consensus=False)
    with pytest.raises(ValueError, match="eth: a consensus's top-mode scale is fitted"):
        check_decoding("eth", {"top_scale": [0.5]}, consensus=True)
    check_decoding("sdd", DECODING["sdd"], consensus=False)
