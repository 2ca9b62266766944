"""dgan.series: a table's frames at many times, read once."""

from __future__ import annotations

import datetime as dt

import numpy as np
import pytest
from conftest import zara1_records

import dgan
from dgan.exceptions import InvalidFrameError


def _same(a: dgan.Frame, b: dgan.Frame) -> bool:
    return (
        np.array_equal(a.positions, b.positions, equal_nan=True)
        and np.array_equal(a.mask, b.mask)
        and np.array_equal(a.agent_ids, b.agent_ids)
        and a.time == b.time
        and a.classes == b.classes
    )


def test_every_frame_equals_from_records_at_its_time() -> None:
    rows = zara1_records()
    frames = dgan.series.frames(rows, t_obs=8, dt=0.4, time_unit=0.04)
    times = np.unique(rows["time"])
    assert len(frames) == len(times) == 20
    for frame, t in zip(frames, times, strict=True):
        assert _same(frame, dgan.Frame.from_records(rows, t_obs=8, dt=0.4, time_unit=0.04, current_time=t))
    some = dgan.series.frames(rows, [5500.0, 5430.0], t_obs=8, dt=0.4, time_unit=0.04, map=dgan.scene_map("zara1"))
    assert [f.time for f in some] == [5500.0, 5430.0]
    assert all(f.map is not None for f in some)


def test_instants_and_string_ids_as_from_records_reads_them() -> None:
    rows = zara1_records()
    start = dt.datetime(2026, 12, 7, 8, 0, tzinfo=dt.UTC)
    iso = [(start + dt.timedelta(seconds=0.04 * t)).isoformat() for t in rows["time"]]
    table = {**rows, "time": np.array(iso), "agent_id": np.array([f"ped-{i}" for i in rows["agent_id"]])}
    at = (start + dt.timedelta(seconds=0.04 * 5500)).isoformat()
    (frame,) = dgan.series.frames(table, [at], t_obs=8, dt=0.4)
    assert _same(frame, dgan.Frame.from_records(table, t_obs=8, dt=0.4, current_time=at))
    assert str(frame.agent_ids[0]).startswith("ped-")


def test_futures_are_the_later_frames_positions() -> None:
    rows = zara1_records()
    (frame, (future, seen)), *_ = dgan.series.frames_with_futures(rows, 12, [5500.0], t_obs=8, dt=0.4, time_unit=0.04)
    later = dgan.Frame.from_records(rows, t_obs=20, dt=0.4, time_unit=0.04, current_time=5620.0)
    for i, agent in enumerate(frame.agent_ids):
        j = np.flatnonzero(later.agent_ids == agent)
        if len(j) and seen[i].all():
            assert np.array_equal(future[i], later.positions[j[0], 8:])
    assert future.shape == (len(frame), 12, 2)
    assert seen.any(axis=1).all()
    assert np.isnan(future[~seen]).all()


def test_bad_times_and_options_are_refused() -> None:
    rows = zara1_records()
    with pytest.raises(InvalidFrameError, match="no row at current_time 1"):
        dgan.series.frames(rows, [1.0], t_obs=8, dt=0.4, time_unit=0.04)
    with pytest.raises(InvalidFrameError, match="times=, a list"):
        dgan.series.frames(rows, t_obs=8, dt=0.4, current_time=5500.0)
    with pytest.raises(InvalidFrameError, match="unknown option"):
        dgan.series.frames(rows, t_obs=8, dt=0.4, horizon=3)
    with pytest.raises(InvalidFrameError, match="sequence of times"):
        dgan.series.frames(rows, "5500", t_obs=8, dt=0.4)
    with pytest.raises(InvalidFrameError, match="t_f must be"):
        dgan.series.frames_with_futures(rows, 0, t_obs=8, dt=0.4)
    with pytest.raises(InvalidFrameError, match="must be a number"):
        dgan.series.frames(rows, ["later"], t_obs=8, dt=0.4, time_unit=0.04)
