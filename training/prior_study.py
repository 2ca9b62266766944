"""Would a constant-turn-rate (and acceleration) rollout be a better kinematic prior than constant velocity?

    python -m training.prior_study [--data-root ../shared/data]

Measured as physics alone, before any network, on the validation split of the driving models (``hdmap``: the
nuScenes + Waymo validation scenes; ``apolloscape``: the validation recordings), per class: the engine's
constant-velocity prior (``dgan.kinematic_prior``, the model's own settings) against rollouts that keep the speed
and the direction of that prior at t_obs and turn at the engine's estimated yaw rate (``ctrv``), at half of it
(``ctrv_half``), and that also keep the estimated acceleration (``ctra``). Errors in metres, ADE/FDE over the
targets' futures in their agent frames.

    python -m training.prior_study --residual-scale [--data-root ../shared/data]

How much of the network's refinement helps, per class: the bundled model's most probable mode with its residual over
the engine's prior scaled by s, ``prior + s (top mode - prior)``, on its validation windows (the ones its temperature
and top-mode scale are fitted on: ``training.ensemble.top_mode_errors``, which measures the network's own refinement
whatever scale the model was bundled with); s = 1 is the network, s = 0 the prior alone.
"""

from __future__ import annotations

import argparse
from pathlib import Path

import numpy as np
import numpy.typing as npt

import dgan
from training.config import DataConfig
from training.data import cached_windows
from training.ensemble import TOP_SCALES, top_mode_errors

Arr = npt.NDArray[np.float64]

#: The bundled models' checkpoints.
CHECKPOINTS = Path(__file__).resolve().parent / "checkpoints"
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
        w = cached_windows(dataset, root, "val", spec, cache, progress=False)
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


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--data-root", type=Path, default=Path("../shared/data"))
    ap.add_argument("--residual-scale", action="store_true", help="measure the residual scale study instead")
    a = ap.parse_args()
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
