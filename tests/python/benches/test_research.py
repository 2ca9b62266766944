"""benches/research.py, the research-style pipeline, computes what the engine computes: the same tensors from the
contract's text, the same crops of a raster map, a vector map's crops up to anti-aliasing, the same predictions."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest

import dgan
from benches import research
from dgan.demo import scene_for

TENSORS = ("trajectory", "trajectory_mask", "state", "edge_index", "edge_features", "prior", "map_present")


def frame_and_spec(name: str) -> tuple[dgan.Frame, dgan.InputSpec]:
    spec = dgan.Predictor(name, sessions=1).spec
    return scene_for(spec).frame, spec


def per_call(spec: dgan.InputSpec) -> dgan.InputSpec:
    """A scene model's spec read as contract 12 (rasters of the agents' groups each call, the agents' boxes drawn):
    the bundled ``zara1`` and ``sdd`` keep their features with the map (contract 13)."""
    assert spec.map is not None
    assert spec.map.scene is not None
    scene = dataclasses.replace(spec.map.scene, tile_px=0, halo_px=0, channels=0)
    return dataclasses.replace(spec, map=dataclasses.replace(spec.map, draw_agents=True, scene=scene))


@pytest.mark.parametrize("name", ["apolloscape", "zara1", "sdd", "hdmap"])
def test_the_network_inputs_are_the_engines(name: str) -> None:
    frame, spec = frame_and_spec(name)
    engine, ours = dgan.preprocess(frame, spec), research.preprocess(frame, spec)
    for key in TENSORS:
        assert (key in engine) == (key in ours), key
        if key in engine:
            assert ours[key].shape == engine[key].shape, key
            np.testing.assert_allclose(ours[key], engine[key], atol=1e-5, err_msg=key)


@pytest.mark.parametrize("name", ["zara1", "sdd", "univ"])
def test_raster_crops_are_the_engines(name: str) -> None:
    """The crops (``univ``), or a scene model's raster and grids (contract 12: ``zara1`` and ``sdd``, which keep their
    features with the map, read so) of a raster map."""
    frame, spec = frame_and_spec(name)
    assert spec.map is not None
    spec = per_call(spec) if spec.map.scene is not None else spec
    assert spec.map is not None
    bare = dataclasses.replace(spec, map=dataclasses.replace(spec.map, draw_agents=False))
    np.testing.assert_array_equal(research.preprocess(frame, bare)["map"], dgan.preprocess(frame, bare)["map"])
    # With the agents' boxes: the engine's are anti-aliased, ours cover the pixel centres inside them.
    engine, ours = dgan.preprocess(frame, spec), research.preprocess(frame, spec)
    diff = np.abs(ours["map"] - engine["map"])
    assert (diff > 1.01 / 255).mean() < 0.05
    assert ("map_grid" in engine) == (spec.map.scene is not None) == ("map_grid" in ours)
    if spec.map.scene is not None:
        np.testing.assert_allclose(ours["map_grid"], engine["map_grid"], atol=1e-5)
        np.testing.assert_array_equal(ours["map_slot"], engine["map_slot"])


def test_vector_crops_light_the_engines_pixels() -> None:
    frame, spec = frame_and_spec("hdmap")
    engine, ours = dgan.preprocess(frame, spec)["map"], research.preprocess(frame, spec)["map"]
    assert spec.map is not None
    assert spec.map.classes == ("cyclist", "pedestrian")
    readers = np.isin(np.asarray(frame.classes), spec.map.classes)
    assert 0 < readers.sum() < len(frame)
    assert not engine[~readers].any()
    assert not ours[~readers].any()
    lit_engine, lit_ours = engine[readers].max(axis=1) > 0.25, ours[readers].max(axis=1) > 0.25
    assert lit_engine.mean() > 0.1  # a real map under the agents
    assert (lit_engine == lit_ours).mean() > 0.8  # the rest: the engine's anti-aliased thin lines


@pytest.mark.parametrize("fit", ["endpoints", "least_squares", "quadratic"])
def test_the_prior_fits_are_the_engines(fit: str) -> None:
    # Noisy tracks with dropped steps, some standing: every branch of the fits and of the standing rule.
    rng = np.random.default_rng(3)
    n, t_obs = 64, 10
    steps = np.arange(t_obs)[None, :, None]
    speed = rng.choice([0.0, 0.1, 1.5, 8.0], size=(n, 1, 1))
    traj = speed * 0.2 * (steps - t_obs + 1) * np.array([1.0, 0.2]) + rng.normal(0, 0.05, (n, t_obs, 2))
    mask = rng.random((n, t_obs)) > 0.2
    mask[:3, :-1] = False  # one valid step
    mask[3:6, :-2] = False  # two
    traj = np.where(mask[..., None], traj, 0.0).astype(np.float32)
    state = np.zeros((n, 10), dtype=np.float32)
    state[:, 0], state[:, 3] = speed[:, 0, 0], 1.0
    prior = dgan.PriorSpec("constant_velocity", window_s=1.2, fit=fit, standing_mps=0.3)
    spec = dataclasses.replace(frame_and_spec("hdmap")[1], prior=prior)
    ours = research.prior_rollout(traj.astype(np.float64), mask, state, spec)
    engine = dgan.kinematic_prior(traj, mask.astype(np.float32), state, spec)
    np.testing.assert_allclose(ours, engine, atol=2e-5)


@pytest.mark.parametrize(
    ("name", "atol", "n"),
    [("apolloscape", 1e-3, 0), ("sdd", 1e-3, 0), ("zara1", 1e-3, 0), ("zara1", 1e-3, 400)],
)
def test_the_pipeline_predicts_what_the_engine_does(name: str, atol: float, n: int) -> None:
    """Also ``zara1`` (its map features kept, contract 13) on its scene tiled to 400 agents, whose agents read more
    tiles than one network run of the engine computes."""
    from benches.bench import tiled

    pytest.importorskip("torch")
    predictor = dgan.Predictor(name, sessions=1)
    frame = scene_for(predictor.spec).frame
    frame = tiled(frame, n) if n else frame
    if n:
        assert len(dgan.preprocess(frame, predictor.spec)["map"]) > 64
    run = research.pipeline(name)
    assert run is not None
    trajectories, probabilities = run(frame)
    engine = predictor.predict(frame)
    modes = engine.trajectories.shape[1]
    # The same network in PyTorch and ONNX Runtime.
    np.testing.assert_allclose(trajectories[:, 0], engine.trajectories[:, 0], atol=atol)
    np.testing.assert_allclose(probabilities[:, :modes], engine.probabilities, atol=atol)


def test_a_scene_models_groups_are_the_engines() -> None:
    """A frame of scattered groups (the bundled scene tiled 60 m apart): one raster per group of agents whose crops
    meet, of one side, each agent's grid in its group's raster (contract 12)."""
    from benches.bench import tiled

    frame, spec = frame_and_spec("zara1")
    spec = per_call(spec)
    assert spec.map is not None
    big = tiled(frame, 32)
    bare = dataclasses.replace(spec, map=dataclasses.replace(spec.map, draw_agents=False))
    engine, ours = dgan.preprocess(big, bare), research.preprocess(big, bare)
    assert engine["map"].shape[0] > 1
    np.testing.assert_array_equal(ours["map"], engine["map"])
    np.testing.assert_array_equal(ours["map_slot"], engine["map_slot"])
    np.testing.assert_allclose(ours["map_grid"], engine["map_grid"], atol=1e-5)


@pytest.mark.parametrize("with_map", [True, False])
def test_a_kept_features_models_tiles_and_reads_are_the_engines(with_map: bool) -> None:
    """Contract 13 (features kept with the map): the tiles the agents read, in order of first use, each drawn with
    its halo on the world's grid, and each agent's four rows and weights per block centre; a frame without a map
    reads one blank block."""
    from benches.bench import tiled

    frame, spec = frame_and_spec("zara1")
    assert spec.map is not None
    assert spec.map.scene is not None
    scene = dataclasses.replace(spec.map.scene, tile_px=32, halo_px=16, channels=16)
    kept = dataclasses.replace(spec, map=dataclasses.replace(spec.map, draw_agents=False, scene=scene))
    big = tiled(frame, 32) if with_map else tiled(frame, 32).without_map()
    engine, ours = dgan.preprocess(big, kept), research.preprocess(big, kept)
    assert engine["map"].shape[0] > 1 if with_map else engine["map"].shape[0] == 0
    for key in ("map", "map_rows", "map_index"):
        assert ours[key].shape == engine[key].shape, key
        np.testing.assert_array_equal(ours[key], engine[key], err_msg=key)
    np.testing.assert_allclose(ours["map_weight"], engine["map_weight"], atol=1e-5)
