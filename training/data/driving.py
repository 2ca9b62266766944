"""Driving scenes with vector HD maps (nuScenes mini, Waymo; Argoverse 2 as a never-trained-on test), read by
:mod:`dgan.datasets.hdmaps`, at 5 Hz, split by scene."""

from __future__ import annotations

import warnings
from pathlib import Path

import numpy as np

import dgan
from dgan.datasets.hdmaps import read_scenario
from dgan.exceptions import DatasetWarning
from training.data.recording import Recording

#: Driving scenes held out for testing and validation (file names without their extensions); the rest train. The
#: test scenes hold two nuScenes scenes (Boston, Singapore) and six Waymo scenarios, chosen to include cyclists.
HDMAP_TEST = (
    "sd_nuscenes_v1.0-mini_scene-0103",
    "sd_nuscenes_v1.0-mini_scene-1094",
    "tfrecord-00000-of-01000_4",
    "tfrecord-00000-of-01000_402",
    "tfrecord-00004-of-00150_a5c442237e79e506",
    "tfrecord-00005-of-00150_2bd577a009790706",
    "tfrecord-00051-of-00150_641ead285b0c7516",
    "sd_training.tfrecord-00000-of-01000_c403d5992cab9e0",
)


HDMAP_VAL = (
    "sd_nuscenes_v1.0-mini_scene-0553",
    "tfrecord-00000-of-01000_325",
    "tfrecord-00015-of-00150_a898cbc905050656",
)


#: The hdmap protocol samples 10 Hz sources every second step.
HDMAP_EVERY = 2


def _stem(path: Path) -> str:
    return path.name.split(".")[0] if path.name.endswith(".json.gz") else path.stem


def hdmap_files(root: Path, split: str, source: str = "") -> list[Path]:
    """The scenarios of a split: nuScenes' and Waymo's, or with ``source`` ("nuscenes", "waymo") one source's."""
    if source not in ("", "nuscenes", "waymo"):
        raise ValueError(f"unknown hdmap source {source!r}; known: nuscenes, waymo")
    files = [] if source == "waymo" else sorted((root / "nuscenes_mini_scenarionet").glob("*.pkl"))
    waymo = root / "waymo_motion_samples"
    if source != "nuscenes":
        files += sorted((waymo / "gpudrive_json").glob("*.json.gz"))
        files += sorted((waymo / "scenarionet_pkl").glob("*.pkl"))
    if not files:
        raise FileNotFoundError(
            f"no nuScenes or Waymo scenarios under {root}; set data.root to the folder holding "
            "nuscenes_mini_scenarionet/ and waymo_motion_samples/"
        )
    held = {"test": HDMAP_TEST, "val": HDMAP_VAL}
    if split == "train":
        return [p for p in files if _stem(p) not in HDMAP_TEST + HDMAP_VAL]
    return [p for p in files if _stem(p) in held[split]]


def argoverse2_files(root: Path, split: str) -> list[Path]:
    """The Argoverse 2 scenes are a test set only."""
    if split != "test":
        return []
    folder = root / "argoverse2"
    files = sorted((folder / "motion_forecasting").iterdir()) + sorted((folder / "sensor_logs").iterdir())
    if not files:
        raise FileNotFoundError(f"no Argoverse 2 scenes in {folder}; set data.root to the folder holding argoverse2/")
    return files


def hdmap_recordings(path: Path, keyframes_only: bool = False) -> list[Recording]:
    """One scenario as two 5 Hz recordings (the two phases of its 10 Hz steps). With ``keyframes_only``, windows of
    sources with sparse annotations (nuScenes) may end only at a real annotation."""
    with warnings.catch_warnings():  # the element types left out are the module table's (driveways, stop signs)
        warnings.simplefilter("ignore", DatasetWarning)
        sc = read_scenario(path)
    if abs(sc.dt_s - 0.1) > 0.005:
        raise ValueError(f"{path.name}: expected 10 Hz states, got a step of {sc.dt_s} s")
    labels = dgan.CLASSES  # the hdmap dataset's labels (training.data.datasets.DATASETS)
    out = []
    for phase in range(HDMAP_EVERY):
        cols = np.arange(phase, sc.num_steps, HDMAP_EVERY)
        agent, step = np.nonzero(sc.valid[:, cols])
        src = cols[step]
        now_steps = None
        if keyframes_only and sc.keyframe_every > 1:
            now_steps = np.flatnonzero(cols % sc.keyframe_every == 0)
        out.append(
            Recording.sorted(
                name=f"{_stem(path)}@{phase}",
                step=step.astype(np.int64),
                agent=sc.ids[agent],
                xy=sc.positions[agent, src],
                label=np.array([labels.index(sc.labels[a]) for a in agent], np.int64),
                heading=sc.heading[agent, src],
                length=sc.length[agent, src],
                width=sc.width[agent, src],
                map=sc.map,
                now_steps=now_steps,
            )
        )
    return out
