"""Which map from the network's mode probabilities to calibrated ones carries over from validation to the test sets?

    python -m training.studies.calibration [--data-root ../shared/data] [--out docs/calibration_study.json]

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
  three rounds (as many parameters as the validation split allows);
- ``class_temperature``: a second temperature on the class probabilities, p(c) ∝ p(c)^(1/T_c) beside p(k | c)'s T,
  both fitted by the Brier score (the class is an input, so p(c) ≈ 1, yet a multi-class model's best mode is often
  one of another class's anchors);
- ``temperature_by_speed``: T = exp(a + b · log(1 + v)) per agent, v its speed over the last step in the data's
  unit per second, a and b fitted by the Brier score (fast agents' top modes are rarely the best of K, standing
  agents' often).

Printed per model: the worst gap between predicted probability and observed frequency in a bin with p ≥ 0.3 (the
must-show of ``docs/results.md``), on the validation split the map was fitted on and on the test set. Written beside
the study: each model's :func:`diagnostics` on its validation split, what a single temperature cannot fix.
"""

from __future__ import annotations

import argparse
import json
from collections.abc import Callable
from pathlib import Path
from typing import Any

import numpy as np
import torch
from scipy.optimize import minimize
from sklearn.isotonic import IsotonicRegression

import dgan
from training import metrics
from training.calibrate import best_mode_brier, best_mode_log_loss, best_mode_reliability
from training.data.datasets import DATASETS, recordings
from training.data.windows import iter_windows
from training.evaluate import per_class_normalised, prior_speeds, rows_of, untempered, untempered_classes
from training.losses import Calibration
from training.metrics import worst_gap

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
        cal = Calibration.of(predictor.contract)
        use_map = spec.map is not None
        pk, pc, mc, best, speed, own, margin = [], [], [], [], [], [], []
        for rec in recordings(dataset, root, split, fold, with_map=use_map):
            for w in iter_windows(rec, info, spec.t_obs, spec.t_f):
                t = w.target
                pred = rows_of(predictor.predict(w.frame(info, spec.t_obs, with_map=use_map)), t)
                rows = np.arange(len(pred.probabilities))[:, None]
                pcm = np.asarray(untempered_classes(pred, cal)[rows, pred.mode_classes], np.float64)  # p(c), T_c = 1
                v = prior_speeds(w.frame(info, spec.t_obs, with_map=False), spec)[t] if cal.speed_exponent else None
                pk.append(untempered(pred, cal, v) / np.maximum(pcm, 1e-300))
                pc.append(pcm)
                mc.append(pred.mode_classes)
                gt = w.positions[t, spec.t_obs :]
                ade = metrics.displacement(pred.trajectories, gt).mean(axis=2)
                best.append(ade.argmin(axis=1))
                own.append(pred.class_probabilities.argmax(axis=1))
                in_own = pred.mode_classes == own[-1][:, None]
                margin.append(np.where(in_own, ade, np.inf).min(axis=1) - ade.min(axis=1))
                last = w.positions[t, spec.t_obs - 2 : spec.t_obs]
                speed.append(np.linalg.norm(last[:, 1] - last[:, 0], axis=1) / info.dt_s)
        self.pk, self.pc = np.concatenate(pk), np.concatenate(pc)
        self.mc, self.best = np.concatenate(mc), np.concatenate(best)
        self.speed = np.nan_to_num(np.concatenate(speed))
        #: The model's most probable class of each target, and how much closer its best mode (of all K) is than the
        #: best of that class's modes (0 where the best is that class's).
        self.own, self.margin = np.concatenate(own), np.concatenate(margin)
        self.temperature, self.classes = cal.temperature, spec.classes

    def nll(self, p: np.ndarray) -> float:
        """Mean −log probability of the best mode, given the modes' calibrated probabilities ``p``."""
        return best_mode_log_loss(torch.from_numpy(p), torch.from_numpy(self.best))

    def brier(self, p: np.ndarray) -> float:
        """Mean Brier score of the best-mode indicator, given the modes' calibrated probabilities ``p``."""
        return best_mode_brier(torch.from_numpy(p), torch.from_numpy(self.best))

    def reliability(self, p: np.ndarray) -> dict[str, Any]:
        """The reliability bins of the modes' calibrated probabilities ``p``."""
        return best_mode_reliability(torch.from_numpy(p), torch.from_numpy(self.best))


def tempered(pk: np.ndarray, mc: np.ndarray, t: float | np.ndarray) -> np.ndarray:
    """p(k | c) ∝ p^(1/t), renormalised within each class; ``t`` a scalar or one temperature per row ``(N, 1)``."""
    logp = np.log(np.maximum(pk, 1e-300)) / t
    return per_class_normalised(np.exp(logp - logp.max(axis=1, keepdims=True)), mc)


def class_tempered(pc: np.ndarray, mc: np.ndarray, t: float) -> np.ndarray:
    """p(c) of each mode's class, tempered by ``t`` and renormalised over the classes present in each row."""
    rows = np.arange(len(pc))[:, None]
    logp = np.full((len(pc), int(mc.max()) + 1), -np.inf)
    logp[rows, mc] = np.log(np.maximum(pc, 1e-300)) / t
    z = np.exp(logp - logp.max(axis=1, keepdims=True))
    out: np.ndarray = (z / z.sum(axis=1, keepdims=True))[rows, mc]
    return out


def platt(pk: np.ndarray, mc: np.ndarray, a: float, b: float) -> np.ndarray:
    p = np.clip(pk, 1e-12, 1 - 1e-12)
    return per_class_normalised(1.0 / (1.0 + np.exp(-(a * np.log(p / (1 - p)) + b))), mc)


#: A fitted map: the calibrated probability of every mode of the given modes.
Fitted = Callable[[Modes], np.ndarray]


def _params(score: Callable[[np.ndarray], float], model: Callable[..., np.ndarray], x0: list[float]) -> np.ndarray:
    """The parameters ``x`` minimising ``score(model(*x))`` on the validation modes ``model`` is closed over."""
    x: np.ndarray = minimize(lambda x: score(model(*x)), x0, method="Nelder-Mead").x
    return x


def _fitted(score: Callable[[np.ndarray], float], model: Callable[..., np.ndarray], x0: list[float]) -> Fitted:
    """``model(*x, m=modes)`` with :func:`_params`' ``x``."""
    x = _params(score, model, x0)
    return lambda m: model(*x, m=m)


def fit(family: str, val: Modes) -> Fitted:
    """The family's map fitted on ``val`` (by the best mode's likelihood unless the family says otherwise)."""

    def temp(log_t: float, m: Modes = val) -> np.ndarray:
        return tempered(m.pk, m.mc, float(np.exp(log_t))) * m.pc

    if family in ("temperature", "temperature_brier"):
        return _fitted(val.nll if family == "temperature" else val.brier, temp, [0.0])
    if family == "platt":
        return _fitted(val.nll, lambda a, b, m=val: platt(m.pk, m.mc, a, b) * m.pc, [1.0, 0.0])
    if family == "class_temperature":

        def two(log_t: float, log_tc: float, m: Modes = val) -> np.ndarray:
            pc = class_tempered(m.pc, m.mc, float(np.exp(log_tc)))
            return np.asarray(tempered(m.pk, m.mc, float(np.exp(log_t))) * pc)

        return _fitted(val.brier, two, [0.0, 0.0])
    if family == "temperature_by_speed":

        def by_speed(a: float, b: float, m: Modes = val) -> np.ndarray:
            return tempered(m.pk, m.mc, np.exp(a + b * np.log1p(m.speed))[:, None]) * m.pc

        return _fitted(val.brier, by_speed, [0.0, 0.0])
    t = float(np.exp(_params(val.nll, temp, [0.0])[0]))  # the "temperature" family's
    hit = np.zeros(val.pk.shape)
    hit[np.arange(len(val.best)), val.best] = 1.0
    rounds, q = [], tempered(val.pk, val.mc, t)
    for _ in range(3):
        iso = IsotonicRegression(y_min=1e-4, y_max=1.0, out_of_bounds="clip").fit(q.ravel(), hit.ravel())
        rounds.append(iso)
        q = per_class_normalised(iso.predict(q.ravel()).reshape(q.shape), val.mc)

    def apply(m: Modes) -> np.ndarray:
        q = tempered(m.pk, m.mc, t)
        for iso in rounds:
            q = per_class_normalised(iso.predict(q.ravel()).reshape(q.shape), m.mc)
        return q * m.pc

    return apply


FAMILIES = ("temperature", "temperature_brier", "platt", "isotonic", "class_temperature", "temperature_by_speed")


def study(root: Path) -> tuple[dict[str, Any], dict[str, Any]]:
    """Every family's worst gaps per model, and every model's :func:`diagnostics` on its validation split."""
    out: dict[str, Any] = {}
    why: dict[str, Any] = {}
    for name, dataset, fold, tests in MODELS:
        predictor = dgan.Predictor(name)
        val = Modes(predictor, dataset, root, fold, "val")
        why[name] = diagnostics(val)
        held = {t: Modes(predictor, t, root, fold, "test") for t in tests}
        for family in FAMILIES:
            f = fit(family, val)
            row = {"validation": worst_gap(val.reliability(f(val)))}
            row.update({t: worst_gap(m.reliability(f(m))) for t, m in held.items()})
            out.setdefault(name, {})[family] = row
            cells = ", ".join(f"{k} {g:.2f} (p≈{p:.2f})" for k, (g, p) in row.items())
            print(f"{name:12s} {family:12s} worst gap: {cells}", flush=True)
    return out, why


#: Speed bands (m/s at the last observed step) of :func:`diagnostics`.
SPEED_BANDS: tuple[tuple[str, float, float], ...] = (
    ("standing, under 0.2 m/s", 0.0, 0.2),
    ("0.2 to 3 m/s", 0.2, 3.0),
    ("faster than 3 m/s", 3.0, np.inf),
)


def diagnostics(m: Modes) -> dict[str, Any]:
    """Why a temperature cannot calibrate a model: per class, the share of targets whose best mode (of all K) is
    another class's and by how much (median, metres: every reader's positions are) it is closer than their own
    class's best; per speed band, how often the most probable mode at the model's temperature is the best, and its
    mean probability."""
    out: dict[str, Any] = {"classes": {}, "speeds": {}}
    for c, name in enumerate(m.classes):
        sel = m.own == c
        if len(m.classes) > 1 and sel.any():
            other = m.margin[sel] > 0
            closer = float(np.median(m.margin[sel][other])) if other.any() else 0.0
            out["classes"][name] = {"targets": int(sel.sum()), "other_class": float(other.mean()), "closer": closer}
    p = tempered(m.pk, m.mc, m.temperature) * m.pc
    top = p.argmax(axis=1)
    rows = np.arange(len(top))
    for band, lo, hi in SPEED_BANDS:
        sel = (m.speed >= lo) & (m.speed < hi)
        if sel.any():
            wins = float((top[sel] == m.best[sel]).mean())
            out["speeds"][band] = {
                "targets": int(sel.sum()),
                "top_wins": wins,
                "top_p": float(p[rows, top][sel].mean()),
            }
    return out


#: Where :func:`main` writes the study and :func:`section` reads it.
STUDY = Path(__file__).resolve().parents[2] / "docs" / "calibration_study.json"
#: Where :func:`main` writes each model's :func:`diagnostics` on its validation split.
DIAGNOSTICS = STUDY.with_name("calibration_diagnostics.json")


def _written(path: Path) -> Any:
    """What :func:`main` wrote at ``path``, or None before the study has run."""
    return json.loads(path.read_text()) if path.is_file() else None


def _not_run(path: Path) -> str:
    return f"*(not run: `python -m training.studies.calibration` writes `docs/{path.name}`)*"


def _head(*columns: str) -> list[str]:
    """A Markdown table's header and rule lines."""
    return ["| " + " | ".join(columns) + " |", "|" + "---|" * len(columns)]


def section(path: Path = STUDY) -> str:
    """The study as a Markdown table for ``docs/results.md``: per model and family, the worst gap on the validation
    split it was fitted on and on each test set."""
    study = _written(path)
    if study is None:
        return _not_run(path)
    lines = _head("model", "calibration map", "worst gap, validation (fitted there)", "worst gap, test")
    for name, families in study.items():
        for family, row in families.items():
            gap = {k: f"{g:.2f} (p≈{p:.2f})" if p == p else "no bin of 30 modes" for k, (g, p) in row.items()}
            tests = ", ".join(f"{k}: {v}" if len(row) > 2 else v for k, v in gap.items() if k != "validation")
            lines.append(f"| {name} | {family} | {gap['validation']} | {tests} |")
    return "\n".join(lines)


def diagnostics_section(path: Path = DIAGNOSTICS) -> str:
    """:func:`diagnostics` as two Markdown tables: the multi-class models' classes, every model's speed bands (those
    of at least 30 targets)."""
    why = _written(path)
    if why is None:
        return _not_run(path)
    lines = _head(
        "model", "class", "validation targets", "best mode another class's", "closer than the class's best (median)"
    )
    for name, d in why.items():
        for c, r in d["classes"].items():
            lines.append(f"| {name} | {c} | {r['targets']} | {r['other_class']:.0%} | {r['closer']:.2f} m |")
    speeds = (
        "model",
        "speed at the last observed step",
        "validation targets",
        "top mode the best",
        "its mean probability",
    )
    lines += ["", *_head(*speeds)]
    for name, d in why.items():
        for band, r in d["speeds"].items():
            if r["targets"] < 30:  # as the reliability bins: fewer say little
                continue
            lines.append(f"| {name} | {band} | {r['targets']} | {r['top_wins']:.0%} | {r['top_p']:.2f} |")
    return "\n".join(lines)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--data-root", type=Path, default=Path("../shared/data"))
    ap.add_argument("--out", type=Path, default=STUDY)
    a = ap.parse_args()
    out, why = study(a.data_root.expanduser())
    a.out.write_text(json.dumps(out, indent=2))
    a.out.with_name(DIAGNOSTICS.name).write_text(json.dumps(why, indent=2))


if __name__ == "__main__":
    main()
