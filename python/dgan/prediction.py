""":class:`Prediction`, every agent's modes, and the long tables it becomes (numpy, pandas, Arrow, parquet)."""

from __future__ import annotations

import numbers
import os
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
import numpy.typing as npt

from dgan import _dgan
from dgan._times import TableTime
from dgan.exceptions import OutputError

Columns = dict[str, npt.NDArray[Any]]


@dataclass(frozen=True)
class Prediction:
    """Every agent's modes, most probable first. Positions are world metres.

    Attributes:
        agent_ids: ``(N,)`` the frame's ids as given (integers, or strings in an object array), in row order.
        trajectories: ``(N, M, T_f, 2)`` future positions of each mode.
        probabilities: ``(N, M)`` p(c) · p(k | c) of each mode.
        class_probabilities: ``(N, C)`` p(c), columns in ``classes`` order.
        mode_classes: ``(N, M)`` index into ``classes`` of each mode's anchor class.
        edges: ``(E, 2)`` undirected attention-zone edges between frame rows ``i < j``.
        classes: the model's class names.
        dt_s: seconds between predicted steps (the model's time base); step ``s`` is ``(s + 1) · dt_s`` after now.
        time: the frame's current time as its table or tracker gave it (:attr:`Frame.time`, with its unit), None
            for a frame built from arrays; :meth:`to_records` then has a ``time`` column.
    """

    agent_ids: npt.NDArray[Any]
    trajectories: npt.NDArray[np.float64]
    probabilities: npt.NDArray[np.float64]
    class_probabilities: npt.NDArray[np.float64]
    mode_classes: npt.NDArray[np.int64]
    edges: npt.NDArray[np.int64]
    classes: tuple[str, ...]
    dt_s: float = float("nan")
    time: TableTime | None = None

    @classmethod
    def from_native(
        cls,
        native: _dgan.Prediction,
        agent_ids: npt.NDArray[Any],
        classes: tuple[str, ...],
        dt_s: float,
        time: TableTime | None = None,
    ) -> Prediction:
        """The engine's prediction with the frame's ids as given, the model's classes and time base."""
        return cls(
            agent_ids=agent_ids,
            trajectories=native.trajectories,
            probabilities=native.probabilities,
            class_probabilities=native.class_probabilities,
            mode_classes=native.mode_classes,
            edges=native.edges,
            classes=classes,
            dt_s=dt_s,
            time=time,
        )

    def __len__(self) -> int:
        return int(self.agent_ids.shape[0])

    @property
    def times_s(self) -> npt.NDArray[np.float64]:
        """``(T_f,)`` seconds after the current time of each predicted step."""
        return np.round(np.arange(1, self.trajectories.shape[2] + 1) * self.dt_s, 9)

    def to_records(self) -> dict[str, npt.NDArray[Any]]:
        """The prediction as a long table of numpy columns, one row per agent, mode and step: ``agent_id``,
        ``mode`` (0 = most probable), ``probability``, ``class`` (the mode's anchor class), ``class_probability``,
        ``step`` (1..T_f), ``time_offset_s``, ``x``, ``y`` (world metres); for a frame of a table or a tracker also
        ``time``, each step's time as the table wrote its times (a number in its unit, or ``datetime64[ns]``)."""
        return prediction_columns(self)

    def to_pandas(self) -> Any:
        """:meth:`to_records` as a pandas DataFrame (needs pandas)."""
        import pandas as pd

        return pd.DataFrame(self.to_records())

    def to_arrow(self) -> Any:
        """:meth:`to_records` as a pyarrow Table (needs pyarrow); its schema metadata holds ``dt_s`` and the
        classes.

        Raises:
            OutputError: ids an Arrow column cannot hold (integers mixed with strings, integers past 64 bits).
        """
        import pyarrow as pa

        cols = self.to_records()
        arrays = {k: pa.array(v.tolist() if v.dtype == object else v) for k, v in cols.items() if k != "agent_id"}
        table = pa.table({"agent_id": _arrow_ids(cols["agent_id"]), **arrays})
        meta = {b"dgan.dt_s": str(self.dt_s).encode(), b"dgan.classes": ",".join(self.classes).encode()}
        return table.replace_schema_metadata(meta)

    def to_parquet(self, path: str | os.PathLike[str]) -> None:
        """Writes :meth:`to_arrow` to a parquet file (needs pyarrow). The file is written beside ``path`` and then
        renamed onto it, so a failed write leaves ``path`` as it was (a path that is not a regular file, such as a
        device or a pipe, is written in place and never removed).

        Raises:
            OutputError: as :meth:`to_arrow`. OSError: the file cannot be written.
        """
        import pyarrow.parquet as pq

        write_atomically(path, lambda f: pq.write_table(self.to_arrow(), f))

    @property
    def most_likely(self) -> npt.NDArray[np.float64]:
        """``(N, T_f, 2)`` the top-1 mode of each agent."""
        return self.trajectories[:, 0]


def prediction_columns(prediction: Prediction) -> Columns:
    """A prediction as a long table: one row per agent, mode and future step.

    Columns: ``agent_id``, ``mode`` (0 = most probable), ``probability`` (of the mode), ``class`` (the mode's
    anchor class), ``class_probability`` (of that class), ``step`` (1..T_f), ``time_offset_s`` (step · dt, seconds
    after the current time), ``x``, ``y`` (world metres).
    """
    n, m, t_f, _ = prediction.trajectories.shape
    agent = np.repeat(np.arange(n), m * t_f)
    mode = np.tile(np.repeat(np.arange(m), t_f), n)
    step = np.tile(np.arange(1, t_f + 1), n * m)
    names = np.asarray(prediction.classes, dtype=object)
    mode_class = prediction.mode_classes[agent, mode] if n else np.zeros(0, dtype=np.int64)
    xy = prediction.trajectories.reshape(-1, 2)
    offsets = np.round(step * prediction.dt_s, 9)
    columns: Columns = {
        "agent_id": prediction.agent_ids[agent],
        "mode": mode.astype(np.int64),
        "probability": prediction.probabilities[agent, mode],
        "class": names[mode_class] if n else np.zeros(0, dtype=object),
        "class_probability": prediction.class_probabilities[agent, mode_class] if n else np.zeros(0),
        "step": step.astype(np.int64),
        "time_offset_s": offsets,
    }
    if prediction.time is not None:
        columns["time"] = prediction.time.at(offsets)
    return columns | {"x": xy[:, 0].copy(), "y": xy[:, 1].copy()}


def _arrow_ids(ids: npt.NDArray[Any]) -> Any:
    """The agent-id column of an Arrow table: one type, or :class:`OutputError`."""
    import pyarrow as pa

    if ids.dtype != object:
        return pa.array(ids)
    values = ids.tolist()
    if all(isinstance(v, str) for v in values):
        return pa.array(values, type=pa.string())
    if all(isinstance(v, numbers.Integral) and not isinstance(v, bool) for v in values):
        ints = [int(v) for v in values]
        if all(-(2**63) <= v < 2**63 for v in ints):
            return pa.array(ints, type=pa.int64())
        if all(0 <= v < 2**64 for v in ints):
            return pa.array(ints, type=pa.uint64())
        raise OutputError("agent ids past 64 bits cannot be an Arrow column; give them as strings")
    kinds = sorted({type(v).__name__ for v in values})
    raise OutputError(
        f"agent ids mix {' and '.join(kinds)}; an Arrow or parquet column holds one type: give the frame ids of one "
        "type (e.g. strings), or use to_records() / to_pandas(), which keep them as given"
    )


def write_atomically(path: str | os.PathLike[str], write: Any) -> None:
    """Calls ``write(file)`` on a temporary file beside ``path``, then renames it onto ``path``: a failure leaves
    ``path`` as it was. A path that exists and is not a regular file (a device, a pipe) is opened and written in
    place, and never removed."""
    target = Path(path)
    if target.exists() and not target.is_file():
        with open(target, "wb") as f:
            write(f)
        return
    tmp = target.with_name(f".{target.name}.{os.getpid()}.tmp")
    try:
        with open(tmp, "wb") as f:
            write(f)
        os.replace(tmp, target)
    except OSError as e:
        tmp.unlink(missing_ok=True)
        raise OSError(e.errno, f"cannot write {target}: {e.strerror or e}", os.fspath(target)) from None
    except BaseException:
        tmp.unlink(missing_ok=True)
        raise
