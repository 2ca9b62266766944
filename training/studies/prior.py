"""Would a constant-turn-rate (and acceleration) rollout be a better kinematic prior than constant velocity?

    python -m training.studies.prior [--data-root ../shared/data]

Measured as physics alone, before any network, on the validation split of the driving models (``hdmap``: the
nuScenes + Waymo validation scenes; ``apolloscape``: the validation recordings), per class: the engine's
constant-velocity prior (``dgan.kinematic_prior``, the model's own settings) against rollouts that keep the speed
and the direction of that prior at t_obs and turn at the engine's estimated yaw rate (``ctrv``), at half of it
(``ctrv_half``), and that also keep the estimated acceleration (``ctra``). Errors in metres, ADE/FDE over the
targets' futures in their agent frames.

    python -m training.studies.prior --residual-scale [--data-root ../shared/data]

How much of the network's refinement helps, per class: the bundled model's most probable mode with its residual over
the engine's prior scaled by s, ``prior + s (top mode - prior)``, on its validation windows (the ones its temperature
and top-mode scale are fitted on: ``training.ensemble.top_mode_errors``, which measures the network's own refinement
whatever scale the model was bundled with); s = 1 is the network, s = 0 the prior alone.

    python -m training.studies.prior --velocity [--data-root ../shared/data] [--json docs/prior_study.json]

Which velocity estimate should the prior take, on real and on tracker-like histories? Every fully observed agent of
the validation split of ``hdmap``, ``apolloscape`` and ``sdd`` (standing ones too), clean and with Gaussian noise of
0.1 m and 0.3 m on the observed positions and 10% of the observed steps before the current one dropped
(:func:`training.data.augment.tracker_noise`), each frame preprocessed by the engine and rolled out by
``dgan.kinematic_prior``: the last two steps, the endpoints, the least-squares line and the least-squares parabola
over windows of 0.4-2 s, each with and without a standing threshold. Errors in metres (ADE/FDE), overall, per
class and for moving and standing agents (moved less than 1 m from the first observed to the last true position).
"""

from __future__ import annotations

import argparse
import json
from dataclasses import replace
from pathlib import Path

import numpy as np
import numpy.typing as npt

import dgan
from training.config import DataConfig
from training.data.augment import tracker_noise
from training.data.datasets import DATASETS, recordings
from training.data.recording import WindowSet
from training.data.splits import window_set
from training.data.windows import iter_windows
from training.ensemble import TOP_SCALES, top_mode_errors

Arr = npt.NDArray[np.float64]

#: The bundled models' checkpoints.
CHECKPOINTS = Path(__file__).resolve().parents[1] / "checkpoints"
#: (bundled model, dataset).
MODELS = (("hdmap", "hdmap"), ("apolloscape", "apolloscape"))


def turning_rollout(velocity: Arr, yaw_rate: Arr, acceleration: Arr, dt_s: float, t_f: int, substeps: int = 10) -> Arr:
    """``(N, t_f, 2)`` positions from the origin of agents starting at ``velocity (N, 2)`` that turn at
    ``yaw_rate (N,)`` rad/s and speed up at ``acceleration (N,)`` m/s² (the speed never below 0), integrated in
    ``substeps`` per step."""
    speed = np.linalg.norm(velocity, axis=1)
    theta = np.arctan2(velocity[:, 1], velocity[:, 0])
    pos = np.zeros((len(speed), 2))
    out = np.zeros((len(speed), t_f, 2))
    h = dt_s / substeps
    for k in range(t_f):
        for _ in range(substeps):
            pos = pos + np.c_[np.cos(theta), np.sin(theta)] * (speed * h)[:, None]
            theta = theta + yaw_rate * h
            speed = np.maximum(speed + acceleration * h, 0.0)
        out[:, k] = pos
    return out


def study(root: Path) -> dict[str, dict[str, dict[str, tuple[float, float]]]]:
    """Per model and class (and ``all``): each rollout's ADE and FDE on the validation targets."""
    out: dict[str, dict[str, dict[str, tuple[float, float]]]] = {}
    for model, dataset in MODELS:
        spec = dgan.Predictor(model).spec
        cache = Path(DataConfig().cache_dir).expanduser()
        w = window_set(WindowSet(dataset, "val"), root, spec, cache)
        t = w.target
        traj, mask, state, future = w.trajectory[t], w.trajectory_mask[t], w.state[t], w.future[t]
        cv = np.asarray(dgan.kinematic_prior(traj, mask, state, spec), dtype=np.float64)
        v0 = cv[:, 0] / spec.dt_s  # the prior's velocity at t_obs
        yaw, acc, none = state[:, 2].astype(np.float64), state[:, 1].astype(np.float64), np.zeros(len(cv))
        rollouts = {
            "constant velocity": cv,
            "ctrv": turning_rollout(v0, yaw, none, spec.dt_s, spec.t_f),
            "ctrv_half": turning_rollout(v0, 0.5 * yaw, none, spec.dt_s, spec.t_f),
            "ctra": turning_rollout(v0, yaw, acc, spec.dt_s, spec.t_f),
        }
        groups = {c: w.class_index[t] == i for i, c in enumerate(spec.classes)} | {"all": np.ones(len(cv), bool)}
        for name, sel in groups.items():
            if not sel.any():
                continue
            for kind, r in rollouts.items():
                d = np.linalg.norm(r[sel] - future[sel], axis=2)
                out.setdefault(model, {}).setdefault(name, {})[kind] = (float(d.mean()), float(d[:, -1].mean()))
    return out


def residual_scale_study(root: Path) -> dict[str, dict[str, tuple[int, list[float]]]]:
    """Per driving model and class: its validation targets and its top mode's ADE at each of ``TOP_SCALES``."""
    out: dict[str, dict[str, tuple[int, list[float]]]] = {}
    for model, _ in MODELS:
        errors, klass, classes = top_mode_errors(CHECKPOINTS / f"{model}.pt", root)
        out[model] = {
            c: (int((klass == i).sum()), errors[klass == i].mean(axis=0).tolist())
            for i, c in enumerate(classes)
            if (klass == i).any()
        }
    return out


#: The histories of the velocity study: (name, noise sigma in metres, share of observed steps dropped).
CONDITIONS = (("clean", 0.0, 0.0), ("noise 0.1 m", 0.1, 0.1), ("noise 0.3 m", 0.3, 0.1))
#: Datasets of the velocity study (their validation splits).
VELOCITY_DATASETS = ("hdmap", "apolloscape", "sdd")


def velocity_candidates() -> dict[str, dgan.PriorSpec]:
    """The velocity estimates compared: the last two steps, then endpoints, a least-squares line, a least-squares
    parabola and the adaptive line over 0.4-2 s, each also with a standing threshold of 0.3 m/s."""
    out = {"last two steps": dgan.PriorSpec("constant_velocity")}
    for window in (0.4, 0.8, 1.2, 2.0):
        for fit in ("endpoints", "least_squares", "quadratic", "adaptive"):
            for standing in (0.0, 0.3):
                name = f"{fit} {window:g} s" + (f", standing < {standing:g} m/s" if standing else "")
                out[name] = dgan.PriorSpec("constant_velocity", window, fit, standing)
    return out


def velocity_study(
    root: Path, seed: int = 0, datasets: tuple[str, ...] = VELOCITY_DATASETS, only: tuple[str, ...] = ()
) -> dict[str, dict[str, dict[str, dict[str, list[float]]]]]:
    """Per dataset, condition, candidate and group (``all``, ``moving``, ``standing`` and each class): the number of
    targets and the prior's ADE and FDE (metres) on the validation split. ``only`` keeps the candidates named."""
    from tqdm import tqdm

    cands = velocity_candidates()
    if unknown := set(only) - set(cands):
        raise ValueError(f"unknown velocity candidates {sorted(unknown)}; known: {', '.join(cands)}")
    cands = {k: v for k, v in cands.items() if not only or k in only}
    out: dict[str, dict[str, dict[str, dict[str, list[float]]]]] = {}
    for dataset in datasets:
        info = DATASETS[dataset]
        spec = dgan.InputSpec(info.dt_s, info.t_obs, info.t_f, classes=info.classes)
        specs = {name: replace(spec, prior=prior) for name, prior in cands.items()}
        windows = [
            w
            for r in recordings(dataset, root, "val", with_map=False)
            for w in iter_windows(r, info, info.t_obs, info.t_f)
        ]
        for cond, sigma, drop in CONDITIONS:
            rng = np.random.default_rng(seed)
            err: dict[str, list[Arr]] = {c: [] for c in cands}
            groups: dict[str, list[Arr]] = {}
            for w in tqdm(windows, desc=f"{dataset} {cond}", leave=False):
                obs, keep = tracker_noise(w.positions[:, : info.t_obs], w.mask[:, : info.t_obs], sigma, drop, rng)
                frame = dgan.Frame(obs, mask=keep, classes=[info.label_class[k] for k in w.label], ids=w.ids)
                x = dgan.preprocess(frame, spec)
                t = w.target
                truth = dgan.to_agent_frame(w.positions[t, info.t_obs :], x["origin"][t], x["heading"][t])
                moved = w.moving()
                klass = np.array([info.label_class[k] for k in w.label[t]])
                groups.setdefault("moving", []).append(moved)
                groups.setdefault("class", []).append(klass)
                for name, pspec in specs.items():
                    r = dgan.kinematic_prior(x["trajectory"][t], x["trajectory_mask"][t], x["state"][t], pspec)
                    err[name].append(np.linalg.norm(np.asarray(r, np.float64) - truth, axis=2))
            moving: npt.NDArray[np.bool_] = np.concatenate(groups["moving"]).astype(bool)
            klass = np.concatenate(groups["class"])
            sel = {"all": np.ones(len(moving), bool), "moving": moving, "standing": ~moving}
            sel |= {c: klass == c for c in info.classes}
            for name in cands:
                d = np.concatenate(err[name])
                out.setdefault(dataset, {}).setdefault(cond, {})[name] = {
                    g: [int(m.sum()), float(d[m].mean()), float(d[m, -1].mean())] for g, m in sel.items() if m.any()
                }
    return out


def chosen_velocity(study: dict[str, dict[str, dict[str, dict[str, list[float]]]]], dataset: str) -> str:
    """The rule (set before the study was run): the candidate with the lowest ADE over all targets, averaged over
    the three conditions (clean, noise 0.1 m, noise 0.3 m), on the dataset's validation split."""
    by_cond = study[dataset]
    names = next(iter(by_cond.values())).keys()
    return min(names, key=lambda n: float(np.mean([by_cond[c][n]["all"][1] for c in by_cond])))


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--data-root", type=Path, default=Path("../shared/data"))
    ap.add_argument("--residual-scale", action="store_true", help="measure the residual scale study instead")
    ap.add_argument("--velocity", action="store_true", help="measure the velocity-estimate study instead")
    ap.add_argument("--json", type=Path, help="with --velocity: also write the study here")
    ap.add_argument("--datasets", nargs="+", default=list(VELOCITY_DATASETS), help="with --velocity: the datasets")
    ap.add_argument("--only", nargs="+", default=[], metavar="CANDIDATE", help="with --velocity: these candidates")
    a = ap.parse_args()
    if a.velocity:
        res = velocity_study(a.data_root.expanduser(), datasets=tuple(a.datasets), only=tuple(a.only))
        if a.json:
            a.json.write_text(json.dumps(res, indent=1) + "\n")
        for dataset, by_cond in res.items():
            print(f"{dataset}: chosen {chosen_velocity(res, dataset)!r}")
            for cond, by_cand in by_cond.items():
                for name, groups in by_cand.items():
                    cells = "  ".join(f"{g} {ade:.3f}/{fde:.3f}" for g, (_, ade, fde) in groups.items())
                    print(f"  {cond:12s} {name:42s} {cells}")
        return
    if a.residual_scale:
        for model, by_class in residual_scale_study(a.data_root.expanduser()).items():
            for name, (n, ade) in by_class.items():
                cells = "  ".join(f"s={s:g} {x:.3f}" for s, x in zip(TOP_SCALES, ade, strict=True))
                print(f"{model:12s} {name:10s} n={n:5d}  {cells}")
        return
    for model, classes in study(a.data_root.expanduser()).items():
        for name, rows in classes.items():
            cells = "  ".join(f"{k} {ade:.2f}/{fde:.2f}" for k, (ade, fde) in rows.items())
            print(f"{model:12s} {name:10s} {cells}")


if __name__ == "__main__":
    main()
