"""The top-mean power of a model's classes (contract 16), fitted on its validation split by the engine.

    python -m training.top_mean CHECKPOINT [--data-root DIR]

An agent of a class with a power β has as its most probable mode the mean of all its modes weighted by p^β (p the
calibrated mode probabilities, the engine's decoding): with β = 1 the error-minimising single guess of the predicted
mixture, with a larger β nearer the most probable mode. Every figure is the engine's, on the validation split of the
checkpoint's dataset (its held-out scene's folds for ETH/UCY), every target included (runs/RULES-2026-12-06p and q):

1. The checkpoint is exported once per power of :data:`POWERS` (every class at it) and once without. A class's
   candidates are the powers that lower its top-1 ADE by at least :data:`MIN_GAIN` without raising its FDE, if it has
   at least :data:`MIN_TARGETS` targets.
2. Class by class, largest gain first, each candidate from the lowest ADE on is tried with the classes accepted so
   far; the first with which the model keeps minADE20 and minFDE20 within :data:`MAX_MIN20_RISE` of the model without
   a power and its worst checked reliability bin within max(:data:`CALIBRATION_BOUND`, its own) is accepted. A class
   with none keeps its most probable mode as decoded (0).

The result is stored in the checkpoint as ``top_mean_power`` (one value per class); exporting it (``training.export``,
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
#: The most a model's minADE20 or minFDE20 may rise with its powers, as a share.
MAX_MIN20_RISE = 0.01
#: The worst checked reliability bin a model's powers may leave (or its own without them, if wider).
CALIBRATION_BOUND = 0.10

#: Per class: top-1 ADE, FDE and the number of targets.
ClassErrors = dict[str, tuple[float, float, int]]


@dataclass(frozen=True)
class Errors:
    """A model's validation errors: top-1 ADE/FDE and targets per class, minADE20/FDE20 and the worst checked
    reliability bin."""

    by_class: ClassErrors
    min20: tuple[float, float]
    worst_bin: float

    def keeps(self, plain: Errors) -> bool:
        """Whether these errors keep the model-level bounds against the model without a power (``plain``)."""
        rise = 1.0 + MAX_MIN20_RISE
        within = all(a <= b * rise for a, b in zip(self.min20, plain.min20, strict=True))
        return within and self.worst_bin <= max(CALIBRATION_BOUND, plain.worst_bin)


@dataclass(frozen=True)
class TopMeanFit:
    """The model without a power (``plain``), with every class at each of :data:`POWERS` (``powered``), each trial
    of step 2 (class, power, whether the model kept its bounds) and the power kept per class (0: none)."""

    classes: list[str]
    plain: Errors
    powered: dict[float, Errors]
    trials: list[tuple[str, float, bool]]
    power: list[float]

    def __str__(self) -> str:
        lines = []
        for c, b in zip(self.classes, self.power, strict=True):
            ade, fde, n = self.plain.by_class.get(c, (float("nan"), float("nan"), 0))
            tried = ", ".join(f"{p:g}: {e.by_class[c][0]:.4f}/{e.by_class[c][1]:.4f}" for p, e in self.powered.items())
            model = ", ".join(f"{p:g} {'kept' if ok else 'refused'}" for k, p, ok in self.trials if k == c)
            lines.append(
                f"{c} ({n} targets): none {ade:.4f}/{fde:.4f}; {tried}; model: {model or 'none tried'} -> {b:g}"
            )
        return "\n".join(lines)


def model_errors(model: Path, dataset: str, fold: str, root: Path) -> Errors:
    """The engine's :class:`Errors` on the validation split of ``dataset`` (every target)."""
    from training.evaluate import evaluate
    from training.metrics import worst_gap

    r = evaluate(dgan.Predictor(model), dataset, root, fold, split="val")
    by_class = {c: (v["ade"], v["fde"], v["agents"]) for c, v in r["by_class"].items()}
    return Errors(by_class, (r["min_ade20"], r["min_fde20"]), worst_gap(r["calibration"])[0])


def class_powers(plain: ClassErrors, powered: dict[float, ClassErrors], klass: str) -> list[float]:
    """Step 1 for one class: its candidate powers, lowest top-1 ADE first."""
    if klass not in plain or plain[klass][2] < MIN_TARGETS:
        return []
    ade, fde, _ = plain[klass]
    good = [p for p, e in powered.items() if e[klass][0] <= ade * (1.0 - MIN_GAIN) and e[klass][1] <= fde]
    return sorted(good, key=lambda p: powered[p][klass][0])


def choose_power(plain: ClassErrors, powered: dict[float, ClassErrors], klass: str) -> float:
    """The candidate of lowest top-1 ADE of one class (step 1 alone), if it is the class's best power; else 0."""
    best = min(powered, key=lambda p: powered[p][klass][0]) if klass in plain else 0.0
    return best if best in class_powers(plain, powered, klass) else 0.0


def fit_top_mean(path: Path, data_root: Path | None = None, progress: bool = False) -> TopMeanFit:
    """Fits the checkpoint at ``path``'s top-mean power per class (this module's docstring) and stores it there as
    ``top_mean_power``."""
    ckpt = load_checkpoint(path)
    cfg, classes = ckpt.config, list(ckpt.spec.classes)
    dataset, root = cfg.data.dataset, data_root or Path(cfg.data.root)
    fold = cfg.data.scene if dataset == "ethucy" else cfg.data.val_recordings if dataset == "apolloscape" else ""
    powered: dict[float, Errors] = {}
    with tempfile.TemporaryDirectory() as tmp:

        def errors_with(powers: list[float]) -> Errors:
            onnx = export_checkpoint(path, Path(tmp) / "trial.onnx", "fit", top_mean=powers)
            return model_errors(onnx, dataset, fold, root)

        for power in (0.0, *POWERS):
            powered[power] = errors_with([power] * len(classes))
            if progress:
                print(
                    f"power {power:g}: "
                    + ", ".join(f"{c} {e[0]:.4f}/{e[1]:.4f}" for c, e in powered[power].by_class.items())
                )
        plain = powered.pop(0.0)
        by_class = {p: e.by_class for p, e in powered.items()}
        candidates = {c: class_powers(plain.by_class, by_class, c) for c in classes}
        gain = {c: plain.by_class[c][0] - by_class[ps[0]][c][0] for c, ps in candidates.items() if ps}
        kept, trials = dict.fromkeys(classes, 0.0), []
        for c in sorted(gain, key=lambda k: -gain[k] / plain.by_class[k][0]):
            for p in candidates[c]:
                ok = errors_with([p if k == c else kept[k] for k in classes]).keeps(plain)
                trials.append((c, p, ok))
                if ok:
                    kept[c] = p
                    break
    chosen = [kept[c] for c in classes]
    update_checkpoint(path, top_mean_power=chosen)
    return TopMeanFit(classes, plain, powered, trials, chosen)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("checkpoint", type=Path)
    ap.add_argument("--data-root", type=Path, default=None)
    a = ap.parse_args()
    print(fit_top_mean(a.checkpoint, a.data_root, progress=True))


if __name__ == "__main__":
    main()
