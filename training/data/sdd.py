"""Stanford Drone, multi-class (Multiclass-SGCN's ``multiclass_step10``): pixels made metres by each video's scale,
its box-filtered ``reference.jpg`` as the raster map."""

from __future__ import annotations

import re
from functools import cache
from pathlib import Path

import numpy as np

from dgan.scenes import SDD_LABEL_CLASS, sdd_raster_map
from training.data.recording import Recording

#: Target resolution of the box-filtered SDD reference images, metres per pixel.
SDD_MAP_RESOLUTION_M = 0.25


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
    labels = tuple(SDD_LABEL_CLASS)  # the sdd dataset's labels (training.data.datasets.DATASETS)
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
