"""ETH/UCY in the Social-GAN layout (metres, 0.4 s), leave-one-scene-out; each scene's colourised semantic mask is
its raster map."""

from __future__ import annotations

from functools import cache
from pathlib import Path

import numpy as np

import dgan
from dgan.scenes import scene_raster_map
from training.data.recording import Recording

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
