"""dgan.Frame: construction, from_records, and every kind of bad input."""

from __future__ import annotations

from typing import Any

import numpy as np
import pytest
from conftest import zara1_records

import dgan
from dgan import exceptions as exc


def test_defaults() -> None:
    mixed: list[str | int] = ["vehicle", 1, "pedestrian"]
    f = dgan.Frame(np.zeros((3, 8, 2)), classes=mixed)
    assert len(f) == 3
    assert f.classes == list(dgan.CLASSES)
    np.testing.assert_array_equal(f.ids, [0, 1, 2])
    np.testing.assert_array_equal(f.lengths, [4.5, 1.8, 0.5])
    assert f.mask.all()
    assert dgan.Frame(np.zeros((2, 8, 2))).classes == ["pedestrian", "pedestrian"]


def test_select_rows_a_mask_or_none() -> None:
    f = dgan.Frame(np.arange(24.0).reshape(3, 4, 2), classes=[0, 1, 2], ids=[7, 8, 9])
    np.testing.assert_array_equal(f.select([2, 0]).ids, [9, 7])
    assert f.select([2, 0]).classes == [f.classes[2], f.classes[0]]
    np.testing.assert_array_equal(f.select(np.array([False, True, False])).positions, f.positions[1:2])
    nothing: tuple[Any, ...] = ([], np.zeros(0, dtype=bool), np.zeros(0, dtype=np.int64))
    for none in nothing:
        empty = f.select(none)
        assert len(empty) == 0
        assert empty.positions.shape == (0, 4, 2)
    assert len(f.select([]).select([])) == 0
    for bad in ([3], [-4], [0.0, 1.0], [[0, 1]], np.array([True, False]), ["a"]):
        with pytest.raises(exc.InvalidFrameError, match="rows"):
            f.select(bad)


def test_moved_keeps_the_scene_under_another_origin() -> None:
    shift = np.array([512345.678, 4123456.789])
    mask = np.ones((2, 4), bool)
    mask[1, 0] = False
    lanes = dgan.VectorMap([("lane_centerline", [[0.0, 0.0], [40.0, 4.0]])])
    f = dgan.Frame(
        np.arange(16.0).reshape(2, 4, 2), mask=mask, classes=[0, 2], ids=["car", "ped"], lengths=[4.0, 0.6], map=lanes
    )
    g = f.moved(shift)
    np.testing.assert_array_equal(g.positions[mask], f.positions[mask] + shift)
    np.testing.assert_array_equal(g.mask, f.mask)
    assert g.classes == f.classes
    assert list(g.agent_ids) == list(f.agent_ids) == ["car", "ped"]
    np.testing.assert_array_equal(g.lengths, f.lengths)
    assert isinstance(g.map, dgan.VectorMap)
    np.testing.assert_array_equal(g.map.elements()[0][1], lanes.elements()[0][1] + shift)
    assert f.without_map().moved(shift).map is None
    np.testing.assert_array_equal(f.moved([0.0, 0.0]).positions[mask], f.positions[mask])
    bad_shifts: tuple[Any, ...] = ([1.0], [np.inf, 0.0], "north", None)
    for bad in bad_shifts:
        with pytest.raises(exc.InvalidFrameError, match="shift_m"):
            f.moved(bad)


def test_optional_values_with_nan_for_unknown() -> None:
    f = dgan.Frame(
        np.zeros((2, 4, 2)),
        classes=np.array([0, 2]),
        ids=[10, 20],
        headings=[0.5, np.nan],
        velocities=[[1.0, 0.0], [np.nan, np.nan]],
        lengths=[np.nan, 0.8],
        widths=[2.2, np.nan],
    )
    np.testing.assert_array_equal(f.lengths, [4.5, 0.8])
    np.testing.assert_array_equal(f.widths, [2.2, 0.5])
    np.testing.assert_array_equal(f.ids, [10, 20])


def test_masked_out_steps_may_hold_nan() -> None:
    p = np.zeros((1, 4, 2))
    p[0, :2] = np.nan
    f = dgan.Frame(p, mask=[[False, False, True, True]])
    assert f.mask.sum() == 2


@pytest.mark.parametrize(
    ("kwargs", "error", "match"),
    [
        ({"positions": np.full((2, 8, 2), np.nan)}, exc.InvalidFrameError, "non-finite position"),
        ({"positions": np.full((2, 8, 2), np.inf)}, exc.InvalidFrameError, "non-finite position"),
        ({"positions": np.zeros((2, 8))}, exc.InvalidFrameError, r"shape \(N, T, 2\)"),
        ({"positions": np.zeros((2, 8, 3))}, exc.InvalidFrameError, r"shape \(N, T, 2\)"),
        ({"positions": [["a", "b"]]}, exc.InvalidFrameError, "positions must be an array"),
        ({"mask": np.ones((2, 7), bool)}, exc.InvalidFrameError, "mask must have shape"),
        ({"mask": np.zeros((2, 8), bool)}, exc.InvalidFrameError, "agent 0 has no valid step"),
        ({"classes": ["vehicle", "truck"]}, exc.UnknownClassError, "truck"),
        ({"classes": [0, 7]}, exc.UnknownClassError, "class code 7"),
        ({"classes": ["vehicle"]}, exc.InvalidFrameError, "1 classes given for 2 agents"),
        ({"classes": "vehicle"}, exc.InvalidFrameError, "one class per agent, got str"),
        ({"ids": [3, 3]}, exc.InvalidFrameError, "appears more than once"),
        ({"ids": [1, 2, 3]}, exc.InvalidFrameError, "3 ids given for 2 agents"),
        ({"headings": [np.inf, 0.0]}, exc.InvalidFrameError, "heading of agent 0 is infinite"),
        ({"velocities": [[1.0, 2.0]]}, exc.InvalidFrameError, "1 velocities given for 2 agents"),
        ({"velocities": [1.0, 2.0]}, exc.InvalidFrameError, r"shape \(N, 2\)"),
        ({"lengths": [1.0, -2.0]}, exc.InvalidFrameError, "length of agent 1 must be a positive"),
        ({"widths": [0.0, 1.0]}, exc.InvalidFrameError, "width of agent 0 must be a positive"),
        ({"map": "a map"}, exc.InvalidMapError, "map must be a dgan.RasterMap"),
    ],
)
def test_bad_input_raises_a_typed_error(kwargs: dict[str, Any], error: type[Exception], match: str) -> None:
    args: dict[str, Any] = {"positions": np.zeros((2, 8, 2)), **kwargs}
    with pytest.raises(error, match=match):
        dgan.Frame(**args)


def test_errors_are_value_errors() -> None:
    with pytest.raises(ValueError, match="non-finite"):
        dgan.Frame(np.full((1, 8, 2), np.nan))
    with pytest.raises(dgan.DganError):
        dgan.Frame(np.zeros((1, 8, 2)), classes=["bus"])


def test_empty_frame() -> None:
    assert len(dgan.Frame(np.zeros((0, 8, 2)))) == 0


def test_from_records_reads_a_real_long_table() -> None:
    rec = zara1_records()
    f = dgan.Frame.from_records(rec, t_obs=8, dt=0.4, time_unit=0.04, current_time=5500.0)
    # Agents seen at frame 5500, their histories from frames 5430..5500.
    at_now = np.unique(rec["agent_id"][rec["time"] == 5500.0])
    np.testing.assert_array_equal(f.ids, at_now)
    assert f.positions.shape == (len(at_now), 8, 2)
    for i, pid in enumerate(f.ids):
        rows = (rec["agent_id"] == pid) & (rec["time"] >= 5430) & (rec["time"] <= 5500)
        steps = ((rec["time"][rows] - 5430) / 10).astype(int)
        np.testing.assert_array_equal(np.flatnonzero(f.mask[i]), np.sort(steps))
        np.testing.assert_allclose(f.positions[i, steps, 0], rec["x"][rows])
    # dt is inferred, current_time defaults to the last time.
    g = dgan.Frame.from_records(rec, t_obs=8)
    assert g.positions.shape[1] == 8
    np.testing.assert_array_equal(g.ids, np.unique(rec["agent_id"][rec["time"] == rec["time"].max()]))


def test_from_records_optional_columns_and_structured_arrays() -> None:
    table = np.array(
        [
            (1, 0.0, 0.0, 0.0, "vehicle", 0.1, 4.0),
            (1, 1.0, 1.0, 0.0, "vehicle", 0.2, 4.0),
            (2, 1.0, 5.0, 5.0, "cyclist", 1.0, 1.5),
        ],
        dtype=[
            ("agent_id", "i8"),
            ("time", "f8"),
            ("x", "f8"),
            ("y", "f8"),
            ("class", "U10"),
            ("heading", "f8"),
            ("length", "f8"),
        ],
    )
    f = dgan.Frame.from_records(table, t_obs=2)
    assert f.classes == ["vehicle", "cyclist"]
    np.testing.assert_array_equal(f.lengths, [4.0, 1.5])
    np.testing.assert_array_equal(f.mask, [[True, True], [False, True]])


def test_from_records_errors() -> None:
    with pytest.raises(exc.InvalidFrameError, match="lack the column 'x'"):
        dgan.Frame.from_records({"agent_id": [1], "time": [0.0], "y": [0.0]}, t_obs=2)
    with pytest.raises(exc.InvalidFrameError, match="t_obs"):
        dgan.Frame.from_records(zara1_records(), t_obs=0)
    with pytest.raises(exc.InvalidFrameError, match="time column"):
        dgan.Frame.from_records({"agent_id": [1], "time": [np.nan], "x": [0.0], "y": [0.0]}, t_obs=2)


def test_denoised_smooths_noisy_tracks_and_keeps_the_rest() -> None:
    from dgan.demo import scene_for

    scene = scene_for(dgan.Predictor("zara1").spec)
    clean = scene.frame
    rng = np.random.default_rng(3)
    noisy_positions = clean.positions + rng.normal(0.0, 0.15, clean.positions.shape)
    noisy = dgan.Frame(noisy_positions, mask=clean.mask, classes=clean.classes, ids=clean.agent_ids, map=clean.map)
    # The real, clean tracks pass as they are; the noisy ones come closer to the clean ones.
    np.testing.assert_array_equal(clean.denoised().positions, clean.positions)
    out = noisy.denoised()
    valid = clean.mask
    before = np.abs(noisy.positions - clean.positions)[valid].mean()
    after = np.abs(out.positions - clean.positions)[valid].mean()
    assert after < 0.8 * before, (before, after)
    assert out.map is noisy.map
    np.testing.assert_array_equal(out.agent_ids, noisy.agent_ids)
    np.testing.assert_array_equal(out.mask, noisy.mask)
    assert out.classes == noisy.classes
    # A gate above the noise leaves it; a string id survives; bad gates are typed errors.
    np.testing.assert_array_equal(noisy.denoised(gate_m=5.0).positions, noisy.positions)
    labelled = dgan.Frame(noisy_positions[:2], ids=["a", "b"]).denoised()
    assert list(labelled.agent_ids) == ["a", "b"]
    for gate in (-0.1, float("nan"), float("inf")):
        with pytest.raises(exc.InvalidFrameError, match="denoising gate"):
            noisy.denoised(gate_m=gate)
