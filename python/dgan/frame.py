"""The scene at the current time: :class:`Frame` (its maps are :mod:`dgan.maps`)."""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from typing import Any

import numpy as np
import numpy.typing as npt

from dgan import _dgan
from dgan._times import TableTime, TimeLike
from dgan._values import ClassLike, as_given, checked_array, checked_real, checked_shift
from dgan.columnnames import names_of
from dgan.exceptions import InvalidFrameError, InvalidMapError, TimeBaseError
from dgan.labels import classes_of
from dgan.maps import RasterMap, VectorMap
from dgan.records import Parsed, from_records

#: :meth:`Frame.denoised`'s default gate, metres: chosen on the ETH/UCY validation windows (0.08, 0.10 and 0.12 m
#: tried; 0.10 the lowest that kept clean top-1 ADE within 0.5% on every fold).
DENOISE_GATE_M = 0.1


def _ids(ids: Any, n: int) -> tuple[npt.NDArray[np.int64] | None, npt.NDArray[Any] | None]:
    """Signed integer ids as they are; other ids (strings, uint64 hashes, a mix) as codes 0..N with the ids kept as
    given."""
    if ids is None:
        return None, None
    arr = as_given(ids)
    if arr.dtype.kind == "i":
        return checked_array("ids", arr, np.int64), None
    if arr.dtype.kind == "f":
        if not np.all(np.isfinite(arr)) or np.any(arr != np.round(arr)):
            raise InvalidFrameError("float ids must be whole finite numbers (NaN or fractional ids are ambiguous)")
        return checked_array("ids", arr, np.int64), None
    if arr.dtype.kind not in "OUSu" or arr.ndim != 1:
        raise InvalidFrameError(f"ids must be a 1-D array of integers or strings, got {arr.dtype} {arr.shape}")
    labels = arr.copy() if arr.dtype.kind == "u" else np.asarray(arr, dtype=object)
    if labels.dtype == object and any(v is None or (isinstance(v, float) and not np.isfinite(v)) for v in labels):
        raise InvalidFrameError("ids hold None or NaN")
    if len({*labels.tolist()}) != labels.size:
        raise InvalidFrameError("ids repeat")
    return np.arange(labels.size, dtype=np.int64), labels


#: What a frame built from a table knows of it: the rows' median spacing in seconds, whether they were upsampled, and
#: the frame's time as the table wrote it.
Source = tuple[float | None, bool, TableTime | None]


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
        class_names: other labels of ``classes`` read as dgan classes (``{"car": "vehicle"}``, without case;
            :data:`dgan.COMMON_CLASS_NAMES` holds common ones).

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
        *,
        class_names: Mapping[Any, ClassLike] | None = None,
    ) -> None:
        pos = checked_array("positions", positions, np.float64, required=True)
        if map is not None and not isinstance(map, (RasterMap, VectorMap)):
            raise InvalidMapError(f"map must be a dgan.RasterMap or dgan.VectorMap, got {type(map).__name__}")
        n = pos.shape[0] if pos.ndim >= 1 else 0
        codes, self._labels = _ids(ids, n)
        self._map = map
        self._source: Source | None = None
        self._frame = _dgan.Frame(
            pos,
            checked_array("mask", mask, np.bool_),
            classes_of(classes, n, class_names),
            codes,
            checked_array("headings", headings, np.float64),
            checked_array("velocities", velocities, np.float64),
            checked_array("lengths", lengths, np.float64),
            checked_array("widths", widths, np.float64),
            None if map is None else map._map,
            checked_real("dt", dt, TimeBaseError, optional=True),
        )

    @classmethod
    def _wrap(
        cls,
        native: _dgan.Frame,
        labels: npt.NDArray[Any] | None,
        map: RasterMap | VectorMap | None,
        source: Source | None = None,
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
        current_time: TimeLike | None = None,
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
        class_names: Mapping[Any, ClassLike] | None = None,
        map: RasterMap | VectorMap | None = None,
        duplicates: str = "error",
        upsample: bool = False,
    ) -> Frame:
        """A frame from a long table, one row per agent and time, resampled to a model's time base.

        Args:
            records: any table: a dict of arrays, a sequence of records (dicts), a numpy structured array, a pandas
                or polars DataFrame, a pyarrow Table, or anything with the Arrow stream or dataframe interchange
                interface (:func:`dgan.tables.columns`). Ids may be integers, strings or a mix; they come back as given.
            t_obs, dt: the frame's steps and the seconds between them; both from ``spec`` (an
                :class:`~dgan.InputSpec` or a :class:`~dgan.Predictor`) if given. ``dt`` None: the data's own
                spacing (the smallest gap between distinct times).
            time_unit: seconds per unit of a numeric time column (0.04 for video frames at 25 fps, 1e-9 for
                nanoseconds). A column of datetimes (numpy, pandas with or without a time zone, polars, Arrow), ISO
                8601 strings or timedeltas carries its own unit; ``time_unit`` then stays 1.
            current_time: the frame's current time t_obs, in the time column's unit or kind (a datetime or ISO 8601
                string for a column of instants; the latest time if None); it must be a time of the table.
            max_gap: the longest gap in seconds between two rows of an agent that is interpolated (1.5 · dt if None).
            duplicates: several rows of one agent at one time: ``"error"`` (refused), ``"first"`` or ``"last"``
                (in row order), ``"mean"`` (positions, sizes, velocities averaged; headings by circular mean).
            upsample: interpolate data up to 2.5× sparser than ``dt`` onto its grid (2 Hz data for a 0.4 s model),
                bridging gaps up to 1.5× the data's spacing; :attr:`upsampled` records it.
            class_names: the class column's labels read as dgan classes (``{"car": "vehicle", ...}``, without case;
                :data:`dgan.COMMON_CLASS_NAMES` holds common ones); a label it does not name is read as it is.

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
        names = names_of(
            agent_id=agent_id, time=time, x=x, y=y, cls_column=cls_column, heading=heading, length=length,
            width=width, velocity=velocity,
        )  # fmt: skip
        native, labels, source = from_records(
            records,
            t_obs=t_obs,
            dt=dt,
            spec=spec,
            time_unit=time_unit,
            current_time=current_time,
            max_gap=max_gap,
            names=names,
            default_class=default_class,
            class_names=class_names,
            duplicates=duplicates,
            upsample=upsample,
        )
        return cls._of_parsed((native, labels, source), map)

    @classmethod
    def _of_parsed(cls, parsed: Parsed, map: RasterMap | VectorMap | None) -> Frame:
        """The frame of what the engine resampled from a table (:mod:`dgan.records`), with ``map``."""
        native, labels, source = parsed
        out = cls._wrap(native, labels, None, source)
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

    def select(self, rows: npt.ArrayLike) -> Frame:
        """The frame of the agents at ``rows`` (integer indices or a boolean mask), in that order, with their ids,
        states and the map; an empty list selects none. Other rows raise :class:`~dgan.exceptions.InvalidFrameError`.
        """
        r = np.asarray(rows)
        if r.size == 0 and r.dtype != bool:
            r = r.astype(np.int64)  # np.asarray([]) is float64
        if r.ndim != 1 or r.dtype.kind not in "biu":
            raise InvalidFrameError(
                f"rows must be a 1-D array of integer indices or a boolean mask, got {r.ndim}-D {r.dtype}"
            )
        try:
            index = np.arange(len(self))[r]
        except IndexError as e:
            raise InvalidFrameError(f"rows of a frame of {len(self)} agents: {e}") from None
        labels = None if self._labels is None else self._labels[index]
        return _unpickle_frame(self._state(index), labels, self._map, self._source)

    @property
    def source_dt(self) -> float | None:
        """For a frame of :meth:`from_records`: the median spacing in seconds of the rows it resampled (None when no
        agent had two rows in the window, or for a frame built from arrays)."""
        return None if self._source is None else self._source[0]

    @property
    def time(self) -> float | np.datetime64 | None:
        """The frame's current time as its table or tracker gave it: a number in the time column's unit (a
        :class:`~dgan.Tracker`'s seconds), or a ``numpy.datetime64`` for a column of instants; None for a frame built
        from arrays. A prediction of the frame counts its ``time`` column from it (:meth:`Prediction.to_records`)."""
        clock = self._table_time
        return None if clock is None else clock.now

    @property
    def _table_time(self) -> TableTime | None:
        return None if self._source is None else self._source[2]

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

    def moved(self, shift_m: npt.ArrayLike) -> Frame:
        """The same scene under another origin: every position and the map (:meth:`VectorMap.moved`,
        :meth:`RasterMap.moved`) moved by ``shift_m`` ``(x, y)`` metres; ids, classes, states and how the frame was
        sampled are kept. A model that draws each agent's crop in its own frame predicts it as before, moved; see
        docs/model-contract.md (*The map's grid and the world's origin*) for those that read a grid fixed in the world.

        Raises:
            InvalidFrameError: ``shift_m`` is not two finite numbers.
        """
        shift = checked_shift("shift_m", shift_m, InvalidFrameError)
        (positions, *rest), classes, dt = self._state()
        world_map = None if self._map is None else self._map.moved(shift)
        return _unpickle_frame(((positions + shift, *rest), classes, dt), self._labels, world_map, self._source)

    def denoised(self, gate_m: float = DENOISE_GATE_M) -> Frame:
        """The same frame with tracker noise taken out of its histories, for tracks from a detector and tracker.

        Each agent whose observed positions (four steps or more) lie off their least-squares parabola by ``gate_m``
        metres or more (root mean square) has them replaced by that parabola; the other agents, the given headings,
        velocities and sizes, the ids and the map are kept. Smooth annotated tracks (ETH/UCY's pedestrians) follow a
        parabola within a few centimetres over 3.2 s, so they pass as they are. The default was chosen on the ETH/UCY
        validation windows with the bundled models: 0.4–0.5% higher top-1 ADE on clean tracks, and with 0.1 m of
        Gaussian noise (10% of steps dropped) 14–28% below constant velocity instead of up to 17% above it. It is for
        models trained on clean tracks: on ApolloScape's noisier LiDAR tracks the same gate is mixed, and ``hdmap``,
        trained on noisy copies, is worse with it (docs/results.md). A model that declares ``denoise_gate_m``
        (contract 10; the five ETH/UCY models, 0.1 m) has the engine do this itself on every frame it predicts.

        Raises:
            InvalidFrameError: ``gate_m`` is negative or not finite.
        """
        native, _ = self._frame.denoised(checked_real("gate_m", gate_m))
        return Frame._wrap(native, self._labels, self._map, self._source)

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
    source: Source | None,
) -> Frame:
    """A frame from :meth:`Frame._state` and what the Python side keeps (for pickling and :meth:`Frame.select`)."""
    (pos, mask, codes, headings, velocities, lengths, widths), classes, dt = state
    native = _dgan.Frame(pos, mask, classes, codes, headings, velocities, lengths, widths, None, dt)
    out = Frame._wrap(native, labels, None, source)
    return out if map is None else out.with_map(map)
