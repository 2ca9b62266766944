"""Maps of a scene: :class:`RasterMap` (an image and its homography) and :class:`VectorMap` (typed polylines and
polygons, drawn by the engine in the contract's colours)."""

from __future__ import annotations

import os
from collections.abc import Iterable
from typing import Any

import numpy as np
import numpy.typing as npt

from dgan import _dgan
from dgan._values import checked_array, checked_shift, typename
from dgan.contract import MAP_ELEMENT_KINDS
from dgan.exceptions import InvalidMapError


class RasterMap:
    """An RGB image of the scene and its 3×3 homography from world metres to pixels.

    Pixels are ``(u, v)`` = (column, row) with integer values at pixel centres. ``image`` is ``(H, W, 3)`` uint8.
    """

    __slots__ = ("__weakref__", "_map")

    def __init__(self, image: npt.ArrayLike, world_to_pixel: npt.ArrayLike) -> None:
        img = checked_array("image", image, np.uint8, InvalidMapError, required=True)
        h = checked_array("world_to_pixel", world_to_pixel, np.float64, InvalidMapError, required=True)
        self._map = _dgan.RasterMap(img, h)

    @classmethod
    def from_file(cls, path: str | os.PathLike[str], world_to_pixel: npt.ArrayLike) -> RasterMap:
        """Reads a PNG or JPEG image (converted to RGB)."""
        if not isinstance(path, (str, os.PathLike)):
            raise InvalidMapError(f"path must be an image file's path, got {typename(path)}")
        h = checked_array("world_to_pixel", world_to_pixel, np.float64, InvalidMapError, required=True)
        obj = cls.__new__(cls)
        obj._map = _dgan.RasterMap.from_file(os.fspath(path), h)
        return obj

    @classmethod
    def from_pixel_to_world(cls, image_path: str | os.PathLike[str], pixel_to_world: npt.ArrayLike) -> RasterMap:
        """Reads an image whose homography is given pixel → world (as ETH/UCY's ``H.txt``)."""
        h = checked_array("pixel_to_world", pixel_to_world, np.float64, InvalidMapError, required=True)
        if h.shape != (3, 3):
            raise InvalidMapError(f"pixel_to_world must be 3×3, got {h.shape}")
        try:
            inv = np.linalg.inv(h)
        except np.linalg.LinAlgError:
            raise InvalidMapError("pixel_to_world is singular") from None
        return cls.from_file(image_path, inv)

    @property
    def image(self) -> npt.NDArray[np.uint8]:
        """The image, ``(H, W, 3)``."""
        img = self._map.image
        assert img is not None
        return img

    @property
    def world_to_pixel(self) -> npt.NDArray[np.float64]:
        """The world → pixel homography."""
        h = self._map.world_to_pixel
        assert h is not None
        return h

    def moved(self, shift_m: npt.ArrayLike) -> RasterMap:
        """The same image with every world coordinate moved by ``shift_m`` ``(x, y)`` metres: what lay at world point
        ``p`` lies at ``p + shift_m`` (the same scene under another origin). The new map keeps no features.

        Raises:
            InvalidMapError: ``shift_m`` is not two finite numbers.
        """
        dx, dy = checked_shift("shift_m", shift_m, InvalidMapError)
        return RasterMap(
            self.image, self.world_to_pixel @ np.array([[1.0, 0.0, -dx], [0.0, 1.0, -dy], [0.0, 0.0, 1.0]])
        )

    @property
    def features_kept(self) -> int:
        """How many tiles of scene models' features are kept with this map (contract 13: computed once per map and
        predictor, reused by every later call with this map; at most 512, the least recently used replaced first)."""
        return self._map.features_kept

    def __reduce__(self) -> tuple[Any, ...]:
        return (RasterMap, (self.image, self.world_to_pixel))

    def __repr__(self) -> str:
        return f"RasterMap(image={self.image.shape})"


class VectorMap:
    """Typed polylines and polygons of a semantic HD map, in world metres.

    ``elements`` are ``(kind, points)`` pairs with ``points`` of shape ``(P, 2)``; kinds are
    :data:`MAP_ELEMENT_KINDS`. Polylines need 2 points, polygons (crosswalk, bike lane, obstacle) 3.
    """

    __slots__ = ("_map",)

    def __init__(self, elements: Iterable[tuple[str, npt.ArrayLike]] = ()) -> None:
        if elements is None or isinstance(elements, (str, bytes)) or not hasattr(elements, "__iter__"):
            raise InvalidMapError(f"elements must be an iterable of (kind, points) pairs, got {typename(elements)}")
        items = []
        for k, item in enumerate(elements):
            try:
                kind, points = item
            except (TypeError, ValueError):
                raise InvalidMapError(f"element {k} must be a (kind, points) pair") from None
            if not isinstance(kind, str):
                raise InvalidMapError(f"element {k}'s kind must be a string of {MAP_ELEMENT_KINDS}, got {kind!r}")
            items.append(
                (kind, checked_array(f"points of element {k}", points, np.float64, InvalidMapError, required=True))
            )
        self._map = _dgan.VectorMap(items)

    def elements(self) -> list[tuple[str, npt.NDArray[np.float64]]]:
        """The elements, in drawing order."""
        return self._map.elements()

    def moved(self, shift_m: npt.ArrayLike) -> VectorMap:
        """The same elements with every point moved by ``shift_m`` ``(x, y)`` metres (the same scene under another
        origin). The new map keeps no tiles or features.

        Raises:
            InvalidMapError: ``shift_m`` is not two finite numbers.
        """
        shift = checked_shift("shift_m", shift_m, InvalidMapError)
        return VectorMap([(kind, points + shift) for kind, points in self.elements()])

    def to_json(self, path: str | os.PathLike[str]) -> None:
        """Writes the map as dgan's vector-map JSON (``{"format": "dgan.vector_map", "version": 1, "elements":
        [{"kind": ..., "points": [[x, y], ...]}, ...]}``), what :meth:`from_json` and ``dgan predict --map`` read."""
        import json

        doc = {
            "format": "dgan.vector_map",
            "version": 1,
            "elements": [{"kind": k, "points": p.tolist()} for k, p in self.elements()],
        }
        with open(path, "w") as f:
            json.dump(doc, f)

    @classmethod
    def from_json(cls, path: str | os.PathLike[str]) -> VectorMap:
        """Reads dgan's vector-map JSON (see :meth:`to_json`).

        Raises:
            InvalidMapError: not readable, not that format, or bad elements.
        """
        import json

        try:
            with open(path) as f:
                doc = json.load(f)
        except (OSError, UnicodeDecodeError, json.JSONDecodeError) as e:
            raise InvalidMapError(f"cannot read vector map {path}: {e}") from None
        if not isinstance(doc, dict) or doc.get("format") != "dgan.vector_map":
            raise InvalidMapError(f"{path} is not a dgan vector map (format 'dgan.vector_map')")
        if doc.get("version") != 1:
            raise InvalidMapError(f"{path}: unsupported dgan vector map version {doc.get('version')!r} (this dgan: 1)")
        elements = doc.get("elements")
        if not isinstance(elements, list):
            raise InvalidMapError(f"{path}: 'elements' must be a list")
        try:
            return cls((e["kind"], e["points"]) for e in elements)
        except (KeyError, TypeError):
            raise InvalidMapError(f"{path}: each element needs 'kind' and 'points'") from None

    @property
    def tiles_kept(self) -> int:
        """How many tiles of this map are kept for the crops of models with ``map.render = "tiles"`` (drawn once,
        reused by every later call with this map; at most 512, the least recently used replaced first)."""
        return self._map.tiles_kept

    @property
    def features_kept(self) -> int:
        """How many tiles of scene models' features are kept with this map (contract 13: computed once per map and
        predictor, reused by every later call with this map; at most 512, the least recently used replaced first)."""
        return self._map.features_kept

    def __len__(self) -> int:
        return len(self._map)

    def __reduce__(self) -> tuple[Any, ...]:
        return (VectorMap, (self.elements(),))

    def __repr__(self) -> str:
        return f"VectorMap({len(self)} elements)"
