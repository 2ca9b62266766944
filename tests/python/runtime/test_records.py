"""dgan.records (Frame.from_records): repeated rows, upsampling, time-unit and column warnings, ids as given."""

from __future__ import annotations

import pickle
import warnings
from typing import Any

import numpy as np
import pytest

import dgan
from dgan import exceptions as exc


def walk(ids: list[object], step_s: float, seconds: float = 4.0) -> dict[str, np.ndarray]:
    """Each agent walking at 1.2 m/s along x, one row every ``step_s`` seconds."""
    t = np.round(np.arange(0.0, seconds + 1e-9, step_s), 9)
    agent = np.empty(len(ids) * len(t), dtype=object)
    agent[:] = [a for a in ids for _ in t]
    k = np.repeat(np.arange(len(ids)), len(t))
    return {"agent_id": agent, "time": np.tile(t, len(ids)), "x": np.tile(1.2 * t, len(ids)), "y": 2.0 * k}


@pytest.fixture(scope="module")
def zara1() -> dgan.Predictor:
    return dgan.Predictor("zara1")


def test_repeated_rows_are_refused_by_default_naming_the_option_and_the_agent() -> None:
    rec = walk(["a", "b"], 0.4)
    doubled = {k: np.r_[v, v[:3]] for k, v in rec.items()}
    with pytest.raises(exc.InvalidFrameError, match=r"agent 'a' has two rows at time 0 s.*duplicates="):
        dgan.Frame.from_records(doubled, t_obs=8, dt=0.4)


@pytest.mark.parametrize(("how", "expected"), [("first", 0.0), ("last", 1.0), ("mean", 0.5)])
def test_repeated_rows_resolved_as_asked(how: str, expected: float) -> None:
    rec = {"agent_id": [1, 1, 1, 1], "time": [0.0, 0.4, 0.4, 0.8], "x": [0.0, 0.0, 1.0, 2.0], "y": [0.0] * 4}
    frame = dgan.Frame.from_records(rec, t_obs=3, dt=0.4, duplicates=how)
    assert frame.positions[0, 1, 0] == expected
    with pytest.raises(exc.InvalidSpecError, match="duplicates must be one of"):
        dgan.Frame.from_records(rec, t_obs=3, dt=0.4, duplicates="median")


def test_sparse_data_name_the_models_whose_step_fits(zara1: dgan.Predictor) -> None:
    with pytest.raises(exc.TimeBaseError, match=r"1.25× the model's dt = 0.4 s.*upsample=True.*apolloscape \(0.5 s\)"):
        dgan.Frame.from_records(walk([1], 0.5), spec=zara1)
    with pytest.raises(exc.TimeBaseError, match=r"no bundled model's step fits them as they are; with upsample=True"):
        dgan.Frame.from_records(walk([1], 0.8, 8.0), spec=zara1)
    with pytest.raises(exc.TimeBaseError, match=r"more than 2.5× sparser.*no bundled model's step fits them"):
        dgan.Frame.from_records(walk([1], 2.0, 20.0), spec=zara1, upsample=True)


def test_upsample_interpolates_sparser_data_onto_the_grid_and_says_so(zara1: dgan.Predictor) -> None:
    frame = dgan.Frame.from_records(walk([1, 2], 0.5), spec=zara1, upsample=True)
    assert frame.upsampled
    assert frame.source_dt == pytest.approx(0.5)
    assert frame.dt == pytest.approx(0.4)
    assert frame.mask.all()
    t = 4.0 - 0.4 * np.arange(7, -1, -1)
    np.testing.assert_allclose(frame.positions[0, :, 0], 1.2 * t, atol=1e-9)
    dense = dgan.Frame.from_records(walk([1], 0.1), spec=zara1, upsample=True)
    assert not dense.upsampled
    assert dense.source_dt == pytest.approx(0.1)
    assert len(zara1.predict(frame)) == 2
    assert pickle.loads(pickle.dumps(frame)).upsampled


def test_a_wrong_time_unit_warns(zara1: dgan.Predictor) -> None:
    rec = walk([1, 2], 0.4)
    rec["time"] = rec["time"] * 1000  # milliseconds read as seconds
    with pytest.warns(exc.TimeUnitWarning, match="milliseconds read as seconds"):
        frame = dgan.Frame.from_records(rec, spec=zara1)
    assert frame.mask.sum(axis=1).max() == 1
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        dgan.Frame.from_records(rec, spec=zara1, time_unit=1e-3)


def test_a_misspelled_optional_column_warns_with_the_close_name() -> None:
    rec = walk([1], 0.4)
    rec["Class"] = np.array(["vehicle"] * len(rec["x"]), dtype=object)
    rec["heding"] = np.zeros(len(rec["x"]))
    with pytest.warns(exc.ColumnWarning) as record:
        frame = dgan.Frame.from_records(rec, t_obs=8, dt=0.4)
    messages = " ".join(str(w.message) for w in record)
    assert "cls_column='Class'" in messages
    assert "heading='heding'" in messages
    assert frame.classes == ["pedestrian"]
    read = dgan.Frame.from_records(rec, t_obs=8, dt=0.4, cls_column="Class", heading="heding")
    assert read.classes == ["vehicle"]
    missing = {("agent" if k == "agent_id" else k): v for k, v in rec.items()}
    with pytest.raises(exc.InvalidFrameError, match=r"did you mean 'agent' \(agent_id='agent'\)"):
        dgan.Frame.from_records(missing, t_obs=8, dt=0.4)


@pytest.mark.parametrize(
    "ids",
    [
        [1, "1", "b"],
        [2**63 + 5, 7],
        np.array([2**64 - 1, 3], dtype=np.uint64),
        ["x", "y"],
        [5, -3],
    ],
    ids=["mixed", "past-int64-list", "uint64", "strings", "ints"],
)
def test_ids_come_back_as_given_through_every_path(zara1: dgan.Predictor, ids: Any) -> None:
    given = ids.tolist() if isinstance(ids, np.ndarray) else list(ids)
    times = np.arange(0, 3.2, 0.4)
    rows = [{"agent_id": a, "time": t, "x": 0.3 * t, "y": float(k)} for k, a in enumerate(given) for t in times]
    via_rows = dgan.Frame.from_records(rows, spec=zara1)
    direct = dgan.Frame(np.cumsum(np.full((len(given), 8, 2), 0.3), axis=1), ids=ids)
    tracker = dgan.Tracker(zara1)
    for t in times:
        tracker.update(t, ids=ids, positions=np.c_[np.full(len(given), 0.3 * t), np.arange(len(given))])
    for frame in (via_rows, direct, tracker.frame(), pickle.loads(pickle.dumps(direct))):
        back = sorted(frame.agent_ids.tolist(), key=repr)
        assert back == sorted(given, key=repr), back
        assert sorted(map(type, back), key=repr) == sorted(map(type, given), key=repr)
        out = zara1.predict(frame, modes=1).to_records()["agent_id"].tolist()
        assert sorted(set(out), key=repr) == sorted(given, key=repr)
    pred = zara1.predict(direct, modes=1)
    if {type(v) for v in given} == {int, str}:
        with pytest.raises(exc.OutputError, match="mix int and str"):
            pred.to_arrow()
    else:
        assert sorted(set(pred.to_arrow().column("agent_id").to_pylist()), key=repr) == sorted(given, key=repr)


def test_the_tracker_keeps_the_integer_1_and_the_string_1_apart(zara1: dgan.Predictor) -> None:
    tracker = dgan.Tracker(zara1)
    for k, t in enumerate(np.arange(0, 3.2, 0.4)):
        tracker.update(t, ids=[1, "1"], positions=[[0.3 * k, 0.0], [0.0, 0.3 * k]])
    frame = tracker.frame()
    assert frame.agent_ids.tolist() == [1, "1"]
    assert frame.mask.all()


def test_a_track_is_sampled_as_a_frame_of_records_samples_it() -> None:
    """``dgan.sample_track`` gives the positions ``Frame.from_records`` puts on its grid (one implementation, the
    engine's), and NaN where the frame masks a step: across a gap wider than ``max_gap`` and outside the track."""
    times = np.array([0.0, 0.4, 0.8, 1.2, 2.4, 2.8])  # 1.2 s without a row before 2.4
    xy = np.stack([1.3 * times, 0.2 * times**2], axis=1)
    grid = np.round(np.arange(0.0, 2.8 + 1e-9, 0.4), 9)
    got = dgan.sample_track(times, xy, grid, dt=0.4)
    rows = {"agent_id": np.zeros(len(times)), "time": times, "x": xy[:, 0], "y": xy[:, 1]}
    frame = dgan.Frame.from_records(rows, t_obs=len(grid), dt=0.4)
    seen = frame.mask[0]
    np.testing.assert_array_equal(np.isfinite(got[:, 0]), seen)
    np.testing.assert_allclose(got[seen], frame.positions[0][seen], atol=1e-12)
    assert not seen[4:6].any()  # 1.6 and 2.0 s lie in the gap
    half = dgan.sample_track(times, xy, [0.2, 3.0, -0.1], dt=0.4)
    np.testing.assert_allclose(half[0], (xy[0] + xy[1]) / 2)
    assert np.isnan(half[1:]).all()  # nothing extrapolated
    wide = dgan.sample_track(times, xy, [2.0], dt=0.4, max_gap=1.2)
    np.testing.assert_allclose(wide[0], xy[3] + (2.0 - 1.2) / 1.2 * (xy[4] - xy[3]))


@pytest.mark.parametrize(
    ("times", "xy", "at", "dt", "error", "match"),
    [
        ([0.4, 0.0], [[0, 0], [1, 1]], [0.2], 0.4, exc.InvalidFrameError, "increase strictly"),
        ([0.0, 0.0], [[0, 0], [1, 1]], [0.2], 0.4, exc.InvalidFrameError, "increase strictly"),
        ([0.0, np.nan], [[0, 0], [1, 1]], [0.2], 0.4, exc.InvalidFrameError, "time 1 is not finite"),
        ([0.0, 0.4], [[0, 0], [1, np.inf]], [0.2], 0.4, exc.InvalidFrameError, "position 1 is not finite"),
        ([0.0, 0.4], [[0, 0], [1, 1]], [np.nan], 0.4, exc.InvalidFrameError, "must be finite"),
        ([0.0, 0.4, 0.8], [[0, 0], [1, 1]], [0.2], 0.4, exc.InvalidFrameError, "one position per time"),
        ([0.0, 0.4], [[0, 0, 0], [1, 1, 1]], [0.2], 0.4, exc.InvalidFrameError, r"shape \(N, 2\)"),
        (["a", "b"], [[0, 0], [1, 1]], [0.2], 0.4, exc.InvalidFrameError, "times must be an array of float64"),
        ([0.0, 0.4], [[0, 0], [1, 1]], [0.2j], 0.4, exc.InvalidFrameError, "at must be an array of float64"),
        ([0.0, 0.4], "xy", [0.2], 0.4, exc.InvalidFrameError, "xy must be an array of float64"),
        ([0.0, 0.4], [[0, 0], [1, 1]], None, 0.4, exc.InvalidFrameError, "at is required"),
        ([0.0, 0.4], [[0, 0], [1, 1]], [0.2], 0.0, exc.TimeBaseError, "positive"),
        ([0.0, 0.4], [[0, 0], [1, 1]], [0.2], np.nan, exc.TimeBaseError, "positive"),
    ],
)
def test_a_bad_track_is_refused_with_a_typed_error(
    times: list[float], xy: list[list[float]], at: list[float], dt: float, error: type[Exception], match: str
) -> None:
    with pytest.raises(error, match=match):
        dgan.sample_track(times, xy, at, dt=dt)


def test_a_negative_gap_is_a_time_base_error() -> None:
    with pytest.raises(exc.TimeBaseError, match="max_gap must be a non-negative"):
        dgan.sample_track([0.0, 0.4], [[0, 0], [1, 1]], [0.2], dt=0.4, max_gap=-1.0)


def test_a_missing_column_is_named_where_a_tracker_calls_it_otherwise() -> None:
    rec = walk(["a", "b"], 0.4)
    theirs = {
        "Track-ID": rec["agent_id"],
        "frame_id": np.round(rec["time"] / 0.4),
        "pos_x": rec["x"],
        "pos_y": rec["y"],
        "yaw": np.zeros(rec["x"].size),
    }
    with pytest.raises(exc.InvalidFrameError, match=r"did you mean 'Track-ID' \(agent_id='Track-ID'\)\?"):
        dgan.Frame.from_records(theirs, t_obs=8, dt=0.4)
    with pytest.raises(
        exc.InvalidFrameError,
        match=r"did you mean 'frame_id' \(time='frame_id', with time_unit= the seconds per frame\)\?",
    ):
        dgan.Frame.from_records(theirs, t_obs=8, dt=0.4, agent_id="Track-ID")
    with pytest.raises(exc.InvalidFrameError, match=r"did you mean 'pos_x' \(x='pos_x'\)\?"):
        dgan.Frame.from_records(theirs, t_obs=8, dt=0.4, agent_id="Track-ID", time="frame_id")
    with pytest.warns(exc.ColumnWarning, match="has 'yaw', which is not read; pass heading='yaw'"):
        frame = dgan.Frame.from_records(
            theirs, t_obs=8, dt=0.4, agent_id="Track-ID", time="frame_id", time_unit=0.4, x="pos_x", y="pos_y"
        )
    same = dgan.Frame.from_records(rec, t_obs=8, dt=0.4)
    np.testing.assert_allclose(frame.positions, same.positions, atol=1e-12)
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        dgan.Frame.from_records(
            theirs,
            t_obs=8,
            dt=0.4,
            agent_id="Track-ID",
            time="frame_id",
            time_unit=0.4,
            x="pos_x",
            y="pos_y",
            heading="yaw",
        )
