"""How values a user gives are read: as given (ids keep their types), as checked arrays that refuse every
conversion that would lose or invent information, and named in error messages."""

from __future__ import annotations

import numbers
from typing import Any, Final

import numpy as np
import numpy.typing as npt

from dgan.exceptions import InvalidFrameError

ClassLike = str | int


def typename(value: Any) -> str:
    """How an error message names what it was given: ``None``, or the type's name."""
    return "None" if value is None else type(value).__name__


#: The array kinds each target dtype accepts without losing information (numpy ``dtype.kind`` codes).
_ACCEPTED_KINDS = {"f": "fiu", "i": "iu", "b": "b", "u": "u"}
#: The largest number of values one input array may hold (2³¹: 16 GiB of float64).
MAX_ARRAY_VALUES: Final = 2**31


def checked_array(
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


def as_given(values: Any) -> npt.NDArray[Any]:
    """``values`` as an array that keeps them as given: a list mixing strings with numbers stays a list of both (an
    object array; numpy alone would turn ``1`` into ``'1'``), and a list of integers past int64 is uint64 (or an
    object array past 64 bits), never rounded to floats."""
    arr = np.asarray(values)
    if isinstance(values, np.ndarray) or arr.dtype.kind not in "USfO" or arr.ndim != 1:
        return arr
    items = list(values)
    if arr.dtype.kind in "US" and all(isinstance(v, (str, bytes)) for v in items):
        return arr
    if (
        arr.dtype.kind in "fO"
        and items
        and all(isinstance(v, numbers.Integral) and not isinstance(v, bool) for v in items)
    ):
        for dtype in (np.int64, np.uint64):
            try:
                return np.array(items, dtype=dtype)
            except OverflowError:
                pass
    elif arr.dtype.kind == "f":
        return arr
    out = np.empty(len(items), dtype=object)
    out[:] = items
    return out


def checked_shift(name: str, value: Any, error: type[Exception]) -> npt.NDArray[np.float64]:
    """``value`` as a finite ``(2,)`` vector of metres (a move of the world's origin), or ``error``."""
    shift: npt.NDArray[np.float64] = checked_array(name, value, np.float64, error, required=True)
    if shift.shape != (2,) or not np.isfinite(shift).all():
        raise error(f"{name} must be two finite metres (x, y), got {shift.tolist()}")
    return shift


def shown(value: Any) -> str:
    """A value as an error message shows it: its type, and its first characters."""
    if value is None or isinstance(value, bool):
        return repr(value)
    text = repr(value)
    return f"{typename(value)} {text[:40]}{'…' if len(text) > 40 else ''}"


def checked_real(name: str, value: Any, error: type[Exception] = InvalidFrameError, *, optional: bool = False) -> Any:
    """``value`` as a Python float when it is a real number (an int, a float or a numpy one; not a bool, a string or
    an array), None when ``optional`` and None, else ``error`` naming ``name``. Its range is the caller's to check."""
    if value is None and optional:
        return None
    if isinstance(value, (bool, np.bool_)) or not isinstance(value, numbers.Real):
        raise error(f"{name} must be a real number, got {shown(value)}")
    try:
        return float(value)
    except OverflowError:
        raise error(f"{name} is out of range: {shown(value)}") from None


def checked_text(name: str, value: Any, error: type[Exception] = InvalidFrameError) -> str:
    """``value`` when it is a string (a column name, a path), else ``error`` naming ``name``."""
    if not isinstance(value, str):
        raise error(f"{name} must be a string, got {shown(value)}")
    return value
