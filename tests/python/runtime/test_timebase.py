"""Time bases: frames know their dt; denser data are resampled to the model's, sparser data refused (never a
silently short prediction); the same through the CLI."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest
from conftest import zara1_records

import dgan
from dgan import exceptions as exc
from dgan.cli import main
from dgan.datasets.hdmaps import read_waymo_json
from dgan.demo import APOLLO_FILE, WAYMO_FILE

NOW = 6.0  # seconds into the 9.1 s Waymo scenario: 2.8 s of history for a 0.4 s model


def waymo_tables() -> tuple[dict[str, np.ndarray], dict[str, np.ndarray]]:
    """The bundled Waymo scenario (real, 10 Hz) as a long table, and the same rows every 0.4 s up to ``NOW``, for the
    agents seen at every 10 Hz step of the 0.4 s model's window (so both tables describe the same observations)."""
    sc = read_waymo_json(WAYMO_FILE)
    now_step = round(NOW / sc.dt_s)
    window = slice(now_step - 28, now_step + 1)
    keep = np.flatnonzero(sc.valid[:, window].all(axis=1))
    agent, step = np.nonzero(sc.valid[keep])
    agent = keep[agent]
    rows = step <= now_step
    dense = {
        "agent_id": sc.ids[agent[rows]].astype(np.int64),
        "time": step[rows] * sc.dt_s,
        "x": sc.positions[agent[rows], step[rows], 0],
        "y": sc.positions[agent[rows], step[rows], 1],
    }
    every4 = (now_step - step[rows]) % 4 == 0
    sparse = {k: v[every4] for k, v in dense.items()}
    return dense, sparse


def test_10hz_data_predict_as_the_same_data_at_0_4_s() -> None:
    p = dgan.Predictor("zara1")
    dense, coarse = waymo_tables()
    assert len(np.unique(dense["agent_id"])) >= 10
    f10 = dgan.Frame.from_records(dense, spec=p, current_time=NOW)
    f04 = dgan.Frame.from_records(coarse, spec=p, current_time=NOW)
    assert f10.dt == f04.dt == pytest.approx(0.4)
    np.testing.assert_allclose(f10.positions, f04.positions, atol=1e-9, equal_nan=True)
    a, b = p.predict(f10), p.predict(f04)
    assert a.agent_ids.tolist() == b.agent_ids.tolist()
    np.testing.assert_allclose(a.trajectories, b.trajectories, atol=1e-6)
    np.testing.assert_allclose(a.probabilities, b.probabilities, atol=1e-6)


def test_a_frame_at_another_time_base_is_refused() -> None:
    p = dgan.Predictor("zara1")
    dense, _ = waymo_tables()
    # dt left to the data: the frame is at 0.1 s, and the 0.4 s model refuses it instead of predicting 4x too short.
    frame = dgan.Frame.from_records(dense, t_obs=8, current_time=NOW)
    assert frame.dt == pytest.approx(0.1)
    with pytest.raises(exc.TimeBaseError, match=r"0.1 s apart but the model's are 0.4 s"):
        p.predict(frame)
    with pytest.raises(exc.TimeBaseError):
        p.predict_batch([frame])
    with pytest.raises(exc.TimeBaseError):
        p.predict(dgan.Frame(np.zeros((1, 8, 2)), dt=0.1))
    with pytest.raises(exc.TimeBaseError, match="positive"):
        dgan.Frame(np.zeros((1, 8, 2)), dt=-1.0)
    # A frame that does not say its dt is taken as the model's (arrays built by hand).
    p.predict(dgan.Frame(np.zeros((1, 8, 2))))
    p.predict(dgan.Frame(np.zeros((1, 8, 2)), dt=0.4))


def test_sparser_data_are_refused() -> None:
    rows = np.loadtxt(APOLLO_FILE)  # ApolloScape at 2 Hz: sparser than a 0.4 s model
    table = {"agent_id": rows[:, 1].astype(np.int64), "time": rows[:, 0] * 0.5, "x": rows[:, 3], "y": rows[:, 4]}
    with pytest.raises(
        exc.TimeBaseError,
        match=r"sampled every 0.5000 s \(median\), 1.25× the model's dt = 0.4 s, sparser than its grid",
    ):
        dgan.Frame.from_records(table, spec=dgan.Predictor("zara1"))


def test_irregular_timestamps_are_interpolated() -> None:
    rec = zara1_records()
    rng = np.random.default_rng(0)
    t = rec["time"] * 0.04
    jitter = np.where(np.isclose(t, 220.0), 0.0, rng.uniform(-0.03, 0.03, t.shape))
    # A straight walk so that interpolation is exact: x = 1.3 * t.
    table = {"agent_id": rec["agent_id"], "time": t + jitter, "x": 1.3 * (t + jitter), "y": rec["y"] * 0}
    f = dgan.Frame.from_records(table, t_obs=8, dt=0.4, current_time=220.0)
    grid = 220.0 - 0.4 * np.arange(7, -1, -1)
    for i in range(len(f)):
        seen = f.mask[i]
        np.testing.assert_allclose(f.positions[i, seen, 0], 1.3 * grid[seen], atol=1e-9)


def test_cli_resamples_10hz_data(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    dense, coarse = waymo_tables()
    outs = []
    for name, table in (("dense", dense), ("coarse", coarse)):
        path = tmp_path / f"{name}.csv"
        lines = ["agent_id,time,x,y"] + [
            f"{a},{t!r},{x!r},{y!r}" for a, t, x, y in zip(*(v.tolist() for v in table.values()), strict=True)
        ]
        path.write_text("\n".join(lines) + "\n")
        assert main(["predict", "zara1", str(path), "--json", "--time", str(NOW)]) == 0
        outs.append(json.loads(capsys.readouterr().out))
    a, b = outs
    assert a["dt_s"] == 0.4
    assert [x["id"] for x in a["agents"]] == [x["id"] for x in b["agents"]]
    ta = np.array([[m["trajectory"] for m in x["modes"]] for x in a["agents"]])
    tb = np.array([[m["trajectory"] for m in x["modes"]] for x in b["agents"]])
    np.testing.assert_allclose(ta, tb, atol=1e-6)
    # A time base the CLI is told wrongly (milliseconds read as seconds) is refused as too sparse, not predicted.
    path = tmp_path / "dense.csv"
    assert main(["predict", "zara1", str(path), "--time-unit", "10", "--time", str(NOW)]) == 2
    assert "sparser than its grid" in capsys.readouterr().err
