"""The top-mean power of a model's classes (contract 16), fitted on its validation split by the engine.

    python -m training.top_mean CHECKPOINT [--data-root DIR]

An agent of a class with a power β has as its most probable mode the mean of all its modes weighted by p^β (p the
calibrated mode probabilities, the engine's decoding): with β = 1 the error-minimising single guess of the predicted
mixture, with a larger β nearer the most probable mode. The checkpoint is exported once per power of :data:`POWERS`
(and once without) and each export predicts the validation split of its configuration's dataset (its held-out
scene's folds for ETH/UCY) with the engine, every target included. For each class the power of lowest top-1 ADE is
kept if the class has at least :data:`MIN_TARGETS` validation targets, its top-1 ADE falls by at least
:data:`MIN_GAIN` and its top-1 FDE does not rise; otherwise the class keeps its most probable mode as decoded (0). The
result is stored in the checkpoint as ``top_mean_power`` (one value per class); exporting it (``training.export``,
``training.release.bundle --reexport``) writes the contract's ``top_mean_power``.
"""

from __future__ import annotations

import argparse
import tempfile
from dataclasses import dataclass
from pathlib import Path

import dgan
from training.checkpoint import update_checkpoint
from training.export import export_checkpoint, load_checkpoint

#: The powers tried.
POWERS = (1.0, 2.0, 4.0, 8.0)
#: The fewest validation targets of a class for a power to be kept.
MIN_TARGETS = 50
#: A power is kept only if it lowers its class's top-1 ADE by at least this share.
MIN_GAIN = 0.005

#: Per class: top-1 ADE, FDE and the number of targets.
ClassErrors = dict[str, tuple[float, float, int]]


@dataclass(frozen=True)
class TopMeanFit:
    """Each class's validation top-1 ADE/FDE without a power (``plain``) and with each of :data:`POWERS`
    (``powered``), and the power kept per class (0: none)."""

    classes: list[str]
    plain: ClassErrors
    powered: dict[float, ClassErrors]
    power: list[float]

    def __str__(self) -> str:
        lines = []
        for c, b in zip(self.classes, self.power, strict=True):
            ade, fde, n = self.plain.get(c, (float("nan"), float("nan"), 0))
            tried = ", ".join(f"{p:g}: {e[c][0]:.4f}/{e[c][1]:.4f}" for p, e in self.powered.items() if c in e)
            lines.append(f"{c} ({n} targets): none {ade:.4f}/{fde:.4f}; {tried} -> {b:g}")
        return "\n".join(lines)


def class_errors(model: Path, dataset: str, fold: str, root: Path) -> ClassErrors:
    """The engine's top-1 ADE/FDE per class on the validation split of ``dataset`` (every target)."""
    from training.evaluate import evaluate

    r = evaluate(dgan.Predictor(model), dataset, root, fold, split="val")
    return {c: (v["ade"], v["fde"], v["agents"]) for c, v in r["by_class"].items()}


def choose_power(plain: ClassErrors, powered: dict[float, ClassErrors], klass: str) -> float:
    """The rule of this module's docstring for one class: its kept power, or 0."""
    if klass not in plain or plain[klass][2] < MIN_TARGETS:
        return 0.0
    ade, fde, _ = plain[klass]
    best = min(powered, key=lambda p: powered[p][klass][0])
    b_ade, b_fde, _ = powered[best][klass]
    return best if b_ade <= ade * (1.0 - MIN_GAIN) and b_fde <= fde else 0.0


def fit_top_mean(path: Path, data_root: Path | None = None, progress: bool = False) -> TopMeanFit:
    """Fits the checkpoint at ``path``'s top-mean power per class (this module's docstring) and stores it there as
    ``top_mean_power``."""
    ckpt = load_checkpoint(path)
    cfg, classes = ckpt.config, list(ckpt.spec.classes)
    dataset, root = cfg.data.dataset, data_root or Path(cfg.data.root)
    fold = cfg.data.scene if dataset == "ethucy" else cfg.data.val_recordings if dataset == "apolloscape" else ""
    powered: dict[float, ClassErrors] = {}
    with tempfile.TemporaryDirectory() as tmp:
        for power in (0.0, *POWERS):
            onnx = export_checkpoint(path, Path(tmp) / f"power_{power:g}.onnx", "fit", top_mean=[power] * len(classes))
            powered[power] = class_errors(onnx, dataset, fold, root)
            if progress:
                print(f"power {power:g}: " + ", ".join(f"{c} {e[0]:.4f}/{e[1]:.4f}" for c, e in powered[power].items()))
    plain = powered.pop(0.0)
    kept = [choose_power(plain, powered, c) for c in classes]
    update_checkpoint(path, top_mean_power=kept)
    return TopMeanFit(classes, plain, powered, kept)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("checkpoint", type=Path)
    ap.add_argument("--data-root", type=Path, default=None)
    a = ap.parse_args()
    print(fit_top_mean(a.checkpoint, a.data_root, progress=True))


if __name__ == "__main__":
    main()
