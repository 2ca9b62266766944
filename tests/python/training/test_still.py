"""training.still: the still radius kept by its rule, and its way into the contract and the parity check's decoding."""

from __future__ import annotations

from typing import Any

import numpy as np
import pytest
import torch

import dgan
from training.export import contract
from training.losses import decode_torch
from training.still import MIN_STILL, RADII, StillErrors, choose_radius


def errors(n_still: int, network: tuple[float, float], held: tuple[float, float], at: int = 1) -> StillErrors:
    """One class; ``n_still`` targets still from radius ``RADII[at]`` on (the others move), with those errors."""
    n = n_still + 100
    still = np.zeros((n, len(RADII)), dtype=bool)
    still[:n_still, at:] = True
    net = np.tile([1.0, 2.0], (n, 1))
    net[:n_still] = network
    hold = np.tile([1.5, 3.0], (n, 1))
    hold[:n_still] = held
    return StillErrors(np.zeros(n, np.int64), still, net, hold)


def test_a_radius_is_kept_where_holding_lowers_the_still_group_enough() -> None:
    radius, groups = choose_radius(errors(MIN_STILL, (0.10, 0.20), (0.09, 0.20)), 0)
    assert radius == RADII[1], "the smallest radius of the equal best"
    assert groups[0][0] == 0
    assert groups[1] == pytest.approx((MIN_STILL, 0.10, 0.20, 0.09, 0.20))


@pytest.mark.parametrize(
    ("n_still", "network", "held", "why"),
    [
        (MIN_STILL - 1, (0.10, 0.20), (0.05, 0.10), "too few still targets"),
        (MIN_STILL, (0.10, 0.20), (0.099, 0.19), "a gain under 2%"),
        (MIN_STILL, (0.10, 0.20), (0.05, 0.21), "FDE rises"),
        (MIN_STILL, (0.10, 0.20), (0.20, 0.10), "holding is worse"),
    ],
)
def test_no_radius_is_kept_otherwise(
    n_still: int, network: tuple[float, float], held: tuple[float, float], why: str
) -> None:
    assert choose_radius(errors(n_still, network, held), 0)[0] == 0.0, why


@pytest.mark.parametrize(("argument", "key"), [("still_radius", "still_radius_m"), ("top_mean", "top_mean_power")])
def test_the_contract_names_the_classes_with_a_value_alone(argument: str, key: str) -> None:
    """Contract 15's still radius and 16's top-mean power: written for the classes above 0 (training.top_mean too)."""
    spec = dgan.Predictor("hdmap").spec
    anchors = np.zeros((len(spec.classes), spec.t_f, 2))
    class_of = np.arange(len(spec.classes))

    def meta(values: list[float]) -> dict[str, Any]:
        kept = {argument: values}
        return contract(
            spec, anchors, class_of, "m", "", still_radius=kept.get("still_radius"), top_mean=kept.get("top_mean")
        )

    assert meta([0.2, 0.0, 2.0])[key] == {spec.classes[0]: 0.2, spec.classes[2]: 2.0}
    assert key not in meta([0.0] * 3)


def test_decode_torch_holds_the_most_probable_mode_of_a_still_agent_at_its_prior() -> None:
    anchors = torch.tensor([[[1.0, 0.0]], [[0.0, 1.0]]])
    class_of = torch.zeros(2, dtype=torch.long)
    offsets = torch.full((2, 2, 1, 2), 0.5)
    anchor_logits = torch.tensor([[0.0, 1.0], [1.0, 0.0]])
    prior = torch.tensor([[[0.25, 0.0]], [[0.0, 0.5]]])
    args = (torch.zeros(2, 1), anchor_logits, offsets, anchors, class_of, prior)
    plain, p = decode_torch(*args)
    held, q = decode_torch(*args, still=torch.tensor([False, True]))
    assert torch.equal(p, q)
    assert torch.equal(held[0], plain[0])
    assert torch.equal(held[1, 1], plain[1, 1])
    assert held[1, 0].tolist() == [[0.0, 0.5]]
