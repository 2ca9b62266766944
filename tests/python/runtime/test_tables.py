"""dgan.tables and Frame.from_records: every kind of table a user has, and predictions as tables."""

from __future__ import annotations

from pathlib import Path
from typing import Any

import numpy as np
import pandas as pd
import polars as pl
import pyarrow as pa
import pyarrow.parquet as pq
import pytest
from conftest import zara1_records

import dgan
from dgan import exceptions as exc
from dgan.tables import columns


def zara1_string_table() -> dict[str, Any]:
    """The bundled zara1 excerpt with string ids (``"ped-76"``) and time in seconds."""
    rec = zara1_records()
    return {
        "agent_id": np.array([f"ped-{i}" for i in rec["agent_id"]], dtype=object),
        "time": rec["time"] * 0.04,
        "x": rec["x"],
        "y": rec["y"],
    }


def every_table_kind(cols: dict[str, Any]) -> dict[str, Any]:
    records = [dict(zip(cols, row, strict=True)) for row in zip(*cols.values(), strict=True)]
    structured = np.zeros(len(cols["x"]), dtype=[("agent_id", "U16"), ("time", "f8"), ("x", "f8"), ("y", "f8")])
    for name in ("agent_id", "time", "x", "y"):
        structured[name] = cols[name]
    return {
        "dict": cols,
        "records": records,
        "structured": structured,
        "pandas": pd.DataFrame(cols),
        "polars": pl.DataFrame({k: list(v) for k, v in cols.items()}),
        "pyarrow": pa.table({k: list(v) for k, v in cols.items()}),
        "pyarrow_batch": pa.RecordBatch.from_pydict({k: list(v) for k, v in cols.items()}),
    }


def test_every_kind_of_table_gives_the_same_prediction() -> None:
    predictor = dgan.Predictor("zara1")
    tables = every_table_kind(zara1_string_table())
    out = {}
    for name, table in tables.items():
        frame = dgan.Frame.from_records(table, spec=predictor, current_time=220.0, map=dgan.scene_map("zara1"))
        assert frame.dt == pytest.approx(0.4)
        out[name] = (frame, predictor.predict(frame))
    ref_frame, ref = out["dict"]
    assert len(ref_frame) == 18
    assert ref.agent_ids.tolist()[:2] == ["ped-76", "ped-77"]
    for name, (frame, pred) in out.items():
        np.testing.assert_array_equal(frame.positions, ref_frame.positions, err_msg=name)
        assert pred.agent_ids.tolist() == ref.agent_ids.tolist(), name
        np.testing.assert_array_equal(pred.trajectories, ref.trajectories, err_msg=name)
        np.testing.assert_array_equal(pred.probabilities, ref.probabilities, err_msg=name)


def test_string_ids_equal_integer_ids() -> None:
    p = dgan.Predictor("zara1")
    strings = dgan.Frame.from_records(zara1_string_table(), spec=p, current_time=220.0)
    ints = dgan.Frame.from_records(zara1_records(), spec=p, time_unit=0.04, current_time=5500.0)
    np.testing.assert_array_equal(strings.positions, ints.positions)
    np.testing.assert_array_equal(p.predict(strings).trajectories, p.predict(ints).trajectories)
    assert ints.agent_ids.dtype == np.int64


@pytest.mark.parametrize(
    ("table", "match"),
    [
        (None, "must be a table"),
        ("agent_id,time", "must be a table"),
        (42, "must be a table"),
        ([1, 2, 3], "one mapping"),
        ([{"agent_id": 1, "time": 0.0}, {"agent_id": 2}], "missing from some records"),
        ({"agent_id": [1, 2], "time": [0.0]}, "different lengths"),
        ({"agent_id": [[1, 2]], "time": [0.0]}, "one-dimensional"),
        (np.zeros(3), "structured array"),
    ],
)
def test_columns_refuses_what_is_not_a_table(table: Any, match: str) -> None:
    with pytest.raises(exc.InvalidFrameError, match=match):
        columns(table)


def test_from_records_faults_of_real_users() -> None:
    p = dgan.Predictor("zara1")
    table = zara1_string_table()
    # A current time that matches no row: a typed error naming the span, never an empty frame.
    with pytest.raises(exc.InvalidFrameError, match=r"no row at current_time 220.1; the table spans"):
        dgan.Frame.from_records(table, spec=p, current_time=220.1)
    # Conflicting duplicate rows (same agent, same time).
    dup = {k: np.r_[v, v[:1]] for k, v in table.items()}
    with pytest.raises(exc.InvalidFrameError, match="two rows at time"):
        dgan.Frame.from_records(dup, spec=p)
    # NaN or None ids.
    nan_ids = {**table, "agent_id": np.r_[np.nan, np.arange(len(table["x"]) - 1.0)]}
    with pytest.raises(exc.InvalidFrameError, match="NaN"):
        dgan.Frame.from_records(nan_ids, spec=p)
    none_ids = {**table, "agent_id": np.array([None, *table["agent_id"][1:]], dtype=object)}
    with pytest.raises(exc.InvalidFrameError, match="None"):
        dgan.Frame.from_records(none_ids, spec=p)
    with pytest.raises(exc.InvalidFrameError, match="needs t_obs"):
        dgan.Frame.from_records(table)
    with pytest.raises(exc.TimeBaseError, match="time_unit"):
        dgan.Frame.from_records(table, spec=p, time_unit=0.0)
    with pytest.raises(exc.InvalidFrameError, match="numeric"):
        dgan.Frame.from_records({**table, "x": np.array(["a"] * len(table["x"]), dtype=object)}, spec=p)


def test_prediction_as_a_long_table(tmp_path: Path) -> None:
    p = dgan.Predictor("sdd", modes=3)
    frame = dgan.Frame.from_records(zara1_string_table(), t_obs=8, dt=1 / 3, time_unit=1 / 0.4 / 3)
    pred = p.predict(frame)
    n, m, t_f = len(pred), 3, p.spec.t_f
    rec = pred.to_records()
    assert list(rec) == [
        "agent_id",
        "mode",
        "probability",
        "class",
        "class_probability",
        "step",
        "time_offset_s",
        "time",
        "x",
        "y",
    ]
    assert all(len(v) == n * m * t_f for v in rec.values())
    # A frame of a table counts its times as the table does (here units of 0.8333 s, the frame's time 8 units).
    assert isinstance(frame.time, float)
    np.testing.assert_allclose(rec["time"][:3], frame.time + np.arange(1, 4) * (1 / 3) / (1 / 0.4 / 3))
    assert "time" not in dgan.Predictor("sdd").predict(dgan.Frame(frame.positions, dt=1 / 3)).to_records()
    # Row (agent i, mode k, step s) holds trajectories[i, k, s - 1].
    i, k, s = 2, 1, 5
    row = (i * m + k) * t_f + (s - 1)
    assert rec["agent_id"][row] == pred.agent_ids[i]
    assert (rec["mode"][row], rec["step"][row]) == (k, s)
    assert rec["time_offset_s"][row] == pytest.approx(s / 3)
    assert rec["x"][row] == pred.trajectories[i, k, s - 1, 0]
    assert rec["probability"][row] == pred.probabilities[i, k]
    assert rec["class"][row] == pred.classes[pred.mode_classes[i, k]]
    assert rec["class_probability"][row] == pred.class_probabilities[i, pred.mode_classes[i, k]]
    df = pred.to_pandas()
    assert df.shape == (n * m * t_f, 10)
    assert df["agent_id"].iloc[0] == pred.agent_ids[0]
    path = tmp_path / "pred.parquet"
    pred.to_parquet(path)
    back = pq.read_table(path)
    assert back.schema.metadata[b"dgan.dt_s"] == str(1 / 3).encode()
    assert back.column("agent_id").to_pylist()[:1] == [pred.agent_ids[0]]
    np.testing.assert_array_equal(back.column("y").to_numpy(), rec["y"])
    np.testing.assert_allclose(pred.times_s, np.arange(1, t_f + 1) / 3)


def test_ids_beyond_int64_are_kept_as_given() -> None:
    p = dgan.Predictor("zara1")
    positions = np.cumsum(np.full((3, 8, 2), 0.4), axis=1)
    for ids in ([2**70, 1, 2], np.array([2**64 - 1, 5, 7], dtype=np.uint64)):
        pred = p.predict(dgan.Frame(positions, ids=ids))
        assert [int(a) for a in pred.agent_ids] == [int(a) for a in ids]
