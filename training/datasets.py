"""The real datasets training reads, each as :class:`Recording` tables in world metres with per-row labels.

- ``ethucy``: ETH/UCY in the Social-GAN layout (metres, 0.4 s), leave-one-scene-out (``fold`` is the held-out
  scene), each scene's colourised semantic mask as the raster map. One class: pedestrian.
- ``sdd``: Stanford Drone, multi-class, in Multiclass-SGCN's ``multiclass_step10`` release (all 60 videos, split
  30/13/17 by video, box centres in pixels, one step = 10 video frames ≈ 0.33 s). Positions become metres with each
  video's scale from ``estimated_scales.yaml``; errors are reported back in pixels (``Recording.unit_m``). Each
  video's ``reference.jpg``, box-filtered to about 0.25 m per pixel, is its raster map.
- ``apolloscape``: ApolloScape trajectory (2 Hz, measured class, length, width and heading; the heading's
  convention differs between recordings), split by recording;
  no map. Its "others" take part as neighbours only, never as targets.
- ``hdmap``: driving scenes with vector HD maps, nuScenes mini (ScenarioNet) and Waymo Open Motion (GPUDrive JSON and
  ScenarioNet), read by :mod:`dgan.datasets.hdmaps`, at 5 Hz: 2 s observed (10 steps), 3 s predicted (15 steps), split
  by scene (:data:`HDMAP_TEST`, :data:`HDMAP_VAL`). Targets are agents seen at all 25 steps that move more than 1 m
  over them. The 10 Hz sources are sampled every second step, in both phases (each scenario gives two recordings,
  steps 0, 2, 4 … and 1, 3, 5 …). nuScenes annotates agents only at 2 Hz keyframes, every fifth 10 Hz step, and the
  conversion interpolated linearly between them: its test windows end at a keyframe, so t_obs and the 3 s endpoint
  (FDE) are real annotations and the points between are linear interpolations of real ones.
- ``argoverse2``: the three Argoverse 2 scenes (one motion-forecasting scenario, two sensor logs), never trained on:
  a test of the ``hdmap`` protocol on a source the model has not seen.

Each dataset's labels map onto the engine's three classes as in the paper: pedestrian; cyclist (Biker, Skater;
bicyclist/motorcyclist); vehicle (Cart, Car, Bus; small and big vehicles).
"""

from __future__ import annotations

import re
import warnings
from dataclasses import dataclass, replace
from functools import cache
from pathlib import Path
from typing import Any

import numpy as np
import numpy.typing as npt

import dgan
from dgan.datasets.hdmaps import read_scenario
from dgan.exceptions import DatasetWarning
from dgan.scenes import APOLLO_TYPES, SDD_LABEL_CLASS, scene_raster_map, sdd_raster_map

Arr = npt.NDArray[Any]


@dataclass(frozen=True)
class DatasetInfo:
    """A dataset's time base, protocol and labels."""

    name: str
    dt_s: float
    t_obs: int
    t_f: int
    labels: tuple[str, ...]  # the dataset's own labels, in code order
    label_class: tuple[str, ...]  # the engine class of each label
    scored: tuple[bool, ...]  # whether agents with the label can be targets
    unit: str  # the unit errors are reported in: "m" or "px"
    min_targets: int  # a window needs at least this many targets
    has_map: bool
    min_move_m: float = 0.0  # a target must move more than this over the window (first to last point)

    @property
    def classes(self) -> tuple[str, ...]:
        """The model's classes, in the engine's canonical order, among those of the scored labels."""
        used = {c for c, s in zip(self.label_class, self.scored, strict=True) if s}
        return tuple(c for c in dgan.CLASSES if c in used)


DATASETS: dict[str, DatasetInfo] = {
    "ethucy": DatasetInfo(
        "ethucy", 0.4, 8, 12, ("Pedestrian",), ("pedestrian",), (True,), "m", min_targets=2, has_map=True
    ),
    "sdd": DatasetInfo(
        "sdd",
        1 / 3,  # 10 frames of 30 fps video
        8,
        12,
        tuple(SDD_LABEL_CLASS),
        tuple(SDD_LABEL_CLASS.values()),
        (True,) * 6,
        "px",
        min_targets=2,
        has_map=True,
    ),
    "apolloscape": DatasetInfo(
        "apolloscape",
        0.5,
        6,
        6,
        tuple(label for label, _ in APOLLO_TYPES.values()),
        tuple(cls for _, cls in APOLLO_TYPES.values()),
        (True, True, True, True, False),  # "others" are neighbours only
        "m",
        min_targets=1,
        has_map=False,
    ),
    "hdmap": DatasetInfo(
        "hdmap", 0.2, 10, 15, dgan.CLASSES, dgan.CLASSES, (True,) * 3, "m", min_targets=1, has_map=True
    ),
}
DATASETS["argoverse2"] = replace(DATASETS["hdmap"], name="argoverse2")

#: ApolloScape recordings held out for testing and validation; the other recordings train.
APOLLO_TEST = (9048, 9056, 9058, 9061)
APOLLO_VAL = (9049, 9060)
#: Target resolution of the box-filtered SDD reference images, metres per pixel.
SDD_MAP_RESOLUTION_M = 0.25
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


@dataclass
class Recording:
    """One recording's rows, sorted by (step, agent). Steps are integer time indices ``dt_s`` apart."""

    name: str
    step: Arr  # (R,) int64
    agent: Arr  # (R,) int64
    xy: Arr  # (R, 2) f64, world metres
    label: Arr  # (R,) int64 into DatasetInfo.labels
    heading: Arr | None = None  # (R,) radians
    length: Arr | None = None  # (R,) metres
    width: Arr | None = None  # (R,) metres
    unit_m: float = 1.0  # metres per reporting unit
    map: dgan.RasterMap | dgan.VectorMap | None = None
    now_steps: Arr | None = None  # the steps a window may end at (all if None)

    @classmethod
    def sorted(cls, **kw: Any) -> Recording:
        rec = cls(**kw)
        order = np.lexsort((rec.agent, rec.step))
        for k in ("step", "agent", "xy", "label", "heading", "length", "width"):
            v = getattr(rec, k)
            if v is not None:
                setattr(rec, k, v[order])
        return rec


def recordings(dataset: str, root: Path, split: str, fold: str = "", with_map: bool = True) -> list[Recording]:
    """Every recording of a split (``train``, ``val`` or ``test``); ``fold`` is the held-out ETH/UCY scene, or
    ApolloScape's validation recordings (:func:`apollo_val_recordings`)."""
    files = source_files(dataset, root, split, fold)
    if dataset == "ethucy":
        return [ethucy_recording(p, root, with_map) for p in files]
    if dataset == "sdd":
        return [sdd_recording(p, root, with_map) for p in files]
    if dataset in ("hdmap", "argoverse2"):
        return [r for p in files for r in hdmap_recordings(p, keyframes_only=split == "test")]
    return [apollo_recording(p) for p in files]


def source_files(dataset: str, root: Path, split: str, fold: str = "") -> list[Path]:
    """The files behind a split (also the cache key of its windows)."""
    if dataset not in DATASETS:
        raise ValueError(f"unknown dataset {dataset!r}; known: {', '.join(DATASETS)}")
    if split not in ("train", "val", "test"):
        raise ValueError(f"unknown split {split!r}; known: train, val, test")
    if dataset == "ethucy":
        return split_files(root, fold, split)
    if dataset == "sdd":
        return sdd_files(root, split)
    if dataset == "hdmap":
        return hdmap_files(root, split)
    if dataset == "argoverse2":
        return argoverse2_files(root, split)
    return apollo_files(root, split, fold)


# ---- ETH/UCY -------------------------------------------------------------------------------------------------------

#: Frame ids step by 10 between 0.4 s steps in the Social-GAN files.
ETHUCY_FRAME_STEP = 10
#: Which scene map each Social-GAN file is recorded on.
FILE_SCENES = {
    "biwi_eth": "eth",
    "biwi_hotel": "hotel",
    "students001": "univ",
    "students003": "univ",
    "uni_examples": "univ",
    "crowds_zara01": "zara1",
    "crowds_zara02": "zara2",
    "crowds_zara03": "zara2",
}


def scene_of(path: Path) -> str:
    for prefix, scene in FILE_SCENES.items():
        if path.name.startswith(prefix):
            return scene
    raise ValueError(f"unknown ETH/UCY file {path.name}")


def split_files(data_root: Path, scene: str, split: str) -> list[Path]:
    """The Social-GAN files of a leave-one-scene-out fold: ``train``/``val`` hold the other scenes, ``test`` the
    held-out one."""
    folder = data_root / "eth_ucy" / "datasets" / scene / split
    files = sorted(folder.glob("*.txt"))
    if not files:
        raise FileNotFoundError(f"no ETH/UCY files in {folder}; set data.root to the folder holding eth_ucy/")
    return files


@cache
def _ethucy_map(root: Path, scene: str) -> dgan.RasterMap:
    return scene_raster_map(scene, root / "eth_ucy_scene_maps" / "semantic_masks" / scene)


def ethucy_recording(path: Path, root: Path, with_map: bool = True) -> Recording:
    rows = np.loadtxt(path, ndmin=2)
    scene = scene_of(path)
    return Recording.sorted(
        name=path.stem,
        step=np.rint(rows[:, 0] / ETHUCY_FRAME_STEP).astype(np.int64),
        agent=rows[:, 1].astype(np.int64),
        xy=rows[:, 2:4].astype(np.float64),
        label=np.zeros(len(rows), np.int64),
        map=_ethucy_map(root, scene) if with_map else None,
    )


# ---- Stanford Drone ------------------------------------------------------------------------------------------------


def sdd_files(root: Path, split: str) -> list[Path]:
    folder = root / "sdd" / "multiclass_step10" / split
    files = sorted(folder.glob("stan_*.txt"))
    if not files:
        raise FileNotFoundError(f"no SDD files in {folder}; set data.root to the folder holding sdd/")
    return files


def sdd_video(path: Path) -> tuple[str, int]:
    """``stan_deathCircle_3.txt`` → ``("deathCircle", 3)``."""
    m = re.fullmatch(r"stan_(\w+?)_(\d+)", path.stem)
    if m is None:
        raise ValueError(f"not an SDD multiclass file name: {path.name}")
    return m.group(1), int(m.group(2))


@cache
def sdd_scales(root: Path) -> dict[tuple[str, int], float]:
    """Metres per pixel of every video, from ``estimated_scales.yaml`` (a two-level mapping; read without PyYAML)."""
    path = root / "sdd" / "raw_annotations" / "estimated_scales.yaml"
    scales: dict[tuple[str, int], float] = {}
    scene, video = "", -1
    for line in path.read_text().splitlines():
        if m := re.fullmatch(r"(\w+):\s*", line):
            scene = m.group(1)
        elif m := re.fullmatch(r"\s+video(\d+):\s*", line):
            video = int(m.group(1))
        elif m := re.fullmatch(r"\s+scale:\s*([0-9.eE+-]+)\s*", line):
            scales[(scene, video)] = float(m.group(1))
    if not scales:
        raise ValueError(f"no scales found in {path}")
    return scales


def sdd_recording(path: Path, root: Path, with_map: bool = True) -> Recording:
    scene, video = sdd_video(path)
    scale = sdd_scales(root).get((scene, video))
    if scale is None:
        raise ValueError(f"no scale for SDD {scene} video {video} in estimated_scales.yaml")
    raw = np.loadtxt(path, dtype=str, ndmin=2)
    labels = DATASETS["sdd"].labels
    unknown = set(raw[:, 4]) - set(labels)
    if unknown:
        raise ValueError(f"{path.name}: unknown SDD labels {sorted(unknown)}; known: {labels}")
    smap = None
    if with_map:
        image = root / "sdd" / "raw_annotations" / scene / f"video{video}" / "reference.jpg"
        smap = sdd_raster_map(image, scale, SDD_MAP_RESOLUTION_M)
    return Recording.sorted(
        name=path.stem,
        step=raw[:, 0].astype(float).astype(np.int64),
        agent=raw[:, 1].astype(float).astype(np.int64),
        xy=raw[:, 2:4].astype(np.float64) * scale,
        label=np.array([labels.index(s) for s in raw[:, 4]], np.int64),
        unit_m=scale,
        map=smap,
    )


# ---- Pedestrians of other sources, for the ETH/UCY models -----------------------------------------------------------

#: Sources whose pedestrians can join the ETH/UCY training windows (``data.extra_pedestrians``).
PEDESTRIAN_SOURCES = ("sdd",)


def pedestrian_sources(names: str) -> list[str]:
    """The sources named by ``data.extra_pedestrians`` (comma-separated; empty for none), each checked."""
    sources = [s.strip() for s in names.split(",") if s.strip()]
    unknown = [s for s in sources if s not in PEDESTRIAN_SOURCES]
    if unknown:
        raise ValueError(f"unknown pedestrian source(s) {unknown}; known: {', '.join(PEDESTRIAN_SOURCES)}")
    return sources


def resampled(rec: Recording, dt_from_s: float, dt_to_s: float) -> Recording:
    """``rec`` (steps ``dt_from_s`` apart) on a grid of steps ``dt_to_s`` apart: each agent's position at a new step
    is interpolated linearly between its rows at the two old steps around it, and the new step is left out where the
    agent lacks either of them (no interpolation across gaps). Per-row headings and sizes are not carried."""
    ratio = dt_to_s / dt_from_s
    steps, agents, xys, labels = [], [], [], []
    for agent in np.unique(rec.agent):
        sel = np.flatnonzero(rec.agent == agent)
        old, xy = rec.step[sel], rec.xy[sel]
        new = np.arange(np.ceil(old[0] / ratio - 1e-9), np.floor(old[-1] / ratio + 1e-9) + 1).astype(np.int64)
        t = new * ratio
        lo = np.clip(np.searchsorted(old, np.floor(t + 1e-9), side="right") - 1, 0, len(old) - 1)
        hi = np.clip(lo + 1, 0, len(old) - 1)
        frac = t - old[lo]
        exact = np.abs(frac) < 1e-9
        ok = exact | ((old[hi] - old[lo] == 1) & (frac > 0) & (frac < 1))
        w = np.where(exact, 0.0, frac)[:, None]
        steps.append(new[ok])
        agents.append(np.full(int(ok.sum()), agent))
        xys.append(((1 - w) * xy[lo] + w * xy[hi])[ok])
        labels.append(np.full(int(ok.sum()), rec.label[sel[0]]))
    if not steps:
        return replace(rec, heading=None, length=None, width=None, now_steps=None)
    return Recording.sorted(
        name=rec.name,
        step=np.concatenate(steps),
        agent=np.concatenate(agents),
        xy=np.concatenate(xys),
        label=np.concatenate(labels),
        unit_m=rec.unit_m,
        map=rec.map,
    )


def pedestrian_recordings(source: str, root: Path, dt_s: float) -> list[Recording]:
    """The pedestrians of ``source``'s training split, in metres, resampled to ``dt_s`` and labelled with ETH/UCY's one
    label, without their maps (a model whose map is optional sees a blank crop for them, as under map dropout). The
    source's other agents are left out: the ETH/UCY models know only pedestrians."""
    pedestrian_sources(source)
    info = DATASETS[source]
    pedestrian = info.labels.index("Pedestrian")
    out = []
    for path in sdd_files(root, "train"):
        rec = sdd_recording(path, root, with_map=False)
        keep = rec.label == pedestrian
        only = Recording.sorted(
            name=f"{source}:{rec.name}",
            step=rec.step[keep],
            agent=rec.agent[keep],
            xy=rec.xy[keep],
            label=np.zeros(int(keep.sum()), np.int64),
        )
        out.append(resampled(only, info.dt_s, dt_s))
    return out


# ---- ApolloScape ---------------------------------------------------------------------------------------------------


def apollo_recording_id(path: Path) -> int:
    m = re.fullmatch(r"result_(\d+)_\d+_frame", path.stem)
    if m is None:
        raise ValueError(f"not an ApolloScape trajectory file name: {path.name}")
    return int(m.group(1))


def apollo_val_recordings(fold: str) -> tuple[int, ...]:
    """The ApolloScape recordings of the validation split: ``fold`` (comma-separated recording numbers, never a test
    recording) or, if empty, :data:`APOLLO_VAL`."""
    if not fold:
        return APOLLO_VAL
    try:
        ids = tuple(int(x) for x in fold.split(","))
    except ValueError:
        raise ValueError(f"data.val_recordings must be comma-separated recording numbers, got {fold!r}") from None
    if clash := sorted(set(ids) & set(APOLLO_TEST)):
        raise ValueError(f"data.val_recordings {clash} are test recordings (training.datasets.APOLLO_TEST)")
    return ids


def apollo_files(root: Path, split: str, fold: str = "") -> list[Path]:
    """The files of a split; ``fold`` names the validation recordings (:func:`apollo_val_recordings`)."""
    folder = root / "apolloscape_trajectory" / "prediction_train"
    files = sorted(folder.glob("result_*_frame.txt"))
    if not files:
        raise FileNotFoundError(f"no ApolloScape files in {folder}; set data.root to the folder holding it")
    val = apollo_val_recordings(fold)
    if missing := sorted(set(val) - {apollo_recording_id(p) for p in files}):
        raise ValueError(f"no ApolloScape recording {missing} in {folder}")
    held = {"test": APOLLO_TEST, "val": val}
    if split == "train":
        return [p for p in files if apollo_recording_id(p) not in APOLLO_TEST + val]
    return [p for p in files if apollo_recording_id(p) in held[split]]


def apollo_recording(path: Path) -> Recording:
    rows = np.loadtxt(path, ndmin=2)
    types = rows[:, 2].astype(np.int64)
    if not np.isin(types, [1, 2, 3, 4, 5]).all():
        raise ValueError(f"{path.name}: object types must be 1..5, found {sorted(set(types.tolist()))}")
    return Recording.sorted(
        name=path.stem,
        step=rows[:, 0].astype(np.int64),
        agent=rows[:, 1].astype(np.int64),
        xy=rows[:, 3:5].astype(np.float64),
        label=types - 1,
        heading=rows[:, 9].astype(np.float64),
        length=rows[:, 6].astype(np.float64),
        width=rows[:, 7].astype(np.float64),
    )


# ---- Driving scenes with vector HD maps (nuScenes, Waymo, Argoverse 2) -----------------------------------------------


def _stem(path: Path) -> str:
    return path.name.split(".")[0] if path.name.endswith(".json.gz") else path.stem


def hdmap_files(root: Path, split: str) -> list[Path]:
    files = sorted((root / "nuscenes_mini_scenarionet").glob("*.pkl"))
    waymo = root / "waymo_motion_samples"
    files += sorted((waymo / "gpudrive_json").glob("*.json.gz")) + sorted((waymo / "scenarionet_pkl").glob("*.pkl"))
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
    labels = DATASETS["hdmap"].labels
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
