"""The HD-map section of ``docs/results.md``: DGAN with the vector-map branch (the bundled ``hdmap`` model), the same
network without it (``training/checkpoints/baselines/hdmap-nomap.pt``) and constant velocity, per class, on the held-out
driving scenes of nuScenes mini and Waymo (``training.data.driving.HDMAP_TEST``) and on the three Argoverse 2 scenes
that neither model saw; and the picture of each source's map beside the engine's rasterisation of it.

    python -m training.results                  # writes every section, this one included
    python -m training.results --train-hdmap    # first trains both models and bundles hdmap (about 40 minutes)
"""

from __future__ import annotations

import gzip
import json
import pickle
import tempfile
import warnings
from pathlib import Path
from typing import Any

import numpy as np

import dgan
from dgan.datasets.hdmaps import bird_eye, read_scenario
from dgan.exceptions import DatasetWarning
from training.data.datasets import DATASETS
from training.evaluate import evaluate
from training.reports.multiclass import relative

ROOT = Path(__file__).resolve().parents[2]
NOMAP = ROOT / "training" / "checkpoints" / "baselines" / "hdmap-nomap.pt"
#: One scene of each source for the map pictures: (title, path under the data root, 10 Hz step).
PICTURES = (
    (
        "nuScenes mini, scene-1094 (Singapore Holland Village)",
        "nuscenes_mini_scenarionet/sd_nuscenes_v1.0-mini_scene-1094.pkl",
        100,
    ),
    (
        "Waymo Open Motion 8a346109094cd5aa",
        "waymo_motion_samples/scenarionet_pkl/sd_training.tfrecord-00000-of-01000_8a346109094cd5aa.pkl",
        10,
    ),
    ("Argoverse 2 sensor log adcf7d18 (Pittsburgh)", "argoverse2/sensor_logs/adcf7d18-0510-35b0-a2fa-b4cea13a6d76", 50),
)
#: Side and resolution of the map pictures.
PICTURE_EXTENT_M = 120.0
PICTURE_RESOLUTION_M = 0.2
METRICS = (("ade", "fde"), ("min_ade5", "min_fde5"))


# ---- map pictures ----------------------------------------------------------------------------------------------------


def _source_lines(path: Path) -> list[tuple[str, np.ndarray]]:
    """The source's own map geometry with its own type names, read straight from the file (not through
    :mod:`dgan.datasets.hdmaps`), so that the picture checks the conversion as well as the rasteriser."""
    out: list[tuple[str, np.ndarray]] = []
    if path.suffix == ".pkl":
        with path.open("rb") as fh:
            d = pickle.load(fh)  # the shared data's ScenarioNet files
        for key, f in d["map_features"].items():
            kind = "ROAD_EDGE (boundary_*)" if key.startswith("boundary_") else str(f["type"])
            pts = f.get("polygon") if kind == "CROSSWALK" else f.get("polyline")
            if pts is not None and len(pts) > 1:
                out.append((kind, np.asarray(pts, dtype=float)[:, :2]))
        return out
    if path.name.endswith(".json.gz"):
        with gzip.open(path, "rt") as text:
            d = json.load(text)
        for r in d["roads"]:
            pts = np.array([[p["x"], p["y"]] for p in r["geometry"]])
            out.append((f"{r['type']} {r.get('map_element_id', '')}".strip(), pts))
        return out
    (map_file,) = sorted(path.glob("**/log_map_archive_*.json"))
    d = json.loads(map_file.read_text())

    def xy(pts: list[dict[str, float]]) -> np.ndarray:
        return np.array([[p["x"], p["y"]] for p in pts])

    for a in d["drivable_areas"].values():
        ring = xy(a["area_boundary"])
        out.append(("drivable area", np.vstack([ring, ring[:1]])))
    for c in d["pedestrian_crossings"].values():
        out.append(("pedestrian crossing", np.vstack([xy(c["edge1"]), xy(c["edge2"])[::-1], xy(c["edge1"])[:1]])))
    for ls in d["lane_segments"].values():
        for side in ("left", "right"):
            mark = ls[f"{side}_lane_mark_type"]
            out.append(
                (
                    f"lane boundary {mark}" if mark == "NONE" else f"lane mark {mark.split('_')[0]}",
                    xy(ls[f"{side}_lane_boundary"]),
                )
            )
    return out


def sources_figure(root: Path, out: Path) -> Path:
    """Each source's map as the file has it (left, coloured by the source's own types) beside the engine's raster of
    it (right), the same square of the world."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, axes = plt.subplots(len(PICTURES), 2, figsize=(13, 6.2 * len(PICTURES)), dpi=80)
    for (title, rel, step), (left, right) in zip(PICTURES, axes, strict=True):
        path = root / rel
        with warnings.catch_warnings():
            warnings.simplefilter("ignore", DatasetWarning)
            sc = read_scenario(path)
        centre = np.nanmean(sc.positions[sc.valid[:, step], step], axis=0)
        half = PICTURE_EXTENT_M / 2
        lo, hi = centre - half, centre + half
        lines = _source_lines(path)
        kinds = sorted({k for k, _ in lines})
        cmap = plt.get_cmap("tab10")
        for j, kind in enumerate(kinds):
            first = True
            for k, pts in lines:
                if k != kind:
                    continue
                left.plot(pts[:, 0], pts[:, 1], "-", color=cmap(j % 10), lw=1, label=kind if first else None)
                first = False
        left.set_xlim(lo[0], hi[0])
        left.set_ylim(lo[1], hi[1])
        left.set_aspect("equal")
        left.set_title(f"{title}: the source map", fontsize=10)
        left.legend(fontsize=6, loc="upper left", ncol=2, framealpha=0.8)
        left.set_xlabel("x (m)")
        left.set_ylabel("y (m)")
        img = bird_eye(sc, step, centre, PICTURE_EXTENT_M, PICTURE_RESOLUTION_M)
        right.imshow(img, extent=(lo[0], hi[0], lo[1], hi[1]), interpolation="nearest")
        right.set_title("rasterised by the engine (agents as blue boxes)", fontsize=10)
        right.set_xlabel("x (m)")
    fig.tight_layout()
    out.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(out)
    plt.close(fig)
    return out


# ---- evaluation ------------------------------------------------------------------------------------------------------


def evaluate_hdmap(root: Path) -> dict[str, Any]:
    """The bundled ``hdmap`` model and the no-map variant on the held-out nuScenes/Waymo scenes and on Argoverse 2."""
    from training.export import export_checkpoint

    out: dict[str, Any] = {}
    with tempfile.TemporaryDirectory() as tmp:
        with_map = dgan.Predictor("hdmap")
        nomap = dgan.Predictor(export_checkpoint(NOMAP, Path(tmp) / "nomap.onnx", "dgan-hdmap-nomap"))
        optional = with_map.spec.map is not None and with_map.spec.map.optional
        for dataset in ("hdmap", "argoverse2"):
            out[dataset] = {"map": evaluate(with_map, dataset, root), "nomap": evaluate(nomap, dataset, root)}
            if optional:  # the same model, the same frames, no map
                out[dataset]["map_absent"] = evaluate(with_map, dataset, root, with_map=False)
    return out


def _cells(r: dict[str, Any]) -> str:
    return " | ".join(f"{r[a]:.2f}/{r[b]:.2f}" for a, b in METRICS) + f" | {r['brier_min_fde5']:.2f}"


def table(res: dict[str, Any]) -> str:
    """Per class: with the map, without it, constant velocity (same windows and agents)."""
    lines = [
        "| agents | n | model | top-1 ADE/FDE | minADE5/FDE5 | Brier-minFDE5 |",
        "|---|---|---|---|---|---|",
    ]
    absent = res.get("map_absent")
    groups = [
        (c, res["map"]["by_class"].get(c), res["nomap"]["by_class"].get(c), (absent or {}).get("by_class", {}).get(c))
        for c in dgan.CLASSES
    ]
    groups.append(("**all**", res["map"], res["nomap"], absent))
    for name, m, n, a in groups:
        if m is None or n is None:
            continue
        lines.append(f"| {name} | {m['agents']} | DGAN with the map | {_cells(m)} |")
        if a is not None:
            lines.append(f"| | {a['agents']} | the same model given no map | {_cells(a)} |")
        lines.append(f"| | {n['agents']} | DGAN trained without the map branch | {_cells(n)} |")
        cv = f"constant velocity ({m['cv_variant']})"
        lines.append(f"| | {m['agents']} | {cv} | {m['cv_ade']:.2f}/{m['cv_fde']:.2f} | | |")
    return "\n".join(lines)


def verdict(res: dict[str, Any]) -> str:
    """Per class, how much the map changes top-1 ADE, minADE5 and Brier-minFDE5 (relative)."""
    parts = []
    for cls in dgan.CLASSES:
        m, n = res["map"]["by_class"].get(cls), res["nomap"]["by_class"].get(cls)
        if m is None or n is None:
            continue
        keys = (("top-1 ADE", "ade"), ("minADE5", "min_ade5"), ("Brier-minFDE5", "brier_min_fde5"))
        parts.append(f"{cls}s ({m['agents']} agents): {relative(m, n, keys, 'worse better')}")
    return "With the map against the network trained without the map branch: " + "; ".join(parts) + "."


def section(results: dict[str, Any]) -> str:
    info = DATASETS["hdmap"]
    held = results["hdmap"]
    av2 = results["argoverse2"]
    text = [
        "## Driving scenes with a vector HD map (nuScenes mini, Waymo Open Motion, Argoverse 2)",
        "",
        f"{info.t_obs} observed and {info.t_f} predicted steps of {info.dt_s:g} s (2 s and 3 s, the paper's driving "
        "setting at 5 Hz). Errors in metres. One model for vehicles, cyclists and pedestrians, trained on the other "
        "scenes of nuScenes mini and Waymo with map dropout; *the same model given no map* runs it on the same frames "
        "without their map; *trained without the map branch* is the same network and training without the map "
        "branch (the paper's '20' against '20S' rows). Targets are the agents seen at all 25 steps, standing ones "
        "too (moving and standing apart in the tables above); every agent seen at t_obs is in the graph. "
        "Brier-minFDE5: minFDE5 plus (1 − p)² of that mode. How the sources are sampled to 5 Hz (and nuScenes' "
        "2 Hz keyframes) is in `training/data/datasets.py`.",
        "",
        f"### Held-out scenes of nuScenes mini and Waymo: {held['map']['windows']} windows, "
        f"{held['map']['agents']} target agents",
        "",
        table(held),
        "",
        verdict(held),
        "",
        f"### Argoverse 2, never trained on: {av2['map']['windows']} windows, {av2['map']['agents']} target agents",
        "",
        table(av2),
        "",
        verdict(av2),
        "",
    ]
    return "\n".join(text)


def reading(results: dict[str, Any]) -> str:
    """The paper's '20' against '20S' for vehicles, in words, from the numbers: the map model against the network
    trained without the map branch, and against itself given no map, on both driving test sets."""
    lines = []
    for key, name in (("hdmap", "held-out nuScenes + Waymo scenes"), ("argoverse2", "Argoverse 2")):
        res = results[key]
        m, n = res["map"]["by_class"].get("vehicle"), res["nomap"]["by_class"].get("vehicle")
        if m is None or n is None:
            continue
        keys = (("top-1 ADE", "ade"), ("top-1 FDE", "fde"), ("minADE5", "min_ade5"))
        text = f"- *Vehicles, {name}* ({m['agents']} targets): with the map against the network trained without it, "
        text += relative(m, n, keys, "worse better")
        a = (res.get("map_absent") or {}).get("by_class", {}).get("vehicle")
        if a is not None:
            text += f"; against the same model given no map, {relative(m, a, keys, 'worse better')}"
        lines.append(text + ".")
    return "\n".join(lines)
