"""training.bundle: the model card's words follow the training configuration."""

from __future__ import annotations

from typing import Any

import pytest

pytest.importorskip("torch")

from training.bundle import classification_words, extra_data_line, extra_licence_line


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


def test_the_classification_target_is_named() -> None:
    assert classification_words(cfg()) == "the paper's hierarchical classification"
    best = {"data": {}, "train": {"cls_target": "best_mode"}}
    assert "decoded mode closest to the future" in classification_words(best)
