"""The scene files ``dgan predict`` and ``dgan evaluate`` read (dgan.scenefiles): driving scenarios with their own
vector map beside tables and headerless layouts, folders and globs of them, and their bad input."""

from __future__ import annotations

import json
import shutil
import warnings
from pathlib import Path

import numpy as np
import pytest
from conftest import interaction_recording, shared_data

import dgan
from dgan.cli import main
from dgan.datasets import is_scenario
from dgan.datasets.hdmaps import Scenario, read_scenario
from dgan.demo import SCENE_FILE, WAYMO_FILE
from dgan.exceptions import DatasetWarning, InvalidFrameError
from dgan.scenefiles import read_scene, scene_files


def waymo() -> Scenario:
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", DatasetWarning)  # its driveways, which no engine kind draws
        return read_scenario(WAYMO_FILE)


def test_a_scenarios_records_are_its_valid_states() -> None:
    sc = waymo()
    rows = sc.records()
    agent, step = np.nonzero(sc.valid)
    assert len(rows["agent_id"]) == int(sc.valid.sum()) == len(agent)
    np.testing.assert_array_equal(rows["agent_id"], sc.ids[agent])
    np.testing.assert_allclose(rows["time"], step * sc.dt_s, atol=1e-9)
    np.testing.assert_array_equal(np.c_[rows["x"], rows["y"]], sc.positions[agent, step])
    np.testing.assert_array_equal(rows["heading"], sc.heading[agent, step])
    assert list(rows["class"]) == [sc.labels[i] for i in agent]
    assert np.isfinite(rows["x"]).all()


def test_read_scene_tells_a_scenario_from_a_table() -> None:
    with pytest.warns(DatasetWarning, match="driveway"):
        read = read_scene(WAYMO_FILE)
    assert is_scenario(WAYMO_FILE)
    assert read.layout == "waymo scenario"
    assert read.time_unit == 1.0
    assert read.map is not None
    assert read.description is not None
    assert read.description.startswith("a scenario of Waymo (10 Hz tracks of ")
    table = read_scene(SCENE_FILE)
    assert not is_scenario(SCENE_FILE)
    assert (table.layout, table.description, table.map) == ("social-gan", None, None)


def test_the_command_line_predicts_a_scenario_over_its_own_map(capsys: pytest.CaptureFixture[str]) -> None:
    """``dgan predict hdmap scenario.json.gz`` is the Python API's from_records of the scenario's records with its
    map; ``--no-map`` the same without it."""
    sc = waymo()
    p = dgan.Predictor("hdmap")
    runs = []
    for extra, scene_map in (([], sc.map), (["--no-map"], None)):
        assert main(["predict", "hdmap", str(WAYMO_FILE), "--time", "4", "--modes", "6", "--json", *extra]) == 0
        captured = capsys.readouterr()
        assert "read as a scenario of Waymo" in captured.err
        assert "no --map given" not in captured.err
        got = json.loads(captured.out)
        frame = dgan.Frame.from_records(sc.records(), spec=p, time_unit=1.0, current_time=4.0, map=scene_map)
        want = p.predict(frame, modes=6)
        assert [a["id"] for a in got["agents"]] == want.agent_ids.tolist()
        trajectories = np.array([[m["trajectory"] for m in a["modes"]] for a in got["agents"]])
        np.testing.assert_allclose(trajectories, want.trajectories, atol=1e-9)
        runs.append(trajectories)
    assert not np.allclose(runs[0], runs[1])  # its pedestrians and cyclists read the map


def test_evaluate_scores_a_scenario_with_its_map(capsys: pytest.CaptureFixture[str]) -> None:
    sc = waymo()
    assert main(["evaluate", "hdmap", str(WAYMO_FILE), "--json"]) == 0
    got = json.loads(capsys.readouterr().out)
    want = dgan.evaluate("hdmap", sc.records(), time_unit=1.0, map=sc.map)
    assert got["times"] == want.times
    assert got["rows"] == json.loads(json.dumps(want.rows()))
    assert main(["evaluate", "hdmap", str(WAYMO_FILE), "--json", "--no-map"]) == 0
    assert json.loads(capsys.readouterr().out)["rows"] != got["rows"]


def test_argoverse_folders_are_one_scene_each(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    """An Argoverse 2 scenario folder is one scene, not a folder of files; a folder of them is a folder of scenes,
    the bundled Waymo scenario beside them."""
    root = shared_data("argoverse2") / "argoverse2"
    scenario = next((root / "motion_forecasting").iterdir())
    assert is_scenario(scenario)
    assert scene_files(str(scenario)) is None
    for log in (root / "sensor_logs").iterdir():
        shutil.copytree(log, tmp_path / log.name, ignore=shutil.ignore_patterns("map"))
        shutil.copytree(log / "map", tmp_path / log.name / "map")
    shutil.copy(WAYMO_FILE, tmp_path / WAYMO_FILE.name)
    files = scene_files(str(tmp_path))
    assert files is not None
    assert sorted(f.name for f in files) == sorted(p.name for p in tmp_path.iterdir())
    out = tmp_path / "modes.csv"
    assert main(["predict", "hdmap", str(tmp_path), "--out", str(out)]) == 0
    err = capsys.readouterr().err
    assert err.count("read as a scenario of Argoverse 2") == 1
    assert "read as a scenario of Waymo" in err
    assert f"of {len(files)} scenes" in err


@pytest.mark.parametrize(
    ("name", "content", "message"),
    [
        ("corrupt.pkl", b"\x80\x04garbage", "cannot read ScenarioNet scenario"),
        ("table.json", b'{"agent_id": [1], "time": [0]}', "not a GPUDrive scenario"),
        ("truncated.json.gz", b"\x1f\x8b\x08", "truncated.json.gz"),
    ],
)
def test_a_bad_scenario_is_a_clear_error(
    tmp_path: Path, capsys: pytest.CaptureFixture[str], name: str, content: bytes, message: str
) -> None:
    path = tmp_path / name
    path.write_bytes(content)
    with pytest.raises(InvalidFrameError):
        read_scene(path)
    assert main(["predict", "hdmap", str(path)]) == 2
    err = capsys.readouterr().err
    assert err.startswith("dgan: error: ")
    assert message in err
    assert "utf-8" not in err


def test_map_and_no_map_together_are_refused(capsys: pytest.CaptureFixture[str]) -> None:
    assert main(["predict", "hdmap", str(WAYMO_FILE), "--no-map", "--map", "zara1"]) == 2
    assert "--map and --no-map ask for opposite things" in capsys.readouterr().err


def test_a_scene_with_no_target_is_left_out_of_a_pooled_evaluation(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    """One short scene of a folder (no agent seen over the model's window and horizon) is named and left out; the
    others are scored as alone. A folder where no scene has a target is an error."""
    short = tmp_path / "short.csv"
    short.write_text("agent_id,time,x,y\n1,0.0,0.0,0.0\n1,0.2,0.3,0.0\n")
    shutil.copy(WAYMO_FILE, tmp_path / WAYMO_FILE.name)
    assert main(["evaluate", "hdmap", str(tmp_path), "--json"]) == 0
    captured = capsys.readouterr()
    assert f"{short}: left out: no target" in captured.err
    got = json.loads(captured.out)
    assert got["scenes"] == [WAYMO_FILE.name]
    assert main(["evaluate", "hdmap", str(WAYMO_FILE), "--json"]) == 0
    assert json.loads(capsys.readouterr().out)["rows"] == got["rows"]
    (tmp_path / WAYMO_FILE.name).unlink()
    shutil.copy(short, tmp_path / "short2.csv")
    assert main(["evaluate", "hdmap", str(tmp_path)]) == 2
    assert "no target in any of the 2 scenes" in capsys.readouterr().err


def test_the_command_line_reproduces_the_argoverse_row_of_the_results(capsys: pytest.CaptureFixture[str]) -> None:
    """``dgan evaluate hdmap`` on Argoverse 2's public files (a scenario and two sensor logs, each over its own map)
    gives docs/results_hdmap.json's Argoverse 2 row, which training.evaluate measured: the same targets, and the
    same errors to float32 precision (ONNX Runtime's kernels differ a little between CPUs)."""
    root = shared_data("argoverse2") / "argoverse2"
    assert main(["evaluate", "hdmap", str(root / "*" / "*"), "--json"]) == 0
    rows = json.loads(capsys.readouterr().out)["rows"]
    (got,) = [r for r in rows if (r["class"], r["motion"]) == ("all", "all")]
    results = Path(__file__).resolve().parents[3] / "docs" / "results_hdmap.json"
    want = json.loads(results.read_text())["argoverse2"]["map"]
    assert got["targets"] == want["agents"] == 12222
    for ours, theirs in (("ade", "ade"), ("fde", "fde"), ("min_ade", "min_ade20"), ("min_fde", "min_fde20")):
        assert got[ours] == pytest.approx(want[theirs], rel=1e-6)
    assert got["cv"] == want["cv_variant"] == "last2"
    assert (got["cv_ade"], got["cv_fde"]) == pytest.approx((want["cv_ade"], want["cv_fde"]), rel=1e-9)


def test_interaction_tracks_and_a_lanelet2_map(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    """An INTERACTION track file is read by its header as dgan.datasets.lanelet2 reads it, and ``--map x.osm`` is its
    Lanelet2 map; a map that is no OSM file is refused."""
    from dgan.datasets.lanelet2 import lanelet2_map, read_interaction

    sample = shared_data("interaction_format_sample") / "interaction_format_sample"
    tracks = sample / "recorded_trackfiles" / "TestScenarioForScripts" / "vehicle_tracks_000.csv"
    osm = sample / "maps" / "TestScenarioForScripts.osm"
    assert main(["predict", "hdmap", str(tracks), "--map", str(osm), "--time", "5", "--json"]) == 0
    captured = capsys.readouterr()
    assert "read as INTERACTION tracks (10 Hz, 2 agents" in captured.err
    got = json.loads(captured.out)
    p = dgan.Predictor("hdmap")
    sc = read_interaction(tracks, osm)
    frame = dgan.Frame.from_records(sc.records(), spec=p, time_unit=1.0, current_time=5.0, map=lanelet2_map(osm))
    want = p.predict(frame, modes=3)
    trajectories = np.array([[m["trajectory"] for m in a["modes"]] for a in got["agents"]])
    np.testing.assert_allclose(trajectories, want.trajectories, atol=1e-9)
    bad = tmp_path / "map.osm"
    bad.write_text("<notosm/>")
    assert main(["predict", "hdmap", str(tracks), "--map", str(bad)]) == 2
    assert "is not an OSM file" in capsys.readouterr().err


def test_an_interaction_recordings_two_files_are_read_once(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    """A folder holding a recording's vehicle and pedestrian track files is one scene, read once (by the vehicle
    file, which brings the other), and the note says so; the pedestrians are predicted beside the vehicles."""
    vehicles, pedestrians = interaction_recording(tmp_path / "rec")
    assert scene_files(str(tmp_path / "rec")) == [vehicles]
    assert scene_files(str(tmp_path / "rec" / "*.csv")) == [vehicles]
    assert main(["predict", "hdmap", str(pedestrians), "--time", "3", "--json"]) == 0
    captured = capsys.readouterr()
    assert "5 agents, with vehicle_tracks_000.csv beside it" in captured.err
    ids = sorted(a["id"] for a in json.loads(captured.out)["agents"])
    assert ids == [1, 2, 1_000_001, 1_000_002, 1_000_007]


def test_a_glob_of_scenarios_warns_of_each_kind_once(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    """Each Waymo scenario's undrawn driveways are one dataset warning per file: over a folder the command shows the
    first and counts the rest. The shared ScenarioNet pickle holds a quiet moment (no agent at 1 m/s) whose
    radians are unwrapped up to 10.5: not taken for degrees (it was, once per command)."""
    for name in ("a", "b"):
        shutil.copy(WAYMO_FILE, tmp_path / f"{name}_{WAYMO_FILE.name}")
    pickles = shared_data("waymo_motion_samples") / "waymo_motion_samples" / "scenarionet_pkl"
    quiet = pickles / "sd_training.tfrecord-00000-of-01000_2a1e44d405a6833f.pkl"
    shutil.copy(quiet, tmp_path / quiet.name)
    assert main(["evaluate", "hdmap", str(tmp_path), "--json"]) == 0
    err = capsys.readouterr().err
    assert err.count("map elements not drawn") == 1
    assert "dgan: note: 2 more dataset warning(s) like those above, for other files" in err
    assert "degrees" not in err
