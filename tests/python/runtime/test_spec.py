"""dgan.InputSpec, dgan.preprocess and the geometry helpers training uses."""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

import dgan
from dgan import exceptions as exc

SPEC = dgan.InputSpec(dt_s=0.4, t_obs=8, t_f=12, classes=("pedestrian",))


def test_spec_validation() -> None:
    assert SPEC.state_dim == 8
    assert dgan.InputSpec.from_dict(json_round_trip(SPEC)) == SPEC
    with pytest.raises(exc.InvalidSpecError, match="dt_s"):
        dgan.InputSpec(dt_s=-1.0, t_obs=8, t_f=12)
    for dt in (1e-300, 1e9):  # a step that would overflow speeds, or a prior of light-years
        with pytest.raises(exc.InvalidSpecError, match=r"dt_s must be a number of seconds in 0\.001\.\.=3600"):
            dgan.InputSpec(dt_s=dt, t_obs=8, t_f=12)
    with pytest.raises(exc.InvalidSpecError, match=r"t_obs must be in 1..=1000 steps, got 0"):
        dgan.InputSpec(dt_s=0.4, t_obs=0, t_f=12)
    # Bounds before any allocation: a spec (or a model's metadata) claiming 10^9 future steps is refused.
    with pytest.raises(exc.InvalidSpecError, match=r"t_f must be in 1..=1000 steps, got 1000000000"):
        dgan.InputSpec(dt_s=0.4, t_obs=8, t_f=10**9)
    with pytest.raises(exc.InvalidSpecError, match="repeat"):
        dgan.InputSpec(dt_s=0.4, t_obs=8, t_f=12, classes=("vehicle", "vehicle"))
    with pytest.raises(exc.InvalidSpecError, match="outside"):
        dgan.InputSpec(dt_s=0.4, t_obs=8, t_f=12, map=dgan.MapSpec(agent_row=64))
    with pytest.raises(exc.InvalidSpecError, match="not an input specification"):
        dgan.InputSpec(dt_s=0.4, t_obs=8, t_f=12, classes=("truck",))


def test_map_classes_name_classes_of_the_model_and_are_written_only_when_given() -> None:
    """Contract 11's ``map.classes``: the readers' names round-trip, none is written for every class (contracts
    1-10), and a class the model lacks, a repeat or a bare string is refused."""
    readers = dgan.InputSpec(0.5, 4, 6, ("vehicle", "pedestrian"), map=dgan.MapSpec(classes=["pedestrian"]))
    assert readers.map is not None
    assert readers.map.classes == ("pedestrian",)
    assert dgan.InputSpec.from_dict(json_round_trip(readers)) == readers
    every = dgan.InputSpec(0.5, 4, 6, ("vehicle", "pedestrian"), map=dgan.MapSpec())
    assert "classes" not in json_round_trip(every)["map"]  # type: ignore[operator]
    for bad, says in ((("cyclist",), "map.classes names cyclist"), (("vehicle", "vehicle"), "repeat")):
        with pytest.raises(exc.InvalidSpecError, match=says):
            dgan.InputSpec(0.5, 4, 6, ("vehicle", "pedestrian"), map=dgan.MapSpec(classes=bad))
    with pytest.raises(exc.InvalidSpecError, match="sequence of class names"):
        dgan.MapSpec(classes="pedestrian")


def test_a_specs_json_is_built_once_and_follows_a_replaced_copy() -> None:
    from dataclasses import replace

    assert SPEC.to_json() is SPEC.to_json()  # built once: preprocess passes it to the engine on every call
    wider = replace(SPEC, attention_lambda=2.0)
    assert json_round_trip(wider)["attention_lambda"] == 2.0
    assert json_round_trip(SPEC)["attention_lambda"] == 0.5
    assert wider == dgan.InputSpec.from_dict(json_round_trip(wider))
    assert wider != SPEC
    assert "_json" not in repr(SPEC)


def json_round_trip(spec: dgan.InputSpec) -> dict[str, object]:
    import json

    out: dict[str, object] = json.loads(spec.to_json())
    return out


def test_preprocess_shapes_on_a_real_frame(zara1_frame: dgan.Frame) -> None:
    x = dgan.preprocess(zara1_frame, SPEC)
    n = len(zara1_frame)
    assert x["trajectory"].shape == (n, 8, 2)
    assert x["trajectory"].dtype == np.float32
    assert x["state"].shape == (n, 8)
    assert x["edge_index"].dtype == np.int64
    assert x["edge_index"].shape[1] == 2
    assert x["edge_features"].shape == (x["edge_index"].shape[0], 6)
    assert "map" not in x
    # Every agent's last observed position is its origin: (0, 0) in its own frame.
    np.testing.assert_allclose(x["trajectory"][:, -1], 0.0, atol=1e-6)
    # Self-loops first-class: one per agent, and the directed edges are the undirected ones both ways.
    assert x["edge_index"].shape[0] == n + 2 * x["edges"].shape[0]
    # Pedestrians walk 0.5..2 m/s in zara1.
    assert 0.3 < np.median(x["speed"]) < 2.5


def test_preprocess_rejects_unknown_classes_for_the_spec() -> None:
    frame = dgan.Frame(np.zeros((1, 8, 2)), classes=["vehicle"])
    with pytest.raises(exc.UnknownClassError, match="knows only"):
        dgan.preprocess(frame, SPEC)


def test_transforms_round_trip() -> None:
    rng = np.random.default_rng(0)
    pts = rng.uniform(-100, 100, (5, 12, 2))
    origins, headings = rng.uniform(-50, 50, (5, 2)), rng.uniform(-4, 4, 5)
    local = dgan.to_agent_frame(pts, origins, headings)
    np.testing.assert_allclose(dgan.to_world_frame(local, origins, headings), pts, atol=1e-9)
    # Heading +y: a point 1 m north of the origin is 1 m ahead.
    np.testing.assert_allclose(
        dgan.to_agent_frame([[[3.0, 5.0]]], [[3.0, 4.0]], [np.pi / 2]), [[[1.0, 0.0]]], atol=1e-12
    )
    with pytest.raises(exc.InvalidFrameError, match="origins"):
        dgan.to_agent_frame(pts, origins[:2], headings)


@settings(max_examples=30, deadline=None)
@given(n=st.integers(0, 400), seed=st.integers(0, 2**32 - 1), side=st.floats(1.0, 500.0))
def test_attention_graph_equals_brute_force(n: int, seed: int, side: float) -> None:
    rng = np.random.default_rng(seed)
    centres = rng.uniform(0, side, (n, 2))
    radii = rng.exponential(3.0, n)
    fast = dgan.attention_graph(centres, radii)
    slow = dgan.attention_graph(centres, radii, brute_force=True)
    np.testing.assert_array_equal(fast, slow)
    if n:
        d = np.linalg.norm(centres[:, None] - centres[None], axis=2)
        want = np.argwhere(np.triu(d <= radii[:, None] + radii[None], k=1))
        np.testing.assert_array_equal(fast, want.reshape(-1, 2))


def test_attention_graph_errors() -> None:
    with pytest.raises(exc.InvalidFrameError, match="radius"):
        dgan.attention_graph([[0.0, 0.0]], [np.nan])
    with pytest.raises(exc.InvalidFrameError, match=r"\(N, 2\)"):
        dgan.attention_graph([0.0, 0.0], [1.0])


def test_rigid_motion_leaves_inputs_unchanged(zara1_frame: dgan.Frame) -> None:
    angle, shift = 2.1, np.array([250.0, -75.0])
    rot = np.array([[np.cos(angle), -np.sin(angle)], [np.sin(angle), np.cos(angle)]])
    moved = dgan.Frame(zara1_frame.positions @ rot.T + shift, mask=zara1_frame.mask, ids=zara1_frame.ids)
    a, b = dgan.preprocess(zara1_frame, SPEC), dgan.preprocess(moved, SPEC)
    for key in ("trajectory", "state", "edge_features"):  # not a contract copy: the arrays checked here
        np.testing.assert_allclose(a[key], b[key], atol=1e-4, err_msg=key)
    np.testing.assert_array_equal(a["edge_index"], b["edge_index"])


def _bilinear(img: np.ndarray, grid: np.ndarray) -> np.ndarray:
    """``grid_sample`` (bilinear, align_corners=False, zeros outside) of ``img (C, H, W)`` at ``grid (..., 2)``."""
    c, h, w = img.shape
    u, v = (grid[..., 0] + 1) * w / 2 - 0.5, (grid[..., 1] + 1) * h / 2 - 0.5
    u0, v0 = np.floor(u).astype(int), np.floor(v).astype(int)
    out = np.zeros((c, *grid.shape[:-1]))
    for du in (0, 1):
        for dv in (0, 1):
            uu, vv = u0 + du, v0 + dv
            wt = (1 - np.abs(u - uu)) * (1 - np.abs(v - vv))
            inside = (uu >= 0) & (uu < w) & (vv >= 0) & (vv < h)
            out += np.where(inside, wt, 0.0) * img[:, np.clip(vv, 0, h - 1), np.clip(uu, 0, w - 1)]
    return out


def test_scene_raster_and_crop_grid_read_each_agents_crop(zara1_frame: dgan.Frame) -> None:
    """Sampling the scene raster on an agent's grid (stride 1) gives its crop, up to the second resampling."""
    spec = dgan.InputSpec(0.4, 8, 12, ("pedestrian",), map=dgan.MapSpec(32, 31, 0.5, 24, 15, draw_agents=False))
    frame = zara1_frame.with_map(dgan.scene_map("zara1"))
    x = dgan.preprocess(frame, spec)
    centre = x["origin"].mean(axis=0)
    scene = dgan.scene_raster(frame, spec, 160, centre, np.pi / 2 + 0.4)
    assert scene.shape == (3, 160, 160)
    assert scene.dtype == np.float32
    assert scene.min() >= 0.0
    assert scene.max() <= 1.0
    assert scene.std() > 0.05
    grid = dgan.crop_grid(x["origin"], x["heading"], spec, 1, 160, centre, np.pi / 2 + 0.4)
    assert grid.shape == (len(frame), 32, 31, 2)
    assert grid.dtype == np.float32
    # Sharp mask edges resampled twice: 0.011-0.035 an agent here; the grid mirrored reads 0.10-0.36.
    for i in range(len(frame)):
        err = np.abs(_bilinear(scene, grid[i]) - x["map"][i]).mean()
        mirrored = np.abs(_bilinear(scene, grid[i][:, ::-1]) - x["map"][i]).mean()
        assert err < 0.05, (i, err)
        assert mirrored > 2 * err, (i, err, mirrored)
    coarse = dgan.crop_grid(x["origin"], x["heading"], spec, 4, 160, centre, np.pi / 2 + 0.4)
    assert coarse.shape == (len(frame), 8, 8, 2)
    # Blocks of 4: rows from the top (centres at 2, 6, ..), columns centred on the agent's (1.5, 5.5, .., 29.5).
    np.testing.assert_allclose(coarse, (grid[:, 1::4, 1::4] + grid[:, 2::4, 1::4]) / 2, atol=1e-5)


def test_scene_raster_and_crop_grid_refuse_bad_input(zara1_frame: dgan.Frame) -> None:
    spec = dgan.InputSpec(0.4, 8, 12, ("pedestrian",), map=dgan.MapSpec(32, 31, 0.5, 24, 15))
    one = (np.zeros((1, 2)), np.zeros(1))
    with pytest.raises(exc.InvalidSpecError, match="no map"):
        dgan.scene_raster(zara1_frame, SPEC, 64, (0, 0), 0.0)
    with pytest.raises(exc.InvalidSpecError, match="pixels a side"):
        dgan.scene_raster(zara1_frame, spec, 4096, (0, 0), 0.0)
    with pytest.raises(exc.InvalidSpecError, match="size_px must be a positive int"):
        dgan.scene_raster(zara1_frame, spec, 0, (0, 0), 0.0)
    with pytest.raises(exc.InvalidFrameError, match="finite"):
        dgan.scene_raster(zara1_frame, spec, 64, (np.nan, 0), 0.0)
    with pytest.raises(exc.InvalidFrameError, match="two numbers"):
        dgan.crop_grid(*one, spec, 4, 64, (0, 0, 0), 0.0)
    with pytest.raises(exc.InvalidFrameError, match="must be \\(N, 2\\)"):
        dgan.crop_grid(np.zeros((2, 3)), np.zeros(2), spec, 4, 64, (0, 0), 0.0)
    with pytest.raises(exc.InvalidFrameError, match="finite"):
        dgan.crop_grid(np.full((1, 2), np.inf), np.zeros(1), spec, 4, 64, (0, 0), 0.0)
    with pytest.raises(exc.InvalidSpecError, match="stride"):
        dgan.crop_grid(*one, spec, 40, 64, (0, 0), 0.0)
    with pytest.raises(exc.InvalidSpecError, match="stride must be a positive int"):
        dgan.crop_grid(*one, spec, True, 64, (0, 0), 0.0)


def test_a_scene_models_grid_is_the_engines(zara1_frame: dgan.Frame) -> None:
    """``MapSpec.scene_grid``: the blocks whose reads the engine gives each agent (zara1: 32 × 31 px in 4 px blocks);
    None for a crop model."""
    spec = dgan.Predictor("zara1").spec
    assert spec.map is not None
    assert spec.map.scene_grid == (8, 8)
    assert dgan.preprocess(zara1_frame, spec)["map_index"].shape[1] == 8 * 8 * 4
    assert dgan.MapSpec().scene_grid is None


def test_still_agents_are_the_engines_still_histories_and_refuse_bad_input(zara1_frame: dgan.Frame) -> None:
    spec = dgan.Predictor("zara1").spec
    still = np.broadcast_to(zara1_frame.positions[0, -1], (1, spec.t_obs, 2))
    frame = dgan.Frame(
        np.concatenate([zara1_frame.positions, still]), mask=np.concatenate([zara1_frame.mask, [[True] * spec.t_obs]])
    )
    x = dgan.preprocess(frame, spec)
    held = dgan.still_agents(x["trajectory"], x["trajectory_mask"], x["state"], [0.05])
    assert held.dtype == np.bool_
    assert held[-1]
    assert not held[:-1].all()
    assert not dgan.still_agents(x["trajectory"], x["trajectory_mask"], x["state"], [0.0]).any()
    assert dgan.still_agents(x["trajectory"], x["trajectory_mask"], x["state"], []).shape == (0,)
    for radius, says in [([0.05, 0.05], "state \\(N, 9\\)"), ([float("nan")], "finite"), ([-1.0], "not negative")]:
        with pytest.raises(exc.InvalidSpecError, match=says):
            dgan.still_agents(x["trajectory"], x["trajectory_mask"], x["state"], radius)
