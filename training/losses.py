"""The paper's loss: hierarchical classification −log(p(c*) · p(k* | c*)) plus α times the mean L2 error of the
offset-corrected closest anchor k* (closest to the ground truth by summed squared distance, among the agent's class's
anchors, or among all with ``train.anchor_pool = "all_classes"``; c* is k*'s class)."""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from typing import Any, ClassVar

import numpy as np
import torch
from torch import Tensor

import dgan


def closest_anchor(future: Tensor, anchors: Tensor, pool: Tensor) -> Tensor:
    """``(N,)`` index k* of the anchor closest to each future among those ``pool (N, K)`` allows."""
    d = ((anchors.unsqueeze(0) - future.unsqueeze(1)) ** 2).sum(dim=(-1, -2))  # (N, K)
    return d.masked_fill(~pool, float("inf")).argmin(dim=1)


#: ``train.anchor_pool``: which anchors an agent's targets are drawn from (:func:`dgan_loss`).
ANCHOR_POOLS = ("own_class", "all_classes")


def check_anchor_pool(name: str) -> None:
    """Raises a ValueError naming the choices unless ``name`` is one of :data:`ANCHOR_POOLS`."""
    if name not in ANCHOR_POOLS:
        raise ValueError(f"train.anchor_pool must be 'own_class' or 'all_classes', got {name!r}")


def anchor_pool(name: str, class_of_anchor: Tensor, class_index: Tensor) -> Tensor:
    """``(N, K)`` the anchors each agent may be taught: its own class's ("own_class", the paper's) or every class's
    ("all_classes": the class probability p(c) then learns which class's anchors hold the future, not the input
    class, and p(c) · p(k | c) is the probability that anchor k is the closest of all K)."""
    check_anchor_pool(name)
    if name == "all_classes":
        return torch.ones(len(class_index), len(class_of_anchor), dtype=torch.bool, device=class_index.device)
    return class_of_anchor.unsqueeze(0) == class_index.unsqueeze(1)


#: ``train.cls_target``: what the classifier is taught to pick (:func:`dgan_loss`).
CLS_TARGETS = ("closest_anchor", "best_mode")


def check_cls_target(name: str) -> None:
    """Raises a ValueError naming the choices unless ``name`` is one of :data:`CLS_TARGETS`."""
    if name not in CLS_TARGETS:
        raise ValueError(f"train.cls_target must be 'closest_anchor' or 'best_mode', got {name!r}")


def dgan_loss(
    class_logits: Tensor,
    anchor_logits: Tensor,
    offsets: Tensor,
    future: Tensor,
    class_index: Tensor,
    anchors: Tensor,
    class_of_anchor: Tensor,
    alpha: float,
    beta: float = 0.0,
    weights: Tensor | None = None,
    cls_target: str = "closest_anchor",
    pool: str = "own_class",
    classify: bool = True,
) -> tuple[Tensor, dict[str, float]]:
    """Mean loss over the given (target) agents, and its parts.

    ``beta`` > 0 adds the mean L2 error of the most probable mode (its selection carries no gradient), so the offset
    of the mode a user sees first also learns to correct a wrong anchor choice; the other modes keep their diversity.
    ``weights`` ``(N,)`` makes the mean a weighted one (:func:`class_weights`). ``cls_target`` "best_mode" teaches
    the classifier the decoded mode closest to its future (by ADE; no gradient through the choice) instead of the
    closest anchor. ``pool`` (:func:`anchor_pool`) says whether both are sought among the agent's class's anchors
    or among all; the class taught to p(c) is the chosen anchor's. ``classify`` False leaves the classification
    term out (the regression terms only: a teacher's mode that should not teach the mode probabilities).
    """
    allowed = anchor_pool(pool, class_of_anchor, class_index)
    k_star = closest_anchor(future, anchors, allowed)
    rows = torch.arange(len(future))
    check_cls_target(cls_target)
    k_cls = k_star
    if cls_target == "best_mode":
        with torch.no_grad():
            ade = torch.linalg.norm(anchors + offsets - future.unsqueeze(1), dim=-1).mean(dim=-1)
            k_cls = ade.masked_fill(~allowed, float("inf")).argmin(dim=1)
    c_cls = class_of_anchor[k_cls]
    log_pc = torch.log_softmax(class_logits, dim=1)[rows, c_cls]
    in_class = class_of_anchor.unsqueeze(0) == c_cls.unsqueeze(1)
    log_pk = torch.log_softmax(anchor_logits.masked_fill(~in_class, float("-inf")), dim=1)[rows, k_cls]
    cls = -(log_pc + log_pk)
    pred = anchors[k_star] + offsets[rows, k_star]
    reg = torch.linalg.norm(pred - future, dim=-1).mean(dim=-1)
    per_agent = alpha * reg + cls if classify else alpha * reg
    parts = {"cls": float(cls.mean().detach()), "reg": float(reg.mean().detach())}
    if beta > 0:
        with torch.no_grad():
            top = mode_probabilities(class_logits, anchor_logits, class_of_anchor).argmax(dim=1)
        top_err = torch.linalg.norm(anchors[top] + offsets[rows, top] - future, dim=-1).mean(dim=-1)
        per_agent = per_agent + beta * top_err
        parts["top1"] = float(top_err.mean().detach())
    loss = per_agent.mean() if weights is None else (weights * per_agent).sum() / weights.sum()
    return loss, parts


def class_weights(class_index: Tensor, num_classes: int, power: float) -> Tensor:
    """``(C,)`` loss weight of each class: (its share of the targets)^-power, scaled so that the mean weight over the
    targets is 1. ``power`` 0 weighs every target alike, 1 every class alike; a class without targets weighs 0."""
    counts = torch.bincount(class_index, minlength=num_classes).to(torch.float64)
    share = counts / counts.sum()
    w = torch.where(counts > 0, share.clamp(min=1e-12) ** -power, torch.zeros_like(share))
    w = w / (w[class_index].mean() if len(class_index) else 1.0)
    return w.to(torch.float32)


#: The temperatures an agent may get (the engine's ``Calibration::MIN_TEMPERATURE`` and ``MAX_TEMPERATURE``).
MIN_TEMPERATURE, MAX_TEMPERATURE = 1e-3, 1e3


@dataclass(frozen=True)
class Calibration:
    """How the logits become probabilities, as the engine decodes (contract 9): p(c) = softmax(class logits /
    ``class_temperature``), p(k | c) = softmax(anchor logits / T_i) with T_i = ``temperature`` · (1 + v_i) ^
    ``speed_exponent``, v_i the speed of agent i's kinematic prior (m/s). The defaults are contract 2's single
    temperature of 1."""

    temperature: float = 1.0
    speed_exponent: float = 0.0
    class_temperature: float = 1.0

    #: The checkpoint and contract keys of the two contract-9 terms (``temperature`` keeps its own).
    KEYS: ClassVar[tuple[str, ...]] = ("temperature_speed_exponent", "class_temperature")

    @classmethod
    def of(cls, ckpt: Mapping[str, Any]) -> Calibration:
        """The calibration a checkpoint or a model's contract holds (the same keys; a single temperature of 1 for
        one without)."""
        return cls(
            float(ckpt.get("temperature", 1.0)),
            float(ckpt.get("temperature_speed_exponent", 0.0)),
            float(ckpt.get("class_temperature", 1.0)),
        )

    def keys(self, complete: bool = False) -> dict[str, float]:
        """The contract's keys, rounded as the contract stores them: the temperature, and the contract-9 terms where
        they differ from a single temperature's (so that such a model reads as before). ``complete``: a
        checkpoint's instead, every key at full precision (so that a refit replaces an earlier one's)."""
        if complete:
            exponent, klass = self.KEYS
            return {"temperature": self.temperature, exponent: self.speed_exponent, klass: self.class_temperature}
        out = {"temperature": round(self.temperature, 6)}
        if self.speed_exponent != 0.0:
            out["temperature_speed_exponent"] = round(self.speed_exponent, 6)
        if self.class_temperature != 1.0:
            out["class_temperature"] = round(self.class_temperature, 6)
        return out

    def anchor_temperatures(self, prior: Tensor | None, dt_s: float) -> float | Tensor:
        """Each agent's temperature of the anchor logits ``(N, 1)`` given the kinematic ``prior (N, T_f, 2)`` (its
        first step is the velocity times ``dt_s``), or the single temperature when the speed plays no part."""
        if self.speed_exponent == 0.0 or prior is None:
            return self.temperature
        return self.at_speed(torch.linalg.norm(prior[:, 0].double(), dim=-1) / dt_s).to(prior.dtype)

    def at_speed(self, speed_mps: Tensor) -> Tensor:
        """``(N, 1)`` float64 the anchor temperature of agents whose priors move at ``speed_mps (N,)``."""
        t: Tensor = self.temperature * (1.0 + speed_mps.double().clamp_min(0.0)) ** self.speed_exponent
        return t.clamp(MIN_TEMPERATURE, MAX_TEMPERATURE).unsqueeze(1)


def mode_probabilities(
    class_logits: Tensor,
    anchor_logits: Tensor,
    class_of_anchor: Tensor,
    temperature: float | Tensor = 1.0,
    class_temperature: float = 1.0,
) -> Tensor:
    """``(N, K)`` p(c(k)) · p(k | c(k)) of every anchor: p(k | c) = softmax(anchor logits / temperature), one
    temperature or one per agent ``(N, 1)``; p(c) = softmax(class logits / class_temperature)."""
    pc = torch.softmax(class_logits / class_temperature, dim=1)[:, class_of_anchor]
    pk = torch.zeros_like(anchor_logits)
    for c in range(class_logits.shape[1]):
        sel = class_of_anchor == c
        pk[:, sel] = torch.softmax(anchor_logits[:, sel] / temperature, dim=1)
    return pc * pk


def log_mode_probabilities(class_logits: Tensor, anchor_logits: Tensor, class_of_anchor: Tensor) -> Tensor:
    """``(N, K)`` log p(c(k)) + log p(k | c(k)) of every anchor (:func:`mode_probabilities` at T = 1, in logs)."""
    log_pc = torch.log_softmax(class_logits, dim=1)[:, class_of_anchor]
    log_pk = torch.zeros_like(anchor_logits)
    for c in range(class_logits.shape[1]):
        sel = class_of_anchor == c
        log_pk[:, sel] = torch.log_softmax(anchor_logits[:, sel], dim=1)
    return log_pc + log_pk


def soft_class_loss(class_logits: Tensor, anchor_logits: Tensor, class_of_anchor: Tensor, target: Tensor) -> Tensor:
    """``(N,)`` cross-entropy −Σ_k q_k log(p(c(k)) · p(k | c(k))) of the mode probabilities against a distribution
    ``target (N, K)`` over the same anchors (a teacher's, ``training.step.Teacher.mode_targets``): the paper's
    classification term with the closest anchor drawn from q instead of given."""
    log_p = log_mode_probabilities(class_logits, anchor_logits, class_of_anchor)
    return -(target.to(log_p.dtype) * log_p.masked_fill(target <= 0, 0.0)).sum(dim=1)


def decode_torch(
    class_logits: Tensor,
    anchor_logits: Tensor,
    offsets: Tensor,
    anchors: Tensor,
    class_of_anchor: Tensor,
    prior: Tensor | None = None,
    temperature: float | Tensor = 1.0,
    class_temperature: float = 1.0,
    still: Tensor | None = None,
    top_scale: Tensor | None = None,
    top_mean: Tensor | None = None,
) -> tuple[Tensor, Tensor]:
    """Agent-frame modes ``(N, K, T, 2)`` (the kinematic ``prior (N, T, 2)`` + anchor + offset) sorted by
    p(c) · p(k | c), and those probabilities ``(N, K)``; the engine's decoding, in PyTorch (temperatures as in
    :func:`mode_probabilities`; :meth:`Calibration.anchor_temperatures` gives a speed-dependent one). ``still (N,)``:
    the agents whose most probable mode is held at the prior (contract 15, ``dgan.still_agents``). ``top_scale (C,)``:
    contract 14's share of the residual kept by the most probable class's top anchor (the first of equal logits), for
    a single network (a consensus applies its own in its graph). ``top_mean (C,)``: contract 16's power β of the most
    probable class (0: none): the most probable mode becomes the mean of all modes weighted by p^β."""
    p = mode_probabilities(class_logits, anchor_logits, class_of_anchor, temperature, class_temperature)
    order = torch.argsort(-p, dim=1, stable=True)
    modes = anchors.unsqueeze(0) + offsets
    if top_scale is not None:
        top_class = class_logits.argmax(dim=1)
        block = class_of_anchor.unsqueeze(0) == top_class.unsqueeze(1)
        k = anchor_logits.masked_fill(~block, float("-inf")).argmax(dim=1)
        rows = torch.arange(len(k))
        modes = modes.clone()
        modes[rows, k] = modes[rows, k] * top_scale.to(modes.dtype)[top_class][:, None, None]
    if prior is not None:
        modes = modes + prior.unsqueeze(1)
    traj = modes.gather(1, order[..., None, None].expand(-1, -1, *offsets.shape[2:]))
    if top_mean is not None:
        beta = top_mean.to(traj.dtype)[class_logits.argmax(dim=1)]
        ps = p.gather(1, order).to(traj.dtype)
        w = (ps / ps[:, :1]) ** beta[:, None]
        mean = (w[..., None, None] * traj).sum(1) / w.sum(1)[:, None, None]
        traj = torch.cat([torch.where((beta > 0)[:, None, None], mean, traj[:, 0])[:, None], traj[:, 1:]], dim=1)
    if still is not None and bool(still.any()):
        held = prior[still] if prior is not None else torch.zeros_like(traj[still, 0])
        traj = traj.clone()
        traj[still, 0] = held.to(traj.dtype)
    return traj, p.gather(1, order)


@dataclass(frozen=True)
class DecodingKeys:
    """A contract's per-class decoding keys as :func:`decode_torch` takes them, in the model's class order: contract
    14's top-mode scale (None without one, or for a consensus, whose forward applies its own), 15's still radii
    (empty without) and 16's top-mean powers (None without)."""

    top_scale: Tensor | None
    still_radius: list[float]
    top_mean: Tensor | None
    device: str = "cpu"

    @classmethod
    def of(
        cls, contract: Mapping[str, Any], classes: Sequence[str], consensus: bool, device: str = "cpu"
    ) -> DecodingKeys:
        def per_class(key: str, neutral: float) -> list[float]:
            values = contract.get(key, {})
            return [float(values.get(c, neutral)) for c in classes] if values else []

        scale, power = per_class("top_scale", 1.0), per_class("top_mean_power", 0.0)
        return cls(
            torch.tensor(scale, device=device) if scale and not consensus else None,
            per_class("still_radius_m", 0.0),
            torch.tensor(power, device=device) if power else None,
            device,
        )

    def still(self, x: Mapping[str, np.ndarray]) -> Tensor | None:
        """Which agents of network inputs ``x`` are held at their prior (``dgan.still_agents``); None without radii."""
        if not self.still_radius:
            return None
        held = dgan.still_agents(x["trajectory"], x["trajectory_mask"], x["state"], self.still_radius)
        return torch.from_numpy(held).to(self.device)
