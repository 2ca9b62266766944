"""Tables in and out: any table a user has, as columns; predictions as a long table (pandas, Arrow, parquet).

Input tables may be a dict of arrays, a numpy structured array, a sequence of records (dicts), a pandas or polars
DataFrame, a pyarrow Table or RecordBatch, or anything with the Arrow PyCapsule stream interface
(``__arrow_c_stream__``) or the dataframe interchange protocol (``__dataframe__``). Nothing here imports pandas,
polars or pyarrow unless the table is one of theirs (or the output asks for one).
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from typing import Any

import numpy as np
import numpy.typing as npt

from dgan._values import as_given
from dgan.exceptions import InvalidFrameError

Columns = dict[str, npt.NDArray[Any]]


def _numpy(name: str, values: Any) -> npt.NDArray[Any]:
    try:
        out = as_given(values)
    except (TypeError, ValueError) as e:
        raise InvalidFrameError(f"column {name!r} cannot be read as an array: {e}") from None
    if out.ndim != 1:
        raise InvalidFrameError(f"column {name!r} must be one-dimensional, got shape {out.shape}")
    return out


def _pandas_values(series: Any) -> Any:
    """A pandas column's values; datetimes with a time zone as UTC ``datetime64`` (pandas gives objects)."""
    if getattr(series.dtype, "tz", None) is not None:
        series = series.dt.tz_convert("UTC").dt.tz_localize(None)
    return series.to_numpy()


def _from_arrow(table: Any) -> Columns:
    """A pyarrow Table / RecordBatch (or anything pyarrow can read as one) as numpy columns."""
    import pyarrow as pa

    if not isinstance(table, (pa.Table, pa.RecordBatch)):
        table = pa.table(table)
    out: Columns = {}
    for name in table.column_names:
        col = table.column(name)
        if isinstance(col, pa.ChunkedArray):
            col = col.combine_chunks()
        if pa.types.is_dictionary(col.type):
            col = col.dictionary_decode()
        if pa.types.is_string(col.type) or pa.types.is_large_string(col.type):
            out[name] = np.asarray(col.to_pylist(), dtype=object)
        elif col.null_count and (pa.types.is_integer(col.type) or pa.types.is_floating(col.type)):
            out[name] = col.cast(pa.float64()).to_numpy(zero_copy_only=False)
        else:
            out[name] = _numpy(name, col.to_numpy(zero_copy_only=False))
    return out


def columns(records: Any) -> Columns:
    """The columns of a table, as 1-D numpy arrays by name.

    Raises:
        InvalidFrameError: ``records`` is not a table, or its columns are not one-dimensional or of unequal length.
    """
    if records is None:
        raise InvalidFrameError("records must be a table (dict of columns, DataFrame, Arrow table, list of dicts)")
    module = type(records).__module__.split(".")[0]
    out: Columns
    if isinstance(records, np.ndarray):
        if records.dtype.names is None:
            raise InvalidFrameError("a numpy array of records must be a structured array with named fields")
        out = {n: np.asarray(records[n]) for n in records.dtype.names}
    elif isinstance(records, Mapping):
        out = {str(k): _numpy(str(k), v) for k, v in records.items()}
    elif module == "pandas" and hasattr(records, "columns"):
        out = {str(k): _numpy(str(k), _pandas_values(records[k])) for k in records.columns}
    elif module == "polars" and hasattr(records, "get_column"):
        out = {str(k): _numpy(str(k), records.get_column(k).to_numpy()) for k in records.columns}
    elif module == "pyarrow" or hasattr(records, "__arrow_c_stream__"):
        try:
            out = _from_arrow(records)
        except ImportError:
            raise InvalidFrameError("reading an Arrow table needs pyarrow: pip install pyarrow") from None
    elif hasattr(records, "__dataframe__"):
        try:
            import pyarrow.interchange as pi
        except ImportError:
            raise InvalidFrameError("reading an interchange dataframe needs pyarrow: pip install pyarrow") from None
        out = _from_arrow(pi.from_dataframe(records))
    elif isinstance(records, Sequence) and not isinstance(records, (str, bytes)):
        if not all(isinstance(r, Mapping) for r in records):
            raise InvalidFrameError("a sequence of records must hold one mapping (dict) per row")
        keys: dict[str, None] = {}
        for r in records:
            keys.update(dict.fromkeys(map(str, r)))
        missing = object()
        out = {}
        for k in keys:
            vals = [r.get(k, missing) for r in records]
            if any(v is missing for v in vals):
                raise InvalidFrameError(f"column {k!r} is missing from some records; give every record the same keys")
            out[k] = _numpy(k, vals)
    else:
        raise InvalidFrameError(
            f"records must be a table (dict of columns, DataFrame, Arrow table, list of dicts), "
            f"got {type(records).__name__}"
        )
    lengths = {k: v.shape[0] for k, v in out.items()}
    if len(set(lengths.values())) > 1:
        raise InvalidFrameError(f"columns have different lengths: {lengths}")
    return out
