"""Which map from the network's mode probabilities to calibrated ones carries over from validation to the test sets?

    python -m training.calibration_study [--data-root ../shared/data] [--out docs/calibration_study.json]

Every bundled model's probabilities p(k | c) at temperature 1 are collected on its validation split and on its test
set(s) with the engine. Each family below is fitted on the validation split alone, by the likelihood of the best
mode (the mode of smallest ADE, the event the reliability diagram counts; the Brier score where said), then
applied to the test set:

- ``temperature``: p(k | c) ∝ p^(1/T), what the models carry (contract 2), T fitted by the best mode's likelihood;
- ``temperature_brier``: the same map with T fitted by the Brier score of the best-mode indicator instead (the
  bundled models carry whichever of these two temperatures is closer on the validation split's checked bins,
  ``training.calibrate``);
- ``platt``: p(k | c) ∝ sigmoid(a · logit p + b), two parameters per model;
- ``isotonic``: a monotone step map of the tempered p, fitted by isotonic regression and renormalised per class,
  three rounds (as many parameters as the validation split allows).

Printed per model: the worst gap between predicted probability and observed frequency in a bin with p ≥ 0.3 (the
must-show of ``docs/results.md``), on the validation split the map was fitted on and on the test set.
"""

from __future__ import annotations

import argparse
import json
from collections.abc import Callable
from pathlib import Path
from typing import Any

import numpy as np
from scipy.optimize import minimize
from sklearn.isotonic import IsotonicRegression

import dgan
from training import metrics
from training.data import iter_windows
from training.datasets import DATASETS, recordings
from training.evaluate import calibration, per_class_normalised, rows_of, untempered
from training.scorecard import worst_gap

#: (bundled model, dataset, ETH/UCY fold, test datasets).
MODELS: list[tuple[str, str, str, tuple[str, ...]]] = [
    *[(s, "ethucy", s, ("ethucy",)) for s in ("eth", "hotel", "univ", "zara1", "zara2")],
    ("sdd", "sdd", "", ("sdd",)),
    ("apolloscape", "apolloscape", "", ("apolloscape",)),
    ("hdmap", "hdmap", "", ("hdmap", "argoverse2")),
]


class Modes:
    """Per target agent: p(k | c) at temperature 1 of its modes, p(c) of each mode's class, the classes, and the
    index of the best mode (smallest ADE)."""

    def __init__(self, predictor: dgan.Predictor, dataset: str, root: Path, fold: str, split: str) -> None:
        spec, info = predictor.spec, DATASETS[dataset]
        temperature = float(predictor.contract.get("temperature", 1.0))
        use_map = spec.map is not None
        pk, pc, mc, best = [], [], [], []
        for rec in recordings(dataset, root, split, fold, with_map=use_map):
            for w in iter_windows(rec, info, spec.t_obs, spec.t_f):
                t = w.target
                pred = rows_of(predictor.predict(w.frame(info, spec.t_obs, with_map=use_map)), t)
                rows = np.arange(len(pred.probabilities))[:, None]
                pcm = pred.class_probabilities[rows, pred.mode_classes]
                pk.append(untempered(pred, temperature) / np.maximum(pcm, 1e-300))
                pc.append(pcm)
                mc.append(pred.mode_classes)
                gt = w.positions[t, spec.t_obs :]
                best.append(metrics.displacement(pred.trajectories, gt).mean(axis=2).argmin(axis=1))
        self.pk, self.pc = np.concatenate(pk), np.concatenate(pc)
        self.mc, self.best = np.concatenate(mc), np.concatenate(best)

    def nll(self, q: np.ndarray) -> float:
        """Mean −log probability of the best mode, given calibrated p(k | c) ``q``."""
        return float(-np.log(np.maximum((q * self.pc)[np.arange(len(self.best)), self.best], 1e-12)).mean())

    def brier(self, q: np.ndarray) -> float:
        """Mean Brier score of the best-mode indicator, given calibrated p(k | c) ``q``."""
        hit = np.zeros(q.shape)
        hit[np.arange(len(self.best)), self.best] = 1.0
        return float((((q * self.pc) - hit) ** 2).sum(axis=1).mean())

    def reliability(self, q: np.ndarray) -> dict[str, Any]:
        hit = np.zeros(q.shape, dtype=bool)
        hit[np.arange(len(self.best)), self.best] = True
        return calibration((q * self.pc).ravel(), hit.ravel())


def tempered(pk: np.ndarray, mc: np.ndarray, t: float) -> np.ndarray:
    logp = np.log(np.maximum(pk, 1e-300)) / t
    return per_class_normalised(np.exp(logp - logp.max(axis=1, keepdims=True)), mc)


def platt(pk: np.ndarray, mc: np.ndarray, a: float, b: float) -> np.ndarray:
    p = np.clip(pk, 1e-12, 1 - 1e-12)
    return per_class_normalised(1.0 / (1.0 + np.exp(-(a * np.log(p / (1 - p)) + b))), mc)


Fitted = Callable[[np.ndarray, np.ndarray], np.ndarray]


def fit(family: str, val: Modes) -> Fitted:
    """The family's map fitted on ``val`` by the best mode's likelihood."""
    if family == "temperature":
        t = float(np.exp(minimize(lambda x: val.nll(tempered(val.pk, val.mc, np.exp(x[0]))), [0.0]).x[0]))
        return lambda pk, mc: tempered(pk, mc, t)
    if family == "temperature_brier":
        t = float(np.exp(minimize(lambda x: val.brier(tempered(val.pk, val.mc, np.exp(x[0]))), [0.0]).x[0]))
        return lambda pk, mc: tempered(pk, mc, t)
    if family == "platt":
        a, b = minimize(lambda x: val.nll(platt(val.pk, val.mc, x[0], x[1])), [1.0, 0.0], method="Nelder-Mead").x
        return lambda pk, mc: platt(pk, mc, a, b)
    base = fit("temperature", val)
    hit = np.zeros(val.pk.shape)
    hit[np.arange(len(val.best)), val.best] = 1.0
    rounds, q = [], base(val.pk, val.mc)
    for _ in range(3):
        iso = IsotonicRegression(y_min=1e-4, y_max=1.0, out_of_bounds="clip").fit(q.ravel(), hit.ravel())
        rounds.append(iso)
        q = per_class_normalised(iso.predict(q.ravel()).reshape(q.shape), val.mc)

    def apply(pk: np.ndarray, mc: np.ndarray) -> np.ndarray:
        q = base(pk, mc)
        for iso in rounds:
            q = per_class_normalised(iso.predict(q.ravel()).reshape(q.shape), mc)
        return q

    return apply


FAMILIES = ("temperature", "temperature_brier", "platt", "isotonic")


def study(root: Path) -> dict[str, Any]:
    out: dict[str, Any] = {}
    for name, dataset, fold, tests in MODELS:
        predictor = dgan.Predictor(name)
        val = Modes(predictor, dataset, root, fold, "val")
        held = {t: Modes(predictor, t, root, fold, "test") for t in tests}
        for family in FAMILIES:
            f = fit(family, val)
            row = {"validation": worst_gap(val.reliability(f(val.pk, val.mc)))}
            row.update({t: worst_gap(m.reliability(f(m.pk, m.mc))) for t, m in held.items()})
            out.setdefault(name, {})[family] = row
            cells = ", ".join(f"{k} {g:.2f} (p≈{p:.2f})" for k, (g, p) in row.items())
            print(f"{name:12s} {family:12s} worst gap: {cells}", flush=True)
    return out


#: Where :func:`main` writes the study and :func:`section` reads it.
STUDY = Path(__file__).resolve().parents[1] / "docs" / "calibration_study.json"


def section(path: Path = STUDY) -> str:
    """The study as a Markdown table for ``docs/results.md``: per model and family, the worst gap on the validation
    split it was fitted on and on each test set."""
    if not path.is_file():
        return "*(not run: `python -m training.calibration_study` writes `docs/calibration_study.json`)*"
    study = json.loads(path.read_text())
    lines = [
        "| model | calibration map | worst gap, validation (fitted there) | worst gap, test |",
        "|---|---|---|---|",
    ]
    for name, families in study.items():
        for family, row in families.items():
            gap = {k: f"{g:.2f} (p≈{p:.2f})" if p == p else "no bin of 30 modes" for k, (g, p) in row.items()}
            tests = ", ".join(f"{k}: {v}" if len(row) > 2 else v for k, v in gap.items() if k != "validation")
            lines.append(f"| {name} | {family} | {gap['validation']} | {tests} |")
    return "\n".join(lines)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--data-root", type=Path, default=Path("../shared/data"))
    ap.add_argument("--out", type=Path, default=STUDY)
    a = ap.parse_args()
    a.out.write_text(json.dumps(study(a.data_root.expanduser()), indent=2))


if __name__ == "__main__":
    main()
