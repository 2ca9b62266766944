"""The dataset readers and the window rule (``training.data.datasets``, ``training.data.windows``) on small hand-made
recordings and on the real shared data."""

from __future__ import annotations

import pickle
from dataclasses import replace
from pathlib import Path
from typing import Any

import numpy as np
import pytest
from conftest import shared_data

import dgan
from training.data.apolloscape import APOLLO_TEST, APOLLO_VAL, apollo_files, apollo_recording_id
from training.data.datasets import DATASETS, recordings, source_files
from training.data.driving import HDMAP_TEST, HDMAP_VAL, hdmap_recordings
from training.data.recording import Recording
from training.data.sdd import sdd_scales, sdd_video
from training.data.windows import iter_windows
from training.evaluate import calibration

ROOT = Path(__file__).resolve().parents[3]


def data_root() -> Path:
    return shared_data("sdd")


def toy(rows: list[tuple[int, int, int]]) -> Recording:
    """(step, agent, label) rows; agent a walks along x at 1 m per step."""
    r = np.array(rows)
    return Recording.sorted(
        name="toy", step=r[:, 0], agent=r[:, 1], xy=np.c_[r[:, 0] * 1.0 + r[:, 1] * 10.0, r[:, 1] * 1.0], label=r[:, 2]
    )


def test_windows_need_two_agents_present_at_every_step() -> None:
    info = DATASETS["sdd"]
    # Agents 1 and 2 cover steps 0..19; agent 3 misses step 15; agent 4 appears at step 5 only (a neighbour).
    rows = [(s, a, 0) for s in range(20) for a in (1, 2)] + [(s, 3, 1) for s in range(20) if s != 15] + [(5, 4, 2)]
    windows = list(iter_windows(toy(rows), info, 8, 12))
    assert [w.now for w in windows] == [7]
    w = windows[0]
    assert w.ids.tolist() == [1, 2, 3]
    assert w.target.tolist() == [True, True, False]
    assert not w.mask[2, 15]
    assert w.mask[2, :15].all()
    np.testing.assert_allclose(w.positions[0, :, 0], np.arange(20) + 10.0)
    # One target is not enough.
    assert not list(iter_windows(toy([r for r in rows if r[1] != 2]), info, 8, 12))


def test_unscored_labels_are_neighbours_only() -> None:
    info = DATASETS["apolloscape"]
    others = info.labels.index("others")
    rows = [(s, 1, 0) for s in range(12)] + [(s, 2, others) for s in range(12)]
    (w,) = iter_windows(toy(rows), info, 6, 6)
    assert w.target.tolist() == [True, False]
    frame = w.frame(info, 6)
    assert frame.classes == ["vehicle", "cyclist"]


def test_labels_map_to_the_papers_classes() -> None:
    assert DATASETS["sdd"].classes == dgan.CLASSES
    sdd = dict(zip(DATASETS["sdd"].labels, DATASETS["sdd"].label_class, strict=True))
    assert sdd == {
        "Pedestrian": "pedestrian",
        "Biker": "cyclist",
        "Skater": "cyclist",
        "Cart": "vehicle",
        "Car": "vehicle",
        "Bus": "vehicle",
    }
    assert DATASETS["ethucy"].classes == ("pedestrian",)
    assert DATASETS["apolloscape"].classes == dgan.CLASSES


def test_sdd_reads_metres_and_its_map_lines_up() -> None:
    root = data_root()
    scales = sdd_scales(root)
    assert len(scales) == 60
    assert scales[("hyang", 0)] == pytest.approx(0.034749693)
    assert sdd_video(Path("stan_deathCircle_3.txt")) == ("deathCircle", 3)
    (rec,) = [r for r in recordings("sdd", root, "test") if r.name == "stan_hyang_0"]
    raw = np.loadtxt(root / "sdd/multiclass_step10/test/stan_hyang_0.txt", dtype=str)
    assert len(rec.step) == len(raw)
    assert rec.unit_m == pytest.approx(0.034749693)
    first = raw[(raw[:, 0].astype(float) == rec.step[0]) & (raw[:, 1].astype(float) == rec.agent[0])][0]
    np.testing.assert_allclose(rec.xy[0], first[2:4].astype(float) * rec.unit_m)
    # The world → pixel map of the box-filtered image puts a world point on the same image content.
    assert isinstance(rec.map, dgan.RasterMap)
    small, h = rec.map.image, rec.map.world_to_pixel
    full = dgan.RasterMap.from_file(root / "sdd/raw_annotations/hyang/video0/reference.jpg", np.eye(3)).image
    f = full.shape[1] // small.shape[1]
    u, v = (h @ np.r_[rec.xy[0], 1.0])[:2]
    px = (rec.xy[0] / rec.unit_m).round().astype(int)
    block = full[int(v) * f : int(v) * f + f, int(u) * f : int(u) * f + f].reshape(-1, 3).mean(axis=0)
    np.testing.assert_allclose(small[int(v), int(u)], block, atol=1.0)
    assert abs(px[0] // f - int(u)) <= 1
    assert abs(px[1] // f - int(v)) <= 1


def test_apolloscape_splits_by_recording() -> None:
    root = data_root()
    splits = {s: {apollo_recording_id(p) for p in apollo_files(root, s)} for s in ("train", "val", "test")}
    assert splits["test"] == set(APOLLO_TEST)
    assert splits["val"] == set(APOLLO_VAL)
    assert not splits["train"] & (splits["val"] | splits["test"])
    rec = recordings("apolloscape", root, "test")[0]
    assert rec.heading is not None
    assert rec.length is not None
    assert rec.width is not None
    assert rec.label.min() >= 0
    assert rec.label.max() <= 4


def test_apolloscape_validation_recordings_can_be_chosen() -> None:
    root = data_root()
    val = {apollo_recording_id(p) for p in apollo_files(root, "val", "9050,9055")}
    train = {apollo_recording_id(p) for p in apollo_files(root, "train", "9050,9055")}
    assert val == {9050, 9055}
    assert set(APOLLO_VAL) <= train  # the default validation recordings train in this fold
    assert not train & (val | set(APOLLO_TEST))
    with pytest.raises(ValueError, match="test recordings"):
        apollo_files(root, "val", f"9050,{APOLLO_TEST[0]}")
    with pytest.raises(ValueError, match="no ApolloScape recording"):
        apollo_files(root, "val", "1234")
    with pytest.raises(ValueError, match="comma-separated"):
        apollo_files(root, "val", "9050;9055")


def test_calibration_bins_probabilities_and_hits() -> None:
    prob = np.array([0.01, 0.01, 0.95, 0.95, 0.5])
    hit = np.array([False, False, True, False, True])
    cal = calibration(prob, hit)
    count = np.array(cal["count"])
    assert count.sum() == 5
    first, last = 0, len(count) - 1
    assert count[first] == 2
    assert cal["frequency"][first] == 0.0
    assert count[last] == 2
    assert cal["frequency"][last] == 0.5
    expected = (2 * 0.01 + 2 * abs(0.95 - 0.5) + 1 * 0.5) / 5
    assert cal["ece"] == pytest.approx(expected)


def test_bad_dataset_files_are_clear_errors(tmp_path: Path) -> None:
    from dgan.exceptions import InvalidMapError
    from dgan.scenes import sdd_raster_map
    from training.data.apolloscape import apollo_recording
    from training.data.sdd import sdd_recording

    (tmp_path / "sdd" / "raw_annotations").mkdir(parents=True)
    (tmp_path / "sdd" / "raw_annotations" / "estimated_scales.yaml").write_text(
        "hyang:\n   video0:\n      scale: 0.03\n      certainty: 1.0\n"
    )
    bad_label = tmp_path / "stan_hyang_0.txt"
    bad_label.write_text("1 0.0 10.0 20.0 Pedestrian\n2 0.0 11.0 20.0 Horse\n")
    with pytest.raises(ValueError, match="unknown SDD labels"):
        sdd_recording(bad_label, tmp_path, with_map=False)
    no_scale = tmp_path / "stan_quad_7.txt"
    no_scale.write_text("1 0.0 10.0 20.0 Pedestrian\n")
    with pytest.raises(ValueError, match="no scale for SDD quad video 7"):
        sdd_recording(no_scale, tmp_path, with_map=False)
    bad_type = tmp_path / "result_9048_1_frame.txt"
    bad_type.write_text("0 1 7 1.0 2.0 0.0 4.0 2.0 1.5 0.0\n")
    with pytest.raises(ValueError, match=r"object types must be 1\.\.5"):
        apollo_recording(bad_type)
    with pytest.raises(InvalidMapError, match="metres_per_px must be positive"):
        sdd_raster_map(ROOT / "python/dgan/data/sdd/hyang_0/reference.jpg", 0.0)


def test_a_per_class_run_needs_a_known_class_and_keeps_its_targets_alone(monkeypatch: pytest.MonkeyPatch) -> None:
    pytest.importorskip("torch")
    from training import train
    from training.build import input_spec
    from training.config import Config
    from training.data.splits import TrainingSplits, target_class_index

    cfg = Config.load(ROOT / "training" / "configs" / "apolloscape.toml", {"data.target_class": "cyclist"})
    spec = input_spec(cfg)
    assert target_class_index("", spec) is None
    assert target_class_index("cyclist", spec) == list(spec.classes).index("cyclist")
    with pytest.raises(ValueError, match="'bus' is not among the classes"):
        target_class_index("bus", spec)

    def windows() -> Any:
        return type("W", (), {"target": np.ones(3, bool), "class_index": np.arange(3)})()

    def splits(*_: object) -> TrainingSplits:
        train, val = windows(), windows()
        return TrainingSplits([train], train, val, target_class_index("cyclist", spec))

    monkeypatch.setattr(train, "training_splits", splits)
    kept = {"anchors": np.zeros((1, spec.t_f, 2)), "class_of": np.zeros(1, np.int64)}
    tr, val, _, _ = train.training_data(cfg, spec, kept, False)
    cyclist = np.arange(3) == list(spec.classes).index("cyclist")
    assert tr.target.tolist() == val.target.tolist() == cyclist.tolist()


def test_hdmap_splits_by_scene_and_samples_5_hz() -> None:
    root = data_root()
    files = {s: {p.name for p in source_files("hdmap", root, s)} for s in ("train", "val", "test")}
    assert not files["train"] & files["val"]
    assert not files["train"] & files["test"]
    assert not files["val"] & files["test"]
    assert sum(len(f) for f in files.values()) == 45  # 10 nuScenes scenes and 35 Waymo scenarios
    assert len(files["test"]) == len(HDMAP_TEST)
    assert len(files["val"]) == len(HDMAP_VAL)
    assert source_files("argoverse2", root, "train") == []
    assert len(source_files("argoverse2", root, "test")) == 3
    nu = next(p for p in source_files("hdmap", root, "test") if "scene-0103" in p.name)
    info = DATASETS["hdmap"]
    both = hdmap_recordings(nu, keyframes_only=True)
    assert [r.name for r in both] == ["sd_nuscenes_v1.0-mini_scene-0103@0", "sd_nuscenes_v1.0-mini_scene-0103@1"]
    for phase, rec in enumerate(both):
        windows = list(iter_windows(rec, info, info.t_obs, info.t_f))
        assert windows
        for w in windows:
            # t_obs is a real 2 Hz annotation (10 Hz step divisible by 5), and so is the 3 s endpoint.
            assert (2 * w.now + phase) % 5 == 0
            assert (2 * (w.now + info.t_f) + phase) % 5 == 0
            # Every agent seen at all 25 steps is a target, standing ones too.
            assert np.array_equal(w.target, w.mask.all(axis=1))
    # Training windows may end at any step.
    assert len(list(iter_windows(hdmap_recordings(nu)[0], info, 10, 15))) > len(
        list(iter_windows(both[0], info, 10, 15))
    )


def test_a_run_needs_a_known_weight_selection(tmp_path: Path) -> None:
    import torch  # noqa: F401  (training.train needs torch)

    from training.train import main

    config = str(ROOT / "training" / "configs" / "hdmap.toml")
    with pytest.raises(ValueError, match=r"train\.select must be 'val_loss', 'val_ade' or 'last', got 'best'"):
        main(["--config", config, "--out", str(tmp_path), "--set", "train.select=best"])


def test_hdmap_needs_10_hz_sources(tmp_path: Path) -> None:
    # A ScenarioNet scenario at 2 Hz: readable, but not a source of the 5 Hz protocol (every second 10 Hz step).
    t = 5
    track = {
        "type": "VEHICLE",
        "state": {
            "position": np.zeros((t, 3)),
            "heading": np.zeros(t),
            "velocity": np.zeros((t, 2)),
            "valid": np.ones(t),
            "length": np.full((t, 1), 4.5),
            "width": np.full((t, 1), 2.0),
        },
    }
    meta = {"dataset": "nuscenes", "sample_rate": 0.5}
    path = tmp_path / "slow.pkl"
    path.write_bytes(pickle.dumps({"tracks": {"a": track}, "map_features": {}, "metadata": meta}))
    with pytest.raises(ValueError, match=r"slow\.pkl: expected 10 Hz states, got a step of 0\.5 s"):
        hdmap_recordings(path)


def test_resampling_interpolates_and_never_bridges_a_gap() -> None:
    from training.data.datasets import resampled

    # Agent 0 walks 1 m per old step (1/3 s) over steps 0..12; agent 1 is missing at old step 4.
    steps = np.r_[np.arange(13), [0, 1, 2, 3, 5, 6]]
    agents = np.r_[np.zeros(13, np.int64), np.ones(6, np.int64)]
    xy = np.c_[steps.astype(float), agents * 10.0]
    rec = Recording.sorted(name="r", step=steps, agent=agents, xy=xy, label=np.zeros(len(steps), np.int64))
    out = resampled(rec, 1 / 3, 0.4)
    walker = out.agent == 0
    np.testing.assert_array_equal(out.step[walker], np.arange(11))  # 0.4 s steps up to 4.0 s (old step 12)
    np.testing.assert_allclose(out.xy[walker, 0], 1.2 * np.arange(11))  # positions on the line, interpolated
    # Agent 1: new steps at old 0, 1.2, 2.4, 3.6, 4.8, 6.0; 3.6 and 4.8 need old step 4, which is missing.
    other = out.agent == 1
    np.testing.assert_array_equal(out.step[other], [0, 1, 2, 5])
    np.testing.assert_allclose(out.xy[other, 0], [0.0, 1.2, 2.4, 6.0])


def test_other_sources_pedestrians_join_the_ethucy_time_base() -> None:
    from training.data.datasets import pedestrian_recordings

    root = shared_data("sdd")
    recs = pedestrian_recordings("sdd", root, 0.4)
    assert len(recs) == len(source_files("sdd", root, "train"))  # the training split only
    rec = recs[0]
    assert rec.map is None
    assert (rec.label == 0).all()  # ETH/UCY's one label
    # Consecutive 0.4 s steps of one agent are at most a few metres apart (metres, not pixels).
    a = rec.agent == rec.agent[0]
    gaps = np.diff(rec.step[a]) == 1
    assert (np.linalg.norm(np.diff(rec.xy[a], axis=0), axis=1)[gaps] < 5.0).all()
    with pytest.raises(ValueError, match="unknown pedestrian source 'apolloscape'"):
        pedestrian_recordings("apolloscape", root, 0.4)


def test_extra_pedestrian_sources_are_parsed_and_checked() -> None:
    from training.data.splits import pedestrian_sources

    assert pedestrian_sources("") == []
    assert pedestrian_sources(" sdd , ") == ["sdd"]
    with pytest.raises(ValueError, match=r"unknown pedestrian source\(s\) \['kitti'\]"):
        pedestrian_sources("sdd,kitti")


def test_resampling_carries_sizes_and_leaves_headings_out() -> None:
    from training.data.datasets import resampled

    steps = np.arange(5)
    rec = Recording.sorted(
        name="r",
        step=steps,
        agent=np.zeros(5, np.int64),
        xy=np.c_[steps * 1.0, np.zeros(5)],
        label=np.zeros(5, np.int64),
        heading=np.zeros(5),
        length=np.array([4.0, 4.0, 4.2, 4.2, 4.4]),
        width=np.full(5, 1.8),
    )
    out = resampled(rec, 0.5, 0.2)  # 2 Hz onto 5 Hz: new steps at old steps 0, 0.4, 0.8 ... 4.0
    np.testing.assert_allclose(out.xy[:, 0], 0.4 * np.arange(11))
    assert out.length is not None
    assert out.width is not None
    np.testing.assert_allclose(out.length, np.array([4.0] * 5 + [4.2] * 5 + [4.4]))  # the earlier row's
    np.testing.assert_allclose(out.width, np.full(11, 1.8))
    assert out.heading is None


def test_hdmap_sources_apart_split_its_scenes() -> None:
    root = shared_data("nuscenes_mini_scenarionet")
    for split in ("train", "val", "test"):
        both = source_files("hdmap", root, split)
        nu, waymo = source_files("nuscenes", root, split), source_files("waymo", root, split)
        assert sorted(nu + waymo) == sorted(both)
        assert nu
        assert waymo
        assert all("nuscenes" in p.parent.name for p in nu)
        assert all("waymo" in str(p.parent) for p in waymo)


@pytest.mark.parametrize(
    ("source", "protocol"),
    [
        ("ethucy_5hz", (0.2, 10, 15)),
        ("sdd_5hz", (0.2, 10, 15)),
        ("apolloscape_5hz", (0.2, 10, 15)),
        ("ethucy_2hz", (0.5, 6, 6)),
        ("sdd_2hz", (0.5, 6, 6)),
        ("hdmap_2hz", (0.5, 6, 6)),
    ],
)
def test_other_sources_join_a_protocol(source: str, protocol: tuple[float, int, int]) -> None:
    """Each source's recordings on the hdmap (0.2 s) or ApolloScape (0.5 s) time base, in metres (nothing moves over
    40 m/s), without a map, its own labels and scoring; windows at that protocol."""
    root = shared_data("sdd")
    info = DATASETS[source]
    assert (info.dt_s, info.t_obs, info.t_f, info.unit, info.has_map) == (*protocol, "m", False)
    files = source_files(source, root, "val")
    rec = recordings(source, root, "val")[0]
    assert files
    assert rec.map is None
    assert rec.unit_m == 1.0
    assert rec.heading is None
    one = rec.agent == rec.agent[len(rec.agent) // 2]
    steps = np.diff(rec.step[one]) == 1
    assert (np.linalg.norm(np.diff(rec.xy[one], axis=0), axis=1)[steps] < 40.0 * info.dt_s).all()
    windows = list(iter_windows(rec, info, info.t_obs, info.t_f, stride=5))
    assert windows
    assert all(w.positions.shape[1] == info.t_obs + info.t_f for w in windows)


def test_ethucy_as_one_source_tests_every_scene() -> None:
    root = shared_data("eth_ucy")
    test = source_files("ethucy_5hz", root, "test")
    assert {p.parent.parent.name for p in test} == {"eth", "hotel", "univ", "zara1", "zara2"}
    assert len(test) == 6  # univ is students001 and students003
    train = source_files("ethucy_5hz", root, "train")
    assert len(train) == 8
    assert all(p.parent.name == "train" for p in train)


def test_extra_sources_are_checked_against_the_protocol() -> None:
    from training.config import DataConfig
    from training.data.splits import extra_sources, window_sets

    assert extra_sources("", "hdmap") == []
    assert extra_sources(" ethucy_5hz, sdd_5hz:6 ", "hdmap", 2) == [("ethucy_5hz", 2), ("sdd_5hz", 6)]
    for bad in ("sdd_5hz:0", "sdd_5hz:x", "sdd_5hz:"):
        if bad.endswith(":"):
            assert extra_sources(bad, "hdmap", 3) == [("sdd_5hz", 3)]
            continue
        with pytest.raises(ValueError, match="needs a whole stride"):
            extra_sources(bad, "hdmap")
    with pytest.raises(ValueError, match=r"unknown data.extra_sources \['kitti'\]"):
        extra_sources("kitti", "hdmap")
    with pytest.raises(ValueError, match="not one protocol"):
        extra_sources("ethucy", "hdmap")  # 0.4 s steps, 8 + 12
    with pytest.raises(ValueError, match="repeats a source or names the dataset"):
        extra_sources("waymo,ethucy_5hz", "waymo")
    with pytest.raises(ValueError, match="classes"):
        extra_sources("sdd_5hz", "ethucy_5hz")  # cyclists and vehicles for a pedestrian dataset
    d = DataConfig(dataset="hdmap", extra_sources="ethucy_5hz:4", augment_noise="0.1")
    train, val = window_sets(d, "train"), window_sets(d, "val")
    want = [("hdmap", 1, 0), ("hdmap", 1, 0.1), ("ethucy_5hz", 4, 0)]
    assert [(p.dataset, p.stride, p.noise[0]) for p in train] == want
    assert [(p.dataset, p.split, p.stride) for p in val] == [("hdmap", "val", 1), ("ethucy_5hz", "val", 4)]


def test_the_kept_epoch_can_be_chosen_on_the_own_validation_windows(tmp_path: Path) -> None:
    from dataclasses import replace

    from training.build import input_spec
    from training.config import Config
    from training.data.splits import training_splits

    root = shared_data("apolloscape_trajectory")
    cfg = Config.load(ROOT / "training" / "configs" / "apolloscape.toml", {"data.root": str(root)})
    cfg = replace(cfg, data=replace(cfg.data, cache_dir=str(tmp_path), extra_sources="ethucy_2hz:20"))
    spec = input_spec(cfg)
    pooled = training_splits(cfg, spec, False).val
    own = training_splits(replace(cfg, train=replace(cfg.train, select_split="own")), spec, False).val
    alone = training_splits(replace(cfg, data=replace(cfg.data, extra_sources="")), spec, False).val
    assert int(own.target.sum()) == int(alone.target.sum()) < int(pooled.target.sum())
    with pytest.raises(ValueError, match="select_split must be 'all' or 'own'"):
        training_splits(replace(cfg, train=replace(cfg.train, select_split="mine")), spec, False)


def test_a_source_without_maps_is_flagged_absent_for_a_map_model(tmp_path: Path) -> None:
    """Windows of a dataset without maps carry ``map_absent``, which the batch turns into ``map_present`` 0 (as the
    engine does for a frame without a map); the model's own windows stay present."""
    from training.data.arrays import concat_windows
    from training.data.batches import prepared_batch
    from training.data.windows import build_windows

    spec = dgan.Predictor("hdmap").spec
    rec = toy([(s, a, 2) for s in range(30) for a in (0, 1)])
    info = DATASETS["ethucy_5hz"]
    own = build_windows([rec], replace_info(DATASETS["hdmap"]), spec, stride=10, progress=False)
    other = build_windows([rec], replace_info(info), spec, stride=10, progress=False)
    assert own.map_absent is None
    assert other.map_absent is not None
    assert other.map_absent.all()
    both = concat_windows([own, other])
    assert both.map_absent is not None
    b = prepared_batch(both, np.arange(both.num_windows), spec)
    present = b["map_present"].numpy()
    n_own = int(own.agent_ptr[-1])
    assert (present[:n_own] == 1).all()
    assert (present[n_own:] == 0).all()


def replace_info(info: Any) -> Any:
    """``info`` with toy-sized windows' rule: every agent a target, one label per engine class."""
    from dataclasses import replace

    labels = tuple(dgan.CLASSES)
    return replace(info, labels=labels, label_class=labels, scored=(True,) * 3, min_targets=1)


def zara1_data(cache: Path, augment_noise: str = "", augment_speed: str = "") -> Any:
    """The zara1 fold's data section, windows every 40 steps cached under ``cache``, with the copies asked for."""
    from training.config import DataConfig

    return DataConfig(
        root=str(shared_data("eth_ucy")),
        dataset="ethucy",
        scene="zara1",
        window_stride=40,
        cache_dir=str(cache),
        extra_pedestrians="",
        augment_noise=augment_noise,
        augment_speed=augment_speed,
    )


@pytest.mark.slow
def test_a_noisy_copy_s_agents_are_flagged_noisy(tmp_path: Path) -> None:
    """``data.augment_noise``'s copies carry ``noisy`` (``train.distill_noisy``), through concatenation into the
    batch; the dataset's own windows and the validation split do not."""
    from training.data.arrays import concat_windows
    from training.data.batches import prepared_batch
    from training.data.splits import set_windows, window_sets

    d = zara1_data(tmp_path, augment_noise="0.3")
    spec = dgan.Predictor("zara1").spec
    own, copy = set_windows(d, window_sets(d, "train"), spec, False)
    assert own.noisy is None
    assert copy.noisy is not None
    assert copy.noisy.all()
    assert len(copy.noisy) == len(copy.target)
    assert all(w.noisy is None for w in set_windows(d, window_sets(d, "val"), spec, False))
    both = concat_windows([own, copy])
    b = prepared_batch(both, np.arange(both.num_windows), spec)
    n_own = int(own.agent_ptr[-1])
    assert not b["noisy"][:n_own].any()
    assert b["noisy"][n_own:].all()
    # The copy is the same windows, agents and targets, with other observed histories.
    np.testing.assert_array_equal(copy.target, own.target)
    assert not np.allclose(copy.trajectory, own.trajectory)


def test_speed_factors_are_parsed_and_checked() -> None:
    from training.config import DataConfig
    from training.data.splits import augment_speeds, window_sets

    assert augment_speeds("") == []
    assert augment_speeds(" 1.5, 2 ") == [1.5, 2.0]
    for bad in ("1", "0.5", "5", "2,2", "fast"):
        with pytest.raises(ValueError, match=r"data\.augment_speed"):
            augment_speeds(bad)
    with pytest.raises(ValueError, match=r"data\.augment_speed is for the ETH/UCY models, not 'hdmap'"):
        window_sets(DataConfig(dataset="hdmap", augment_speed="2"), "train")


@pytest.mark.slow
def test_a_faster_copy_moves_its_agents_faster_over_the_same_map(tmp_path: Path) -> None:
    """``data.augment_speed``'s copy is the training split resampled onto longer steps: at its step k each agent is
    where it was at step 2k, on the same scene map; the teacher teaches on it (not flagged noisy), and validation has no
    copy."""
    from training.data.datasets import sped_up
    from training.data.recording import WindowSet
    from training.data.splits import set_windows, window_sets

    root = shared_data("eth_ucy")
    d = zara1_data(tmp_path, augment_speed="2")
    assert [p.speed for p in window_sets(d, "train")] == [1.0, 2.0]
    assert [p.speed for p in window_sets(d, "val")] == [1.0]
    rec = recordings("ethucy", root, "train", "zara1")[0]
    fast = sped_up(WindowSet("ethucy", "train", "zara1", speed=2.0), root, 0.4, True)[0]
    assert fast.map is rec.map
    assert fast.name.endswith(":x2")
    at = {(int(s), int(a)): xy for s, a, xy in zip(rec.step, rec.agent, rec.xy, strict=True)}
    for s, a, xy in zip(fast.step[:500], fast.agent[:500], fast.xy[:500], strict=True):
        np.testing.assert_allclose(xy, at[2 * int(s), int(a)])
    spec = dgan.Predictor("zara1").spec
    own, copy = set_windows(d, window_sets(d, "train"), spec, False)
    assert copy.noisy is None
    assert copy.num_windows > 0
    assert copy.map is not None
    assert own.map is not None
    assert copy.map.shape[1:] == own.map.shape[1:]


def test_a_recording_moved_to_another_origin_moves_its_map_with_it() -> None:
    from training.data.recording import moved

    shift = np.array([512345.678, 4123456.789])
    rec = replace(toy([(0, 0, 0), (1, 0, 0)]), map=dgan.VectorMap([("lane_centerline", [[0.0, 0.0], [40.0, 4.0]])]))
    far = moved(rec, shift)
    np.testing.assert_array_equal(far.xy, rec.xy + shift)
    assert isinstance(far.map, dgan.VectorMap)
    np.testing.assert_array_equal(far.map.elements()[0][1], np.array([[0.0, 0.0], [40.0, 4.0]]) + shift)
    assert moved(replace(rec, map=None), shift).map is None
    with pytest.raises(ValueError, match="two finite metres"):
        moved(rec, [1.0, np.nan])


@pytest.mark.slow
def test_a_model_without_a_map_is_evaluated_alike_under_any_origin() -> None:
    """``training.evaluate``'s ``origin``: ApolloScape's validation recordings moved 4,000 km score as they are."""
    from training.evaluate import evaluate

    root, predictor = shared_data("apolloscape_trajectory"), dgan.Predictor("apolloscape")
    here = evaluate(predictor, "apolloscape", root, split="val")
    far = evaluate(predictor, "apolloscape", root, split="val", origin=(512345.678, 4123456.789))
    assert far["agents"] == here["agents"] > 1000
    for key in ("ade", "fde", "min_ade20", "cv_ade", "cv_fde"):
        assert far[key] == pytest.approx(here[key], abs=1e-6), key
