"""A weight soup (``training.soup``): the mean of runs' weights, checked runs, BatchNorm statistics recomputed."""

from __future__ import annotations

import json
from dataclasses import asdict
from pathlib import Path

import numpy as np
import pytest
import torch

import dgan
from training.build import build_model, input_spec
from training.config import Config
from training.data.batches import INPUTS, to_tensors
from training.modules.dgan import DGAN
from training.modules.scene import MapEncoder
from training.soup import main, recompute_batchnorm, soup_checkpoint, soup_state

ROOT = Path(__file__).resolve().parents[3]
CONFIG = ROOT / "training" / "configs" / "ethucy_zara1.toml"


def _model(seed: int) -> tuple[DGAN, Config, dgan.InputSpec]:
    cfg = Config.load(CONFIG)
    spec = input_spec(cfg)
    torch.manual_seed(seed)
    return build_model(cfg, spec, 20), cfg, spec


def test_the_soup_is_the_mean_of_the_floating_point_weights() -> None:
    a, _, _ = _model(0)
    b, _, _ = _model(1)
    sa, sb = a.state_dict(), b.state_dict()
    soup = soup_state([sa, sb])
    for k, v in soup.items():
        if v.is_floating_point():
            torch.testing.assert_close(v, (sa[k].double() + sb[k].double()).div(2).float())
        else:  # a BatchNorm's batch count: the first run's
            assert torch.equal(v, sa[k])
    # One run's own soup is that run, to the bit.
    for k, v in soup_state([sa, sa, sa]).items():
        assert torch.equal(v, sa[k])
    with pytest.raises(ValueError, match="at least one"):
        soup_state([])
    with pytest.raises(ValueError, match="one architecture"):
        soup_state([sa, {k: v for k, v in sb.items() if "map_enc" not in k}])


def test_batchnorm_statistics_are_recomputed_on_the_batches() -> None:
    model, _, spec = _model(0)
    frame = dgan.demo.scene_for(spec).frame
    x = dgan.preprocess(frame, spec)
    b = to_tensors({k: x[k] for k in INPUTS if k in x})
    enc = model.map_enc
    assert isinstance(enc, MapEncoder)
    conv, first_bn = enc.net[0], enc.net[1]
    assert isinstance(conv, torch.nn.Conv2d)
    assert isinstance(first_bn, torch.nn.BatchNorm2d)
    seen: list[torch.Tensor] = []
    conv.register_forward_hook(lambda _m, _i, out: seen.append(out.detach()))
    assert recompute_batchnorm(model, [b]) == 1
    conv_out = seen[0]
    # One batch: the running statistics are that batch's (the variance unbiased, as BatchNorm keeps it).
    torch.testing.assert_close(first_bn.running_mean, conv_out.mean(dim=(0, 2, 3)))
    torch.testing.assert_close(first_bn.running_var, conv_out.var(dim=(0, 2, 3), unbiased=True))
    assert first_bn.momentum == 0.1
    assert not model.training


def _run(folder: Path, model: DGAN, cfg: Config, seed: int, anchors: np.ndarray) -> Path:
    folder.mkdir()
    config = asdict(cfg)
    config["train"]["seed"] = seed
    torch.save(
        {"model": model.state_dict(), "anchors": anchors, "class_of": np.zeros(len(anchors), np.int64),
         "config": config, "epoch": 14},
        folder / "last.pt",
    )  # fmt: skip
    (folder / "config.json").write_text(json.dumps({"config": config}))
    return folder


def test_runs_that_do_not_share_their_start_are_refused(tmp_path: Path) -> None:
    a, cfg, spec = _model(0)
    anchors = np.zeros((20, spec.t_f, 2), np.float32)
    first = _run(tmp_path / "a", a, cfg, 0, anchors)
    other_anchors = _run(tmp_path / "b", a, cfg, 1, anchors + 1.0)
    with pytest.raises(ValueError, match="anchors differ"):
        soup_checkpoint([first, other_anchors], tmp_path / "soup")
    wider = Config.load(CONFIG, {"train.lr": 0.001})
    other_config = _run(tmp_path / "c", a, wider, 1, anchors)
    with pytest.raises(ValueError, match="configuration differs"):
        soup_checkpoint([first, other_config], tmp_path / "soup")
    with pytest.raises(ValueError, match=r"no last\.pt"):
        soup_checkpoint([first, tmp_path / "nowhere"], tmp_path / "soup")
    with pytest.raises(SystemExit):
        main([str(first), str(tmp_path / "nowhere"), "--out", str(tmp_path / "soup")])


def test_a_soup_is_a_run_that_loads_as_one_network(tmp_path: Path) -> None:
    from conftest import shared_data

    from training.export import load_checkpoint

    data = shared_data("eth_ucy")
    a, cfg, spec = _model(0)
    b, _, _ = _model(1)
    anchors = np.random.default_rng(0).normal(size=(20, spec.t_f, 2)).astype(np.float32)
    runs = [_run(tmp_path / "a", a, cfg, 0, anchors), _run(tmp_path / "b", b, cfg, 100, anchors)]
    path = main([*map(str, runs), "--out", str(tmp_path / "soup"), "--batches", "2", "--data-root", str(data)])
    assert path == tmp_path / "soup" / "best.pt"
    assert (tmp_path / "soup" / "config.json").is_file()
    model, soup_spec, soup_anchors, _, _, _ = load_checkpoint(path)
    assert soup_spec.to_json() == spec.to_json()
    np.testing.assert_array_equal(soup_anchors, anchors)
    mean = soup_state([a.state_dict(), b.state_dict()])
    for k, v in model.state_dict().items():
        if "running_" not in k and "num_batches" not in k:
            torch.testing.assert_close(v, mean[k])
    assert not torch.equal(model.state_dict()["map_enc.net.1.running_mean"], mean["map_enc.net.1.running_mean"])
    assert torch.load(path, weights_only=False)["runs"] == ["a", "b"]
