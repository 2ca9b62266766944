"""The scene at the current time: :class:`Frame`, and its maps :class:`RasterMap` and :class:`VectorMap`."""

from __future__ import annotations

import os
from collections.abc import Iterable, Mapping, Sequence
from typing import Any, Final

import numpy as np
import numpy.typing as npt

from dgan import _dgan
from dgan.exceptions import InvalidFrameError, InvalidMapError

#: The classes dgan knows, by canonical integer code.
CLASSES: Final = ("vehicle", "cyclist", "pedestrian")
#: The vector-map element kinds, each drawn in the paper's colour.
MAP_ELEMENT_KINDS: Final = (
    "lane_centerline",
    "lane_line_dashed",
    "lane_line_solid",
    "road_edge",
    "crosswalk",
    "bike_lane",
    "obstacle",
)

ClassLike = str | int


def _array(name: str, value: Any, dtype: npt.DTypeLike, error: type[Exception] = InvalidFrameError) -> Any:
    if value is None:
        return None
    try:
        return np.ascontiguousarray(value, dtype=dtype)
    except (TypeError, ValueError) as exc:
        raise error(f"{name} must be an array of {np.dtype(dtype).name}: {exc}") from None


class RasterMap:
    """An RGB image of the scene and its 3×3 homography from world metres to pixels.

    Pixels are ``(u, v)`` = (column, row) with integer values at pixel centres. ``image`` is ``(H, W, 3)`` uint8.
    """

    __slots__ = ("_map",)

    def __init__(self, image: npt.ArrayLike, world_to_pixel: npt.ArrayLike) -> None:
        img = _array("image", image, np.uint8, InvalidMapError)
        h = _array("world_to_pixel", world_to_pixel, np.float64, InvalidMapError)
        self._map = _dgan.RasterMap(img, h)

    @classmethod
    def from_file(cls, path: str | os.PathLike[str], world_to_pixel: npt.ArrayLike) -> RasterMap:
        """Reads a PNG or JPEG image (converted to RGB)."""
        h = _array("world_to_pixel", world_to_pixel, np.float64, InvalidMapError)
        obj = cls.__new__(cls)
        obj._map = _dgan.RasterMap.from_file(os.fspath(path), h)
        return obj

    @classmethod
    def from_pixel_to_world(cls, image_path: str | os.PathLike[str], pixel_to_world: npt.ArrayLike) -> RasterMap:
        """Reads an image whose homography is given pixel → world (as ETH/UCY's ``H.txt``)."""
        h = _array("pixel_to_world", pixel_to_world, np.float64, InvalidMapError)
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

    def __repr__(self) -> str:
        return f"RasterMap(image={self.image.shape})"


class VectorMap:
    """Typed polylines and polygons of a semantic HD map, in world metres.

    ``elements`` are ``(kind, points)`` pairs with ``points`` of shape ``(P, 2)``; kinds are
    :data:`MAP_ELEMENT_KINDS`. Polylines need 2 points, polygons (crosswalk, bike lane, obstacle) 3.
    """

    __slots__ = ("_map",)

    def __init__(self, elements: Iterable[tuple[str, npt.ArrayLike]] = ()) -> None:
        items = []
        for k, item in enumerate(elements):
            try:
                kind, points = item
            except (TypeError, ValueError):
                raise InvalidMapError(f"element {k} must be a (kind, points) pair") from None
            items.append((str(kind), _array(f"points of element {k}", points, np.float64, InvalidMapError)))
        self._map = _dgan.VectorMap(items)

    def elements(self) -> list[tuple[str, npt.NDArray[np.float64]]]:
        """The elements, in drawing order."""
        return self._map.elements()

    def __len__(self) -> int:
        return len(self._map)

    def __repr__(self) -> str:
        return f"VectorMap({len(self)} elements)"


def _classes(classes: Sequence[ClassLike] | npt.ArrayLike | None, n: int) -> list[Any]:
    if classes is None:
        return ["pedestrian"] * n
    if isinstance(classes, str):
        raise InvalidFrameError("classes must be a sequence with one class per agent, not a single string")
    return np.asarray(classes).tolist() if isinstance(classes, np.ndarray) else list(classes)  # type: ignore[arg-type]


class Frame:
    """The scene at the current time t_obs.

    Args:
        positions: ``(N, T_obs, 2)`` world positions in metres, oldest step first; the last step is t_obs.
        mask: ``(N, T_obs)`` bool, True where a step was observed (all observed if None). Masked-out positions are
            ignored, whatever they hold (NaN is fine there).
        classes: one class per agent, names (``"vehicle"``, ``"cyclist"``, ``"pedestrian"``) or codes 0, 1, 2;
            all pedestrians if None.
        ids: ``(N,)`` unique integer ids (``0..N`` if None).
        headings: ``(N,)`` world headings in radians; NaN where unknown (then the direction of motion).
        velocities: ``(N, 2)`` world velocities in m/s; NaN rows where unknown (then from the history).
        lengths, widths: ``(N,)`` metres; NaN keeps the class default.
        map: a :class:`RasterMap` or :class:`VectorMap` of the scene.

    Raises:
        InvalidFrameError: wrong shapes, non-finite valid positions, an agent without a valid step.
        UnknownClassError: a class dgan does not know.
    """

    __slots__ = ("_frame", "_map")

    def __init__(
        self,
        positions: npt.ArrayLike,
        mask: npt.ArrayLike | None = None,
        classes: Sequence[ClassLike] | npt.ArrayLike | None = None,
        ids: npt.ArrayLike | None = None,
        headings: npt.ArrayLike | None = None,
        velocities: npt.ArrayLike | None = None,
        lengths: npt.ArrayLike | None = None,
        widths: npt.ArrayLike | None = None,
        map: RasterMap | VectorMap | None = None,
    ) -> None:
        pos = _array("positions", positions, np.float64)
        if map is not None and not isinstance(map, (RasterMap, VectorMap)):
            raise InvalidMapError(f"map must be a dgan.RasterMap or dgan.VectorMap, got {type(map).__name__}")
        n = pos.shape[0] if pos.ndim >= 1 else 0
        self._map = map
        self._frame = _dgan.Frame(
            pos,
            _array("mask", mask, np.bool_),
            _classes(classes, n),
            _array("ids", ids, np.int64),
            _array("headings", headings, np.float64),
            _array("velocities", velocities, np.float64),
            _array("lengths", lengths, np.float64),
            _array("widths", widths, np.float64),
            None if map is None else map._map,
        )

    @classmethod
    def from_records(
        cls,
        records: Mapping[str, Any] | np.ndarray,
        *,
        t_obs: int,
        dt: float | None = None,
        current_time: float | None = None,
        agent_id: str = "agent_id",
        time: str = "time",
        x: str = "x",
        y: str = "y",
        cls_column: str = "class",
        heading: str = "heading",
        length: str = "length",
        width: str = "width",
        velocity: tuple[str, str] = ("vx", "vy"),
        default_class: ClassLike = "pedestrian",
        map: RasterMap | VectorMap | None = None,
    ) -> Frame:
        """A frame from a long table, one row per agent and time.

        ``records`` is a mapping of column name → array (a dict of numpy arrays or a pandas DataFrame) or a numpy
        structured array. The frame ends at ``current_time`` (the latest time if None) and spans ``t_obs`` steps of
        ``dt`` (inferred as the smallest gap between distinct times if None). Agents observed at ``current_time``
        are included; optional columns (class, heading, length, width, velocity) are read at each agent's latest
        row and may be absent.
        """
        names = records.dtype.names if isinstance(records, np.ndarray) else tuple(records.keys())
        if names is None:
            raise InvalidFrameError("records must be a mapping of columns or a structured numpy array")

        def col(name: str, dtype: npt.DTypeLike) -> Any:
            if name not in names:
                return None
            return _array(f"column {name!r}", records[name], dtype)

        for required in (agent_id, time, x, y):
            if required not in names:
                raise InvalidFrameError(f"records lack the column {required!r}; they have {list(names)}")
        ids, times = col(agent_id, np.int64), col(time, np.float64)
        xs, ys = col(x, np.float64), col(y, np.float64)
        if t_obs < 1:
            raise InvalidFrameError(f"t_obs must be at least 1, got {t_obs}")
        if not np.all(np.isfinite(times)):
            raise InvalidFrameError("the time column holds NaN or infinite values")
        uniq = np.unique(times)
        if uniq.size == 0:
            return cls(np.zeros((0, t_obs, 2)), map=map)
        if dt is None:
            gaps = np.diff(uniq)
            dt = float(gaps.min()) if gaps.size else 1.0
        if not dt > 0:
            raise InvalidFrameError(f"dt must be positive, got {dt}")
        now = float(uniq.max()) if current_time is None else float(current_time)
        step = np.rint((times - now) / dt).astype(np.int64) + (t_obs - 1)
        on_grid = np.abs((times - now) / dt - np.rint((times - now) / dt)) < 1e-6
        keep = on_grid & (step >= 0) & (step < t_obs)
        current = np.unique(ids[keep & (step == t_obs - 1)])
        rows = keep & np.isin(ids, current)
        order = np.lexsort((step[rows], ids[rows]))
        r_ids, r_step = ids[rows][order], step[rows][order]
        index = np.searchsorted(current, r_ids)
        n = current.size
        positions = np.full((n, t_obs, 2), np.nan)
        mask = np.zeros((n, t_obs), dtype=bool)
        positions[index, r_step, 0] = xs[rows][order]
        positions[index, r_step, 1] = ys[rows][order]
        mask[index, r_step] = True
        # The latest row of each agent (rows are sorted by id, then step).
        last = np.r_[np.flatnonzero(np.diff(r_ids)), r_ids.size - 1] if n else np.zeros(0, dtype=np.int64)

        def latest(name: str, dtype: npt.DTypeLike) -> Any:
            c = col(name, dtype)
            return None if c is None else c[rows][order][last]

        klass = col(cls_column, object) if cls_column in names else None
        classes = [default_class] * n if klass is None else list(klass[rows][order][last])
        vel = None
        if velocity[0] in names and velocity[1] in names:
            vel = np.stack([latest(velocity[0], np.float64), latest(velocity[1], np.float64)], axis=1)
        return cls(
            positions,
            mask=mask,
            classes=classes,
            ids=current,
            headings=latest(heading, np.float64),
            velocities=vel,
            lengths=latest(length, np.float64),
            widths=latest(width, np.float64),
            map=map,
        )

    def __len__(self) -> int:
        return len(self._frame)

    @property
    def positions(self) -> npt.NDArray[np.float64]:
        """``(N, T_obs, 2)`` world positions."""
        return self._frame.positions

    @property
    def mask(self) -> npt.NDArray[np.bool_]:
        """``(N, T_obs)`` validity."""
        return self._frame.mask

    @property
    def ids(self) -> npt.NDArray[np.int64]:
        """``(N,)`` agent ids."""
        return self._frame.ids

    @property
    def classes(self) -> list[str]:
        """Class names, one per agent."""
        return self._frame.classes

    @property
    def lengths(self) -> npt.NDArray[np.float64]:
        """Lengths in metres (given or class default)."""
        return self._frame.lengths

    @property
    def widths(self) -> npt.NDArray[np.float64]:
        """Widths in metres (given or class default)."""
        return self._frame.widths

    @property
    def headings(self) -> npt.NDArray[np.float64]:
        """``(N,)`` given headings in world radians, NaN where unknown (then estimated from the motion)."""
        return self._frame.headings

    @property
    def velocities(self) -> npt.NDArray[np.float64]:
        """``(N, 2)`` given velocities in world m/s, NaN where unknown (then from the last two steps)."""
        return self._frame.velocities

    @property
    def map(self) -> RasterMap | VectorMap | None:
        """The scene's map."""
        return self._map

    def without_map(self) -> Frame:
        """The same agents, histories and states without a map: how a model with an optional map is run on a scene
        whose map is unknown (a model whose map is required raises :class:`~dgan.exceptions.MapRequiredError`)."""
        out = Frame.__new__(Frame)
        out._map = None
        out._frame = self._frame.without_map()
        return out

    def __repr__(self) -> str:
        return f"Frame(agents={len(self)}, steps={self.positions.shape[1]}, map={self._map!r})"
