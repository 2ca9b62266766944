"""A table's frames at many times, the table read and grouped once: what ``dgan predict --every`` and
:func:`dgan.evaluate` walk.

>>> import dgan
>>> rows = {"agent_id": [1, 1, 1, 2, 2], "time": [0.0, 0.4, 0.8, 0.4, 0.8], "x": [0, 1, 2, 5, 5], "y": [0] * 5}
>>> [len(f) for f in dgan.series.frames(rows, t_obs=2, dt=0.4)]
[1, 2, 2]
"""

from __future__ import annotations

import inspect
from collections.abc import Sequence
from typing import Any, Final

import numpy as np

from dgan._times import TimeLike
from dgan.columnnames import NAME_ARGUMENTS, names_of
from dgan.exceptions import InvalidFrameError
from dgan.frame import Frame
from dgan.records import Future, frames_at, read_table

__all__ = ["Future", "frames", "frames_with_futures"]

#: :meth:`dgan.Frame.from_records`' parameters: the options a series of its frames takes, and their defaults.
_FROM_RECORDS: Final = inspect.signature(Frame.from_records)


def frames(records: Any, times: Sequence[TimeLike] | None = None, **options: Any) -> list[Frame]:
    """The frames of a long table at each of ``times`` (each a time of the table, as its time column gives them;
    every time of the table, in order, if None), equal to :meth:`dgan.Frame.from_records` at each but with the table
    read, checked and grouped into tracks once (for the 872 times of the zara01 test file 0.044 s against 0.85).

    Args:
        records: any table, as :meth:`~dgan.Frame.from_records` takes it.
        times: the current times; None: every distinct time of the table.
        **options: :meth:`~dgan.Frame.from_records`' keywords (``spec``, ``time_unit``, column names, ``map`` ...)
            except ``current_time``.

    Raises:
        InvalidFrameError, TimeBaseError: as :meth:`~dgan.Frame.from_records` raises them, for the first time that
            fails.
    """
    return [f for f, _ in _framed(records, times, 0, options)]


def frames_with_futures(
    records: Any, t_f: int, times: Sequence[TimeLike] | None = None, **options: Any
) -> list[tuple[Frame, Future]]:
    """:func:`frames`, each with what its agents did over the next ``t_f`` steps of its grid, resampled from the same
    rows as their past (the ground truth a prediction of the frame is scored against;
    ``dgan_core::frame_and_future_at``): ``(N, t_f, 2)`` positions, NaN where the agent was not seen, and their
    ``(N, t_f)`` mask."""
    if isinstance(t_f, bool) or not isinstance(t_f, (int, np.integer)) or not 1 <= t_f <= 1000:
        raise InvalidFrameError(f"t_f must be an integer in 1..=1000, got {t_f!r}")
    out = _framed(records, times, int(t_f), options)
    return [(f, future) for f, future in out if future is not None]


def _framed(
    records: Any, times: Sequence[TimeLike] | None, t_f: int, options: dict[str, Any]
) -> list[tuple[Frame, Future | None]]:
    if "current_time" in options:
        raise InvalidFrameError("frames take times=, a list of current times, not current_time")
    unknown = sorted(set(options) - set(_FROM_RECORDS.parameters))
    if unknown:
        takes = sorted(set(_FROM_RECORDS.parameters) - {"records", "current_time"})
        raise InvalidFrameError(f"unknown option(s) {', '.join(unknown)}; Frame.from_records takes {takes}")
    bound = _FROM_RECORDS.bind(records, **options)  # with Frame.from_records' own defaults
    bound.apply_defaults()
    given = {k: v for k, v in bound.arguments.items() if k not in ("records", "current_time")}
    scene_map = given.pop("map")
    names = names_of(**{k: given.pop(k) for k in NAME_ARGUMENTS})
    table = read_table(records, current_time=None, names=names, **given)
    if times is None:
        nows: list[float | None] = [float(t) for t in table.times]
    elif isinstance(times, (str, bytes)) or not isinstance(times, Sequence | np.ndarray):
        raise InvalidFrameError(f"times must be a sequence of times of the table, got {type(times).__name__}")
    else:
        nows = [table.clock.time_of(t) for t in times]
    return [(Frame._of_parsed(parsed, scene_map), future) for parsed, future in frames_at(table, nows, t_f)]
