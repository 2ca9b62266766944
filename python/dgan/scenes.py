"""Scene maps and label mappings of the datasets the bundled models were trained on.

ETH/UCY: each scene's semantic mask, colourised, with its world→pixel homography.

The masks (``eth_ucy_scene_maps/semantic_masks`` of the shared data; MG-GAN layout) label each pixel 0..5; class 1 is
the walkable ground (97-98% of the pedestrians' points on eth, hotel and zara; 71% on univ, which has another 24% on
class 4). The other ids are undocumented, so each gets a distinct colour of the paper's palette. Their homographies
map pixels to the Social-GAN world metres; for eth and hotel the pixel vector is (row, column), for the UCY scenes
(column, row).
"""

from __future__ import annotations

import functools
import os
from collections.abc import Mapping
from pathlib import Path
from typing import Final

import numpy as np
import numpy.typing as npt

from dgan.contract import map_kind
from dgan.exceptions import InvalidMapError
from dgan.maps import RasterMap

#: Colour of each mask id, from the engine's palette: 0 unknown/outside black, 1 walkable in the crosswalk grey, then
#: the obstacle pink, road-edge yellow, centre-line green and bike-lane white.
_MASK_KINDS: Final = ("crosswalk", "obstacle", "road_edge", "lane_centerline", "bike_lane")  # not a contract copy
MASK_PALETTE: Final = np.array([(0, 0, 0), *(map_kind(k).colour for k in _MASK_KINDS)], dtype=np.uint8)
#: Scenes whose homography takes (row, column) rather than (column, row).
ROW_MAJOR_SCENES: Final = frozenset({"eth", "hotel"})
#: The ETH/UCY scenes.
ETH_UCY_SCENES: Final = ("eth", "hotel", "univ", "zara1", "zara2")


#: The contract name of every model trained on ETH/UCY (``dgan-ethucy-zara1``, …): they read its colourised masks.
MASK_MODEL_PREFIX: Final = "dgan-ethucy"
#: How far (per channel) a pixel may lie from a palette colour and still count as one (a mask saved as JPEG), and
#: the share of such pixels below which a map is no mask.
PALETTE_TOLERANCE: Final = 24
MIN_PALETTE_SHARE: Final = 0.8


def reads_masks(contract: Mapping[str, object]) -> bool:
    """Whether a model (its contract) reads the colourised ETH/UCY masks: every model trained on ETH/UCY does."""
    return str(contract.get("name", "")).startswith(MASK_MODEL_PREFIX)


def palette_share(image: npt.NDArray[np.uint8], step: int = 8) -> float:
    """The share of an ``(H, W, 3)`` image's pixels (every ``step``-th row and column) within
    :data:`PALETTE_TOLERANCE` of a colour of :data:`MASK_PALETTE`: 1 for a colourised mask, far less for a photo."""
    pixels = np.asarray(image)[::step, ::step, :3].astype(np.int16)
    if pixels.size == 0:
        return 1.0
    near = np.zeros(pixels.shape[:2], dtype=bool)
    for colour in MASK_PALETTE.astype(np.int16):
        near |= np.abs(pixels - colour).max(axis=-1) <= PALETTE_TOLERANCE
    return float(near.mean())


def colourise_mask(labels: npt.NDArray[np.integer]) -> npt.NDArray[np.uint8]:
    """``(H, W)`` mask ids → ``(H, W, 3)`` RGB in :data:`MASK_PALETTE`."""
    ids = np.asarray(labels)
    if ids.ndim == 3:
        ids = ids[..., 0]
    if ids.min() < 0 or ids.max() >= len(MASK_PALETTE):
        raise InvalidMapError(f"mask ids must be in 0..{len(MASK_PALETTE) - 1}, found {ids.min()}..{ids.max()}")
    return MASK_PALETTE[ids]


def world_to_pixel(scene: str, pixel_to_world: npt.ArrayLike) -> npt.NDArray[np.float64]:
    """The world → (column, row) homography of a scene from its ``H.txt`` (pixel → world)."""
    h = np.asarray(pixel_to_world, dtype=np.float64)
    inv = np.linalg.inv(h)
    if scene in ROW_MAJOR_SCENES:
        inv = inv[[1, 0, 2]]
    return np.asarray(inv, dtype=np.float64)


def scene_map(scene: str) -> RasterMap:
    """The raster map a bundled ETH/UCY model was trained with: ``dgan.scene_map("zara1")``. The same map object on
    every call (maps do not change), so a model that keeps its map features with the map (contract 13) computes them
    once for all the frames that hold it."""
    if not isinstance(scene, str) or scene not in ETH_UCY_SCENES:
        raise InvalidMapError(f"no bundled scene {scene!r:.60}; bundled scenes: {', '.join(ETH_UCY_SCENES)}")
    return _bundled_scene_map(scene)


@functools.lru_cache(maxsize=len(ETH_UCY_SCENES))
def _bundled_scene_map(scene: str) -> RasterMap:
    return scene_raster_map(scene, Path(__file__).parent / "data" / "scenes" / scene)


def scene_image(scene: str) -> tuple[npt.NDArray[np.uint8], npt.NDArray[np.float64]] | None:
    """The bundled camera image of a scene and its world → (column, row) homography, if bundled."""
    folder = Path(__file__).parent / "data" / "scenes" / scene
    if not (folder / "rgb.jpg").is_file():
        return None
    image = RasterMap.from_file(folder / "rgb.jpg", np.eye(3)).image
    return image, world_to_pixel(scene, np.loadtxt(folder / "H.txt"))


def scene_raster_map(scene: str, folder: str | os.PathLike[str]) -> RasterMap:
    """The colourised mask of ``scene`` from a folder holding ``<scene>_mask.png`` (or ``mask.png``) and ``H.txt``."""
    folder = Path(folder)
    mask_path = next((p for p in (folder / f"{scene}_mask.png", folder / "mask.png") if p.is_file()), None)
    if mask_path is None:
        raise InvalidMapError(f"no mask for scene {scene!r} in {folder}")
    labels = RasterMap.from_file(mask_path, np.eye(3)).image
    return RasterMap(colourise_mask(labels), world_to_pixel(scene, np.loadtxt(folder / "H.txt")))


#: Stanford Drone labels → dgan classes, as in the paper (cyclists and skateboarders together; carts, cars, buses).
SDD_LABEL_CLASS: Final = {
    "Pedestrian": "pedestrian",
    "Biker": "cyclist",
    "Skater": "cyclist",
    "Cart": "vehicle",
    "Car": "vehicle",
    "Bus": "vehicle",
}
#: ApolloScape object types → (label, dgan class). "others" (mean size 2.1 × 1.1 m) enter as small neighbours.
APOLLO_TYPES: Final = {
    1: ("small vehicle", "vehicle"),
    2: ("big vehicle", "vehicle"),
    3: ("pedestrian", "pedestrian"),
    4: ("cyclist", "cyclist"),
    5: ("others", "cyclist"),
}


def sdd_raster_map(image_path: str | os.PathLike[str], metres_per_px: float, resolution_m: float = 0.25) -> RasterMap:
    """A Stanford Drone video's ``reference.jpg`` as a raster map in the world frame ``(x, y) = (u, v) ·
    metres_per_px``, box-filtered by an integer factor to about ``resolution_m`` per pixel, so that coarse crops do
    not alias."""
    if not metres_per_px > 0:
        raise InvalidMapError(f"metres_per_px must be positive, got {metres_per_px}")
    image = RasterMap.from_file(image_path, np.eye(3)).image
    f = max(1, round(resolution_m / metres_per_px))
    h, w = (image.shape[0] // f) * f, (image.shape[1] // f) * f
    small = image[:h, :w].reshape(h // f, f, w // f, f, 3).mean(axis=(1, 3)).round().astype(np.uint8)
    # Output pixel j averages input pixels j·f … j·f + f − 1, whose centre is at j·f + (f − 1) / 2.
    s = 1.0 / (metres_per_px * f)
    off = -(f - 1) / 2 / f
    return RasterMap(small, np.array([[s, 0.0, off], [0.0, s, off], [0.0, 0.0, 1.0]]))
