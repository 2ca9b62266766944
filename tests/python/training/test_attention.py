"""training.modules.attention: the padded attention in one group or two by degree computes what the edge list does."""

from __future__ import annotations

from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest
import torch

import dgan
from dgan.contract import PADDED_INPUTS
from training.build import build_model, input_spec
from training.config import Config
from training.data.batches import INPUTS
from training.modules.attention import neighbor_groups

ROOT = Path(__file__).resolve().parents[3]


def skewed_frame(n: int, seed: int = 0) -> dgan.Frame:
    """``n`` agents, most of them slow and apart, a few fast ones whose attention zones reach most of the others: a
    few receivers with many senders, as in a driving scene."""
    rng = np.random.default_rng(seed)
    start = rng.uniform(0.0, 200.0, (n, 1, 2))
    speed = np.where(rng.random((n, 1, 1)) < 0.1, rng.uniform(15.0, 25.0, (n, 1, 1)), rng.uniform(0.0, 1.5, (n, 1, 1)))
    direction = rng.normal(size=(n, 1, 2))
    step = speed * direction / np.linalg.norm(direction, axis=-1, keepdims=True) * 0.5
    return dgan.Frame(start + step * np.arange(6)[None, :, None], classes=rng.integers(0, 3, n))


@pytest.mark.parametrize("n", [1, 2, 40, 150])
def test_two_groups_give_the_edge_lists_attention(n: int) -> None:
    torch.manual_seed(0)
    cfg = Config.load(ROOT / "training" / "configs" / "apolloscape.toml")
    spec = replace(input_spec(cfg), graph="padded")
    one = build_model(cfg, spec, 12).eval()
    two = build_model(replace(cfg, model=replace(cfg.model, neighbor_groups=True)), spec, 12).eval()
    two.load_state_dict(one.state_dict())
    x = dgan.preprocess(skewed_frame(n), spec)
    with torch.no_grad():
        edges = one(*[torch.from_numpy(x[k]) for k in INPUTS if k in x])
        padded = [torch.from_numpy(x[k]) for k in PADDED_INPUTS if k in x]
        for out in (one.forward_padded(*padded), two.forward_padded(*padded)):
            for a, b in zip(edges, out, strict=True):
                torch.testing.assert_close(a, b, atol=1e-5, rtol=1e-5)
        for a, b in zip(one.forward_padded(*padded), two.forward_padded(*padded), strict=True):
            torch.testing.assert_close(a, b, atol=1e-6, rtol=1e-6)


def test_the_groups_cost_fewer_slots_and_cover_every_receiver() -> None:
    spec = input_spec(Config.load(ROOT / "training" / "configs" / "apolloscape.toml"))
    x = dgan.preprocess(skewed_frame(150), replace(spec, graph="padded"))
    index, mask = torch.from_numpy(x["neighbor_index"]), torch.from_numpy(x["neighbor_mask"])
    features = torch.from_numpy(x["neighbor_features"])
    g = neighbor_groups(index, mask, features)
    assert g.receivers is not None
    assert g.wide is not None
    degree = mask.sum(1)
    n, d = index.shape
    t = g.narrow[0].shape[1]
    assert t < d  # the skewed frame pays for two groups
    assert g.narrow[0].shape == (n, t)
    assert g.narrow[2].shape == (n, t, features.shape[2])
    assert n * t + len(g.receivers) * d < n * d
    # every receiver wider than t is in the wide group with its whole list; the narrow rows keep the first t senders
    assert set(torch.nonzero(degree > t).reshape(-1).tolist()) <= set(g.receivers.tolist())
    torch.testing.assert_close(g.wide[0], index[g.receivers])
    torch.testing.assert_close(g.narrow[0], index[:, :t])
    # one agent: both groups hold it
    one = neighbor_groups(index[:1, :1], mask[:1, :1], features[:1, :1])
    assert one.receivers is not None
    assert one.receivers.tolist() == [0]
