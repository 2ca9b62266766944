"""training.modules.dgan: classes that do not read the map (``model.map_classes``) are encoded as without one, and a
per-class temperature folded into the network scales each anchor's logit."""

from __future__ import annotations

import inspect
from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest
import torch

import dgan
from dgan.contract import PADDED_INPUTS
from training.build import build_model, input_spec
from training.config import Config
from training.modules.dgan import DGAN, entropy_tempered

ROOT = Path(__file__).resolve().parents[3]


def test_classes_that_do_not_read_the_map_are_served_as_without_one() -> None:
    """``model.map_classes``: the other classes' agents get map_present 0 inside the network (as a frame without a
    map gives them), the listed classes' agents keep theirs; a per-class temperature scales each anchor's logit."""
    torch.manual_seed(0)
    cfg = Config.load(ROOT / "training" / "configs" / "hdmap.toml")
    spec = replace(input_spec(cfg), graph="padded")
    plain = build_model(cfg, spec, 30).eval()
    gated = build_model(replace(cfg, model=replace(cfg.model, map_classes="cyclist,pedestrian")), spec, 30).eval()
    gated.load_state_dict(plain.state_dict())
    rng = np.random.default_rng(0)
    pos = np.cumsum(rng.normal(0.5, 0.2, (6, spec.t_obs, 2)), axis=1) + rng.uniform(0, 20, (6, 1, 2))
    vector = dgan.VectorMap([("lane_centerline", [[-50, -50], [80, 80]]), ("road_edge", [[-50, 0], [80, 5]])])
    classes = ["vehicle", "pedestrian", "cyclist", "vehicle", "pedestrian", "vehicle"]
    # What encode takes, in order (a scene map encoder's grids are keyword-only).
    keys = [k for k, p in inspect.signature(DGAN.encode).parameters.items() if k != "self" and p.kind != p.KEYWORD_ONLY]
    x = dgan.preprocess(dgan.Frame(pos, classes=classes, map=vector), spec)
    bare = dgan.preprocess(dgan.Frame(pos, classes=classes), spec)
    vehicle = torch.tensor([c == "vehicle" for c in classes])
    with torch.no_grad():
        gated_nodes = gated.encode(*[torch.from_numpy(x[k]) for k in keys])
        with_map = plain.encode(*[torch.from_numpy(x[k]) for k in keys])
        without = plain.encode(*[torch.from_numpy(bare[k]) for k in keys])
    torch.testing.assert_close(gated_nodes[vehicle], without[vehicle])
    torch.testing.assert_close(gated_nodes[~vehicle], with_map[~vehicle])
    assert not torch.allclose(with_map[vehicle], without[vehicle])  # the map reached the plain model's vehicles
    # A frame without a reader: no crop goes through the map CNN (an empty batch), as without the map.
    x3 = dgan.preprocess(dgan.Frame(pos[:3], classes=["vehicle"] * 3, map=vector), spec)
    bare3 = dgan.preprocess(dgan.Frame(pos[:3], classes=["vehicle"] * 3), spec)
    with torch.no_grad():
        torch.testing.assert_close(
            gated.encode(*[torch.from_numpy(x3[k]) for k in keys]),
            plain.encode(*[torch.from_numpy(bare3[k]) for k in keys]),
        )
    inputs = [torch.from_numpy(x[k]) for k in PADDED_INPUTS if k in x]
    with torch.no_grad():
        logits = gated.forward_padded(*inputs)[1]
        gated.set_anchor_logit_scale([0.5] * 30)
        torch.testing.assert_close(gated.forward_padded(*inputs)[1], 0.5 * logits)
        gated.set_entropy_temperature([0.2, 0.3])  # after the scale, as a checkpoint never holds both
        torch.testing.assert_close(
            gated.forward_padded(*inputs)[1], entropy_tempered(0.5 * logits, len(spec.classes), 0.2, 0.3)
        )
    with pytest.raises(ValueError, match="30 positive"):
        gated.set_anchor_logit_scale([0.5] * 29)
    with pytest.raises(ValueError, match="two finite values"):
        gated.set_entropy_temperature([0.2, float("nan")])
    with pytest.raises(ValueError, match="not classes of this model"):
        build_model(replace(cfg, model=replace(cfg.model, map_classes="truck")), spec, 30)


def test_the_spec_declares_the_readers_and_the_engine_draws_their_crops_alone() -> None:
    """``model.map_classes`` is the exported spec's ``map.classes`` (contract 11): the engine leaves the other
    agents' crops blank, each reader's crop is the one drawn for every agent, and the gated network's encoding is the
    same from either (it never reads the others' crops)."""
    cfg = Config.load(ROOT / "training" / "configs" / "hdmap.toml")
    gated_cfg = replace(cfg, model=replace(cfg.model, map_classes="cyclist,pedestrian"))
    every, readers = (replace(input_spec(c), graph="padded") for c in (cfg, gated_cfg))
    assert every.map is not None
    assert readers.map is not None
    assert (every.map.classes, readers.map.classes) == ((), ("cyclist", "pedestrian"))
    rng = np.random.default_rng(1)
    pos = np.cumsum(rng.normal(0.5, 0.2, (5, every.t_obs, 2)), axis=1) + rng.uniform(0, 20, (5, 1, 2))
    vector = dgan.VectorMap([("lane_centerline", [[-50, -50], [80, 80]]), ("road_edge", [[-50, 0], [80, 5]])])
    classes = ["vehicle", "pedestrian", "cyclist", "vehicle", "pedestrian"]
    frame = dgan.Frame(pos, classes=classes, map=vector)
    x, y = dgan.preprocess(frame, every), dgan.preprocess(frame, readers)
    vehicle = np.array([c == "vehicle" for c in classes])
    np.testing.assert_array_equal(y["map"][~vehicle], x["map"][~vehicle])
    assert not y["map"][vehicle].any()
    assert x["map"][vehicle].any()
    model = build_model(gated_cfg, readers, 30).eval()
    keys = [k for k, p in inspect.signature(DGAN.encode).parameters.items() if k != "self" and p.kind != p.KEYWORD_ONLY]
    with torch.no_grad():
        torch.testing.assert_close(
            model.encode(*[torch.from_numpy(x[k]) for k in keys]),
            model.encode(*[torch.from_numpy(y[k]) for k in keys]),
            rtol=0,
            atol=0,
        )
