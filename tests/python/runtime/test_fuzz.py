"""Property-based fuzzing of the bindings (hypothesis): random arrays, maps and tables through the public API give a
result or a typed ``dgan.exceptions`` error, never another exception. The engine's own fuzzer is
``crates/dgan-core/tests/fuzz.rs`` (``./dev fuzz`` for the long run)."""

from __future__ import annotations

from typing import Any

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st
from hypothesis.extra import numpy as hnp

import dgan
from dgan import exceptions as exc

FAST = settings(max_examples=150, deadline=None, suppress_health_check=[HealthCheck.too_slow])
PREDICTOR = dgan.Predictor("zara1", sessions=1)

numbers = st.one_of(
    st.floats(allow_nan=True, allow_infinity=True),
    st.floats(-100, 100),
    st.integers(-(2**40), 2**40),
)
dtypes = st.sampled_from([np.float64, np.float32, np.int64, np.int16, np.uint8, np.bool_, np.complex128, "U3", object])
shapes = hnp.array_shapes(min_dims=0, max_dims=4, min_side=0, max_side=9)


def any_array(draw: Any) -> Any:
    dtype = draw(dtypes)
    shape = draw(shapes)
    if dtype is object or dtype == "U3":
        return np.full(shape, draw(st.sampled_from(["a", None, 1.5])), dtype=dtype)
    return draw(hnp.arrays(dtype, shape, elements=None))


def typed(fn: Any) -> Any:
    try:
        return fn()
    except exc.DganError:
        return None


@FAST
@given(st.data())
def test_frames_from_random_arrays(data: st.DataObject) -> None:
    positions = any_array(data.draw)
    kwargs: dict[str, Any] = {}
    for key in ("mask", "headings", "lengths", "velocities", "ids"):
        if data.draw(st.booleans()):
            kwargs[key] = any_array(data.draw)
    frame = typed(lambda: dgan.Frame(positions, **kwargs))
    if frame is not None and positions.ndim == 3 and positions.shape[1:] == (8, 2):
        typed(lambda: PREDICTOR.predict(frame))


@FAST
@given(st.data())
def test_frames_of_random_numbers_predict_or_refuse(data: st.DataObject) -> None:
    n = data.draw(st.integers(0, 6))
    values = data.draw(st.lists(numbers, min_size=n * 16, max_size=n * 16))
    positions = np.asarray(values, dtype=np.float64).reshape(n, 8, 2) if n else np.zeros((0, 8, 2))
    frame = typed(lambda: dgan.Frame(positions))
    if frame is not None:
        pred = PREDICTOR.predict(frame)
        assert np.all(np.isfinite(pred.trajectories))


@FAST
@given(
    st.lists(
        st.tuples(
            st.sampled_from([*dgan.MAP_ELEMENT_KINDS, "sea", ""]),
            st.lists(st.tuples(numbers, numbers), min_size=0, max_size=12),
        ),
        max_size=5,
    )
)
def test_vector_maps_of_random_geometry(elements: list[tuple[str, list[tuple[float, float]]]]) -> None:
    m = typed(lambda: dgan.VectorMap([(k, np.asarray(p, dtype=np.float64).reshape(-1, 2)) for k, p in elements]))
    if m is not None:
        frame = dgan.Frame(np.cumsum(np.full((2, 8, 2), 0.4), axis=1), map=m)
        PREDICTOR.predict(frame)


@FAST
@given(
    st.lists(
        st.fixed_dictionaries(
            {
                "agent_id": st.one_of(st.integers(0, 4), st.sampled_from(["a", "b"])),
                "time": st.one_of(st.integers(0, 12).map(lambda k: k * 0.4), numbers),
                "x": numbers,
                "y": st.floats(-10, 10),
            }
        ),
        max_size=40,
    ),
    st.sampled_from([None, 0.4, 0.1, -1.0]),
)
def test_tables_of_random_rows(rows: list[dict[str, Any]], dt: float | None) -> None:
    frame = typed(lambda: dgan.Frame.from_records(rows, t_obs=8, dt=dt))
    if frame is not None and len(frame):
        typed(lambda: PREDICTOR.predict(frame))


def test_a_property_failure_would_be_seen() -> None:
    """The properties above are not vacuous: a plain Python error inside is not swallowed by ``typed``."""
    with pytest.raises(ZeroDivisionError):
        typed(lambda: 1 / 0)
