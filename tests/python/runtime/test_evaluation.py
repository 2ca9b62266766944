"""dgan.evaluate: a model scored on a table of tracks beside constant velocity."""

from __future__ import annotations

import json
from pathlib import Path
from typing import Any

import numpy as np
import pytest
from conftest import ROOT, shared_data, zara1_records

import dgan
from dgan.datasets.hdmaps import read_scenario
from dgan.exceptions import InvalidFrameError, InvalidSpecError, NoTargetError, UnknownClassError
from dgan.scenefiles import read_scene


def test_the_one_window_of_the_excerpt_scored_by_hand() -> None:
    rows = zara1_records()  # frames 5430..5620: one current time (5500) with 8 past and 12 future steps
    result = dgan.evaluate("zara1", rows, time_unit=0.04)
    assert result.times == 1
    assert result.modes == 20
    assert result.t_f == 12
    frame = dgan.Frame.from_records(rows, t_obs=8, dt=0.4, time_unit=0.04, current_time=5500.0)
    whole = dgan.Frame.from_records(rows, t_obs=20, dt=0.4, time_unit=0.04, current_time=5620.0)
    targets = [a for a in frame.agent_ids if a in whole.agent_ids and whole.mask[whole.agent_ids == a].all()]
    assert result.agent_ids.tolist() == targets
    assert len(targets) == 14
    rows_of = [int(np.flatnonzero(frame.agent_ids == a)[0]) for a in targets]
    truth = np.stack([whole.positions[whole.agent_ids == a][0, 8:] for a in targets])
    modes = dgan.Predictor("zara1").predict(frame, modes=20).trajectories[rows_of]
    np.testing.assert_allclose(result.ade, np.linalg.norm(modes[:, 0] - truth, axis=-1).mean(axis=1), atol=1e-9)
    np.testing.assert_allclose(result.min_fde, np.linalg.norm(modes[:, :, -1] - truth[:, None, -1], axis=-1).min(1))
    cv = dgan.metrics.constant_velocity(frame.positions[rows_of], frame.mask[rows_of], 12)
    np.testing.assert_allclose(result.cv["last2"][1], np.linalg.norm(cv[:, 0, -1] - truth[:, -1], axis=-1))
    moved = np.linalg.norm(truth[:, -1] - frame.positions[rows_of, 0], axis=-1)
    assert result.moving.tolist() == (moved >= 1.0).tolist()
    assert result.time.tolist() == [5500.0] * 14


def test_it_reproduces_the_results_table() -> None:
    """The zara1 row of docs/results.json (training.results, the Social-GAN protocol: windows of at least two
    targets), from the raw test file through the public API: the same targets, and errors to the network's float32
    precision (ONNX Runtime's kernels round differently on other CPUs: 4e-9 relative between the machine that wrote
    the table and an AMD EPYC one)."""
    test_file = shared_data("eth_ucy") / "eth_ucy" / "datasets" / "zara1" / "test" / "crowds_zara01.txt"
    rows = read_scene(test_file)[0]
    result = dgan.evaluate("zara1", rows, time_unit=0.04, map=dgan.scene_map("zara1"), min_targets=2)
    published = json.loads((ROOT / "docs" / "results.json").read_text())["with_map"]["zara1"]
    row = result.rows()[0]
    assert row["targets"] == 2253
    for mine, theirs in (("ade", "ade"), ("fde", "fde"), ("min_ade", "min_ade20"), ("cv_ade", "cv_ade")):
        assert row[mine] == pytest.approx(published[theirs], rel=1e-6), mine
    every = dgan.evaluate("zara1", rows, time_unit=0.04, map=dgan.scene_map("zara1"), stride=2)
    assert every.times < result.times
    assert len(every) > 1000  # windows of one target too, every other time


def test_classes_motions_and_the_table() -> None:
    result = dgan.evaluate("zara1", zara1_records(), time_unit=0.04, standing_m=1.5, modes=5)
    rows = result.rows()
    assert [(r["class"], r["motion"]) for r in rows] == [("pedestrian", m) for m in ("all", "moving", "standing")]
    assert rows[1]["targets"] + rows[2]["targets"] == rows[0]["targets"] == len(result)
    assert rows[0]["cv"] in ("last2", "mean1s")
    assert rows[0]["ade_vs_cv"] == rows[0]["ade"] / rows[0]["cv_ade"]
    text = str(result)
    assert "min5 ADE/FDE" in text
    assert "constant velocity" in text
    assert "standing: moved < 1.5 m)" in text
    records = result.to_records()
    assert set(records) >= {"time", "agent_id", "class", "moving", "ade", "min5_fde", "cv_mean1s_fde"}
    assert all(len(v) == len(result) for v in records.values())
    horizon = result.by_horizon()
    assert horizon["time_s"].tolist() == pytest.approx([0.4 * k for k in range(1, 13)])
    assert horizon["top-1"].mean() == pytest.approx(rows[0]["ade"])
    assert horizon["top-1"][-1] == pytest.approx(rows[0]["fde"])
    assert horizon["best"].mean() == pytest.approx(rows[0]["min_ade"])
    assert horizon[rows[0]["cv"]].mean() == pytest.approx(rows[0]["cv_ade"])
    moving = result.by_horizon(motion="moving")
    assert moving["top-1"].mean() == pytest.approx(rows[1]["ade"])
    with pytest.raises(InvalidSpecError, match="no target of class 'vehicle'"):
        result.by_horizon("vehicle")
    with pytest.raises(InvalidSpecError, match="motion must be"):
        result.by_horizon(motion="walking")
    both = dgan.evaluation.joined([result, result], ["a", "b"])
    assert len(both) == 2 * len(result)
    assert both.times == 2
    assert both.to_records()["scene"].tolist()[-1] == "b"


def test_a_street_scene_with_a_pedestrian_model() -> None:
    scenario = read_scenario(dgan.demo.WAYMO_FILE)
    rows: dict[str, list[object]] = {"agent_id": [], "time": [], "x": [], "y": [], "class": []}
    for i, agent in enumerate(scenario.ids):
        for t in np.flatnonzero(scenario.valid[i]):
            for k, v in zip(rows, (int(agent), 0.1 * t, *scenario.positions[i, t], scenario.labels[i]), strict=True):
                rows[k].append(v)
    table = {k: np.array(v) for k, v in rows.items()}
    with pytest.raises(UnknownClassError):
        dgan.evaluate("zara1", table)
    walkers = dgan.evaluate("zara1", table, unknown_classes="ignore")
    assert set(walkers.classes.tolist()) == {"pedestrian"}
    assert len(walkers) > 20
    every = dgan.evaluate("hdmap", table, map=scenario.map)
    assert {r["class"] for r in every.rows()} == {"vehicle", "pedestrian", "all"}  # no cyclist seen long enough
    assert every.modes == 20
    assert "all" in str(every)


def test_bad_options_and_tables_are_refused() -> None:
    rows = zara1_records()
    bad: dict[str, Any]
    for bad in ({"modes": 0}, {"modes": 21}, {"stride": 0}, {"stride": 1.5}, {"min_targets": True}):
        with pytest.raises(InvalidSpecError):
            dgan.evaluate("zara1", rows, time_unit=0.04, **bad)
    for bad in ({"standing_m": -1.0}, {"standing_m": "far"}, {"unknown_classes": "drop"}, {"spec": "zara1"}):
        with pytest.raises(InvalidSpecError):
            dgan.evaluate("zara1", rows, time_unit=0.04, **bad)
    with pytest.raises(NoTargetError, match="no target"):
        dgan.evaluate("zara1", {k: v[rows["time"] <= 5600] for k, v in rows.items()}, time_unit=0.04)
    with pytest.raises(InvalidFrameError, match="lack the column"):
        dgan.evaluate("zara1", {"id": [1], "time": [0.0], "x": [0.0], "y": [0.0]})


def test_the_chart(tmp_path: Path) -> None:
    pytest.importorskip("matplotlib")
    fig = dgan.evaluate("zara1", zara1_records(), time_unit=0.04).plot()
    fig.savefig(tmp_path / "chart.png")
    assert (tmp_path / "chart.png").stat().st_size > 10_000
    assert "constant velocity" in fig.axes[0].get_title()
    fig = dgan.evaluate("zara1", zara1_records(), time_unit=0.04).plot(kind="horizon")
    assert [line.get_label() for line in fig.axes[0].get_lines()][:2] == ["zara1 top-1", "zara1 best of 20"]
    with pytest.raises(InvalidSpecError, match="kind must be"):
        dgan.evaluate("zara1", zara1_records(), time_unit=0.04).plot(kind="pie")
