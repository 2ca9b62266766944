"""A streaming :class:`Tracker`: detections in, one tick at a time; predictions at any tick."""

from __future__ import annotations

import datetime as _dt
from collections.abc import Mapping, Sequence
from typing import Any

import numpy as np
import numpy.typing as npt

from dgan import _dgan
from dgan._times import TableTime, after, instant_ns
from dgan._values import ClassLike, as_given, checked_real, typename
from dgan.exceptions import InvalidFrameError, TimeBaseError
from dgan.frame import Frame
from dgan.labels import relabelled
from dgan.maps import RasterMap, VectorMap
from dgan.prediction import Prediction
from dgan.predictor import Predictor


def _column(name: str, values: npt.ArrayLike | None, n: int) -> npt.NDArray[np.float64] | None:
    if values is None:
        return None
    try:
        out = np.ascontiguousarray(values, dtype=np.float64)
    except (TypeError, ValueError) as e:
        raise InvalidFrameError(f"{name} must be numbers: {e}") from None
    if out.shape != (n,):
        raise InvalidFrameError(f"{name} must have shape ({n},), got {out.shape}")
    return out


class Tracker:
    """Keeps every agent's history at a model's time base from detections fed one tick at a time (the core is the
    engine's, shared with :meth:`Frame.from_records`): agents appear, vanish and return; ticks may come at any rate
    at least as dense as the model's (denser or jittered ticks are interpolated). The frame at a tick equals
    ``Frame.from_records`` of the same detections given at once. A tracker pickles and copies with its history (a
    service saves its state and goes on from it; a copy explores other detections), and keeps bounded memory: what
    is older than its window is forgotten, the agents' ids included.

    Args:
        predictor: the model whose time base (``dt``, ``T_obs``) the history follows.
        map: the scene's map, attached to every frame.
        max_gap: the longest gap in seconds between two detections of an agent that is interpolated (1.5 · dt).
        default_class: the class of detections that give none.
        class_names: the detections' labels read as dgan classes (as :meth:`Frame.from_records` reads them).
        denoise: a gate in metres: every frame is :meth:`Frame.denoised` with it (tracks that far or farther off
            their least-squares parabola smoothed), for a detector's noisy positions; None (the default) keeps them
            (a model that declares ``denoise_gate_m``, contract 10, smooths them in the engine all the same).

    >>> tracker = dgan.Tracker(dgan.Predictor("zara1"))  # doctest: +SKIP
    >>> tracker.update(12.4, ids=["a", "b"], positions=[[1.0, 2.0], [3.0, 4.0]])  # doctest: +SKIP
    >>> prediction = tracker.predict()  # doctest: +SKIP
    """

    def __init__(
        self,
        predictor: Predictor,
        *,
        map: RasterMap | VectorMap | None = None,
        max_gap: float | None = None,
        default_class: ClassLike = "pedestrian",
        denoise: float | None = None,
        class_names: Mapping[Any, ClassLike] | None = None,
    ) -> None:
        if not isinstance(predictor, Predictor):
            raise InvalidFrameError(f"Tracker needs a dgan.Predictor, got {typename(predictor)}")
        if denoise is not None and not (isinstance(denoise, (int, float)) and np.isfinite(denoise) and denoise >= 0):
            raise InvalidFrameError(f"denoise must be a non-negative number of metres or None, got {denoise!r}")
        self._predictor = predictor
        self._map = map
        self._denoise = None if denoise is None else float(denoise)
        spec = predictor.spec
        self._max_gap = checked_real("max_gap", max_gap, TimeBaseError, optional=True)
        self._default_class = default_class
        self._class_names = class_names
        self._origin: np.datetime64 | None = None  # the first tick's time, for a tracker fed datetimes
        relabelled([], class_names)  # a class_names that is no mapping is refused here
        self._native = _dgan.Tracker(spec.t_obs, spec.dt_s, self._max_gap, default_class)
        # Signed integer ids go to the engine as they are (agents ordered by id, as in Frame.from_records); other ids
        # (strings, uint64 hashes, a mix of integers and strings) get codes by first appearance, and the frame gives
        # the ids back as given: the integer 1 and the string '1' are two agents.
        self._integer_ids = False
        self._codes: dict[Any, int] = {}
        self._labels: dict[int, Any] = {}
        self._next_code = 0

    def __reduce__(self) -> tuple[Any, tuple[Any, ...]]:
        """A tracker pickles (and copies, ``copy.copy`` too) with what it remembers: a service can save its state
        and go on from it, a copy can be fed other detections without touching this one."""
        options = (self._predictor, self._map, self._max_gap, self._default_class, self._denoise, self._class_names)
        ids = (self._integer_ids, dict(self._labels), self._next_code)
        return _unpickle_tracker, (options, self._native.state(), ids, self._origin)

    @property
    def now(self) -> float | np.datetime64 | None:
        """The latest tick's time: seconds, or a ``numpy.datetime64`` for a tracker fed datetimes."""
        clock = self._tick_time()
        return None if clock is None else clock.now

    def _tick_time(self) -> TableTime | None:
        """The latest tick's time as the ticks gave it."""
        now = self._native.now
        if now is None:
            return None
        return TableTime(float(now)) if self._origin is None else TableTime(after(self._origin, now))

    def _seconds(self, time: Any) -> float:
        """A tick's time as the engine's seconds: a real number as it is; a datetime (or ``numpy.datetime64``) as
        seconds after this tracker's first tick, which every tick then gives as a datetime too."""
        if isinstance(time, (_dt.datetime, np.datetime64)):
            ns = instant_ns(time, "time")
            if self._native.now is not None and self._origin is None:
                raise TimeBaseError("this tracker's ticks are seconds; give seconds at every tick, not a datetime")
            if self._origin is None:
                self._origin = np.datetime64(ns, "ns")
            return float(ns - int(self._origin.astype(np.int64))) * 1e-9
        if isinstance(time, (bool, np.bool_)) or not isinstance(time, (int, float, np.integer, np.floating)):
            raise TimeBaseError(f"time must be seconds, a real number, or a datetime; got {typename(time)} {time!r}")
        if self._origin is not None:
            raise TimeBaseError("this tracker's ticks are datetimes; give a datetime at every tick, not seconds")
        return float(time)

    def __len__(self) -> int:
        """Agents remembered (seen within the history window)."""
        return len(self._native)

    def _code(self, agent: Any) -> int:
        key = agent.item() if isinstance(agent, np.generic) else agent
        if key is None or (isinstance(key, float) and not np.isfinite(key)):
            raise InvalidFrameError("an id is None or NaN")
        if key not in self._codes:
            self._codes[key] = self._next_code
            self._labels[self._next_code] = key
            self._next_code += 1
        return self._codes[key]

    def _forget_labels(self) -> None:
        """Drops the ids of agents the engine no longer remembers (out of the history window), once they are more
        than twice those it does: a stream of ever new ids keeps bounded memory. An id that returns later is a new
        agent to the engine all the same (its history was forgotten), and gets a new code."""
        if len(self._labels) <= 2 * len(self._native) + 64:
            return
        kept = set(self._native.ids().tolist())
        self._labels = {c: k for c, k in self._labels.items() if c in kept}
        self._codes = {k: c for c, k in self._labels.items()}

    def update(
        self,
        time: float | np.floating[Any] | np.integer[Any] | _dt.datetime | np.datetime64,
        ids: npt.ArrayLike | Sequence[object],
        positions: npt.ArrayLike,
        *,
        classes: list[ClassLike] | None = None,
        headings: npt.ArrayLike | None = None,
        lengths: npt.ArrayLike | None = None,
        widths: npt.ArrayLike | None = None,
        velocities: npt.ArrayLike | None = None,
    ) -> None:
        """Adds one tick: every agent detected at ``time`` (seconds, or a datetime at every tick; after the previous
        tick), with its id (integer or string), world position ``(N, 2)`` in metres, and optionally class, heading,
        size and velocity.

        Raises:
            InvalidFrameError: shapes, repeated ids, non-finite positions. TimeBaseError: a tick not after the last.
        """
        seconds = self._seconds(time)
        if ids is None or isinstance(ids, (str, bytes)):
            raise InvalidFrameError("ids must be a sequence of ids (integers or strings)")
        id_array = as_given(ids)
        n = int(id_array.size)
        try:
            pos2 = np.ascontiguousarray(positions, dtype=np.float64)
        except (TypeError, ValueError) as e:
            raise InvalidFrameError(f"positions must be an (N, 2) array of numbers: {e}") from None
        if n == 0 and pos2.size == 0:
            pos2 = pos2.reshape(0, 2)
        if pos2.shape != (n, 2):
            raise InvalidFrameError(f"positions must have shape ({n}, 2), got {pos2.shape}")
        vel = None
        if velocities is not None:
            try:
                vel = np.ascontiguousarray(velocities, dtype=np.float64)
            except (TypeError, ValueError) as e:
                raise InvalidFrameError(f"velocities must be an (N, 2) array of numbers: {e}") from None
            if vel.shape != (n, 2):
                raise InvalidFrameError(f"velocities must have shape ({n}, 2), got {vel.shape}")
        if classes is not None and (isinstance(classes, (str, bytes)) or not isinstance(classes, Sequence)):
            raise InvalidFrameError(f"classes must be a sequence of class names or codes, got {typename(classes)}")
        if classes is not None and len(classes) != n:
            raise InvalidFrameError(f"{len(classes)} classes given for {n} detections")
        if id_array.dtype.kind == "i" and self._next_code == 0:
            self._integer_ids = True
            codes = np.ascontiguousarray(id_array.ravel(), dtype=np.int64)
        elif self._integer_ids and n:
            raise InvalidFrameError("this tracker has had integer ids; give integer ids at every tick")
        else:
            codes = np.asarray([self._code(a) for a in id_array.ravel().tolist()], dtype=np.int64)
        columns = {
            "ids": codes,
            "xs": np.ascontiguousarray(pos2[:, 0]),
            "ys": np.ascontiguousarray(pos2[:, 1]),
            "classes": None if classes is None else relabelled(list(classes), self._class_names),
            "headings": _column("headings", headings, n),
            "lengths": _column("lengths", lengths, n),
            "widths": _column("widths", widths, n),
            "vxs": None if vel is None else np.ascontiguousarray(vel[:, 0]),
            "vys": None if vel is None else np.ascontiguousarray(vel[:, 1]),
        }
        self._native.update(seconds, columns)
        if not self._integer_ids:
            self._forget_labels()

    def frame(self) -> Frame:
        """The frame at the latest tick: the agents detected then, by increasing integer id (other ids: by first
        appearance); denoised when the tracker was made with ``denoise``."""
        native = self._native.frame()
        labels = None
        if not self._integer_ids:
            labels = np.empty(len(native), dtype=object)
            labels[:] = [self._labels[c] for c in native.ids]
        out = Frame._wrap(native, labels, None, (None, False, self._tick_time()))
        out = out if self._map is None else out.with_map(self._map)
        return out if self._denoise is None else out.denoised(self._denoise)

    def predict(self, *, modes: int | None = None, unknown_classes: str = "error") -> Prediction:
        """The predictions of every agent detected at the latest tick (``unknown_classes`` as
        :meth:`Predictor.predict`)."""
        return self._predictor.predict(self.frame(), modes=modes, unknown_classes=unknown_classes)


def _unpickle_tracker(
    options: tuple[Any, ...],
    state: dict[str, Any],
    ids: tuple[bool, dict[int, Any], int],
    origin: np.datetime64 | None = None,
) -> Tracker:
    predictor, world_map, max_gap, default_class, denoise, class_names = options
    tracker = Tracker(
        predictor,
        map=world_map,
        max_gap=max_gap,
        default_class=default_class,
        denoise=denoise,
        class_names=class_names,
    )
    spec = predictor.spec
    tracker._native = _dgan.Tracker.restore(spec.t_obs, spec.dt_s, max_gap, default_class, state)
    tracker._integer_ids, labels, tracker._next_code = ids
    tracker._labels = dict(labels)
    tracker._codes = {label: code for code, label in tracker._labels.items()}
    tracker._origin = origin
    return tracker
