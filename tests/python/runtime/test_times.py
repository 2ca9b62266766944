"""dgan._times through Frame.from_records: time columns of datetimes, ISO 8601 strings and timedeltas, from every
kind of table, give the frame their seconds give; their errors are typed and name what to do."""

from __future__ import annotations

import datetime as dt
import warnings
from typing import Any

import numpy as np
import pytest

import dgan
from dgan import exceptions as exc

START = np.datetime64("2026-03-01T08:15:00", "ns")


def moving(seconds: float = 4.0, step_s: float = 0.1) -> dict[str, np.ndarray]:
    """Three agents at 10 Hz with seconds as numbers; the time column starts at 3.7 s (not at zero)."""
    t = np.round(np.arange(3.7, 3.7 + seconds + 1e-9, step_s), 9)
    k = np.repeat(np.arange(3), t.size)
    tt = np.tile(t, 3)
    return {"agent_id": k, "time": tt, "x": (0.4 + 0.5 * k) * tt + 0.1 * np.sin(3 * tt), "y": 2.0 * k - 0.2 * tt}


def instants(seconds: np.ndarray) -> np.ndarray:
    return START + np.round(seconds * 1e9).astype("timedelta64[ns]")


@pytest.fixture(scope="module")
def hdmap() -> dgan.Predictor:
    return dgan.Predictor("hdmap")


def same(a: dgan.Frame, b: dgan.Frame) -> None:
    np.testing.assert_array_equal(a.mask, b.mask)
    np.testing.assert_allclose(a.positions, b.positions, rtol=0, atol=1e-9)
    assert a.agent_ids.tolist() == b.agent_ids.tolist()


def as_kind(rec: dict[str, np.ndarray], kind: str) -> Any:
    """``rec`` with its time column as instants (or durations) of one kind a user's table holds."""
    times = instants(rec["time"])
    if kind == "datetime64":
        return {**rec, "time": times}
    if kind == "iso-strings":
        return {**rec, "time": np.datetime_as_string(times, unit="ms").astype(object) + "Z"}
    if kind == "datetime-objects":
        return [
            {**{k: v[i] for k, v in rec.items()}, "time": times[i].astype("datetime64[us]").item()}
            for i in range(times.size)
        ]
    if kind == "timedelta64":
        return {**rec, "time": times - START}
    pd = pytest.importorskip("pandas")
    frame = pd.DataFrame({**rec, "time": pd.to_datetime(times).tz_localize("UTC").tz_convert("America/Chicago")})
    if kind == "pandas-tz":
        return frame
    if kind == "polars-tz":
        return pytest.importorskip("polars").from_pandas(frame)
    return pytest.importorskip("pyarrow").Table.from_pandas(frame)


@pytest.mark.parametrize(
    "kind", ["datetime64", "iso-strings", "datetime-objects", "timedelta64", "pandas-tz", "polars-tz", "arrow-tz"]
)
def test_a_column_of_times_gives_the_frame_its_seconds_give(hdmap: dgan.Predictor, kind: str) -> None:
    rec = moving()
    by_seconds = dgan.Frame.from_records(rec, spec=hdmap)
    same(dgan.Frame.from_records(as_kind(rec, kind), spec=hdmap), by_seconds)
    earlier = dgan.Frame.from_records(rec, spec=hdmap, current_time=6.1)
    at = instants(np.array([6.1]))[0]
    asked: Any = {
        "iso-strings": str(at),
        "datetime-objects": at.astype("datetime64[us]").item(),
        "timedelta64": np.timedelta64(6100, "ms"),
    }.get(kind, at)
    same(dgan.Frame.from_records(as_kind(rec, kind), spec=hdmap, current_time=asked), earlier)
    assert not np.array_equal(earlier.positions, by_seconds.positions)


def test_a_zone_aware_current_time_is_the_same_instant_in_utc(hdmap: dgan.Predictor) -> None:
    rec = moving()
    chicago = dt.timezone(dt.timedelta(hours=-6))
    at = dt.datetime(2026, 3, 1, 2, 15, 6, 100000, tzinfo=chicago)  # 08:15:06.1 UTC
    frame = dgan.Frame.from_records(as_kind(rec, "datetime64"), spec=hdmap, current_time=at)
    same(frame, dgan.Frame.from_records(rec, spec=hdmap, current_time=6.1))


def test_times_as_instants_refuse_what_cannot_be_read_and_say_why(hdmap: dgan.Predictor) -> None:
    rec = as_kind(moving(), "datetime64")
    with pytest.raises(
        exc.InvalidFrameError, match=r"current_time 6\.1 is a number where the time column holds instants"
    ):
        dgan.Frame.from_records(rec, spec=hdmap, current_time=6.1)
    with pytest.raises(exc.TimeBaseError, match="carry their own unit; leave time_unit at 1"):
        dgan.Frame.from_records(rec, spec=hdmap, time_unit=0.001)
    with pytest.raises(
        exc.InvalidFrameError,
        match=r"no row at current_time 2026-03-01T09:00:00.000; the table "
        r"spans 2026-03-01T08:15:03.700..2026-03-01T08:15:07.700",
    ):
        dgan.Frame.from_records(rec, spec=hdmap, current_time="2026-03-01T09:00")
    with pytest.raises(exc.InvalidFrameError, match="current_time 'yesterday' is not a time"):
        dgan.Frame.from_records(rec, spec=hdmap, current_time="yesterday")
    gap = {**rec, "time": rec["time"].copy()}
    gap["time"][4] = np.datetime64("NaT")
    with pytest.raises(exc.InvalidFrameError, match=r"the time column 'time' holds missing times \(NaT\)"):
        dgan.Frame.from_records(gap, spec=hdmap)
    words = {**rec, "time": np.array(["soon"] * rec["x"].size, dtype=object)}
    with pytest.raises(exc.InvalidFrameError, match="the time column 'time''s value 'soon' is not a time"):
        dgan.Frame.from_records(words, spec=hdmap)
    with pytest.raises(
        exc.InvalidFrameError, match=r"current_time 6\.1 is a number where the time column holds durations"
    ):
        dgan.Frame.from_records(as_kind(moving(), "timedelta64"), spec=hdmap, current_time=6.1)
    with pytest.raises(exc.InvalidFrameError, match="column 'time' must be numeric or times, got complex128"):
        dgan.Frame.from_records({**rec, "time": rec["x"] + 1j}, spec=hdmap)
    with pytest.raises(exc.InvalidFrameError, match="current_time must be a number in the time column's unit"):
        dgan.Frame.from_records(moving(), spec=hdmap, current_time="6.1")


def test_iso_times_with_utc_offsets_are_the_instants_they_name(hdmap: dgan.Predictor) -> None:
    rec = moving()
    utc = as_kind(rec, "iso-strings")
    # The same instants written two hours behind UTC (as a tracker logging local time with its offset would).
    two_hours_behind: np.ndarray = instants(rec["time"]) - np.timedelta64(2, "h")
    local = np.datetime_as_string(two_hours_behind, unit="ms").astype(object) + "-02:00"
    with warnings.catch_warnings():
        warnings.simplefilter("error")  # numpy's warning that it keeps no zone is not passed on
        same(dgan.Frame.from_records({**rec, "time": local}, spec=hdmap), dgan.Frame.from_records(utc, spec=hdmap))
        at = dgan.Frame.from_records({**rec, "time": local}, spec=hdmap, current_time="2026-03-01T06:15:06.1-02:00")
    same(at, dgan.Frame.from_records(rec, spec=hdmap, current_time=6.1))


def test_a_prediction_counts_its_times_as_the_table_wrote_them(hdmap: dgan.Predictor) -> None:
    rec = moving()
    at = instants(np.array([6.1]))[0]
    frame = dgan.Frame.from_records(as_kind(rec, "datetime64"), spec=hdmap, current_time=at)
    assert frame.time == at
    assert frame.select(np.array([True, False, True])).time == at  # kept by what derives a frame
    out = hdmap.predict(frame).to_records()
    assert out["time"].dtype == np.dtype("datetime64[ns]")
    np.testing.assert_array_equal(out["time"][:3], at + np.array([200, 400, 600], dtype="timedelta64[ms]"))
    by_seconds = dgan.Frame.from_records(rec, spec=hdmap, current_time=6.1)
    assert by_seconds.time == pytest.approx(6.1)
    np.testing.assert_allclose(hdmap.predict(by_seconds).to_records()["time"][:3], [6.3, 6.5, 6.7])
    in_ms = {**rec, "time": np.round(rec["time"] * 1000)}
    frame_ms = dgan.Frame.from_records(in_ms, spec=hdmap, time_unit=0.001, current_time=6100)
    np.testing.assert_allclose(hdmap.predict(frame_ms).to_records()["time"][:3], [6300, 6500, 6700])
    tracker = dgan.Tracker(hdmap)
    for t in (0.0, 0.2, 0.4):
        tracker.update(100.0 + t, ids=["a"], positions=[[t, 0.0]])
    assert tracker.frame().time == pytest.approx(100.4)
    np.testing.assert_allclose(tracker.predict().to_records()["time"][:2], [100.6, 100.8])
