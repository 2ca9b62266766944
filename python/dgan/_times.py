"""A table's time column as seconds: numbers in a unit, or instants (datetimes, ISO 8601 strings) and durations
(timedeltas) that carry their own. What :meth:`dgan.Frame.from_records` and ``dgan predict`` read."""

from __future__ import annotations

import contextlib
import datetime as _dt
import warnings
from collections.abc import Iterator
from dataclasses import dataclass, replace
from typing import Any

import numpy as np
import numpy.typing as npt

from dgan.exceptions import InvalidFrameError, TimeBaseError

_NS = 1e-9
#: What ``current_time`` may be: a number in the time column's unit, or an instant or duration like its values.
TimeLike = float | str | _dt.datetime | _dt.timedelta | np.datetime64 | np.timedelta64


@dataclass(frozen=True)
class TimeColumn:
    """A time column in the unit the rest of :mod:`dgan.records` reads: ``values`` in units of ``unit`` seconds,
    with ``now`` (the current time asked for, None for the latest) in the same unit. Instants are counted from
    ``origin`` (the column's earliest, a ``numpy.datetime64``), numbers and durations from zero (``origin`` None)."""

    values: npt.NDArray[np.float64]
    now: float | None
    unit: float
    origin: np.datetime64 | None = None
    #: What the column holds: "number", "duration" or "instant".
    kind: str = "number"

    def time_of(self, value: TimeLike) -> float:
        """A time given as the column's values are (a number, a duration, an instant) in the column's unit."""
        if self.kind == "number":
            if not isinstance(value, (int, float, np.integer, np.floating)):
                raise InvalidFrameError(f"current_time must be a number in the time column's unit, got {value!r}")
            return float(value)
        if self.kind == "duration":
            return _duration_s(value)
        origin = 0 if self.origin is None else int(self.origin.astype("datetime64[ns]").astype(np.int64))
        return (instant_ns(value, "current_time") - origin) * _NS


@contextlib.contextmanager
def _utc_offsets_read() -> Iterator[None]:
    """numpy reads an ISO 8601 time with a UTC offset (``+01:00``) as the instant it names, in UTC, and warns that
    it keeps no zone; that is what a time column means here, so the warning is not passed on."""
    with warnings.catch_warnings():
        warnings.filterwarnings("ignore", message="no explicit representation of timezones", category=UserWarning)
        yield


def _is_number(value: Any) -> bool:
    """Whether a ``current_time`` (or a value of an object column) is a plain number, not a time."""
    return isinstance(value, (bool, int, float, np.number)) and not isinstance(value, np.timedelta64)


def after(origin: np.datetime64, seconds: float) -> np.datetime64:
    """The instant ``seconds`` after ``origin``, to the nanosecond."""
    return origin + np.timedelta64(round(seconds * 1e9), "ns")


def iso_text(instants: Any) -> Any:
    """Instants (one or an array) as the command line and text tables write them: ISO 8601 to the millisecond."""
    return np.datetime_as_string(instants, unit="ms")


def instant_ns(value: Any, what: str) -> int:
    """One instant as nanoseconds since 1970 (UTC): a ``datetime`` (a zone-aware one converted to UTC, a naive one
    read as UTC), a ``numpy.datetime64`` or an ISO 8601 string (a trailing ``Z`` allowed)."""
    if _is_number(value):
        raise InvalidFrameError(f"{what} {value!r} is a number where the time column holds instants")
    if isinstance(value, _dt.datetime) and value.tzinfo is not None:
        value = value.astimezone(_dt.timezone.utc).replace(tzinfo=None)
    if isinstance(value, (str, np.str_)):
        value = value.strip().removesuffix("Z").removesuffix("z")
    try:
        with _utc_offsets_read():
            instant = np.datetime64(value, "ns")
    except (TypeError, ValueError, OverflowError) as e:
        raise InvalidFrameError(
            f"{what} {value!r} is not a time (a number, datetime or ISO 8601 string): {e}"
        ) from None
    if np.isnat(instant):
        raise InvalidFrameError(f"{what} holds a missing time (NaT)")
    return int(instant.astype(np.int64))


def _instants_ns(col: npt.NDArray[Any], name: str) -> npt.NDArray[np.int64]:
    if col.dtype.kind in "OUS" and all(isinstance(v, str) for v in col.tolist()):
        try:  # ISO 8601 strings parsed at once (five times faster than one by one)
            with _utc_offsets_read():
                col = np.char.rstrip(col.astype(str), "Zz").astype("datetime64[ns]")
        except (TypeError, ValueError, OverflowError):
            pass  # the loop below names the value that is no time
    if col.dtype.kind == "M":
        ns = col.astype("datetime64[ns]")
        if np.isnat(ns).any():
            raise InvalidFrameError(f"the time column {name!r} holds missing times (NaT)")
        return ns.astype(np.int64)
    return np.fromiter((instant_ns(v, f"the time column {name!r}'s value") for v in col.tolist()), np.int64, col.size)


def _is_instants(col: npt.NDArray[Any]) -> bool:
    """Whether a column of strings or objects holds instants (judged by its first value; every value is then read)."""
    first = col.flat[0] if col.size else None
    return isinstance(first, (str, np.str_, _dt.datetime, np.datetime64))


def time_column(col: npt.NDArray[Any], name: str, time_unit: float, current_time: TimeLike | None) -> TimeColumn:
    """The time column ``col`` and ``current_time`` as a :class:`TimeColumn`.

    Numbers are in ``time_unit`` seconds; a datetime or timedelta column (numpy, pandas with or without a time zone,
    polars, Arrow) or ISO 8601 strings carry their own unit, so ``time_unit`` must then be left at 1, and
    ``current_time`` is an instant (or duration) of the same kind.

    Raises:
        InvalidFrameError: values that are neither numbers nor times, missing times, a ``current_time`` of another kind.
        TimeBaseError: a ``time_unit`` other than 1 with a column that carries its unit.
    """
    kind = col.dtype.kind
    if kind in "biuf":
        clock = TimeColumn(np.ascontiguousarray(col, dtype=np.float64), None, float(time_unit))
    elif kind not in "mMOUS" or (kind in "OUS" and not _is_instants(col)):
        raise InvalidFrameError(f"column {name!r} must be numeric or times, got {col.dtype}")
    elif time_unit != 1.0:
        raise TimeBaseError(
            f"the time column {name!r} holds {col.dtype} values, which carry their own unit; leave time_unit at 1 "
            f"(got {time_unit!r})"
        )
    elif kind == "m":
        if np.isnat(col).any():
            raise InvalidFrameError(f"the time column {name!r} holds missing times (NaT)")
        seconds = col.astype("timedelta64[ns]").astype(np.int64).astype(np.float64) * _NS
        clock = TimeColumn(seconds, None, 1.0, kind="duration")
    else:
        ns = _instants_ns(col, name)
        origin = int(ns.min()) if ns.size else 0
        clock = TimeColumn((ns - origin).astype(np.float64) * _NS, None, 1.0, np.datetime64(origin, "ns"), "instant")
    return clock if current_time is None else replace(clock, now=clock.time_of(current_time))


def _duration_s(value: Any) -> float:
    if _is_number(value):
        raise InvalidFrameError(f"current_time {value!r} is a number where the time column holds durations")
    if isinstance(value, _dt.timedelta):
        return value.total_seconds()
    try:
        return float(np.timedelta64(value, "ns").astype(np.int64)) * _NS
    except (TypeError, ValueError) as e:
        raise InvalidFrameError(
            f"current_time {value!r} is not a duration, as the time column's values are: {e}"
        ) from None


def instant_text(origin: np.datetime64 | None, seconds: float) -> str:
    """A time of a column as a user wrote it: ``origin + seconds`` in ISO 8601 (milliseconds) for instants, else the
    number."""
    return f"{seconds:g}" if origin is None else str(iso_text(after(origin, seconds)))


@dataclass(frozen=True)
class TableTime:
    """A frame's current time as its table gave it: ``now`` in the time column's unit (``unit_s`` seconds) or, for a
    column of instants, a ``numpy.datetime64``. What a prediction's ``time`` column counts from."""

    now: float | np.datetime64
    unit_s: float = 1.0

    def at(self, offsets_s: npt.NDArray[np.float64]) -> npt.NDArray[Any]:
        """The times ``offsets_s`` seconds after now, as the table writes them (numbers, or ``datetime64[ns]``)."""
        if isinstance(self.now, np.datetime64):
            return self.now + np.round(np.asarray(offsets_s) * 1e9).astype("timedelta64[ns]")
        return np.round(float(self.now) + np.asarray(offsets_s, dtype=np.float64) / self.unit_s, 9)

    @classmethod
    def of(cls, clock: TimeColumn, now: float) -> TableTime:
        """The time ``now`` of a :class:`TimeColumn` (in its unit) as its table wrote it."""
        return cls(float(now), clock.unit) if clock.origin is None else cls(after(clock.origin, now))
