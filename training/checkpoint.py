"""Checkpoints written so that a run stopped at any moment keeps its last one whole."""

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
