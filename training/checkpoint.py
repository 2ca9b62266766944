"""Checkpoints written so that a run stopped at any moment keeps its last one whole, and the weights a run starts
from (``train.init``)."""

from __future__ import annotations

import os
from pathlib import Path
from typing import Any

import torch


def save_atomic(state: dict[str, Any], path: Path) -> None:
    """``torch.save`` to a temporary file beside ``path``, then renamed over it: a run stopped while it saves (a
    time limit, a killed job) keeps its previous checkpoint whole, so ``--resume`` still loads. Every rewrite of an
    existing checkpoint goes through it (each epoch's, the temperature's and top-mode scales after training or at
    bundling: :func:`update_checkpoint`)."""
    tmp = path.with_name(path.name + ".tmp")
    torch.save(state, tmp)
    os.replace(tmp, path)


def update_checkpoint(path: Path, **values: Any) -> None:
    """Sets ``values`` (a fitted temperature, top-mode scales) in the checkpoint at ``path``, saved with
    :func:`save_atomic`."""
    ckpt = torch.load(path, weights_only=False)
    ckpt.update(values)
    save_atomic(ckpt, path)


#: A crop model's map CNN layers (``MapEncoder.net``) as a scene model's (``SceneMapEncoder``): the stem and both
#: residual stages run over the scene, the last strided convolution per agent (training.modules.scene).
CROP_TO_SCENE = {**{f"map_enc.net.{i}.": f"map_enc.scene.{i}." for i in range(8)}, "map_enc.net.8.": "map_enc.agent.0."}


def init_weights(model: torch.nn.Module, path: Path | str) -> tuple[list[str], list[str]]:
    """Loads into ``model`` the parameters and buffers of the checkpoint at ``path`` (a run's ``{"model": ...}``, or
    a consensus's ``{"members": [...]}``, whose first member is taken) that match one of its own by name (a crop
    model's map CNN renamed as a scene model's, :data:`CROP_TO_SCENE`) and shape; the names loaded and the model's
    names left as initialised. Raises a ValueError when nothing matches (another architecture) or a consensus has no
    members."""
    ckpt = torch.load(path, weights_only=False)
    if "members" in ckpt and not ckpt["members"]:
        raise ValueError(f"train.init: {path} is a consensus without members")
    source = ckpt["members"][0]["model"] if "members" in ckpt else ckpt["model"]
    own = model.state_dict()
    found: dict[str, torch.Tensor] = {}
    for name, value in source.items():
        for old, new in CROP_TO_SCENE.items():
            if name.startswith(old) and name not in own:
                name = new + name[len(old) :]
                break
        if name in own and own[name].shape == value.shape:
            found[name] = value
    if not found:
        raise ValueError(f"train.init: no parameter of {path} matches the model's names and shapes")
    model.load_state_dict(found, strict=False)
    return sorted(found), sorted(set(own) - set(found))
