"""training.release.multiclass_card: a multi-class model's card from its run's log and configuration and its test
metrics: the dataset's words, one row per class, motion and extra label beside constant velocity, the licence."""

from __future__ import annotations

import json
from pathlib import Path
from typing import Any

import pytest

pytest.importorskip("torch")

import torch

from training.release.multiclass_card import MULTICLASS, multiclass_card

ROOT = Path(__file__).resolve().parents[3]


def _row(ade: float, agents: int) -> dict[str, Any]:
    keys = ("fde", "min_ade5", "min_fde5", "min_ade20", "min_fde20", "brier_min_fde20")
    return {"ade": ade, **{k: ade + i for i, k in enumerate(keys, 1)}, "cv_ade": 2 * ade, "cv_fde": 3 * ade,
            "agents": agents}  # fmt: skip


def _metrics() -> dict[str, Any]:
    return {
        **_row(0.5, 30),
        "unit": "m",
        "windows": 7,
        "class_accuracy": 1.0,
        "calibration": {"ece": 0.012},
        "temperature": 1.0,
        "by_class": {"vehicle": _row(0.9, 10), "cyclist": _row(0.7, 5), "pedestrian": _row(0.3, 15)},
        "by_motion": {"moving": _row(0.8, 18), "standing": _row(0.1, 12), "nowhere": _row(0.0, 0)},
        "by_label": {"Vehicle": _row(0.9, 10), "Bus": _row(1.1, 2)},
    }


def _bundled_run(name: str, run: Path) -> dict[str, Any]:
    """The bundled model ``name``'s configuration, written with a three-epoch log as the run folder ``run``."""
    cfg: dict[str, Any] = torch.load(ROOT / "training" / "checkpoints" / f"{name}.pt", weights_only=False)["config"]
    (run / "log.csv").write_text("epoch,val_ade,val_loss,seconds\n1,0.60,3.0,60\n2,0.55,3.1,60\n3,0.58,2.9,60\n")
    (run / "config.json").write_text(json.dumps({"config": cfg}))
    return cfg


def test_the_card_of_the_bundled_hdmap_configuration(tmp_path: Path) -> None:
    text = multiclass_card("hdmap", tmp_path, _metrics(), _bundled_run("hdmap", tmp_path))
    assert text.startswith("# Model card: `hdmap`")
    assert MULTICLASS["hdmap"]["title"] in text
    assert MULTICLASS["hdmap"]["licence"] in text
    assert "| vehicle | 10 | 0.90 | 1.90 |" in text
    assert "| standing | 12 | 0.10 |" in text
    assert "| nowhere |" not in text  # a motion group without agents is left out
    assert "| label Bus | 2 | 1.10 |" in text  # a dataset label that is not a class keeps its own row
    assert "| label Vehicle |" not in text
    assert "3.0 min on" in text  # the epochs' seconds summed
    assert "weights of epoch 2" in text  # train.select = "val_ade"
    assert "training/configs/hdmap.toml" in text


def test_the_card_of_a_scene_model_that_keeps_its_features(tmp_path: Path) -> None:
    cfg = _bundled_run("sdd", tmp_path)
    text = multiclass_card("sdd", tmp_path, _metrics(), cfg)
    assert "its features kept with the map in north-up tiles of 64 px (contract 13" in text
    assert "a call pays only for the reading" in text
    assert "px crops at" not in text  # a crop model's words
    crop = {**cfg, "model": {**cfg["model"], "map_mode": "crop"}}
    assert "map CNN (width 8) over 32×31 px crops at 1.0 m/px, " in multiclass_card("sdd", tmp_path, _metrics(), crop)
