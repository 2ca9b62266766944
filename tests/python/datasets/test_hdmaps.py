"""The HD-map readers (``dgan.datasets.hdmaps``): nuScenes and Waymo in ScenarioNet pickles, Waymo in GPUDrive JSON and
Argoverse 2, their element kinds, frames cut from them, the engine's picture of their maps, and bad input."""

from __future__ import annotations

import gzip
import json
import pickle
import warnings
from collections import Counter
from pathlib import Path
from typing import Any

import numpy as np
import pytest
from conftest import shared_data

import dgan
from dgan.datasets import hdmaps
from dgan.datasets.hdmaps import bird_eye, read_scenario, read_waymo_json, widen
from dgan.demo import WAYMO_FILE
from dgan.exceptions import InvalidFrameError, InvalidMapError


def data_root() -> Path:
    return shared_data("nuscenes_mini_scenarionet")


def kinds(sc: hdmaps.Scenario) -> Counter[str]:
    return Counter(k for k, _ in sc.map.elements())


def test_bundled_waymo_scenario_has_every_element_kind() -> None:
    sc = read_waymo_json(WAYMO_FILE)
    assert (sc.source, sc.dt_s, sc.num_steps) == ("waymo", 0.1, 91)
    assert set(sc.labels) == set(dgan.CLASSES)
    # The source's roads: 82 lanes (8 bike lanes), 39 road lines, 23 road edges (8 medians), 4 crosswalks.
    assert kinds(sc) == Counter(
        lane_centerline=74, bike_lane=8, lane_line_solid=25, lane_line_dashed=14, road_edge=15, obstacle=8, crosswalk=4
    )
    # Invalid steps hold the -10000 sentinel in the file; here they are masked out and NaN.
    assert np.isnan(sc.positions[~sc.valid]).all()
    assert np.isfinite(sc.positions[sc.valid]).all()


def test_frame_samples_every_second_step_back_from_now() -> None:
    sc = read_waymo_json(WAYMO_FILE)
    f = sc.frame(40, 10, every=2)
    row = int(np.flatnonzero(sc.valid[:, 40] & sc.valid[:, 22])[0])
    i = list(f.ids).index(sc.ids[row])
    np.testing.assert_allclose(f.positions[i], sc.positions[row, 22:41:2])
    # Steps before the scenario starts are masked out.
    early = sc.frame(4, 10, every=2)
    assert not early.mask[:, :7].any()
    with pytest.raises(InvalidFrameError, match="outside"):
        sc.frame(91, 10)


def test_each_source_reads_with_its_map() -> None:
    root = data_root()
    nu = read_scenario(root / "nuscenes_mini_scenarionet" / "sd_nuscenes_v1.0-mini_scene-0061.pkl")
    assert (nu.source, nu.keyframe_every, nu.num_steps) == ("nuscenes", 5, 191)
    # 24 vehicles, 60 pedestrians and 6 cyclists; the 136 cones and barriers become obstacles.
    assert Counter(nu.labels) == Counter(vehicle=24, pedestrian=60, cyclist=6)
    assert kinds(nu) == Counter(
        lane_centerline=460, lane_line_dashed=72, lane_line_solid=25, road_edge=29, obstacle=136
    )
    wp = read_scenario(next((root / "waymo_motion_samples" / "scenarionet_pkl").glob("*8a346109094cd5aa.pkl")))
    assert wp.source == "waymo"
    assert wp.dt_s == pytest.approx(0.1)
    assert {"crosswalk", "bike_lane", "obstacle", "road_edge"} <= set(kinds(wp))  # not a contract copy: this map's
    av = read_scenario(root / "argoverse2" / "motion_forecasting" / "0a1e6f0a-1817-4a98-b02e-db8c9327d151")
    # 71 lane segments: 37 bike lanes as regions and 34 centre lines; 6 crossings; 2 drivable areas.
    k = kinds(av)
    assert (k["bike_lane"], k["lane_centerline"], k["crosswalk"], k["road_edge"]) == (37, 34, 6, 2)
    log = read_scenario(root / "argoverse2" / "sensor_logs" / "7fab2350-7eaf-3b7e-a39d-6937a4c1bede")
    # Sensor-log maps have no centre lines: each lane's is the midline of its boundaries.
    assert kinds(log)["lane_centerline"] > 0
    assert log.num_steps == 156
    # The cuboids, composed with the ego poses, land on the city map: vehicles within its drivable areas' extent.
    pts = np.vstack([p for kind, p in log.map.elements() if kind == "road_edge"])
    veh = log.positions[[c == "vehicle" for c in log.labels]]
    v = veh[np.isfinite(veh[..., 0])]
    assert ((v >= pts.min(axis=0) - 5) & (v <= pts.max(axis=0) + 5)).all(axis=1).mean() > 0.99


def test_bird_eye_draws_crosswalks_where_they_are() -> None:
    sc = read_waymo_json(WAYMO_FILE)
    cw = next(p for k, p in sc.map.elements() if k == "crosswalk")
    res = 0.2
    img = bird_eye(sc, 40, cw.mean(axis=0), extent_m=40.0, resolution_m=res)
    assert img.shape == (200, 200, 3)
    assert img.dtype == np.uint8
    # Pixels of the crosswalk polygon (north up: u = 100 + dx / res, v = 100 - dy / res) are mostly grey.
    from matplotlib.path import Path as MplPath

    u, v = np.meshgrid(np.arange(200), np.arange(200))
    world = np.c_[(u.ravel() - 100) * res, (100 - v.ravel()) * res] + cw.mean(axis=0)
    inside = MplPath(cw).contains_points(world).reshape(200, 200)
    grey = (img == 128).all(axis=-1)
    assert inside.sum() > 100
    assert grey[inside].mean() > 0.6
    assert grey[~inside].mean() < 0.05


def test_widen_makes_a_polygon_of_the_width() -> None:
    poly = widen(np.array([[0.0, 0.0], [10.0, 0.0]]), 1.5)
    np.testing.assert_allclose(poly, [[0, 0.75], [10, 0.75], [10, -0.75], [0, -0.75]])


def test_bad_files_are_clear_errors(tmp_path: Path) -> None:
    bad_gz = tmp_path / "bad.json.gz"
    bad_gz.write_bytes(b"not gzip")
    with pytest.raises(InvalidFrameError, match="cannot read Waymo JSON"):
        read_scenario(bad_gz)
    wrong = tmp_path / "wrong.json.gz"
    with gzip.open(wrong, "wt") as fh:
        json.dump({"objects": []}, fh)
    with pytest.raises(InvalidFrameError, match="not a GPUDrive scenario"):
        read_scenario(wrong)
    empty = tmp_path / "empty.json"
    empty.write_text(json.dumps({"objects": [{"type": "unknown"}], "roads": []}))
    with pytest.raises(InvalidFrameError, match="no vehicle, cyclist or pedestrian"):
        read_scenario(empty)
    pkl = tmp_path / "x.pkl"
    pkl.write_bytes(pickle.dumps({"id": 1}))
    with pytest.raises(InvalidFrameError, match="not a ScenarioNet scenario"):
        read_scenario(pkl)
    trunc = tmp_path / "t.pkl"
    trunc.write_bytes(pickle.dumps({"tracks": {}})[:5])
    with pytest.raises(InvalidFrameError, match="cannot read ScenarioNet scenario"):
        read_scenario(trunc)
    with pytest.raises(InvalidFrameError, match="unknown scenario format"):
        read_scenario(tmp_path / "scene.csv")
    folder = tmp_path / "av2"
    folder.mkdir()
    with pytest.raises(InvalidFrameError, match="needs scenario_"):
        read_scenario(folder)
    bad_map = folder / "log_map_archive_x.json"
    bad_map.write_text("{}")
    with pytest.raises(InvalidMapError, match="not an Argoverse 2 map"):
        hdmaps.av2_map(bad_map)
    bad_road = tmp_path / "road.json"
    bad_road.write_text(json.dumps({"objects": [], "roads": [{"type": "lane", "geometry": [[1.0], [2.0]]}]}))
    with pytest.raises(InvalidMapError, match="road 0"):
        hdmaps.waymo_json_map(json.loads(bad_road.read_text())["roads"])


def test_the_waymo_demo_scene_needs_a_full_history() -> None:
    with pytest.raises(dgan.DganError, match=r"needs --time in 18\.\.88, got 5"):
        dgan.demo.waymo_scene(10, 15, 5)


def test_readers_sit_behind_a_registry_outside_the_runtime_import() -> None:
    import subprocess
    import sys

    import dgan.datasets as datasets

    code = "import sys, dgan; print('dgan.datasets.hdmaps' in sys.modules, 'pyarrow' in sys.modules)"
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True).stdout.split()
    assert out == ["False", "False"]
    assert datasets.formats() == (
        "argoverse2_scenario",
        "argoverse2_sensor_log",
        "interaction",
        "scenarionet",
        "waymo_json",
    )
    sc = datasets.read(WAYMO_FILE, "waymo_json")
    assert len(sc.ids) > 0
    assert datasets.read(WAYMO_FILE).ids.tolist() == sc.ids.tolist()
    with pytest.raises(InvalidFrameError, match="unknown scenario format 'kitti'"):
        datasets.reader("kitti")
    with pytest.raises(ValueError, match="module:function"):
        datasets.register("bad", "no_colon")
    import importlib

    old = importlib.import_module("dgan.hdmaps")
    with pytest.warns(DeprecationWarning, match=r"dgan\.datasets\.hdmaps"):
        importlib.reload(old)
    assert old.read_scenario is read_scenario


def moving_heading_error_deg(sc: hdmaps.Scenario) -> float:
    """Median angle between the heading and the direction of motion of agents moving faster than 2 m/s."""
    both = sc.valid[:, 1:] & sc.valid[:, :-1]
    v = (sc.positions[:, 1:] - sc.positions[:, :-1]) / sc.dt_s
    moving = both & (np.hypot(v[..., 0], v[..., 1]) > 2.0)
    motion = np.arctan2(v[..., 1], v[..., 0])[moving]
    err = np.abs((sc.heading[:, 1:][moving] - motion + np.pi) % (2 * np.pi) - np.pi)
    return float(np.degrees(np.median(err)))


@pytest.mark.parametrize("unit", ["radians", "degrees"])
def test_waymo_json_headings_are_radians_whatever_the_file_holds(tmp_path: Path, unit: str) -> None:
    # GPUDrive exports differ: some hold headings in radians, some in degrees (a third of the training scenes). The
    # reader takes the unit whose headings follow the agents' motion.
    opener = gzip.open if WAYMO_FILE.suffix == ".gz" else open
    with opener(WAYMO_FILE, "rt") as fh:
        d = json.load(fh)
    original = read_waymo_json(WAYMO_FILE)
    assert moving_heading_error_deg(original) < 5.0
    if unit == "degrees":
        for o in d["objects"]:
            o["heading"] = [h if h == hdmaps.WAYMO_INVALID else float(np.degrees(h)) for h in o["heading"]]
    path = tmp_path / "scenario.json"
    path.write_text(json.dumps(d))
    sc = read_waymo_json(path)
    np.testing.assert_allclose(sc.heading[sc.valid], original.heading[original.valid], atol=1e-9)
    assert moving_heading_error_deg(sc) < 5.0


def _nuscenes(name: str = "sd_nuscenes_v1.0-mini_scene-0061.pkl") -> dict[str, Any]:
    with (data_root() / "nuscenes_mini_scenarionet" / name).open("rb") as fh:
        out: dict[str, Any] = pickle.load(fh)
    return out


def _predicts_at_every_step(sc: hdmaps.Scenario) -> int:
    """Predicts ``hdmap`` at every step of a scenario with a full 10-step history at 5 Hz; no warning at all."""
    p = dgan.Predictor("hdmap", sessions=1)
    every = max(1, round(p.spec.dt_s / sc.dt_s))
    steps = range(every * (p.spec.t_obs - 1), sc.num_steps)
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        for step in steps:
            if sc.valid[:, step].any():
                p.predict(sc.frame(step, p.spec.t_obs, every=every))
    return len(steps)


def _variant(d: dict[str, Any], how: str) -> dict[str, Any]:
    """Another vintage of a ScenarioNet / MetaDrive scenario, made from a real one."""
    import copy

    v = copy.deepcopy(d)
    if how == "size":  # sizes as one (T, 3) array
        for tr in v["tracks"].values():
            st = tr["state"]
            st["size"] = np.concatenate([np.reshape(st.pop(k), (-1, 1)) for k in ("length", "width", "height")], 1)
    elif how == "top_level_ts":
        v["ts"] = v["metadata"].pop("ts")
        v["metadata"].pop("sample_rate")
    elif how == "cross_walk":
        v["map_features"]["cw"] = {"type": "CROSS_WALK", "polygon": np.array([[0.0, 0.0], [4.0, 0.0], [4.0, 3.0]])}
    return v


@pytest.mark.parametrize("how", ["size", "top_level_ts", "cross_walk"])
@pytest.mark.parametrize("suffix", [".pkl", ".pkl.gz", ".json", ".json.gz"])
def test_scenarionet_and_metadrive_vintages_read_and_predict(tmp_path: Path, how: str, suffix: str) -> None:
    v = _variant(_nuscenes(), how)
    path = tmp_path / f"scene{suffix}"
    if suffix.startswith(".json"):
        text = json.dumps(v, default=lambda a: a.tolist() if isinstance(a, np.ndarray) else str(a))
        path.write_bytes(gzip.compress(text.encode()) if suffix.endswith(".gz") else text.encode())
    else:
        raw = pickle.dumps(v)
        path.write_bytes(gzip.compress(raw) if suffix.endswith(".gz") else raw)
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        sc = read_scenario(path)
    assert sc.dt_s == pytest.approx(0.1)
    assert np.isfinite(sc.length[sc.valid]).all()
    if how == "cross_walk":
        assert kinds(sc)["crosswalk"] == 1
    if suffix == ".pkl":
        assert _predicts_at_every_step(sc) > 100


def test_unmapped_element_types_and_sizeless_boxes_warn_with_names_and_counts(tmp_path: Path) -> None:
    v = _nuscenes()
    v["map_features"]["s1"] = {"type": "STOP_SIGN", "position": np.zeros(3)}
    v["map_features"]["s2"] = {"type": "STOP_SIGN", "position": np.ones(3)}
    v["map_features"]["b"] = {"type": "SPEED_BUMP", "polygon": np.zeros((4, 3))}
    next(iter(v["tracks"].values()))["state"]["length"][:] = 0.0
    path = tmp_path / "s.pkl"
    path.write_bytes(pickle.dumps(v))
    with pytest.warns(dgan.exceptions.DatasetWarning) as record:
        sc = read_scenario(path)
    messages = [str(w.message) for w in record]
    assert any("STOP_SIGN ×2, SPEED_BUMP ×1" in m for m in messages), messages
    assert any("box of zero, negative or infinite size; their class" in m for m in messages), messages
    assert any(np.isnan(sc.length[i][sc.valid[i]]).all() for i in range(len(sc.ids)))


def test_a_nocturne_file_with_a_zero_sized_box_predicts_at_every_step(tmp_path: Path) -> None:
    with gzip.open(WAYMO_FILE, "rt") as fh:
        d = json.load(fh)
    agents = [o for o in d["objects"] if o.get("type") in ("vehicle", "pedestrian", "cyclist")]  # not a contract copy
    agents[0]["length"] = 0.0
    agents[1]["width"] = 0.0
    path = tmp_path / "nocturne.json"
    path.write_text(json.dumps(d))
    with pytest.warns(dgan.exceptions.DatasetWarning, match=r"2 agent\(s\) have a box of zero") as record:
        sc = read_scenario(path)
    assert all("driveway" in str(w.message) or "box of zero" in str(w.message) for w in record)
    assert _predicts_at_every_step(sc) > 60
