"""Several runs of one configuration (seeds) as one exported model: :class:`training.modules.dgan.ConsensusEnsemble`.

    python -m training.ensemble RUN [RUN ...] --out model.onnx [--checkpoint ensemble.pt] [--name NAME]

Each RUN is a ``training.train`` output folder (its ``best.pt``). The model keeps the contract of a single run: the
engine runs it unchanged, with every member inside one ONNX graph (so a call costs about the members' count times one
network). Its most probable mode (of the agent's most probable class) is the mean of the members' most probable
modes; the other modes are the first member's. The temperature is fitted anew on the validation split
(``training.calibrate``; ``--no-calibrate`` keeps the first member's), since the consensus mode is the best mode more
often than any one member's top mode.

Before the temperature, a scale per class of the consensus mode's residual over the kinematic prior is fitted on the
validation split (:func:`fit_top_scale`; ``--no-top-scale`` keeps 1): where the network's refinement makes a class's
most probable mode worse than its prior there, the mode moves towards the prior.
"""

from __future__ import annotations

import argparse
import tempfile
from collections.abc import Iterator
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
import numpy.typing as npt
import torch

from dgan.contract import STATE_FEATURES
from training.calibrate import calibrate_checkpoint
from training.export import SLIM_KEYS, Checkpoint, export_checkpoint, load_checkpoint
from training.losses import Calibration
from training.modules.consensus import ConsensusEnsemble

#: The residual scales tried for a class's most probable mode (:func:`fit_top_scale`); 1 is the network as trained.
TOP_SCALES = (0.0, 0.25, 0.5, 0.75, 1.0)
#: A scale other than 1 is kept only if it lowers the class's validation top-1 ADE by at least this share.
MIN_GAIN = 0.01


def ensemble_checkpoint(runs: list[Path], out: Path, half: bool = False) -> Path:
    """Writes the checkpoint of the runs' ensemble (their ``best.pt``, slimmed) to ``out``. With ``half`` the weights
    are rounded to float16 and kept so (the exported file then stores them as float16 too: half the size of both,
    the same arithmetic in the engine and in PyTorch)."""
    members: list[dict[str, Any]] = []
    for run in runs:
        ckpt = torch.load(run / "best.pt", weights_only=False)
        member = {k: ckpt[k] for k in SLIM_KEYS if k in ckpt}
        if half:
            member["model"] = {k: v.half() if v.is_floating_point() else v for k, v in member["model"].items()}
        members.append(member)
    out.parent.mkdir(parents=True, exist_ok=True)
    first = Calibration.of(members[0]).keys(complete=True)  # the first member's until refitted
    torch.save({"members": members, "runs": [r.name for r in runs], **first}, out)
    load_checkpoint(out)  # the members must share inputs and classes
    return out


def choose_scale(ade: npt.ArrayLike, scales: tuple[float, ...] = TOP_SCALES, min_gain: float = MIN_GAIN) -> float:
    """The scale of ``scales`` with the lowest top-1 ADE ``ade`` (one per scale), kept only if it is at least
    ``min_gain`` below the ADE at scale 1; else 1."""
    a = np.asarray(ade, dtype=np.float64)
    if a.shape != (len(scales),) or not np.isfinite(a).all():
        raise ValueError(f"need one finite ADE per scale {scales}; got {a.tolist()}")
    base = float(a[scales.index(1.0)])
    i = int(np.argmin(a))
    return float(scales[i]) if a[i] <= (1.0 - min_gain) * base else 1.0


def scaled_errors(
    top: npt.ArrayLike, prior: npt.ArrayLike, truth: npt.ArrayLike, scales: tuple[float, ...] = TOP_SCALES
) -> np.ndarray:
    """``(N, len(scales))`` ADE of ``prior + s (top - prior)`` for each scale s; ``top``, ``prior`` and ``truth`` are
    ``(N, t_f, 2)``."""
    t, p, y = (np.asarray(a, dtype=np.float64) for a in (top, prior, truth))
    s = np.asarray(scales, dtype=np.float64)[None, :, None, None]
    pred = p[:, None] + s * (t - p)[:, None]
    return np.asarray(np.linalg.norm(pred - y[:, None], axis=3).mean(axis=2), dtype=np.float64)


@torch.no_grad()
def validation_top_modes(
    ckpt: Checkpoint, data_root: Path | None = None, progress: bool = False
) -> Iterator[tuple[dict[str, torch.Tensor], torch.Tensor]]:
    """Over the validation windows of the loaded checkpoint ``ckpt`` (its configuration's, as the temperature's fit
    uses), batch by batch: the batch, and its targets' most probable mode's residual over the prior ``(n, T, 2)``
    (the model's own top mode at its calibration); the targets are the batch's ``target`` rows."""
    from dataclasses import replace

    from training.data.batches import forward_inputs, prepared_batch, windows_with_targets
    from training.data.splits import split_windows
    from training.losses import mode_probabilities

    model, spec, anchors_np, class_of_np, cfg, cal = ckpt
    if data_root is not None:
        cfg = replace(cfg, data=replace(cfg.data, root=str(data_root)))
    w = split_windows(cfg, spec, "val", progress)
    anchors, class_of = torch.from_numpy(anchors_np).float(), torch.from_numpy(class_of_np).long()
    keep = windows_with_targets(w)
    for start in range(0, len(keep), 64):
        b = prepared_batch(w, keep[start : start + 64], spec)
        cl, al, off = model(*forward_inputs(b))
        t = b["target"]
        temperature = cal.anchor_temperatures(b["prior"][t], spec.dt_s)
        top = mode_probabilities(cl[t], al[t], class_of, temperature, cal.class_temperature).argmax(dim=1)
        yield b, (anchors.unsqueeze(0) + off[t].float())[torch.arange(len(top)), top]


def top_mode_errors(
    path: Path, data_root: Path | None = None, progress: bool = False
) -> tuple[np.ndarray, np.ndarray, tuple[str, ...]]:
    """For every validation target of the checkpoint at ``path`` (an ensemble's, or a single network's whose scale
    the contract carries; :func:`validation_top_modes`; scale 1 whatever the checkpoint holds): the ADE of its most
    probable mode at each of :data:`TOP_SCALES` ``(N, S)`` (:func:`scaled_errors`), its class index ``(N,)``, and the
    model's classes."""
    ckpt = load_checkpoint(path)
    if isinstance(ckpt.model, ConsensusEnsemble):  # a single network's scale is not in its forward
        ckpt.model.top_scale.fill_(1.0)
    errors, classes = [], []
    for b, residual in validation_top_modes(ckpt, data_root, progress):
        t = b["target"]
        prior = b["prior"][t].double()
        errors.append(scaled_errors((prior + residual).numpy(), prior.numpy(), b["future"][t].numpy()))
        classes.append(b["state"][t, len(STATE_FEATURES) :].argmax(dim=1))
    return np.concatenate(errors), torch.cat(classes).numpy(), tuple(ckpt.spec.classes)


@dataclass(frozen=True)
class TopScaleFit:
    """Per class: its name, validation targets, top-1 ADE at each of :data:`TOP_SCALES` and the scale kept."""

    classes: tuple[str, ...]
    targets: tuple[int, ...]
    ade: tuple[tuple[float, ...], ...]
    scale: tuple[float, ...]

    def __str__(self) -> str:
        rows = [
            f"{c} ({n} targets): top-1 ADE {' '.join(f'{x:.4f}' for x in a)} at scales {TOP_SCALES} -> {s:g}"
            for c, n, a, s in zip(self.classes, self.targets, self.ade, self.scale, strict=True)
        ]
        return "top-mode scale on validation: " + "; ".join(rows)


def fit_top_scale(path: Path, data_root: Path | None = None, progress: bool = False) -> TopScaleFit:
    """Fits the top-mode residual scale of each class of the checkpoint at ``path`` (an ensemble's or a single
    network's) on its validation split (:func:`top_mode_errors`, :func:`choose_scale`; a class without validation
    targets keeps 1) and stores it there as ``top_scale``."""
    from training.checkpoint import update_checkpoint

    errors, klass, names = top_mode_errors(path, data_root, progress)
    seen = [bool((klass == i).any()) for i in range(len(names))]
    ade = [errors[klass == i].mean(axis=0) if seen[i] else np.ones(len(TOP_SCALES)) for i in range(len(names))]
    scale = [choose_scale(a) if seen[i] else 1.0 for i, a in enumerate(ade)]
    update_checkpoint(path, top_scale=scale)
    return TopScaleFit(
        tuple(names),
        tuple(int((klass == i).sum()) for i in range(len(names))),
        tuple(tuple(float(x) for x in a) for a in ade),
        tuple(scale),
    )


def main(argv: list[str] | None = None) -> Path:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("runs", nargs="+", type=Path)
    ap.add_argument("--out", type=Path, required=True, help="the ONNX model to write")
    ap.add_argument("--checkpoint", type=Path, help="also keep the ensemble's checkpoint here (for parity tests)")
    ap.add_argument("--name", default="dgan-ensemble")
    ap.add_argument("--description", default="")
    ap.add_argument("--data-root", type=Path, help="the data folder for the validation split (the runs' own if unset)")
    ap.add_argument("--no-calibrate", action="store_true", help="keep the first member's temperature")
    ap.add_argument("--no-top-scale", action="store_true", help="keep every class's top mode as the consensus")
    ap.add_argument("--half", action="store_true", help="round the weights to float16 and store them so")
    a = ap.parse_args(argv)
    missing = [str(r) for r in a.runs if not (r / "best.pt").is_file()]
    if missing:
        ap.error(f"not training runs (no best.pt): {', '.join(missing)}")
    with tempfile.TemporaryDirectory() as tmp:
        ckpt = ensemble_checkpoint(a.runs, a.checkpoint or Path(tmp) / "ensemble.pt", a.half)
        if not a.no_top_scale:
            print(fit_top_scale(ckpt, a.data_root, progress=True))
        if not a.no_calibrate:
            print(calibrate_checkpoint(ckpt, a.data_root, progress=True))
        description = a.description or f"Consensus of {len(a.runs)} runs: {', '.join(r.name for r in a.runs)}"
        path = export_checkpoint(ckpt, a.out, a.name, description)
    print(f"exported {path}")
    return path


if __name__ == "__main__":
    main()
