"""Evaluate an exported model with the engine (``dgan.Predictor``) on a held-out ETH/UCY scene, beside the
constant-velocity baseline on the very same windows and agents.

    python -m training.evaluate MODEL.onnx --scene zara1 [--data-root ../shared/data]

Windows are built exactly as for training (``training.data.iter_windows``); the targets are the agents present at
all 20 steps; errors are in world metres.
"""

from __future__ import annotations

import argparse
import json
from pathlib import Path
from typing import Any

import numpy as np

import dgan
from dgan.scenes import scene_raster_map
from training import metrics
from training.data import iter_windows, read_file, scene_of, split_files


def evaluate(predictor: dgan.Predictor, data_root: Path, scene: str) -> dict[str, Any]:
    """Per-agent metrics of the model and of constant velocity, averaged, with window and agent counts."""
    spec = predictor.spec
    maps_root = data_root / "eth_ucy_scene_maps" / "semantic_masks"
    per: dict[str, list[np.ndarray]] = {}
    windows = 0
    maps: dict[str, dgan.RasterMap] = {}
    for path in split_files(data_root, scene, "test"):
        smap = None
        if spec.map is not None:
            s = scene_of(path)
            if s not in maps:
                maps[s] = scene_raster_map(s, maps_root / s)
            smap = maps[s]
        for _now, ids, pos, mask, target in iter_windows(read_file(path), spec.t_obs, spec.t_f):
            windows += 1
            frame = dgan.Frame(pos[:, : spec.t_obs], mask=mask[:, : spec.t_obs], ids=ids.astype(np.int64), map=smap)
            pred = predictor.predict(frame, modes=min(20, predictor.num_modes))
            gt = pos[target, spec.t_obs :]
            traj, prob = pred.trajectories[target], pred.probabilities[target]
            cv = metrics.constant_velocity(pos[target, : spec.t_obs], mask[target, : spec.t_obs], spec.t_f)
            pairs = {
                ("ade", "fde"): metrics.ade_fde_top1(traj, gt),
                ("min_ade5", "min_fde5"): metrics.min_ade_fde(traj, gt, 5),
                ("min_ade20", "min_fde20"): metrics.min_ade_fde(traj, gt, 20),
                ("cv_ade", "cv_fde"): metrics.ade_fde_top1(cv, gt),
            }
            add = {name: value for names, values in pairs.items() for name, value in zip(names, values, strict=True)}
            add["brier_min_fde20"] = metrics.brier_min_fde(traj, gt, prob, 20)
            for k, v in add.items():
                per.setdefault(k, []).append(v)
    out: dict[str, Any] = {k: float(np.concatenate(v).mean()) for k, v in per.items()}
    out["windows"] = windows
    out["agents"] = int(sum(len(v) for v in per["ade"]))
    out["scene"] = scene
    return out


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("model")
    ap.add_argument("--scene", required=True)
    ap.add_argument("--data-root", default="../shared/data")
    ap.add_argument("--json", type=Path, help="also write the metrics here")
    a = ap.parse_args()
    res = evaluate(dgan.Predictor(a.model), Path(a.data_root).expanduser(), a.scene)
    if a.json:
        a.json.write_text(json.dumps(res, indent=2))
    print(json.dumps(res, indent=2))


if __name__ == "__main__":
    main()
