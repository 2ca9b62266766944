"""The model card of a bundled multi-class model (``python/dgan/models/<name>.md`` for ``sdd``, ``apolloscape`` and
``hdmap``): its data and protocol per dataset, the per-class and moving/standing test metrics beside constant
velocity, the licence; the ETH/UCY cards and the lines both share are in :mod:`training.release.cards`."""

from __future__ import annotations

from pathlib import Path
from typing import Any

from training.release.cards import (
    KEPT,
    classification_words,
    contract_line,
    distill_words,
    map_words,
    scene_words,
    threads_of,
    training_log,
)

#: Per multi-class dataset: the card's title, data, protocol, licence, how to reproduce it and the bundled scene.
MULTICLASS = {
    "sdd": {
        "title": "Stanford Drone (multi-class)",
        "data": "Stanford Drone Dataset in Multiclass-SGCN's `multiclass_step10` release: all 60 videos split 30/13/17 "
        "by video (train/val/test), box centres in pixels, one step = 10 video frames (1/3 s). Positions are "
        "converted to metres with each video's scale (`estimated_scales.yaml`); errors are reported in **pixels**. "
        "Labels → classes as in the paper: Pedestrian → pedestrian; Biker, Skater → cyclist; Cart, Car, Bus → "
        "vehicle. Lengths and widths are the class defaults (the release has no boxes). The map is each video's "
        "`reference.jpg`, box-filtered to about 0.25 m/px, cropped heading-aligned.",
        "protocol": "8 observed steps (2.7 s), 12 predicted (4 s); windows of 20 consecutive steps, targets present "
        "at all of them, windows with at least two targets (Multiclass-SGCN's windows).",
        "licence": "Stanford Drone Dataset: **CC BY-NC-SA 3.0**, non-commercial. Cite Robicquet et al. 2016.",
        "reproduce": "--train-multiclass` (this model and its per-class baselines)",
        "scene": "`dgan demo --model sdd` (hyang video0 of the test split). On a new frame of an SDD video, pass "
        "metres (pixels × the video's scale) and the map `dgan.scenes.sdd_raster_map(reference_jpg, scale)`",
    },
    "apolloscape": {
        "title": "ApolloScape trajectory (multi-class)",
        "data": "ApolloScape trajectory (urban traffic recorded from a vehicle, 2 Hz) with each agent's measured "
        "class, length and width. Its heading column follows the direction of motion in some recordings and is "
        "reversed, mirrored or turned by 90° in others, so the model takes headings from the motion (contract 5, "
        '`heading = "motion"`). '
        "Split by recording: test 9048, 9056, 9058, 9061; val 9049, 9060; "
        "train the other eight. Small and big vehicles → vehicle; bicyclists and motorcyclists → cyclist; "
        'pedestrians; "others" are neighbours only. No map: the model has no map branch.',
        "protocol": "6 observed steps (3 s), 6 predicted (3 s); targets present at all 12 steps.",
        "licence": "ApolloScape: **non-commercial academic research** only. Cite Ma et al. 2019 (TrafficPredict).",
        "reproduce": "--train-multiclass` (this model and its per-class baselines)",
        "scene": "`dgan demo --model apolloscape` (recording 9048 of the test split). Pass lengths and widths in "
        "the frame, as in training; the model ignores given headings",
    },
    "hdmap": {
        "title": "driving scenes with a vector HD map (nuScenes mini and Waymo Open Motion)",
        "data": "nuScenes v1.0-mini (all 10 scenes, ScenarioNet conversion) and 35 Waymo Open Motion scenarios "
        "(GPUDrive JSON and ScenarioNet), read by `dgan.datasets.hdmaps`, split by scene "
        "(`training.data.driving.HDMAP_TEST`: "
        "nuScenes scene-0103 and scene-1094 and six Waymo scenarios; val: scene-0553 and two Waymo scenarios; the "
        "other 34 scenes train). Measured headings and boxes. The map branch sees each agent's heading-aligned crop of "
        "the vector map (lane centre lines, dashed and solid lane lines, road edges, crosswalks, bike lanes, medians "
        "and static obstacles) rasterised by the engine in the paper's colours, other agents as blue boxes.",
        "protocol": "5 Hz: 10 observed steps (2 s), 15 predicted (3 s). The 10 Hz sources are sampled every second "
        "step; nuScenes annotates at 2 Hz only and its test windows end at a keyframe. Targets: every agent seen "
        "at all 25 steps, standing ones too (moving: at least 1 m from the first to the last position).",
        "licence": "nuScenes: **CC BY-NC-SA 4.0**; Waymo Open Dataset: its own licence, **non-commercial use "
        "only**, which also limits redistribution. Cite Caesar et al. 2020 and Ettinger et al. 2021.",
        "reproduce": "--train-hdmap` (this model and its no-map variant)",
        "scene": "`dgan demo --model hdmap` (Waymo scenario 2bd577a009790706 of the test split, over its map as the "
        "engine rasterises it, and one agent's crop). Build frames with `dgan.hdmaps.read_scenario(path).frame(step, "
        "10, every=2)` for 10 Hz sources, with a `dgan.VectorMap`",
    },
}


def multiclass_card(name: str, run: Path, metrics: dict[str, Any], cfg: dict[str, Any]) -> str:
    """The card of the multi-class model ``name`` trained in ``run`` with configuration ``cfg``, with its test
    ``metrics`` (``training.evaluate``) per class, per motion and per dataset label."""
    rows, seconds, best = training_log(run)
    kept, distilled = KEPT[cfg["train"].get("select", "val_loss")], distill_words(name, cfg)
    d = MULTICLASS[cfg["data"]["dataset"]]
    m = cfg["model"]
    keys = ("ade", "fde", "min_ade5", "min_fde5", "min_ade20", "min_fde20", "brier_min_fde20", "cv_ade", "cv_fde")
    groups = [("all", metrics)] + [(c, r) for c, r in metrics["by_class"].items()]
    groups += [(m, r) for m, r in metrics.get("by_motion", {}).items() if r["agents"]]
    groups += [(f"label {k}", r) for k, r in metrics["by_label"].items() if k.lower() not in metrics["by_class"]]
    table = "\n".join(f"| {g} | {r['agents']} | " + " | ".join(f"{r[k]:.2f}" for k in keys) + " |" for g, r in groups)
    data = cfg["data"]
    crops = f"{data['map_height_px']}×{data['map_width_px']} px crops at {data['map_resolution_m']} m/px"
    where = map_words(cfg) if m.get("map_mode", "crop") == "scene" else crops
    map_line = (
        f"map CNN (width {m['map_channels']}{scene_words(cfg)}) over {where}, "
        if m["use_map"] and data["use_map"] and data["dataset"] != "apolloscape"
        else ""
    )
    return f"""# Model card: `{name}`

DGAN (Dong et al. 2020): **one model for vehicles, cyclists and pedestrians** on {d["title"]}, with
{cfg["train"]["anchors_per_class"]} k-means anchors per class and the hierarchical class × anchor probability.

- **Data**: {d["data"]}{joint_words(cfg)}
- **Protocol**: {d["protocol"]}
- **Model**: LSTM({m["lstm_dim"]}) over MLP-embedded positions, traffic-state MLP (speed, acceleration, yaw rate,
  direction of motion, length, width, one-hot class), {map_line}{m["gat_layers"]} GAT layers × {m["gat_heads"]} heads
  over the attention-zone graph (λ = 0.5) with neighbour geometry on the edges. Loss: {classification_words(cfg)} and
  closest-anchor regression (α = {cfg["train"]["alpha"]}) plus β = {cfg["train"]["beta"]} times the error of the most
  probable mode. {contract_line(cfg, metrics)}
- **Training**: {len(rows)} epochs on every {cfg["data"]["window_stride"]}. window, weights of epoch {best["epoch"]}
  ({kept}), {seconds / 60:.1f} min on {threads_of(cfg)}; seed {cfg["train"]["seed"]}; left-right mirroring.{distilled}
- **Test metrics** (engine, {metrics["unit"]}, {metrics["windows"]} windows; most probable class correct for
  {100 * metrics["class_accuracy"]:.1f}% of agents, since the class is an input as in the paper; mode-probability
  calibration error {metrics["calibration"]["ece"]:.3f}, see `docs/results.md`):

| agents | n | top-1 ADE | top-1 FDE | minADE5 | minFDE5 | minADE20 | minFDE20 | Brier-minFDE20 | CV ADE | CV FDE |
|---|---|---|---|---|---|---|---|---|---|---|
{table}

- **Try it**: {d["scene"]}.
- **Licence**: {d["licence"]} The weights are derived from this data: non-commercial research use only.
- **Reproduce**: `python -m training.results {d["reproduce"]}, or
  `python -m training.train --config training/configs/{cfg["data"]["dataset"]}.toml --out runs/{name}`.
"""


def joint_words(cfg: dict[str, Any]) -> str:
    """The card's words for a model trained on other sources too (``data.extra_sources``), empty for one without."""
    names = cfg["data"].get("extra_sources", "")
    if not names:
        return ""
    return (
        f" **Also trained on** the training splits of `{names}` (`data.extra_sources`, source:window stride), each "
        "resampled onto this protocol's time base by the engine, without their maps; their validation splits took "
        "part in choosing the epoch; their licences apply too (non-commercial research use only)."
    )
