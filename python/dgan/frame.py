"""The scene at the current time: :class:`Frame`, and its maps :class:`RasterMap` and :class:`VectorMap`."""

from __future__ import annotations

import os
from collections.abc import Iterable, Sequence
from typing import Any, Final

import numpy as np
import numpy.typing as npt

from dgan import _dgan
from dgan.exceptions import InvalidFrameError, InvalidMapError, UnknownClassError
from dgan.io import as_given

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


def typename(value: Any) -> str:
    """How an error message names what it was given: ``None``, or the type's name."""
    return "None" if value is None else type(value).__name__


#: The array kinds each target dtype accepts without losing information (numpy ``dtype.kind`` codes).
_ACCEPTED_KINDS = {"f": "fiu", "i": "iu", "b": "b", "u": "u"}
#: The largest number of values one input array may hold (2³¹: 16 GiB of float64).
MAX_ARRAY_VALUES: Final = 2**31


def _array(
    name: str,
    value: Any,
    dtype: npt.DTypeLike,
    error: type[Exception] = InvalidFrameError,
    *,
    required: bool = False,
) -> Any:
    """``value`` as a contiguous array of ``dtype``, refusing every conversion that would lose or invent information:
    complex, bool-as-number, strings, objects, ints out of range, a float mask that is not 0/1, a float image."""
    target = np.dtype(dtype)
    if value is None:
        if required:
            raise error(f"{name} is required, got None")
        return None
    try:
        arr = np.asarray(value)
    except (TypeError, ValueError, OverflowError, MemoryError) as exc:
        raise error(f"{name} must be an array of {target.name}: {exc}") from None
    if arr.size > MAX_ARRAY_VALUES:
        raise error(f"{name} has {arr.size} values; at most {MAX_ARRAY_VALUES} are accepted")
    kind = arr.dtype.kind
    if target == np.uint8 and kind != "u" and arr.size:
        raise error(f"{name} must be uint8, got {arr.dtype}; convert it yourself (e.g. (img * 255).round())")
    if target.kind == "b" and kind in "fiu":
        # A mask given as numbers: only exact 0 and 1 (NaN or 0.5 are not "observed").
        if arr.size and not np.all((arr == 0) | (arr == 1)):
            raise error(f"{name} must be bool or 0/1, got values such as {arr[(arr != 0) & (arr != 1)].flat[0]!r}")
    elif kind not in _ACCEPTED_KINDS.get(target.kind, target.kind) and arr.size:
        what = {"c": "complex", "b": "bool", "U": "string", "S": "bytes", "O": "object", "M": "datetime"}.get(
            kind, kind
        )
        raise error(f"{name} must be an array of {target.name}, got {what} values ({arr.dtype})")
    if target.kind in "iu" and kind in "iu" and arr.size:
        info = np.iinfo(target)
        if arr.min() < info.min or arr.max() > info.max:
            raise error(f"{name} holds values outside the range of {target.name} ({info.min}..{info.max})")
    if arr.size == 0:  # nothing to convert (and no casting warning for an empty complex array)
        return np.zeros(arr.shape, dtype=target)
    try:
        return np.ascontiguousarray(arr, dtype=target)
    except (TypeError, ValueError, OverflowError) as exc:
        raise error(f"{name} must be an array of {target.name}: {exc}") from None


class RasterMap:
    """An RGB image of the scene and its 3×3 homography from world metres to pixels.

    Pixels are ``(u, v)`` = (column, row) with integer values at pixel centres. ``image`` is ``(H, W, 3)`` uint8.
    """

    __slots__ = ("_map",)

    def __init__(self, image: npt.ArrayLike, world_to_pixel: npt.ArrayLike) -> None:
        img = _array("image", image, np.uint8, InvalidMapError, required=True)
        h = _array("world_to_pixel", world_to_pixel, np.float64, InvalidMapError, required=True)
        self._map = _dgan.RasterMap(img, h)

    @classmethod
    def from_file(cls, path: str | os.PathLike[str], world_to_pixel: npt.ArrayLike) -> RasterMap:
        """Reads a PNG or JPEG image (converted to RGB)."""
        h = _array("world_to_pixel", world_to_pixel, np.float64, InvalidMapError, required=True)
        obj = cls.__new__(cls)
        obj._map = _dgan.RasterMap.from_file(os.fspath(path), h)
        return obj

    @classmethod
    def from_pixel_to_world(cls, image_path: str | os.PathLike[str], pixel_to_world: npt.ArrayLike) -> RasterMap:
        """Reads an image whose homography is given pixel → world (as ETH/UCY's ``H.txt``)."""
        h = _array("pixel_to_world", pixel_to_world, np.float64, InvalidMapError, required=True)
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
            items.append((kind, _array(f"points of element {k}", points, np.float64, InvalidMapError, required=True)))
        self._map = _dgan.VectorMap(items)

    def elements(self) -> list[tuple[str, npt.NDArray[np.float64]]]:
        """The elements, in drawing order."""
        return self._map.elements()

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

    def __len__(self) -> int:
        return len(self._map)

    def __reduce__(self) -> tuple[Any, ...]:
        return (VectorMap, (self.elements(),))

    def __repr__(self) -> str:
        return f"VectorMap({len(self)} elements)"


def _classes(classes: Sequence[ClassLike] | npt.ArrayLike | None, n: int) -> list[Any]:
    if classes is None:
        return ["pedestrian"] * n
    if isinstance(classes, (str, bytes)) or not hasattr(classes, "__iter__"):
        raise InvalidFrameError(f"classes must be a sequence with one class per agent, got {typename(classes)}")
    out = np.asarray(classes).tolist() if isinstance(classes, np.ndarray) else list(classes)  # type: ignore[arg-type]
    for c in out:
        if isinstance(c, bool) or not isinstance(c, (str, int)):
            raise UnknownClassError(f"a class must be a name {CLASSES} or a code 0, 1, 2; got {c!r}")
    return out


def _ids(ids: Any, n: int) -> tuple[npt.NDArray[np.int64] | None, npt.NDArray[Any] | None]:
    """Signed integer ids as they are; other ids (strings, uint64 hashes, a mix) as codes 0..N with the ids kept as
    given."""
    if ids is None:
        return None, None
    arr = as_given(ids)
    if arr.dtype.kind == "i":
        return _array("ids", arr, np.int64), None
    if arr.dtype.kind == "f":
        if not np.all(np.isfinite(arr)) or np.any(arr != np.round(arr)):
            raise InvalidFrameError("float ids must be whole finite numbers (NaN or fractional ids are ambiguous)")
        return _array("ids", arr, np.int64), None
    if arr.dtype.kind not in "OUSu" or arr.ndim != 1:
        raise InvalidFrameError(f"ids must be a 1-D array of integers or strings, got {arr.dtype} {arr.shape}")
    labels = arr.copy() if arr.dtype.kind == "u" else np.asarray(arr, dtype=object)
    if labels.dtype == object and any(v is None or (isinstance(v, float) and not np.isfinite(v)) for v in labels):
        raise InvalidFrameError("ids hold None or NaN")
    if len({*labels.tolist()}) != labels.size:
        raise InvalidFrameError("ids repeat")
    return np.arange(labels.size, dtype=np.int64), labels


class Frame:
    """The scene at the current time t_obs.

    Args:
        positions: ``(N, T_obs, 2)`` world positions in metres, oldest step first; the last step is t_obs.
        mask: ``(N, T_obs)`` bool, True where a step was observed (all observed if None). Masked-out positions are
            ignored, whatever they hold (NaN is fine there).
        classes: one class per agent, names (``"vehicle"``, ``"cyclist"``, ``"pedestrian"``) or codes 0, 1, 2;
            all pedestrians if None.
        ids: ``(N,)`` unique ids, integers or strings (``0..N`` if None); returned in ``Prediction.agent_ids``.
        headings: ``(N,)`` world headings in radians; NaN where unknown (then the direction of motion).
        velocities: ``(N, 2)`` world velocities in m/s; NaN rows where unknown (then from the history).
        lengths, widths: ``(N,)`` metres; NaN keeps the class default.
        map: a :class:`RasterMap` or :class:`VectorMap` of the scene.
        dt: seconds between the steps. A model refuses a frame whose ``dt`` differs from its own
            (:class:`~dgan.exceptions.TimeBaseError`); None takes the steps as the model's.

    Raises:
        InvalidFrameError: wrong shapes, non-finite valid positions, an agent without a valid step.
        UnknownClassError: a class dgan does not know.
        TimeBaseError: a ``dt`` that is not a positive number of seconds.
    """

    __slots__ = ("_frame", "_labels", "_map", "_source")

    def __init__(
        self,
        positions: npt.ArrayLike,
        mask: npt.ArrayLike | None = None,
        classes: Sequence[ClassLike] | npt.ArrayLike | None = None,
        ids: npt.ArrayLike | Sequence[object] | None = None,
        headings: npt.ArrayLike | None = None,
        velocities: npt.ArrayLike | None = None,
        lengths: npt.ArrayLike | None = None,
        widths: npt.ArrayLike | None = None,
        map: RasterMap | VectorMap | None = None,
        dt: float | None = None,
    ) -> None:
        pos = _array("positions", positions, np.float64, required=True)
        if map is not None and not isinstance(map, (RasterMap, VectorMap)):
            raise InvalidMapError(f"map must be a dgan.RasterMap or dgan.VectorMap, got {type(map).__name__}")
        n = pos.shape[0] if pos.ndim >= 1 else 0
        codes, self._labels = _ids(ids, n)
        self._map = map
        self._source: tuple[float | None, bool] | None = None
        self._frame = _dgan.Frame(
            pos,
            _array("mask", mask, np.bool_),
            _classes(classes, n),
            codes,
            _array("headings", headings, np.float64),
            _array("velocities", velocities, np.float64),
            _array("lengths", lengths, np.float64),
            _array("widths", widths, np.float64),
            None if map is None else map._map,
            None if dt is None else float(dt),
        )

    @classmethod
    def _wrap(
        cls,
        native: _dgan.Frame,
        labels: npt.NDArray[Any] | None,
        map: RasterMap | VectorMap | None,
        source: tuple[float | None, bool] | None = None,
    ) -> Frame:
        out = cls.__new__(cls)
        out._frame, out._labels, out._map, out._source = native, labels, map, source
        return out

    def _state(self, index: npt.NDArray[np.int64] | None = None) -> tuple[Any, ...]:
        """What the native frame is rebuilt from (:func:`_native_from`), of every agent or of those at ``index``."""
        f = self._frame
        arrays: tuple[npt.NDArray[Any], ...] = (
            f.positions,
            f.mask,
            f.ids,
            f.headings,
            f.velocities,
            f.lengths,
            f.widths,
        )
        classes = f.classes
        if index is not None:
            arrays = tuple(np.ascontiguousarray(a[index]) for a in arrays)
            classes = [classes[i] for i in index]
        return arrays, classes, f.dt

    def __reduce__(self) -> tuple[Any, ...]:
        """Pickles as its arrays (for multiprocessing, Ray, Dask): the engine's ids, the ids as given, the map."""
        return (_unpickle_frame, (self._state(), self._labels, self._map, self._source))

    @classmethod
    def from_records(
        cls,
        records: Any,
        *,
        t_obs: int | None = None,
        dt: float | None = None,
        spec: Any = None,
        time_unit: float = 1.0,
        current_time: float | None = None,
        max_gap: float | None = None,
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
        duplicates: str = "error",
        upsample: bool = False,
    ) -> Frame:
        """A frame from a long table, one row per agent and time, resampled to a model's time base.

        Args:
            records: any table: a dict of arrays, a sequence of records (dicts), a numpy structured array, a pandas
                or polars DataFrame, a pyarrow Table, or anything with the Arrow stream or dataframe interchange
                interface (:func:`dgan.io.columns`). Ids may be integers, strings or a mix; they come back as given.
            t_obs, dt: the frame's steps and the seconds between them; both from ``spec`` (an
                :class:`~dgan.InputSpec` or a :class:`~dgan.Predictor`) if given. ``dt`` None: the data's own
                spacing (the smallest gap between distinct times).
            time_unit: seconds per unit of the time column (0.04 for video frames at 25 fps, 1e-9 for nanoseconds).
            current_time: the frame's current time t_obs, in the time column's unit (the latest time if None); it
                must be a time of the table.
            max_gap: the longest gap in seconds between two rows of an agent that is interpolated (1.5 · dt if None).
            duplicates: several rows of one agent at one time: ``"error"`` (refused), ``"first"`` or ``"last"``
                (in row order), ``"mean"`` (positions, sizes, velocities averaged; headings by circular mean).
            upsample: interpolate data up to 2.5× sparser than ``dt`` onto its grid (2 Hz data for a 0.4 s model),
                bridging gaps up to 1.5× the data's spacing; :attr:`upsampled` records it.

        Data denser than ``dt`` or irregular are interpolated linearly at the grid times; steps an agent was not seen
        are masked out. Agents with a row at ``current_time`` are the frame's agents; optional columns (class,
        heading, length, width, velocity) are read at that row and may be absent: a column of a close name
        (``Class``) is not read and warns (:class:`~dgan.exceptions.ColumnWarning`). A frame in which no agent has
        two observed steps warns that the time unit may be wrong (:class:`~dgan.exceptions.TimeUnitWarning`).

        Raises:
            InvalidFrameError: a missing column, a current time with no row, repeated (agent, time) rows.
            TimeBaseError: data sparser than ``dt`` (naming the bundled models whose step fits), a non-positive
                ``dt`` or ``time_unit``.
        """
        from dgan.records import Names, from_records

        names = Names(agent_id, time, x, y, cls_column, heading, length, width, *velocity)
        return from_records(
            cls,
            records,
            t_obs=t_obs,
            dt=dt,
            spec=spec,
            time_unit=time_unit,
            current_time=current_time,
            max_gap=max_gap,
            names=names,
            default_class=default_class,
            map=map,
            duplicates=duplicates,
            upsample=upsample,
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
        """``(N,)`` the engine's integer agent ids (codes 0..N where the ids given were strings)."""
        return self._frame.ids

    @property
    def agent_ids(self) -> npt.NDArray[Any]:
        """``(N,)`` the ids as given: integers, or the strings (an object array)."""
        return self._frame.ids if self._labels is None else self._labels

    def select(self, rows: npt.ArrayLike) -> Frame:
        """The frame of the agents at ``rows`` (integer indices or a boolean mask), in that order, with their ids,
        states and the map."""
        index = np.arange(len(self))[np.asarray(rows)] if len(self) else np.zeros(0, dtype=np.int64)
        labels = None if self._labels is None else self._labels[index]
        return _unpickle_frame(self._state(index), labels, self._map, self._source)

    @property
    def source_dt(self) -> float | None:
        """For a frame of :meth:`from_records`: the median spacing in seconds of the rows it resampled (None when no
        agent had two rows in the window, or for a frame built from arrays)."""
        return None if self._source is None else self._source[0]

    @property
    def upsampled(self) -> bool:
        """Whether :meth:`from_records` interpolated data sparser than ``dt`` onto its grid (``upsample=True``)."""
        return self._source is not None and self._source[1]

    @property
    def dt(self) -> float | None:
        """Seconds between steps, None where the frame does not know its time base."""
        return self._frame.dt

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
        return Frame._wrap(self._frame.without_map(), self._labels, None, self._source)

    def with_map(self, map: RasterMap | VectorMap | None) -> Frame:
        """The same agents with ``map`` (None: :meth:`without_map`)."""
        if map is None:
            return self.without_map()
        if not isinstance(map, (RasterMap, VectorMap)):
            raise InvalidMapError(f"map must be a dgan.RasterMap or dgan.VectorMap, got {type(map).__name__}")
        return Frame._wrap(self._frame.with_map(map._map), self._labels, map, self._source)

    def __repr__(self) -> str:
        return f"Frame(agents={len(self)}, steps={self.positions.shape[1]}, dt={self.dt}, map={self._map!r})"


def _unpickle_frame(
    state: tuple[Any, ...],
    labels: npt.NDArray[Any] | None,
    map: RasterMap | VectorMap | None,
    source: tuple[float | None, bool] | None,
) -> Frame:
    """A frame from :meth:`Frame._state` and what the Python side keeps (for pickling and :meth:`Frame.select`)."""
    (pos, mask, codes, headings, velocities, lengths, widths), classes, dt = state
    native = _dgan.Frame(pos, mask, classes, codes, headings, velocities, lengths, widths, None, dt)
    out = Frame._wrap(native, labels, None, source)
    return out if map is None else out.with_map(map)
