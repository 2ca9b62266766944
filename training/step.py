"""One step of training: the network on a batch and its loss (with a distillation teacher, ``train.distill``), and the
validation figures an epoch is chosen by."""

from __future__ import annotations

from dataclasses import dataclass, replace
from pathlib import Path

import numpy as np
import torch

import dgan
from dgan.contract import SCENE_GRID_INPUTS
from training.config import Config
from training.data.arrays import Windows, concat_windows
from training.data.batches import batch_prior, forward_inputs, prepared_batch, windows_with_targets
from training.data.splits import set_windows, window_sets
from training.export import load_checkpoint
from training.losses import Calibration, anchor_pool, decode_torch, dgan_loss, soft_class_loss
from training.modules.dgan import DGAN


def crop_geometry(m: dgan.MapSpec) -> tuple[int, int, float, int, int, bool]:
    """A crop's size, resolution, the agent's pixel and whether the agents' boxes are drawn: what a teacher's crops
    may differ from its student's in."""
    return m.height_px, m.width_px, m.resolution_m, m.agent_row, m.agent_col, m.draw_agents


def with_geometry(m: dgan.MapSpec, like: dgan.MapSpec) -> dgan.MapSpec:
    """``m`` with the crop geometry (:func:`crop_geometry`) of ``like``."""
    h, w, res, row, col, boxes = crop_geometry(like)
    # A crop per agent, as a teacher reads them (a scene student's spec reads the scene: map.scene).
    return replace(
        m, height_px=h, width_px=w, resolution_m=res, agent_row=row, agent_col=col, draw_agents=boxes, scene=None
    )


@dataclass(frozen=True)
class Teacher:
    """A trained model whose most probable mode is a second target of the student's loss (``train.distill``)."""

    model: torch.nn.Module
    anchors: torch.Tensor
    class_of: torch.Tensor
    calibration: Calibration
    #: The teacher's input spec: the student's but for its kinematic prior, which may differ.
    spec: dgan.InputSpec
    #: Whether that prior differs from the student's (the teacher's modes are then carried onto the student's).
    own_prior: bool
    #: Whether its map crops have another size, resolution or boxes than the student's (a student with cheaper crops,
    #: issue 26): it then runs on crops drawn to its own geometry, the batches' ``teacher_map``
    #: (:func:`teacher_crops`).
    own_map: bool = False

    @classmethod
    def load(cls, path: str, spec: dgan.InputSpec) -> Teacher:
        model, tspec, anchors, class_of, _, calibration = load_checkpoint(Path(path))
        own_map, compared = False, tspec.map
        if tspec.map is not None and spec.map is not None:
            # A teacher runs on the student's crops whichever way its own were drawn (map.render): the same tensors.
            theirs_map = replace(tspec.map, render=spec.map.render)
            tspec = replace(tspec, map=theirs_map)
            own_map = crop_geometry(theirs_map) != crop_geometry(spec.map)
            # Nor is a crop's geometry an input it must share, when it gets crops of its own (the rest of the crop
            # spec, the map's classes, whether it is optional, it must).
            compared = with_geometry(theirs_map, spec.map)
        # The prior is not a network input: a teacher with another one runs on the same tensors.
        theirs = replace(tspec, prior=spec.prior, map=compared)
        # A scene student's windows carry the agents' crops too (map.scene aside, the same spec): a teacher reads them.
        crops = spec if spec.map is None else replace(spec, map=replace(spec.map, scene=None))
        if theirs.to_json() != crops.to_json():
            raise ValueError(f"train.distill: {path} takes other inputs than this configuration ({tspec.to_json()})")
        anchors_t, class_of_t = torch.from_numpy(anchors).float(), torch.from_numpy(class_of).long()
        return cls(model.eval(), anchors_t, class_of_t, calibration, tspec, tspec.prior != spec.prior, own_map)

    def crop_spec(self, spec: dgan.InputSpec) -> dgan.InputSpec:
        """The student's ``spec`` with the teacher's crop geometry: what its crops (``teacher_map``) are drawn by."""
        if not self.own_map or spec.map is None or self.spec.map is None:
            return spec
        return replace(spec, map=with_geometry(spec.map, self.spec.map))

    def inputs(self, b: dict[str, torch.Tensor]) -> list[torch.Tensor]:
        """The teacher's network inputs from a batch: the student's, with its own crops if it has them."""
        if "map_grid" in b:  # a scene student's batch: the teacher reads the agents' crops
            b = {k: v for k, v in b.items() if k not in ("map", *SCENE_GRID_INPUTS)}
            if "crops" in b:
                b["map"] = b.pop("crops")
        if not self.own_map:
            return forward_inputs(b)
        if "teacher_map" not in b:
            raise ValueError(
                "train.distill: the teacher's map crops have another geometry than the student's, and this batch "
                "carries none drawn to its own (teacher_map; training.step.teacher_crops)"
            )
        return forward_inputs({**b, "map": b["teacher_map"]})

    @torch.no_grad()
    def modes(self, b: dict[str, torch.Tensor]) -> tuple[torch.Tensor, torch.Tensor]:
        """The teacher's modes of each target ``(targets, K_t, T_f, 2)`` as residuals from the student's prior
        (``b["prior"]``), most probable first, and their probabilities ``(targets, K_t)`` under its calibration (as
        the engine decodes it, with its own prior's speeds)."""
        cl, al, off = self.model(*self.inputs(b))
        t = b["target"]
        student = b["prior"][t]
        prior = torch.from_numpy(batch_prior(b, self.spec, t)) if self.own_prior else student
        cal = self.calibration
        temperature = cal.anchor_temperatures(prior, self.spec.dt_s)
        shift = (prior - student) if self.own_prior else None  # the teacher's prior from the student's
        tc = cal.class_temperature
        return decode_torch(cl[t], al[t], off[t], self.anchors, self.class_of, shift, temperature, tc)

    def top_residual(self, b: dict[str, torch.Tensor]) -> torch.Tensor:
        """``(targets, T_f, 2)`` the teacher's most probable mode of each target, as a residual from the prior."""
        return self.modes(b)[0][:, 0]

    @torch.no_grad()
    def mode_targets(
        self, b: dict[str, torch.Tensor], anchors: torch.Tensor, class_of: torch.Tensor, pool: str
    ) -> tuple[torch.Tensor, torch.Tensor]:
        """The teacher's most probable mode of each target ``(targets, T_f, 2)`` (a residual from the prior, as
        :meth:`top_residual`) and its whole mode distribution carried onto the student's ``anchors``
        ``(targets, K)``: each teacher mode's probability (with the teacher's calibration) goes to the student
        anchor closest to it among those ``pool`` allows (``training.losses.anchor_pool``). That is the class the
        data's loss would teach if the future were drawn from the teacher's modes (``train.distill_soft``)."""
        modes, p = self.modes(b)
        t = b["target"]
        n, k_t = p.shape
        flat = modes.reshape(n, k_t, -1).double()
        ref = anchors.reshape(len(anchors), -1).double()
        # Squared distances of every teacher mode to every student anchor, (n, K_t, K), without a (.., T, 2) copy.
        d = (flat**2).sum(-1, keepdim=True) + (ref**2).sum(-1) - 2.0 * flat @ ref.T
        allowed = anchor_pool(pool, class_of, b["class_index"][t])
        nearest = d.masked_fill(~allowed.unsqueeze(1), float("inf")).argmin(dim=2)  # (n, K_t)
        soft = torch.zeros(n, len(anchors), dtype=p.dtype).scatter_add_(1, nearest, p)
        return modes[:, 0], soft / soft.sum(dim=1, keepdim=True).clamp_min(1e-12)


def teacher_crops(cfg: Config, spec: dgan.InputSpec, teacher: Teacher, train: Windows, progress: bool) -> Windows:
    """The training windows ``train`` (of ``cfg``, under ``spec``) with their agents' crops drawn to the teacher's
    geometry as well (``teacher_map``) where it differs from the student's (:attr:`Teacher.own_map`): the same
    windows under the teacher's crop spec, from the window cache or built into it."""
    if not teacher.own_map:
        return train
    sets = window_sets(cfg.data, "train")
    theirs = concat_windows(set_windows(cfg.data, sets, teacher.crop_spec(spec), progress))
    if theirs.map is None or not np.array_equal(theirs.agent_ptr, train.agent_ptr):
        raise ValueError("train.distill: the teacher's crops do not line up with the training windows")
    return replace(train, teacher_map=theirs.map)


#: A network's class logits, anchor logits and offsets.
Outputs = tuple[torch.Tensor, torch.Tensor, torch.Tensor]


def _selected(
    keep: torch.Tensor | None, outs: Outputs, classes: torch.Tensor, weights: torch.Tensor | None
) -> tuple[Outputs, torch.Tensor, torch.Tensor | None]:
    """The targets' outputs, classes and weights, of those ``keep`` selects (all if None)."""
    if keep is None:
        return outs, classes, weights
    return (outs[0][keep], outs[1][keep], outs[2][keep]), classes[keep], None if weights is None else weights[keep]


def forward_loss(
    net: torch.nn.Module,
    b: dict[str, torch.Tensor],
    anchors: torch.Tensor,
    class_of: torch.Tensor,
    cfg: Config,
    weight_of_class: torch.Tensor | None = None,
    teacher: Teacher | None = None,
) -> tuple[torch.Tensor, dict[str, float], Outputs]:
    """The network on a batch and the loss over its target agents (on their residuals from the kinematic prior),
    each weighted by its class's ``weight_of_class`` if given (``train.class_balance``); also the targets' outputs.
    With a ``teacher``, the same loss towards its most probable mode is added, weighing ``train.distill_weight``
    (without its classification term if ``train.distill_classifier`` is false),
    and the cross-entropy of the student's mode probabilities against the teacher's (:meth:`Teacher.mode_targets`),
    weighing ``train.distill_soft``."""
    cl, al, off = net(*forward_inputs(b))
    t = b["target"]
    outs = (cl[t], al[t], off[t])
    residual = b["future"][t] - b["prior"][t]
    classes = b["class_index"][t]
    weights = None if weight_of_class is None else weight_of_class[classes]
    tr = cfg.train

    def loss_to(
        target: torch.Tensor, classify: bool = True, keep: torch.Tensor | None = None
    ) -> tuple[torch.Tensor, dict[str, float]]:
        """The loss of the targets ``keep`` selects (all if None) towards ``target`` (theirs)."""
        outs_k, classes_k, weights_k = _selected(keep, outs, classes, weights)
        return dgan_loss(
            *outs_k,
            target,
            classes_k,
            anchors,
            class_of,
            tr.alpha,
            tr.beta,
            weights_k,
            tr.cls_target,
            tr.anchor_pool,
            classify,
        )

    loss, parts = loss_to(residual)
    if teacher is None:
        return loss, parts, outs
    if tr.distill_soft > 0:
        parts["soft"] = 0.0  # a batch of noisy copies alone has no term
    top, soft = teacher.mode_targets(b, anchors, class_of, tr.anchor_pool)
    keep = None
    if not tr.distill_noisy and "noisy" in b:
        # The teacher teaches on the clean histories alone, each of their targets weighing as it would in a batch
        # of clean windows (the mean over them, times their share of the batch's targets).
        keep = ~b["noisy"][t]
        if not keep.any():
            return loss, parts, outs
        top, soft = top[keep], soft[keep]
    distilled, _ = loss_to(top, tr.distill_classifier, keep)
    share = 1.0 if keep is None else float(keep.float().mean())
    loss = loss + tr.distill_weight * share * distilled
    if tr.distill_soft > 0:
        (cl_k, al_k, _), _, w_k = _selected(keep, outs, classes, weights)
        ce = soft_class_loss(cl_k, al_k, class_of, soft)
        parts["soft"] = float(ce.mean().detach())
        loss = loss + tr.distill_soft * share * (ce.mean() if w_k is None else (w_k * ce).sum() / w_k.sum())
    return loss, parts, outs


@torch.no_grad()
def validate(
    model: DGAN, w: Windows, spec: dgan.InputSpec, anchors: torch.Tensor, class_of: torch.Tensor, cfg: Config
) -> dict[str, float]:
    model.eval()
    losses, ade1, fde1, ade20, fde20, n = [], [], [], [], [], 0
    keep = windows_with_targets(w)
    for start in range(0, len(keep), 64):
        b = prepared_batch(w, keep[start : start + 64], spec)
        t = b["target"]
        loss, _, (cl, al, off) = forward_loss(model, b, anchors, class_of, cfg)
        traj, _ = decode_torch(cl, al, off, anchors, class_of, b["prior"][t])
        d = torch.linalg.norm(traj - b["future"][t].unsqueeze(1), dim=-1)  # (n, K, T)
        losses.append(float(loss) * int(t.sum()))
        ade1.append(d[:, 0].mean(-1).sum())
        fde1.append(d[:, 0, -1].sum())
        ade20.append(d[:, :20].mean(-1).min(1).values.sum())
        fde20.append(d[:, :20, -1].min(1).values.sum())
        n += int(t.sum())
    model.train()
    return {
        "val_loss": sum(losses) / n,
        "val_ade": float(sum(ade1)) / n,
        "val_fde": float(sum(fde1)) / n,
        "val_min_ade20": float(sum(ade20)) / n,
        "val_min_fde20": float(sum(fde20)) / n,
    }
