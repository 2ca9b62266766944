"""Evaluate an exported model with the engine (``dgan.Predictor``) on a dataset's test split, beside the
constant-velocity baseline on the very same windows and agents.

    python -m training.evaluate MODEL.onnx --dataset ethucy --scene zara1 [--data-root ../shared/data]
    python -m training.evaluate MODEL.onnx --dataset sdd
    python -m training.evaluate MODEL.onnx --dataset sdd --split val --origin 500 300   # under another origin

Windows are built exactly as for training (``training.data.windows.iter_windows``); the targets are the agents of a
scored label present at all T_obs + T_f steps, standing ones too. Errors are in the dataset's unit (metres; pixels for
Stanford Drone), overall, per class and per label, and for moving and standing targets (moved less than 1 m from the
first observed to the last true position) overall and per class. Also: the accuracy of the most probable class,
and the calibration of the mode probabilities (how often a mode given probability p is the best of all K modes).
"""

from __future__ import annotations

import argparse
import json
from collections.abc import Iterator
from dataclasses import dataclass, replace
from pathlib import Path
from typing import Any

import numpy as np
import torch

import dgan
from training import metrics
from training.data.datasets import DATASETS, recordings
from training.data.recording import moved
from training.data.windows import iter_windows, noisy_window
from training.losses import Calibration

#: Edges of the probability bins of the reliability diagram.
CALIBRATION_BINS = np.array([0.0, 0.02, 0.05, 0.1, 0.2, 0.3, 0.4, 0.5, 0.6, 0.7, 0.8, 0.9, 1.0])


@dataclass
class Scored:
    """One window's targets as every accuracy table scores them: the frame the model is given, the target rows, and
    the targets' truth ``(n, T_f, 2)``, constant-velocity variants ``{name: (n, 1, T_f, 2)}`` (both in the dataset's
    unit), labels and whether each target moves (:data:`STANDING_M`)."""

    frame: dgan.Frame
    target: np.ndarray
    unit: float
    truth: np.ndarray
    cvs: dict[str, np.ndarray]
    label: np.ndarray
    moving: np.ndarray


def scored_windows(
    spec: dgan.InputSpec,
    dataset: str,
    root: Path,
    split: str,
    fold: str = "",
    with_map: bool = True,
    noise: tuple[float, float] = (0.0, 0.0),
    origin: tuple[float, float] = (0.0, 0.0),
) -> Iterator[Scored]:
    """Every window of a split, built as for training (``iter_windows``), with its targets' truth and constant
    velocity; ``with_map=False`` (or a spec without a map) gives frames without their map. ``noise = (sigma_m,
    drop)`` corrupts the observed histories as a tracker would (:func:`training.data.augment.tracker_noise`, seeded per
    split): the model and constant velocity both see the noisy history, the truth stays as recorded. ``origin``: every
    recording and its map moved by that many metres (:func:`training.data.recording.moved`), as if their coordinates
    had another origin."""
    info = DATASETS[dataset]
    use_map = with_map and spec.map is not None
    rng = np.random.default_rng(0)
    for rec in recordings(dataset, root, split, fold, with_map=use_map):
        if origin != (0.0, 0.0):
            rec = moved(rec, origin)
        for w in iter_windows(rec, info, spec.t_obs, spec.t_f):
            moving = w.moving()
            if noise != (0.0, 0.0):
                w = noisy_window(w, spec.t_obs, noise, rng)
            t = w.target
            unit = rec.unit_m
            obs, obs_mask = w.positions[t, : spec.t_obs], w.mask[t, : spec.t_obs]
            cvs = {
                k: v / unit for k, v in metrics.constant_velocity_variants(obs, obs_mask, spec.t_f, spec.dt_s).items()
            }
            truth = w.positions[t, spec.t_obs :] / unit
            yield Scored(w.frame(info, spec.t_obs, with_map=use_map), t, unit, truth, cvs, w.label[t], moving)


def agent_metrics(pred: dgan.Prediction, gt: np.ndarray, cvs: dict[str, np.ndarray]) -> dict[str, np.ndarray]:
    """Per-agent metrics of one window's targets, in the units of ``gt``; ``cvs`` holds the constant-velocity
    variants (``metrics.constant_velocity_variants``)."""
    traj, prob = pred.trajectories, pred.probabilities
    top20 = traj[:, :20]
    pairs = {
        ("ade", "fde"): metrics.ade_fde_top1(traj, gt),
        ("min_ade5", "min_fde5"): metrics.min_ade_fde(traj, gt, 5),
        ("min_ade20", "min_fde20"): metrics.min_ade_fde(top20, gt, 20),
        **{(f"cv_{k}_ade", f"cv_{k}_fde"): metrics.ade_fde_top1(cv, gt) for k, cv in cvs.items()},
    }
    out = {name: value for names, values in pairs.items() for name, value in zip(names, values, strict=True)}
    out["brier_min_fde5"] = metrics.brier_min_fde(traj[:, :5], gt, prob[:, :5], 5)
    out["brier_min_fde20"] = metrics.brier_min_fde(top20, gt, prob[:, :20], 20)
    return out


def calibration(prob: np.ndarray, hit: np.ndarray) -> dict[str, Any]:
    """Reliability of mode probabilities: per bin, the mean probability and how often such a mode was the best."""
    idx = np.clip(np.digitize(prob, CALIBRATION_BINS[1:-1]), 0, len(CALIBRATION_BINS) - 2)
    count = np.bincount(idx, minlength=len(CALIBRATION_BINS) - 1)
    mean_p = np.bincount(idx, prob, minlength=len(count)) / np.maximum(count, 1)
    freq = np.bincount(idx, hit.astype(float), minlength=len(count)) / np.maximum(count, 1)
    ece = float(np.sum(count * np.abs(mean_p - freq)) / max(1, count.sum()))
    return {
        "edges": CALIBRATION_BINS.tolist(),
        "count": count.tolist(),
        "mean_probability": mean_p.tolist(),
        "frequency": freq.tolist(),
        "ece": ece,
    }


def summarise(per: dict[str, np.ndarray], sel: np.ndarray) -> dict[str, Any]:
    """Means over the selected agents. ``cv_ade``/``cv_fde`` are constant velocity's, the better of its two variants
    on these agents for each of the two errors (``cv_variant`` names the better variant by ADE)."""
    out: dict[str, Any] = {k: float(v[sel].mean()) if sel.any() else float("nan") for k, v in per.items()}
    out["agents"] = int(sel.sum())
    variants = sorted({k.split("_")[1] for k in per if k.startswith("cv_")})
    if variants:
        out["cv_ade"] = min(out[f"cv_{v}_ade"] for v in variants)
        out["cv_fde"] = min(out[f"cv_{v}_fde"] for v in variants)
        out["cv_variant"] = min(variants, key=lambda v: out[f"cv_{v}_ade"])
    return out


def evaluate(
    predictor: dgan.Predictor,
    dataset: str,
    data_root: Path,
    fold: str = "",
    with_map: bool = True,
    split: str = "test",
    noise: tuple[float, float] = (0.0, 0.0),
    origin: tuple[float, float] = (0.0, 0.0),
) -> dict[str, Any]:
    """Per-agent metrics of the model and of constant velocity on a split (``"test"``; ``"val"`` for model
    selection), averaged overall (flat keys), per class (``by_class``) and per label (``by_label``), with window and
    agent counts. ``with_map=False`` runs a map model on frames without their map (a model whose map is not optional
    then raises ``MapRequiredError``); ``noise`` and ``origin`` as :func:`scored_windows`."""
    info, spec = DATASETS[dataset], predictor.spec
    if (spec.t_obs, spec.t_f) != (info.t_obs, info.t_f) or abs(spec.dt_s - info.dt_s) > 1e-9:
        raise ValueError(
            f"the model's time base (dt {spec.dt_s} s, {spec.t_obs} + {spec.t_f} steps) is not {dataset}'s "
            f"(dt {info.dt_s} s, {info.t_obs} + {info.t_f} steps)"
        )
    per: dict[str, list[np.ndarray]] = {}
    labels, classes, pred_class, mode_p, mode_p_raw, mode_hit, moving = [], [], [], [], [], [], []
    cal = Calibration.of(predictor.contract)
    windows = 0
    model_classes = list(predictor.classes)
    use_map = with_map and spec.map is not None
    for sw in scored_windows(spec, dataset, data_root, split, fold, with_map, noise, origin):
        windows += 1
        pred = predictor.predict(sw.frame)
        sub = rows_of(pred, sw.target, sw.unit)
        for k, v in agent_metrics(sub, sw.truth, sw.cvs).items():
            per.setdefault(k, []).append(v)
        labels.append(sw.label)
        moving.append(sw.moving)
        classes.append(np.array([model_classes.index(info.label_class[k]) for k in sw.label]))
        pred_class.append(sub.class_probabilities.argmax(axis=1))
        ade_all = metrics.displacement(sub.trajectories, sw.truth).mean(axis=2)  # (n, K)
        mode_p.append(sub.probabilities.ravel())
        speed = prior_speeds(sw.frame, spec)[sw.target] if cal.speed_exponent != 0.0 else None
        mode_p_raw.append(untempered(sub, cal, speed).ravel())
        mode_hit.append((ade_all == ade_all.min(axis=1, keepdims=True)).ravel())
    flat = {k: np.concatenate(v) for k, v in per.items()}
    label = np.concatenate(labels)
    klass = np.concatenate(classes)
    everyone = np.ones(len(label), dtype=bool)
    out: dict[str, Any] = summarise(flat, everyone)
    out["windows"] = windows
    out["num_modes"] = predictor.num_modes
    out["with_map"] = use_map
    out["dataset"] = dataset
    out["unit"] = info.unit
    if fold:
        out["scene"] = fold
    moves = np.concatenate(moving) if moving else np.zeros(0, bool)
    out.update(splits(flat, moves, klass, model_classes))
    out["by_label"] = {n: summarise(flat, label == i) for i, n in enumerate(info.labels) if (label == i).any()}
    out["class_accuracy"] = float((np.concatenate(pred_class) == klass).mean())
    hits = np.concatenate(mode_hit)
    out["calibration"] = calibration(np.concatenate(mode_p), hits)
    out["temperature"] = cal.temperature
    if cal != Calibration(cal.temperature):  # contract 9's terms
        out.update(temperature_speed_exponent=cal.speed_exponent, class_temperature=cal.class_temperature)
    out["calibration_t1"] = calibration(np.concatenate(mode_p_raw), hits)
    return out


def splits(flat: dict[str, np.ndarray], moves: np.ndarray, klass: np.ndarray, classes: list[str]) -> dict[str, Any]:
    """The summaries of the moving and standing agents (``by_motion``) and of each class with its own moving and
    standing split (``by_class``)."""
    motion = (("moving", moves), ("standing", ~moves))
    by_class = {}
    for i, c in enumerate(classes):
        if (klass == i).any():
            by_class[c] = summarise(flat, klass == i)
            by_class[c].update({m: summarise(flat, (klass == i) & sel) for m, sel in motion})
    return {"by_motion": {m: summarise(flat, sel) for m, sel in motion}, "by_class": by_class}


def rows_of(pred: dgan.Prediction, rows: np.ndarray, unit: float = 1.0) -> dgan.Prediction:
    """The prediction of some agents only (``rows``: a mask or indices of the frame's rows), trajectories divided by
    ``unit`` (metres per unit of the dataset)."""
    return replace(
        pred,
        agent_ids=pred.agent_ids[rows],
        trajectories=pred.trajectories[rows] / unit,
        probabilities=pred.probabilities[rows],
        class_probabilities=pred.class_probabilities[rows],
        mode_classes=pred.mode_classes[rows],
    )


def prior_speeds(frame: dgan.Frame, spec: dgan.InputSpec) -> np.ndarray:
    """``(N,)`` the speed (m/s) of each agent's kinematic prior, what a speed-dependent temperature reads (the
    engine's preprocessing without the map, which the prior does not use)."""
    prior = dgan.preprocess(frame, replace(spec, map=None), threads=1)["prior"]
    out: np.ndarray = np.linalg.norm(prior[:, 0].astype(np.float64), axis=1) / spec.dt_s
    return out


def untempered(pred: dgan.Prediction, cal: Calibration | float, speed: np.ndarray | None = None) -> np.ndarray:
    """``(N, M)`` the mode probabilities the model would give at temperature 1, from those it gave under ``cal``
    (all K modes needed; ``speed (N,)`` the agents' prior speeds when ``cal`` depends on speed): p(k | c) at T is
    softmax(l / T), so p(k | c) at 1 is proportional to p(k | c)^T; likewise p(c) and the class temperature."""
    cal = cal if isinstance(cal, Calibration) else Calibration(float(cal))
    prob = pred.probabilities
    if cal == Calibration() or prob.size == 0:
        return prob
    t: float | np.ndarray = cal.temperature
    if cal.speed_exponent != 0.0:
        if speed is None:
            raise ValueError("a speed-dependent temperature needs the agents' prior speeds")
        t = cal.at_speed(torch.from_numpy(np.asarray(speed, dtype=np.float64))).numpy()
    rows = np.arange(len(prob))[:, None]
    pc = pred.class_probabilities[rows, pred.mode_classes]
    pk = (prob / np.maximum(pc, 1e-300)) ** t
    out: np.ndarray = untempered_classes(pred, cal)[rows, pred.mode_classes] * per_class_normalised(
        pk, pred.mode_classes
    )
    return out


def untempered_classes(pred: dgan.Prediction, cal: Calibration) -> np.ndarray:
    """``(N, C)`` the class probabilities at class temperature 1, from those under ``cal``: softmax(l / T_c) at 1 is
    proportional to its value at T_c raised to T_c."""
    if cal.class_temperature == 1.0:
        return pred.class_probabilities
    log_p = cal.class_temperature * np.log(np.maximum(pred.class_probabilities, 1e-300))
    p = np.exp(log_p - log_p.max(axis=1, keepdims=True))
    out: np.ndarray = p / p.sum(axis=1, keepdims=True)
    return out


def per_class_normalised(w: np.ndarray, mode_classes: np.ndarray) -> np.ndarray:
    """Non-negative weights ``w (N, M)`` normalised to sum to 1 over each agent's modes of each class."""
    out = np.zeros_like(w)
    for c in np.unique(mode_classes):
        sel = mode_classes == c
        norm = np.where(sel, w, 0.0).sum(axis=1, keepdims=True)
        out = np.where(sel, w / np.maximum(norm, 1e-300), out)
    return out


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("model")
    ap.add_argument("--dataset", default="ethucy", choices=sorted(DATASETS))
    ap.add_argument("--scene", default="", help="the held-out ETH/UCY scene (ethucy only)")
    ap.add_argument("--data-root", default="../shared/data")
    ap.add_argument("--json", type=Path, help="also write the metrics here")
    ap.add_argument("--split", default="test", choices=["val", "test"], help="val: for choosing models and settings")
    ap.add_argument(
        "--origin",
        nargs=2,
        type=float,
        default=(0.0, 0.0),
        metavar=("X", "Y"),
        help="move every recording and its map by X, Y metres (the same data under another origin)",
    )
    a = ap.parse_args()
    if a.dataset == "ethucy" and not a.scene:
        ap.error("--scene is required for ethucy")
    root, origin = Path(a.data_root).expanduser(), (a.origin[0], a.origin[1])
    res = evaluate(dgan.Predictor(a.model), a.dataset, root, a.scene, split=a.split, origin=origin)
    if a.json:
        a.json.write_text(json.dumps(res, indent=2))
    print(json.dumps({k: v for k, v in res.items() if k != "calibration"}, indent=2))


if __name__ == "__main__":
    main()
