"""training.checkpoint: the weights a run starts from (``train.init``)."""

from __future__ import annotations

from pathlib import Path

import pytest
import torch

from training.build import build_model, input_spec
from training.checkpoint import init_weights
from training.config import Config

ROOT = Path(__file__).resolve().parents[3]
CONFIG = ROOT / "training" / "configs" / "ethucy_zara1.toml"
SCENE = {"model.map_mode": "scene", "data.map_scene_px": 64}


def _model(overrides: dict[str, object] | None = None) -> torch.nn.Module:
    cfg = Config.load(CONFIG, overrides or {})
    return build_model(cfg, input_spec(cfg), 20)


def test_a_crop_models_weights_start_a_scene_model_layer_by_layer(tmp_path: Path) -> None:
    torch.manual_seed(0)
    crop = _model()
    torch.save({"model": crop.state_dict()}, tmp_path / "run.pt")
    torch.manual_seed(1)
    scene = _model(SCENE)
    loaded, left = init_weights(scene, tmp_path / "run.pt")
    assert left == []
    assert len(loaded) == len(scene.state_dict())
    got, want = scene.state_dict(), crop.state_dict()
    assert torch.equal(got["map_enc.scene.0.weight"], want["map_enc.net.0.weight"])
    assert torch.equal(got["map_enc.scene.7.body.3.weight"], want["map_enc.net.7.body.3.weight"])
    assert torch.equal(got["map_enc.agent.0.weight"], want["map_enc.net.8.weight"])
    assert torch.equal(got["map_enc.proj.1.weight"], want["map_enc.proj.1.weight"])
    # A consensus's file: its first member.
    torch.save({"members": [{"model": crop.state_dict()}, {"model": {}}], "runs": ["a", "b"]}, tmp_path / "ens.pt")
    again = _model(SCENE)
    init_weights(again, tmp_path / "ens.pt")
    assert torch.equal(again.state_dict()["map_enc.agent.0.bias"], want["map_enc.net.8.bias"])


def test_weights_of_other_shapes_stay_initialised_and_another_architecture_is_refused(tmp_path: Path) -> None:
    crop = _model()
    torch.save({"model": crop.state_dict()}, tmp_path / "run.pt")
    wide = _model({"model.head_dim": 512})
    loaded, left = init_weights(wide, tmp_path / "run.pt")
    assert left
    assert all(k in wide.state_dict() for k in left)
    assert not set(left) & set(loaded)
    assert "map_enc.net.0.weight" in loaded
    torch.save({"model": {"something.else": torch.zeros(3)}}, tmp_path / "other.pt")
    with pytest.raises(ValueError, match=r"train\.init: no parameter"):
        init_weights(crop, tmp_path / "other.pt")
    torch.save({"members": [], "runs": []}, tmp_path / "empty.pt")
    with pytest.raises(ValueError, match="a consensus without members"):
        init_weights(crop, tmp_path / "empty.pt")


def test_a_run_refuses_an_init_that_is_not_a_file_before_loading_data(tmp_path: Path) -> None:
    from training.train import parse_args

    args = ["--config", str(CONFIG), "--out", str(tmp_path / "run"), "--set", f"train.init={tmp_path / 'no.pt'}"]
    with pytest.raises(ValueError, match=r"train\.init must name a checkpoint file.*no such file"):
        parse_args(args)
