"""Long tables → frames: the work behind :meth:`dgan.Frame.from_records` (ids, time grid, column checks, advice).

The resampling itself (grouping rows into tracks, repeated times, interpolation onto the model's grid, upsampling)
is the engine's ``dgan_core::history``, shared with the streaming :class:`~dgan.Tracker`.
"""

from __future__ import annotations

import functools
import re
import warnings
from collections.abc import Mapping
from dataclasses import dataclass
from typing import Any, Final

import numpy as np
import numpy.typing as npt

from dgan import _dgan
from dgan._times import TableTime, TimeColumn, TimeLike, instant_text, time_column
from dgan._values import ClassLike, checked_array, checked_real, typename
from dgan.columnnames import Names, check_columns
from dgan.exceptions import InvalidFrameError, InvalidSpecError, TimeBaseError, TimeUnitWarning
from dgan.labels import relabelled
from dgan.tables import Columns, columns

#: What a table becomes: the engine's frame, the ids as given of its rows (None when its codes are the ids), and
#: the data's own spacing with whether it was upsampled and the frame's time as the table wrote it.
Parsed = tuple[_dgan.Frame, npt.NDArray[Any] | None, tuple[float | None, bool, TableTime | None] | None]

#: How repeated (agent, time) rows may be resolved (the engine's ``Duplicates``).
DUPLICATES: Final = tuple(_dgan.DUPLICATES)
#: Data at most this many times sparser than a model's step are interpolated with ``upsample=True``, with the
#: engine's relative slack (``dgan_core::history``).
UPSAMPLE_LIMIT: Final = _dgan.UPSAMPLE_LIMIT
_SLACK: Final = 1.0 + _dgan.SPARSE_SLACK


def record_ids(raw: npt.NDArray[Any], name: str) -> tuple[npt.NDArray[np.int64], npt.NDArray[Any] | None]:
    """The engine's integer codes of an id column and the ids as given (None when the codes are the ids).

    Signed integers are their own codes. Other ids (strings, unsigned 64-bit hashes, whole floats, a mix of
    integers and strings) get codes in sorted order (order of first appearance for a mix that cannot be sorted), and
    come back exactly as given: type and value."""
    kind = raw.dtype.kind
    if kind == "i":
        return np.ascontiguousarray(raw, dtype=np.int64), None
    if kind == "b":
        raise InvalidFrameError(f"the id column {name!r} holds booleans; ids are integers or strings")
    if kind == "f" and not np.all(np.isfinite(raw)):
        raise InvalidFrameError(f"the id column {name!r} holds NaN or infinite values")
    if kind == "O" and any(v is None or (isinstance(v, float) and not np.isfinite(v)) for v in raw.tolist()):
        raise InvalidFrameError(f"the id column {name!r} holds None or NaN")
    try:
        uniq, inverse = np.unique(raw, return_inverse=True)
    except TypeError:  # integers and strings mixed: codes by first appearance
        index: dict[Any, int] = {}
        codes = np.fromiter((index.setdefault(v, len(index)) for v in raw.tolist()), dtype=np.int64, count=raw.size)
        labels = np.empty(len(index), dtype=object)
        labels[:] = list(index)
        return codes, labels
    codes = np.ascontiguousarray(inverse.ravel(), dtype=np.int64)
    if kind == "f" and np.all(uniq == np.round(uniq)):
        return codes, uniq.astype(np.int64)  # whole floats: integer ids read through a column with NaNs elsewhere
    return codes, (uniq.astype(object) if kind in "US" else uniq)


def _numeric(cols: Columns, name: str) -> npt.NDArray[np.float64] | None:
    if name not in cols:
        return None
    c = cols[name]
    if c.dtype.kind not in "biuf":
        raise InvalidFrameError(f"column {name!r} must be numeric, got {c.dtype}")
    return np.ascontiguousarray(c, dtype=np.float64)


def _optional_rows(cols: Columns, names: Names, class_names: Mapping[Any, ClassLike] | None) -> dict[str, Any]:
    """The optional per-row columns the engine reads (None where the table has none), the classes read through
    ``class_names``."""
    klass = cols.get(names.cls)
    return {
        "classes": None if klass is None else relabelled(klass.tolist(), class_names),
        "headings": _numeric(cols, names.heading),
        "lengths": _numeric(cols, names.length),
        "widths": _numeric(cols, names.width),
        "vxs": _numeric(cols, names.vx) if names.vy in cols else None,
        "vys": _numeric(cols, names.vy) if names.vx in cols else None,
    }


@functools.lru_cache(maxsize=1)
def _bundled_steps() -> tuple[tuple[str, float], ...]:
    from dgan import models

    return tuple((name, models.info(name).dt_s) for name in models.list())


def sparse_advice(spacing_s: float, upsample: bool) -> str:
    """Which bundled models' steps fit data sampled every ``spacing_s`` seconds, as a sentence."""
    steps = _bundled_steps()
    direct = [f"{n} ({dt:g} s)" for n, dt in steps if spacing_s <= dt * _SLACK]
    up = [f"{n} ({dt:g} s)" for n, dt in steps if dt * _SLACK < spacing_s <= dt * UPSAMPLE_LIMIT * _SLACK]
    if direct:
        return f"bundled models whose step fits these data: {', '.join(direct)}"
    if up and not upsample:
        return f"no bundled model's step fits them as they are; with upsample=True: {', '.join(up)}"
    coarsest = max((dt for _, dt in steps), default=float("nan"))
    return f"no bundled model's step fits them (the coarsest is {coarsest:g} s)"


def _named(error: InvalidFrameError, labels: npt.NDArray[Any] | None) -> InvalidFrameError:
    """The engine's error with the agent it names by code ("agent 3") named by its id as given."""
    if labels is None:
        return error
    text = re.sub(r"\bagent (\d+)\b", lambda m: f"agent {labels[int(m.group(1))]!r}", str(error), count=1)
    return type(error)(text)


def _check_options(t_obs: Any, dt: Any, time_unit: Any, duplicates: Any, upsample: Any) -> None:
    dt = checked_real("dt", dt, TimeBaseError, optional=True)
    time_unit = checked_real("time_unit", time_unit, TimeBaseError)
    if dt is not None and not (np.isfinite(dt) and dt > 0):
        raise TimeBaseError(f"dt must be a positive number of seconds, got {dt!r}")
    if isinstance(t_obs, bool) or not isinstance(t_obs, (int, np.integer)) or not 1 <= t_obs <= 1000:
        raise InvalidFrameError(f"t_obs must be an integer in 1..=1000, got {t_obs!r}")
    if not (np.isfinite(time_unit) and time_unit > 0):
        raise TimeBaseError(f"time_unit must be a positive number of seconds per unit, got {time_unit!r}")
    if not isinstance(duplicates, str):  # which names are valid is the engine's to say
        raise InvalidSpecError(f"duplicates must be one of {DUPLICATES}, got {duplicates!r}")
    if not isinstance(upsample, (bool, np.bool_)):
        raise InvalidSpecError(f"upsample must be True or False, got {upsample!r}")


def _current_time(
    uniq_t: npt.NDArray[np.float64], current_time: float | None, tol: float, origin: np.datetime64 | None
) -> float:
    now = float(uniq_t.max()) if current_time is None else float(current_time)
    if not np.any(np.abs(uniq_t - now) <= tol):
        first, last, asked = (instant_text(origin, t) for t in (uniq_t[0], uniq_t[-1], now))
        raise InvalidFrameError(
            f"no row at current_time {asked}; the table spans {first}..{last} ({uniq_t.size} distinct times)"
        )
    return float(uniq_t[np.argmin(np.abs(uniq_t - now))])


def _median_gap(codes: npt.NDArray[np.int64], times: npt.NDArray[np.float64]) -> float:
    """The median gap between consecutive distinct times of one agent in the table (inf when none has two)."""
    order = np.lexsort((times, codes))
    c, t = codes[order], times[order]
    gaps = np.diff(t)[(np.diff(c) == 0) & (np.diff(t) > 0)]
    return float(np.median(gaps)) if gaps.size else float("inf")


def _warn_time_unit(frame: _dgan.Frame, time_unit: float, gap_s: float) -> None:
    """Warns when agents have several rows in the table, so far apart that none has two observed steps in the frame:
    the time column is most likely in another unit (a recording's first tick, with one row per agent, is not)."""
    window_s = frame.mask.shape[1] * (frame.dt or 0.0)
    many = np.isfinite(gap_s) and gap_s > window_s
    if many and len(frame) and frame.mask.shape[1] >= 2 and not np.any(frame.mask.sum(axis=1) >= 2):
        warnings.warn(
            f"no agent of the frame has two observed steps of its {frame.mask.shape[1]}: the time column may be in "
            f"another unit than time_unit={time_unit:g} s per unit (milliseconds read as seconds?); every prediction "
            "would start from a single position",
            TimeUnitWarning,
            stacklevel=5,
        )


@dataclass(frozen=True)
class Table:
    """A long table read once: its rows as the engine takes them (``rows``, times in seconds), the ids as given
    (``labels``, None when its codes are the ids), its time column (``clock``; ``clock.now`` the current time asked
    for) and distinct times (``times``, in the column's unit), and the grid every frame of it is resampled to."""

    rows: dict[str, Any]
    labels: npt.NDArray[Any] | None
    clock: TimeColumn
    times: npt.NDArray[np.float64]
    t_obs: int
    dt: float
    max_gap: float | None
    default_class: ClassLike
    duplicates: str
    upsample: bool


def read_table(
    records: Any,
    *,
    t_obs: int | None,
    dt: float | None,
    spec: Any,
    time_unit: float,
    current_time: TimeLike | None,
    max_gap: float | None,
    names: Names,
    default_class: ClassLike,
    class_names: Mapping[Any, ClassLike] | None,
    duplicates: str,
    upsample: bool,
) -> Table:
    """The work of :meth:`dgan.Frame.from_records` (documented there) up to the resampling: the table checked and
    read once, for frames at one or many of its times (:func:`frames_at`)."""
    if spec is not None:
        spec = getattr(spec, "spec", spec)
        if not (hasattr(spec, "t_obs") and hasattr(spec, "dt_s")):
            raise InvalidSpecError(f"spec must be a model's InputSpec or a Predictor, got {typename(spec)}")
        t_obs = spec.t_obs if t_obs is None else t_obs
        dt = spec.dt_s if dt is None else dt
    if t_obs is None:
        raise InvalidFrameError("from_records needs t_obs (or spec=, a model's InputSpec or Predictor)")
    _check_options(t_obs, dt, time_unit, duplicates, upsample)
    max_gap = checked_real("max_gap", max_gap, TimeBaseError, optional=True)
    cols = columns(records)
    check_columns(cols, names)
    clock = time_column(cols[names.time], names.time, time_unit, current_time)
    xs, ys = _numeric(cols, names.x), _numeric(cols, names.y)
    assert xs is not None
    assert ys is not None
    if not np.all(np.isfinite(clock.values)):
        raise InvalidFrameError("the time column holds NaN or infinite values")
    codes, labels = record_ids(cols[names.agent_id], names.agent_id)
    uniq_t = np.unique(clock.values)
    if dt is None:
        gaps = np.diff(uniq_t)
        dt = float(f"{float(gaps.min()) * clock.unit:.9g}") if gaps.size else 1.0
    seconds = np.ascontiguousarray(clock.values * clock.unit)
    rows = {"ids": codes, "times": seconds, "xs": xs, "ys": ys, **_optional_rows(cols, names, class_names)}
    return Table(rows, labels, clock, uniq_t, int(t_obs), float(dt), max_gap, default_class, duplicates, upsample)


#: What a frame's agents did next: ``(N, t_f, 2)`` positions (NaN where unseen) and their ``(N, t_f)`` mask.
Future = tuple[npt.NDArray[np.float64], npt.NDArray[np.bool_]]
#: What a frame of :func:`frames_at` is: the frame as :func:`from_records` gives it, and with ``t_f`` > 0 its
#: :data:`Future`.
Framed = tuple[Parsed, Future | None]


def frames_at(table: Table, nows: list[float | None], t_f: int = 0) -> list[Framed]:
    """The frames of ``table`` at each of ``nows`` (in its time column's unit, each a time of the table; None for
    the latest), grouped and resampled by the engine in one call; with ``t_f`` > 0 each with what its agents did over
    the next ``t_f`` steps on the same grid (``dgan_core::frame_and_future_at``)."""
    t_obs, dt, unit = table.t_obs, table.dt, table.clock.unit
    if table.times.size == 0:
        empty = _dgan.Frame(np.zeros((0, t_obs, 2)), None, [], None, None, None, None, None, None, dt)
        nothing = (np.zeros((0, t_f, 2)), np.zeros((0, t_f), dtype=bool)) if t_f else None
        return [((empty, None, None), nothing) for _ in nows]
    at = [_current_time(table.times, now, 1e-6 * dt / unit, table.clock.origin) for now in nows]
    seconds = table.rows["times"]
    try:
        out = _dgan.frames_from_rows(
            table.rows, [t * unit for t in at], t_obs, dt, table.max_gap, table.default_class,
            table.duplicates, bool(table.upsample), t_f,
        )  # fmt: skip
    except TimeBaseError as e:
        spacing_s = getattr(e, "spacing_s", None)
        if spacing_s is None:
            raise _named(e, table.labels) from None
        raise TimeBaseError(f"{e}; {sparse_advice(spacing_s, bool(table.upsample))}") from None
    except InvalidFrameError as e:
        raise _named(e, table.labels) from None
    gap = _median_gap(table.rows["ids"], seconds)
    framed: list[Framed] = []
    for now, (native, spacing, upsampled, future, future_mask) in zip(at, out, strict=True):
        _warn_time_unit(native, unit, gap)
        labels = None if table.labels is None else table.labels[native.ids]
        parsed: Parsed = (native, labels, (spacing, upsampled, TableTime.of(table.clock, now)))
        framed.append((parsed, None if future is None or future_mask is None else (future, future_mask)))
    return framed


def from_records(records: Any, **options: Any) -> Parsed:
    """The work of :meth:`dgan.Frame.from_records` (documented there), which wraps what this returns."""
    table = read_table(records, **options)
    return frames_at(table, [table.clock.now])[0][0]


def sample_track(
    times: npt.ArrayLike, xy: npt.ArrayLike, at: npt.ArrayLike, dt: float, max_gap: float | None = None
) -> npt.NDArray[np.float64]:
    """One agent's positions ``xy (N, 2)`` at ``times (N,)`` seconds, sampled at the times ``at (M,)`` as a frame of
    :meth:`dgan.Frame.from_records` on a grid ``dt`` seconds apart samples them (the engine's
    ``dgan_core::sample_track``): a row within ``dt``·10⁻⁶ s of a time is taken as it is, a time between two rows at
    most ``max_gap`` seconds apart (by default a frame's, 1.5 · ``dt``) is interpolated linearly, and any other time
    is NaN (no wider gap bridged, nothing extrapolated). Returns ``(M, 2)`` float64. ``times`` must increase strictly;
    times, positions and ``at`` must be finite (:class:`dgan.exceptions.InvalidFrameError`); ``dt`` must be positive
    and ``max_gap`` non-negative (:class:`dgan.exceptions.TimeBaseError`).

    >>> import dgan
    >>> dgan.sample_track([0.0, 1.0], [[0.0, 0.0], [2.0, 4.0]], [0.5, 2.0], dt=0.5, max_gap=1.0).tolist()
    [[1.0, 2.0], [nan, nan]]
    """
    t, a = (checked_array(name, v, np.float64, required=True).reshape(-1) for name, v in (("times", times), ("at", at)))
    p = checked_array("xy", xy, np.float64, required=True)
    if p.ndim != 2 or p.shape[1] != 2:
        raise InvalidFrameError(f"xy must have shape (N, 2), got {p.shape}")
    gap = checked_real("max_gap", max_gap, TimeBaseError, optional=True)
    return _dgan.sample_track(t, p, a, checked_real("dt", dt, TimeBaseError), gap)
