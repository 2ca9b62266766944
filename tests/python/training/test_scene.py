"""training.modules.scene: the map CNN shared by a window's agents (``model.map_mode = "scene"``, issue 26), the
windows that carry its scene rasters and grids (``data.map_scene_px``), mirrored with their agents."""

from __future__ import annotations

from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest
import torch
from conftest import shared_data

import dgan
from dgan.contract import SCENE_GRID_INPUTS
from training.build import build_model, input_spec
from training.config import Config
from training.data.arrays import Windows, padded_grids
from training.data.batches import forward_inputs, prepared_batch
from training.data.recording import WindowSet
from training.data.splits import located
from training.data.windows import build_windows
from training.export import export_model
from training.modules.scene import SCENE_MIN_PX, SCENE_STRIDE, SceneMapEncoder, read_slots

ROOT = Path(__file__).resolve().parents[3]
CONFIG = ROOT / "training" / "configs" / "ethucy_zara1.toml"
SCENE = {"model.map_mode": "scene", "data.map_scene_px": 64}


def test_each_agent_reads_its_own_frame_s_features() -> None:
    """One ``grid_sample`` over every frame's stacked grids (the engine's ``map_grid``, ``map_slot``) gives each agent
    what a call on its own frame gives, frames without agents included."""
    torch.manual_seed(0)
    features = torch.randn(4, 5, 9, 11)
    per_frame = np.array([2, 0, 3, 1])
    grids = np.random.default_rng(0).uniform(-1.2, 1.2, (6, 3, 2, 2)).astype(np.float32)  # some outside: zeros
    grid, slot = padded_grids(grids, per_frame)
    assert grid.shape == (4, 3, 3, 2, 2)
    np.testing.assert_array_equal(slot, [0, 1, 6, 7, 8, 9])
    out = read_slots(features, torch.from_numpy(grid), torch.from_numpy(slot))
    assert out.shape == (6, 5, 3, 2)
    for i, f in enumerate(np.repeat(np.arange(4), per_frame)):
        one = torch.nn.functional.grid_sample(
            features[f : f + 1], torch.from_numpy(grids[i : i + 1]), align_corners=False
        )
        torch.testing.assert_close(out[i], one[0])
    empty = padded_grids(grids[:0], np.zeros(2, int))
    assert read_slots(features[:2], *map(torch.from_numpy, empty)).shape == (0, 5, 3, 2)


def _scene_windows(cfg: Config) -> tuple[dgan.InputSpec, Windows]:
    spec = input_spec(cfg)
    found = located([WindowSet("ethucy", "val", fold="zara1")], shared_data("eth_ucy"), spec)[0]
    return spec, build_windows(found.read()[:1], found.info, spec, stride=20, progress=False, scene_px=64)


def test_scene_windows_mirror_with_their_agents_and_train_the_network() -> None:
    cfg = Config.load(CONFIG, SCENE)
    spec, w = _scene_windows(cfg)
    assert w.scene is not None
    assert w.scene_grid is not None
    assert w.scene.shape == (w.num_windows, 3, 64, 64)
    assert w.scene_grid.shape == (len(w.target), 8, 8, 2)
    assert w.map is not None  # the crops stay, for a teacher that reads them
    idx = np.array([0, 1])
    plain, flipped = w.batch(idx), w.batch(idx, flip=np.array([False, True]))
    n0 = int(np.diff(w.agent_ptr)[0])
    assert plain["crops"].shape[0] == len(plain["state"])  # the agents' crops, for a teacher
    np.testing.assert_array_equal(flipped["map"][0], plain["map"][0])
    np.testing.assert_array_equal(flipped["map"][1], plain["map"][1][..., ::-1])
    np.testing.assert_array_equal(flipped["crops"][n0:], plain["crops"][n0:][..., ::-1])
    # The flipped window's agents read their features mirrored: what they read before, columns reversed.
    keys = ("map", *SCENE_GRID_INPUTS)
    read = [read_slots(*(torch.from_numpy(np.ascontiguousarray(b[k])) for k in keys)) for b in (plain, flipped)]
    torch.testing.assert_close(read[1][:n0], read[0][:n0])
    torch.testing.assert_close(read[1][n0:], read[0][n0:].flip(-1), atol=1e-5, rtol=0)
    assert read[0][n0:].abs().sum() > 0
    # The network trains on them: gradients reach the scene CNN.
    torch.manual_seed(0)
    net = build_model(cfg, spec, 20)
    b = prepared_batch(w, idx, spec, np.array([False, True]), 0.5, np.random.default_rng(0))
    cl, al, off = net(*forward_inputs(b))
    assert off.shape == (len(b["state"]), 20, spec.t_f, 2)
    (cl.sum() + al.sum() + off.sum()).backward()
    stem = net.map_enc.scene[0].weight.grad  # type: ignore[union-attr, index]
    assert stem is not None
    assert stem.abs().sum() > 0


def test_scene_settings_that_do_not_go_together_are_clear_errors(tmp_path: Path) -> None:
    cfg = Config.load(CONFIG, SCENE)
    spec = input_spec(cfg)
    with pytest.raises(ValueError, match="go together"):
        build_model(replace(cfg, data=replace(cfg.data, map_scene_px=0)), spec, 20)
    with pytest.raises(ValueError, match="go together"):
        build_model(replace(cfg, model=replace(cfg.model, map_mode="crop")), spec, 20)
    plain = Config.load(CONFIG)
    with pytest.raises(ValueError, match="map_mode must be"):
        build_model(replace(plain, model=replace(plain.model, map_mode="tiles")), input_spec(plain), 20)
    anchors, class_of = np.zeros((20, spec.t_f, 2), np.float32), np.zeros(20, np.int64)
    crops = input_spec(plain)
    with pytest.raises(ValueError, match="reads the scene"):
        export_model(build_model(cfg, spec, 20), crops, anchors, class_of, tmp_path / "m.onnx", "scene")
    assert spec.map is not None
    assert spec.map.scene == dgan.SceneSpec(SCENE_MIN_PX, SCENE_STRIDE)


def test_a_crop_teacher_teaches_a_scene_student_on_the_agents_crops() -> None:
    """The scene student's batches keep the agents' crops (``crops``): a teacher that reads crops runs on them,
    exactly as on a crop student's batch of the same windows."""
    from training.step import Teacher

    cfg = Config.load(CONFIG, SCENE)
    spec, w = _scene_windows(cfg)
    teacher_path = str(ROOT / "training" / "checkpoints" / "teachers" / "zara1.pt")
    teacher = Teacher.load(teacher_path, spec)
    assert not teacher.own_map
    crop_spec = replace(spec, map=replace(spec.map, scene=None)) if spec.map else spec
    idx = np.array([0, 1])
    scene_batch = prepared_batch(w, idx, spec)
    crop_batch = prepared_batch(replace(w, scene=None, scene_grid=None), idx, crop_spec)
    assert "map_grid" in scene_batch
    assert "map_grid" not in crop_batch
    torch.testing.assert_close(teacher.top_residual(scene_batch), teacher.top_residual(crop_batch), rtol=0, atol=0)


def test_a_scene_model_predicts_a_batch_as_each_frame_alone(tmp_path: Path) -> None:
    """Frames of one raster side run as one call (their rasters stacked, their grids padded), frames of another in
    calls of their own; each agent gets what ``predict`` gives it."""
    torch.manual_seed(0)
    cfg = Config.load(CONFIG, SCENE)
    spec = input_spec(cfg)
    anchors = np.cumsum(np.random.default_rng(0).normal(0.4, 0.2, (8, spec.t_f, 2)), axis=1).astype(np.float32)
    path = export_model(
        build_model(cfg, spec, 8).eval(), spec, anchors, np.zeros(8, np.int64), tmp_path / "m.onnx", "s"
    )
    predictor = dgan.Predictor(path)
    frame = dgan.demo.scene_for(predictor.spec).frame
    far = dgan.Frame(frame.positions * 3.0, classes=frame.classes, map=frame.map)  # a larger raster
    frames = [
        frame,
        frame.without_map(),
        dgan.Frame(frame.positions[:2], classes=frame.classes[:2], map=frame.map),
        far,
    ]
    sides = {dgan.preprocess(f, predictor.spec)["map"].shape[-1] for f in frames}
    assert len(sides) >= 2  # the full frame with and without its map share one
    for got, f in zip(predictor.predict_batch(frames), frames, strict=True):
        one = predictor.predict(f)
        np.testing.assert_allclose(got.trajectories, one.trajectories, atol=1e-4)
        np.testing.assert_allclose(got.probabilities, one.probabilities, atol=1e-5)


def test_a_scene_frame_split_across_lanes_equals_one_call() -> None:
    """On two threads a scene frame of scattered groups runs as parts that take whole groups of rasters (with their
    agents' graph components): each agent gets exactly what one call on one thread gives it."""
    from benches.bench import tiled

    one, two = dgan.Predictor("zara1", threads=1), dgan.Predictor("zara1", threads=2)
    assert one.spec.map is not None
    assert one.spec.map.scene is not None
    frame = tiled(dgan.demo.scene_for(one.spec).frame, 128)
    a, b = one.predict(frame), two.predict(frame)
    timings = two.last_timings
    assert timings is not None
    assert timings["parts"] > 0.0  # it did split
    np.testing.assert_allclose(b.trajectories, a.trajectories, atol=1e-5)
    np.testing.assert_allclose(b.probabilities, a.probabilities, atol=1e-6)


KEPT = {**SCENE, "data.map_draw_agents": False, "data.map_scene_tile_px": 32}


def test_kept_tiles_read_what_one_raster_of_the_world_grid_gives() -> None:
    """Contract 13: the features of the map's tiles (each computed from its raster and a halo of the CNN's reach)
    read at each agent's blocks are what the scene CNN over one large north-up raster on the same world grid gives
    there, far from its edges: the tiles are seamless and placed where the engine's grid says."""
    torch.manual_seed(0)
    cfg = Config.load(CONFIG, KEPT)
    spec = input_spec(cfg)
    assert spec.map is not None
    assert spec.map.scene is not None
    assert spec.map.scene.tile_px == 32
    model = build_model(cfg, spec, 8).eval()
    frame = dgan.demo.scene_for(spec).frame
    x = dgan.preprocess(frame, spec)
    assert x["map_rows"].shape == (0, spec.map.scene.channels)
    assert len(x["map"]) >= 2
    enc = model.map_enc
    assert isinstance(enc, SceneMapEncoder)
    with torch.no_grad():
        new = enc.tile_rows(torch.from_numpy(x["map"]), 32, 16)
        assert new.shape == (len(x["map"]) * 64, spec.map.scene.channels)
        patches = dgan.read_kept(new.numpy(), x["map_index"], x["map_weight"], (8, 8))
        got = enc.proj(enc.agent(torch.from_numpy(patches)))
        # One raster of 384 px whose middle pixel is global pixel (40, -40): world (20, 20) at 0.5 m.
        raster = dgan.scene_raster(frame, spec, 384, origin=(20.0, 20.0), heading=np.pi / 2)
        grid = dgan.crop_grid(x["origin"], x["heading"], spec, SCENE_STRIDE, 384, (20.0, 20.0), np.pi / 2)
        assert np.abs(grid).max() < 0.8  # far from the raster's edges
        n = len(grid)
        features = enc.scene(torch.from_numpy(raster)[None])
        reads = read_slots(features, torch.from_numpy(grid)[None], torch.arange(n))
        want = enc.proj(enc.agent(reads))
    torch.testing.assert_close(got, want, rtol=1e-4, atol=1e-4)


def test_a_kept_features_model_exports_and_predicts_as_its_network(tmp_path: Path) -> None:
    """Contract 13 end to end: the exported graph gives the PyTorch network's outputs on the engine's inputs (every
    tile computed, each agent's reading of them by ``dgan.read_kept``), and a predictor's later calls, which read the
    tiles it kept, its batches and its lanes give each agent what its first call gave."""
    from benches.bench import tiled

    torch.manual_seed(0)
    cfg = Config.load(CONFIG, KEPT)
    spec = input_spec(cfg)
    model = build_model(cfg, spec, 8).eval()
    anchors = np.cumsum(np.random.default_rng(0).normal(0.4, 0.2, (8, spec.t_f, 2)), axis=1).astype(np.float32)
    path = export_model(model, spec, anchors, np.zeros(8, np.int64), tmp_path / "m.onnx", "kept")
    frame = dgan.demo.scene_for(spec).frame
    x = dgan.preprocess(frame, dgan.Predictor(path).spec)
    with torch.no_grad():
        rows = model.tile_rows(torch.from_numpy(x["map"])).numpy()
    x["map_patches"] = dgan.read_kept(np.concatenate([x["map_rows"], rows]), x["map_index"], x["map_weight"], (8, 8))
    names = [n for n in (*dgan.contract.PADDED_INPUTS, *dgan.contract.KEPT_INPUTS) if n in x]
    import onnxruntime as ort  # type: ignore[import-untyped]

    got = ort.InferenceSession(str(path)).run(None, {n: x[n] for n in names})
    with torch.no_grad():
        want = model.forward_padded(**{n: torch.from_numpy(x[n]) for n in names})
    assert len(got) == len(want) == 4
    for g, w in zip(got, want, strict=True):
        np.testing.assert_allclose(g, w.numpy(), atol=1e-4)
    predictor = dgan.Predictor(path, threads=2)
    first = predictor.predict(frame)
    for again in (predictor.predict(frame), predictor.predict_batch([frame, frame.without_map(), frame])[2]):
        np.testing.assert_allclose(again.trajectories, first.trajectories, atol=1e-5)
        np.testing.assert_allclose(again.probabilities, first.probabilities, atol=1e-6)
    big = tiled(frame, 128)
    a, b = dgan.Predictor(path).predict(big), predictor.predict(big)
    assert predictor.last_timings is not None
    assert predictor.last_timings["parts"] > 0.0
    np.testing.assert_allclose(b.trajectories, a.trajectories, atol=1e-5)
    assert np.isfinite(predictor.predict(frame.without_map()).trajectories).all()


def test_a_consensus_of_kept_features_members_keeps_their_features_side_by_side(tmp_path: Path) -> None:
    """A consensus (``training.ensemble``) of members that keep their map's features: the kept rows hold every
    member's channels side by side, each member reads its own, and the exported file gives the consensus of the
    members' own outputs, each on its own features."""
    from training.export import kept_side_by_side
    from training.modules.consensus import ConsensusEnsemble
    from training.modules.dgan import DGAN

    cfg = Config.load(CONFIG, KEPT)
    spec = input_spec(cfg)
    members: list[DGAN] = []
    for seed in (0, 1):
        torch.manual_seed(seed)
        members.append(build_model(cfg, spec, 8).eval())
    anchors = np.cumsum(np.random.default_rng(0).normal(0.4, 0.2, (8, spec.t_f, 2)), axis=1).astype(np.float32)
    table = torch.from_numpy(anchors)
    consensus = ConsensusEnsemble(members, [table, table], 1).eval()
    both = kept_side_by_side(spec, 2)
    assert both.map is not None
    assert both.map.scene is not None
    assert spec.map is not None
    assert spec.map.scene is not None
    assert both.map.scene.channels == 2 * spec.map.scene.channels
    path = export_model(consensus, both, anchors, np.zeros(8, np.int64), tmp_path / "m.onnx", "kept consensus")
    frame = dgan.demo.scene_for(spec).frame
    x = dgan.preprocess(frame, dgan.Predictor(path).spec)
    with torch.no_grad():
        rows = [m.tile_rows(torch.from_numpy(x["map"])).numpy() for m in members]
    c = spec.map.scene.channels
    assert x["map_rows"].shape == (0, 2 * c)  # nothing kept yet: every tile is computed
    patches = [dgan.read_kept(r, x["map_index"], x["map_weight"], (8, 8)) for r in rows]
    names = [n for n in (*dgan.contract.PADDED_INPUTS, *dgan.contract.KEPT_INPUTS) if n in x]
    feed = {n: x[n] for n in names} | {"map_patches": np.concatenate(patches, axis=1)}
    import onnxruntime as ort

    got = ort.InferenceSession(str(path)).run(None, feed)
    with torch.no_grad():
        base = {n: torch.from_numpy(feed[n]) for n in names if n != "map_patches"}
        outs = [
            m.forward_padded(**base, map_patches=torch.from_numpy(p)) for m, p in zip(members, patches, strict=True)
        ]
        assert all(len(o) == 4 for o in outs)
        want = consensus.combine([(o[0], o[1], o[2]) for o in outs])
    assert got[3].shape == (len(rows[0]), 2 * c)
    np.testing.assert_allclose(got[3], np.concatenate(rows, axis=1), atol=1e-4)
    with torch.no_grad():
        np.testing.assert_allclose(consensus.tile_rows(torch.from_numpy(x["map"])).numpy(), got[3], atol=1e-4)
    for g, w in zip(got[:3], want, strict=True):
        np.testing.assert_allclose(g, w.numpy(), atol=1e-4)
    first = dgan.Predictor(path)
    a, b = first.predict(frame), first.predict(frame)  # the second reads the tiles the first kept
    np.testing.assert_allclose(b.trajectories, a.trajectories, atol=1e-5)
    odd = {k: torch.from_numpy(np.ascontiguousarray(v[:, :-1] if k == "map_patches" else v)) for k, v in feed.items()}
    with pytest.raises(ValueError, match="channels do not split over 2 members"):
        consensus.forward_padded(**odd)
    with pytest.raises(ValueError, match="a consensus takes map_patches by name"):
        consensus.forward_padded(*[None] * 11)
