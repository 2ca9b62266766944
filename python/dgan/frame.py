"""The scene at the current time: :class:`Frame`, and its maps :class:`RasterMap` and :class:`VectorMap`."""

from __future__ import annotations

import os
from collections.abc import Iterable, Sequence
from typing import Any, Final

import numpy as np
import numpy.typing as npt

from dgan import _dgan
from dgan.exceptions import InvalidFrameError, InvalidMapError, UnknownClassError

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
    """Integer ids as they are; other ids (strings, say) as codes 0..N with the labels kept."""
    if ids is None:
        return None, None
    arr = np.asarray(ids)
    if arr.dtype.kind == "i" or (arr.dtype.kind == "u" and (arr.size == 0 or arr.max() <= np.iinfo(np.int64).max)):
        return _array("ids", arr, np.int64), None
    if arr.dtype.kind == "u":  # uint64 ids past int64 (hashes): kept as labels
        arr = arr.astype(object)
    if arr.dtype.kind == "f":
        if not np.all(np.isfinite(arr)) or np.any(arr != np.round(arr)):
            raise InvalidFrameError("float ids must be whole finite numbers (NaN or fractional ids are ambiguous)")
        return _array("ids", arr, np.int64), None
    if arr.dtype.kind not in "OUS" or arr.ndim != 1:
        raise InvalidFrameError(f"ids must be a 1-D array of integers or strings, got {arr.dtype} {arr.shape}")
    labels = np.asarray(arr, dtype=object)
    if any(v is None or (isinstance(v, float) and not np.isfinite(v)) for v in labels):
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

    __slots__ = ("_frame", "_labels", "_map")

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
        dt: float | None = None,
    ) -> None:
        pos = _array("positions", positions, np.float64, required=True)
        if map is not None and not isinstance(map, (RasterMap, VectorMap)):
            raise InvalidMapError(f"map must be a dgan.RasterMap or dgan.VectorMap, got {type(map).__name__}")
        n = pos.shape[0] if pos.ndim >= 1 else 0
        codes, self._labels = _ids(ids, n)
        self._map = map
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
    def _wrap(cls, native: _dgan.Frame, labels: npt.NDArray[Any] | None, map: RasterMap | VectorMap | None) -> Frame:
        out = cls.__new__(cls)
        out._frame, out._labels, out._map = native, labels, map
        return out

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
    ) -> Frame:
        """A frame from a long table, one row per agent and time, resampled to a model's time base.

        Args:
            records: any table: a dict of arrays, a sequence of records (dicts), a numpy structured array, a pandas
                or polars DataFrame, a pyarrow Table, or anything with the Arrow stream or dataframe interchange
                interface (:func:`dgan.io.columns`). Ids may be integers or strings.
            t_obs, dt: the frame's steps and the seconds between them; both from ``spec`` (an
                :class:`~dgan.InputSpec` or a :class:`~dgan.Predictor`) if given. ``dt`` None: the data's own
                spacing (the smallest gap between distinct times).
            time_unit: seconds per unit of the time column (0.04 for video frames at 25 fps, 1e-9 for nanoseconds).
            current_time: the frame's current time t_obs, in the time column's unit (the latest time if None); it
                must be a time of the table.
            max_gap: the longest gap in seconds between two rows of an agent that is interpolated (1.5 · dt if None).

        Data denser than ``dt`` or irregular are interpolated linearly at the grid times; steps an agent was not seen
        are masked out; data sparser than ``dt`` are refused. Agents with a row at ``current_time`` are the frame's
        agents; optional columns (class, heading, length, width, velocity) are read at that row and may be absent.

        Raises:
            InvalidFrameError: a missing column, a current time with no row, two rows of one agent at one time.
            TimeBaseError: data sparser than ``dt``, a non-positive ``dt`` or ``time_unit``.
        """
        from dgan.exceptions import TimeBaseError
        from dgan.io import columns

        if spec is not None:
            spec = getattr(spec, "spec", spec)
            t_obs = spec.t_obs if t_obs is None else t_obs
            dt = spec.dt_s if dt is None else dt
        if t_obs is None:
            raise InvalidFrameError("from_records needs t_obs (or spec=, a model's InputSpec or Predictor)")
        if dt is not None and not (isinstance(dt, (int, float)) and np.isfinite(dt) and dt > 0):
            raise TimeBaseError(f"dt must be a positive number of seconds, got {dt!r}")
        if isinstance(t_obs, bool) or not isinstance(t_obs, (int, np.integer)) or not 1 <= t_obs <= 1000:
            raise InvalidFrameError(f"t_obs must be an integer in 1..=1000, got {t_obs!r}")
        if not (isinstance(time_unit, (int, float)) and np.isfinite(time_unit) and time_unit > 0):
            raise TimeBaseError(f"time_unit must be a positive number of seconds per unit, got {time_unit!r}")
        cols = columns(records)
        for required in (agent_id, time, x, y):
            if required not in cols:
                raise InvalidFrameError(f"records lack the column {required!r}; they have {list(cols)}")

        def num(name: str) -> npt.NDArray[np.float64] | None:
            if name not in cols:
                return None
            c = cols[name]
            if c.dtype.kind not in "biuf":
                raise InvalidFrameError(f"column {name!r} must be numeric, got {c.dtype}")
            return np.ascontiguousarray(c, dtype=np.float64)

        times, xs, ys = num(time), num(x), num(y)
        assert times is not None
        assert xs is not None
        assert ys is not None
        if not np.all(np.isfinite(times)):
            raise InvalidFrameError("the time column holds NaN or infinite values")
        raw_ids = cols[agent_id]
        if raw_ids.dtype.kind in "iu":
            codes, labels = np.ascontiguousarray(raw_ids, dtype=np.int64), None
        else:
            if raw_ids.dtype.kind == "f" and not np.all(np.isfinite(raw_ids)):
                raise InvalidFrameError(f"the id column {agent_id!r} holds NaN or infinite values")
            if any(v is None for v in raw_ids.tolist()):
                raise InvalidFrameError(f"the id column {agent_id!r} holds None")
            try:
                uniq, inverse = np.unique(raw_ids, return_inverse=True)
            except TypeError:
                raise InvalidFrameError(f"the id column {agent_id!r} mixes types that cannot be ordered") from None
            codes, labels = np.ascontiguousarray(inverse.ravel(), dtype=np.int64), uniq.astype(object)
            if raw_ids.dtype.kind == "f" and np.all(uniq == np.round(uniq)):
                labels = uniq.astype(np.int64)
        uniq_t = np.unique(times)
        if uniq_t.size == 0:
            return cls(np.zeros((0, t_obs, 2)), map=map, dt=dt)
        if dt is None:
            gaps = np.diff(uniq_t)
            dt = float(f"{float(gaps.min()) * time_unit:.9g}") if gaps.size else 1.0
        now = float(uniq_t.max()) if current_time is None else float(current_time)
        tol = 1e-6 * dt / time_unit
        if not np.any(np.abs(uniq_t - now) <= tol):
            raise InvalidFrameError(
                f"no row at current_time {now:g}; the table spans {uniq_t[0]:g}..{uniq_t[-1]:g} "
                f"({uniq_t.size} distinct times)"
            )
        now = float(uniq_t[np.argmin(np.abs(uniq_t - now))])
        klass = cols.get(cls_column)
        rows = {
            "ids": codes,
            "times": np.ascontiguousarray(times * time_unit),
            "xs": xs,
            "ys": ys,
            "classes": None if klass is None else klass.tolist(),
            "headings": num(heading),
            "lengths": num(length),
            "widths": num(width),
            "vxs": num(velocity[0]) if velocity[1] in cols else None,
            "vys": num(velocity[1]) if velocity[0] in cols else None,
        }
        native = _dgan.frame_from_rows(
            rows,
            now * time_unit,
            int(t_obs),
            float(dt),
            max_gap,
            default_class,
        )
        frame_labels = None if labels is None else labels[native.ids]
        out = cls._wrap(native, frame_labels, None)
        return out if map is None else out.with_map(map)

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
        return Frame._wrap(self._frame.without_map(), self._labels, None)

    def with_map(self, map: RasterMap | VectorMap | None) -> Frame:
        """The same agents with ``map`` (None: :meth:`without_map`)."""
        if map is None:
            return self.without_map()
        if not isinstance(map, (RasterMap, VectorMap)):
            raise InvalidMapError(f"map must be a dgan.RasterMap or dgan.VectorMap, got {type(map).__name__}")
        return Frame._wrap(self._frame.with_map(map._map), self._labels, map)

    def __repr__(self) -> str:
        return f"Frame(agents={len(self)}, steps={self.positions.shape[1]}, dt={self.dt}, map={self._map!r})"
