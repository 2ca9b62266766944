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
- ``nuscenes``, ``waymo``: ``hdmap``'s two sources apart, with its splits.
- ``ethucy_5hz``, ``sdd_5hz``, ``apolloscape_5hz``: those sources at the ``hdmap`` protocol (:data:`AT_HDMAP`), for a
  model trained on every source (``data.extra_sources``) and the leave-one-source-out tests
  (:mod:`training.studies.sources`).
- ``ethucy_2hz``, ``sdd_2hz``, ``hdmap_2hz``: those sources at ApolloScape's protocol (:data:`AT_APOLLOSCAPE`), for
  an ApolloScape model that also learns from them.

Each dataset's labels map onto the engine's three classes as in the paper: pedestrian; cyclist (Biker, Skater;
bicyclist/motorcyclist); vehicle (Cart, Car, Bus; small and big vehicles).
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, replace
from pathlib import Path
from typing import Any

import numpy as np

import dgan
from dgan.scenes import APOLLO_TYPES, SDD_LABEL_CLASS
from training.data.apolloscape import apollo_files, apollo_recording
from training.data.driving import argoverse2_files, hdmap_files, hdmap_recordings
from training.data.ethucy import ethucy_recording, split_files
from training.data.recording import DatasetInfo, Located, Recording, WindowSet
from training.data.sdd import sdd_files, sdd_recording

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
# The two sources of ``hdmap`` apart (leave-one-source-out): the same protocol and split by scene, one source each.
DATASETS["nuscenes"] = replace(DATASETS["hdmap"], name="nuscenes")
DATASETS["waymo"] = replace(DATASETS["hdmap"], name="waymo")

#: The sources read at the ``hdmap`` protocol (5 Hz, 10 observed and 15 predicted steps) besides its own, by the name of
#: that dataset: each recording of the source resampled to 0.2 s (:func:`resampled`), in metres, without its map, its
#: labels and which of them are scored as in the source. A joint model trains on them beside ``hdmap``'s scenes
#: (``data.extra_sources``) and a model that never saw one is tested on it (leave-one-source-out).
AT_HDMAP = {"ethucy_5hz": "ethucy", "sdd_5hz": "sdd", "apolloscape_5hz": "apolloscape"}
#: The same at ApolloScape's protocol (2 Hz, 6 observed and 6 predicted steps), ``hdmap``'s driving scenes included.
AT_APOLLOSCAPE = {"ethucy_2hz": "ethucy", "sdd_2hz": "sdd", "hdmap_2hz": "hdmap"}
#: Every resampled source, by its name: the source it reads.
RESAMPLED = {**AT_HDMAP, **AT_APOLLOSCAPE}
#: Each resampled source's protocol: the dataset whose time base it takes.
PROTOCOL_OF = {**dict.fromkeys(AT_HDMAP, "hdmap"), **dict.fromkeys(AT_APOLLOSCAPE, "apolloscape")}
for _name, _source in RESAMPLED.items():
    _p = DATASETS[PROTOCOL_OF[_name]]
    DATASETS[_name] = replace(
        DATASETS[_source], name=_name, dt_s=_p.dt_s, t_obs=_p.t_obs, t_f=_p.t_f, unit="m", min_targets=1, has_map=False
    )


@dataclass(frozen=True)
class Source:
    """How a dataset's recordings are found and read: ``files(root, split, fold)`` lists a split's files (also the
    cache key of its windows), ``read(path, root, split, with_map)`` reads one file into recordings."""

    files: Callable[[Path, str, str], list[Path]]
    read: Callable[[Path, Path, str, bool], list[Recording]]


#: The readers of each dataset of :data:`DATASETS`, by name (:func:`register` adds one).
SOURCES: dict[str, Source] = {
    "ethucy": Source(
        lambda root, split, fold: split_files(root, fold, split), lambda p, root, _, m: [ethucy_recording(p, root, m)]
    ),
    "sdd": Source(lambda root, split, _: sdd_files(root, split), lambda p, root, _, m: [sdd_recording(p, root, m)]),
    "apolloscape": Source(apollo_files, lambda p, *_: [apollo_recording(p)]),
    "hdmap": Source(
        lambda root, split, _: hdmap_files(root, split), lambda p, _, split, __: hdmap_recordings(p, split == "test")
    ),
    "argoverse2": Source(
        lambda root, split, _: argoverse2_files(root, split),
        lambda p, _, split, __: hdmap_recordings(p, split == "test"),
    ),
    "nuscenes": Source(
        lambda root, split, _: hdmap_files(root, split, "nuscenes"),
        lambda p, _, split, __: hdmap_recordings(p, split == "test"),
    ),
    "waymo": Source(
        lambda root, split, _: hdmap_files(root, split, "waymo"),
        lambda p, _, split, __: hdmap_recordings(p, split == "test"),
    ),
}


def ethucy_all_files(root: Path, split: str) -> list[Path]:
    """ETH/UCY as one source, every scene: ``train`` and ``val`` the Social-GAN ``raw`` files (each scene's first
    and second part in time), ``test`` the five scenes' whole test files (which overlap them: a model tested on these
    must not have trained on ETH/UCY at all)."""
    if split == "test":
        return [f for scene in ("eth", "hotel", "univ", "zara1", "zara2") for f in split_files(root, scene, "test")]
    folder = root / "eth_ucy" / "datasets" / "raw" / split
    files = sorted(folder.glob("*.txt"))
    if not files:
        raise FileNotFoundError(f"no ETH/UCY files in {folder}; set data.root to the folder holding eth_ucy/")
    return files


def _at(source: str, protocol: str) -> Source:
    """``source``'s recordings at the time base of the dataset ``protocol`` (:data:`AT_HDMAP`,
    :data:`AT_APOLLOSCAPE`)."""
    files = SOURCES[source].files if source != "ethucy" else (lambda root, split, _: ethucy_all_files(root, split))
    dt_from, dt_to = DATASETS[source].dt_s, DATASETS[protocol].dt_s

    def read(path: Path, root: Path, split: str, _with_map: bool) -> list[Recording]:
        out = []
        for rec in SOURCES[source].read(path, root, split, False):
            out.append(replace(resampled(rec, dt_from, dt_to), unit_m=1.0, map=None))  # in metres, no map
        return out

    return Source(files, read)


def register(info: DatasetInfo, source: Source) -> None:
    """Adds a dataset: its time base, protocol and labels, and how its recordings are found and read. Training,
    evaluation and the window cache then take it by ``info.name`` (``data.dataset`` in a configuration)."""
    if info.name in DATASETS:
        raise ValueError(f"a dataset {info.name!r} is registered already")
    DATASETS[info.name] = info
    SOURCES[info.name] = source


def recordings(dataset: str, root: Path, split: str, fold: str = "", with_map: bool = True) -> list[Recording]:
    """Every recording of a split (``train``, ``val`` or ``test``); ``fold`` is the held-out ETH/UCY scene, or
    ApolloScape's validation recordings (:func:`~training.data.apolloscape.apollo_val_recordings`)."""
    files = source_files(dataset, root, split, fold)  # refuses an unknown dataset or split first
    return [r for p in files for r in SOURCES[dataset].read(p, root, split, with_map)]


def source_files(dataset: str, root: Path, split: str, fold: str = "") -> list[Path]:
    """The files behind a split (also the cache key of its windows)."""
    if dataset not in DATASETS or dataset not in SOURCES:
        raise ValueError(f"unknown dataset {dataset!r}; known: {', '.join(DATASETS)}")
    if split not in ("train", "val", "test"):
        raise ValueError(f"unknown split {split!r}; known: train, val, test")
    return SOURCES[dataset].files(root, split, fold)


def locate(part: WindowSet, root: Path, dt_s: float, with_map: bool) -> Located:
    """``part``'s files under ``root`` and a reader of its recordings (at the model's time base ``dt_s`` for other
    sources' pedestrians; without maps unless ``with_map``). Refuses an unknown dataset, split or source first."""
    if part.pedestrians:
        files = source_files(part.dataset, root, "train")
        return Located(part, files, DATASETS["ethucy"], lambda: pedestrian_recordings(part.dataset, root, dt_s))
    files = source_files(part.dataset, root, part.split, part.fold)
    info = DATASETS[part.dataset]
    if part.speed != 1.0:
        return Located(part, files, info, lambda: sped_up(part, root, info.dt_s, with_map))
    return Located(part, files, info, lambda: recordings(part.dataset, root, part.split, part.fold, with_map))


def sped_up(part: WindowSet, root: Path, dt_s: float, with_map: bool) -> list[Recording]:
    """``part``'s recordings resampled onto steps ``part.speed`` times as long (:func:`resampled`) and read on the
    ``dt_s`` grid: every agent ``part.speed`` times as fast over the same map (``data.augment_speed``)."""
    recs = recordings(part.dataset, root, part.split, part.fold, with_map)
    return [replace(resampled(r, dt_s, dt_s * part.speed), name=f"{r.name}:x{part.speed:g}") for r in recs]


#: Sources whose pedestrians can join the ETH/UCY training windows (``data.extra_pedestrians``).
PEDESTRIAN_SOURCES = ("sdd",)


def resampled(rec: Recording, dt_from_s: float, dt_to_s: float) -> Recording:
    """``rec`` (steps ``dt_from_s`` apart) on a grid of steps ``dt_to_s`` apart, each agent's track sampled by the
    engine as a frame samples it (``dgan.sample_track``, with no gap wider than one old step bridged): at a new step
    its position is interpolated linearly between its rows at the two old steps around it, and the step is left out
    where it lacks either of them. Sizes are carried from the earlier of the two rows; headings are not (a model at
    the new rate takes them from the motion)."""
    ratio = dt_to_s / dt_from_s
    steps, agents, xys, labels = [], [], [], []
    sizes: dict[str, list[Any]] = {k: [] for k in ("length", "width") if getattr(rec, k) is not None}
    for agent in np.unique(rec.agent):
        sel = np.flatnonzero(rec.agent == agent)
        old = rec.step[sel]
        new = np.arange(np.ceil(old[0] / ratio - 1e-9), np.floor(old[-1] / ratio + 1e-9) + 1).astype(np.int64)
        xy = dgan.sample_track(old * dt_from_s, rec.xy[sel], new * dt_to_s, dt=dt_to_s, max_gap=dt_from_s)
        ok = np.isfinite(xy[:, 0])
        steps.append(new[ok])
        agents.append(np.full(int(ok.sum()), agent))
        xys.append(xy[ok])
        labels.append(np.full(int(ok.sum()), rec.label[sel[0]]))
        if sizes:
            earlier = np.clip(np.searchsorted(old, np.floor(new[ok] * ratio + 1e-9), side="right") - 1, 0, len(old) - 1)
            for k, v in sizes.items():
                v.append(getattr(rec, k)[sel][earlier])
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
        **{k: np.concatenate(v) for k, v in sizes.items()},
    )


def pedestrian_recordings(source: str, root: Path, dt_s: float) -> list[Recording]:
    """The pedestrians of ``source``'s training split, in metres, resampled to ``dt_s`` and labelled with ETH/UCY's one
    label, without their maps (a model whose map is optional sees a blank crop for them, as under map dropout). The
    source's other agents are left out: the ETH/UCY models know only pedestrians."""
    if source not in PEDESTRIAN_SOURCES:
        raise ValueError(f"unknown pedestrian source {source!r}; known: {', '.join(PEDESTRIAN_SOURCES)}")
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


# ---- Driving scenes with vector HD maps (nuScenes, Waymo, Argoverse 2) -----------------------------------------------


for _name, _source in RESAMPLED.items():
    SOURCES[_name] = _at(_source, PROTOCOL_OF[_name])
