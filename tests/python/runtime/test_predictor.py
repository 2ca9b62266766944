"""dgan.Predictor: end-to-end against an independent numpy computation, and every way a model can be wrong."""

from __future__ import annotations

import os
import threading
import warnings
from pathlib import Path

import numpy as np
import pytest
import reference
from make_fixtures import reference_outputs

import dgan
from dgan import exceptions as exc

FIXTURES = Path(__file__).resolve().parents[2] / "fixtures"


def mixed_frame() -> tuple[np.ndarray, np.ndarray, list[str]]:
    rng = np.random.default_rng(4)
    n = 12
    start = rng.uniform(-15, 15, (n, 2))
    vel = rng.uniform(-4, 4, (n, 2))
    t = np.arange(8)[None, :, None] * 0.4
    positions = start[:, None] + vel[:, None] * t + 0.3 * rng.normal(size=(n, 8, 2)) * t
    mask = np.ones((n, 8), dtype=bool)
    mask[3, :4] = False
    mask[7, ::2] = False
    mask[9, :7] = False  # a single observation
    classes = [dgan.CLASSES[i % 3] for i in range(n)]
    return positions, mask, classes


def test_predict_equals_an_independent_numpy_decode(nomap_model: Path, zara1_frame: dgan.Frame) -> None:
    predictor = dgan.Predictor(nomap_model)
    positions, mask, classes = mixed_frame()
    frames = [
        (dgan.Frame(positions, mask=mask, classes=classes), positions, mask, classes),
        (zara1_frame, zara1_frame.positions, zara1_frame.mask, zara1_frame.classes),
    ]
    for frame, pos, m, cls in frames:
        ref_in = reference.preprocess(pos, m, cls, predictor.contract)
        outputs = reference_outputs(ref_in, with_map=False)
        want = reference.decode(outputs, predictor.contract, ref_in["origin"], ref_in["heading"])
        got = predictor.predict(frame)
        assert got.trajectories.shape == (len(frame), 7, 12, 2)
        np.testing.assert_allclose(got.probabilities, want["probabilities"], atol=1e-5)
        np.testing.assert_allclose(got.trajectories, want["trajectories"], atol=1e-4)
        np.testing.assert_array_equal(got.edges, ref_in["edges"])
        np.testing.assert_array_equal(got.agent_ids, frame.ids)


def test_engine_inputs_equal_the_reference(nomap_model: Path) -> None:
    predictor = dgan.Predictor(nomap_model)
    positions, mask, classes = mixed_frame()
    got = dgan.preprocess(dgan.Frame(positions, mask=mask, classes=classes), predictor.spec)
    want = reference.preprocess(positions, mask, classes, predictor.contract)
    for key in ("trajectory", "trajectory_mask", "state", "edge_features", "origin", "heading"):
        np.testing.assert_allclose(got[key], want[key], atol=1e-5, err_msg=key)
    np.testing.assert_array_equal(got["edge_index"], want["edge_index"])


def test_a_denoising_spec_equals_the_reference(nomap_model: Path) -> None:
    # Contract 10: the engine's inputs from the denoised histories, against numpy's least-squares parabolas.
    from dataclasses import replace

    predictor = dgan.Predictor(nomap_model)
    positions, mask, classes = mixed_frame()
    frame = dgan.Frame(positions, mask=mask, classes=classes)
    spec = replace(predictor.spec, denoise_gate_m=0.1)
    got = dgan.preprocess(frame, spec)
    want = reference.preprocess(positions, mask, classes, {**predictor.contract, "denoise_gate_m": 0.1})
    smoothed = reference.denoise(positions, mask, 0.1)
    changed = np.any(np.abs(smoothed - positions) > 1e-9, axis=(1, 2))
    assert 0 < changed.sum() < len(positions), changed  # some agents smoothed, some kept
    for key in ("trajectory", "trajectory_mask", "state", "edge_features", "origin", "heading"):
        np.testing.assert_allclose(got[key], want[key], atol=1e-5, err_msg=key)
    np.testing.assert_array_equal(got["edge_index"], want["edge_index"])
    as_frame = dgan.preprocess(frame.denoised(0.1), predictor.spec)
    for key in ("trajectory", "state", "edge_features", "prior"):
        np.testing.assert_array_equal(got[key], as_frame[key], err_msg=key)


def test_a_bundled_model_with_a_gate_predicts_from_the_denoised_frame(zara1_frame: dgan.Frame) -> None:
    # zara1 declares denoise_gate_m (contract 10): a noisy frame predicts as its denoised copy does, whose tracks now
    # lie on their parabolas (so the engine's own pass leaves them), and unlike the noisy histories taken as given.
    predictor = dgan.Predictor("zara1")
    rng = np.random.default_rng(5)
    noisy = dgan.Frame(
        zara1_frame.positions + rng.normal(0.0, 0.15, zara1_frame.positions.shape),
        mask=zara1_frame.mask,
        classes=zara1_frame.classes,
        map=zara1_frame.map,
    )
    got = predictor.predict(noisy)
    smoothed = predictor.predict(noisy.denoised(predictor.spec.denoise_gate_m))
    np.testing.assert_allclose(got.trajectories, smoothed.trajectories, atol=1e-5)
    from dataclasses import replace

    as_given = dgan.preprocess(noisy, replace(predictor.spec, denoise_gate_m=0.0))
    assert np.abs(dgan.preprocess(noisy, predictor.spec)["trajectory"] - as_given["trajectory"]).max() > 0.05


def test_map_model_uses_the_engine_raster(map_model: Path) -> None:
    predictor = dgan.Predictor(map_model)
    positions, mask, classes = mixed_frame()
    vmap = dgan.VectorMap([("lane_centerline", [[-50, 0], [50, 0]]), ("crosswalk", [[0, -5], [3, -5], [3, 5], [0, 5]])])
    frame = dgan.Frame(positions, mask=mask, classes=classes, map=vmap)
    inputs = dgan.preprocess(frame, predictor.spec)
    assert inputs["map"].shape == (12, 3, 16, 16)
    assert inputs["map"].max() > 0.5
    outputs = reference_outputs(inputs, with_map=True)
    want = reference.decode(outputs, predictor.contract, inputs["origin"], inputs["heading"])
    got = predictor.predict(frame)
    np.testing.assert_allclose(got.trajectories, want["trajectories"], atol=1e-4)


def test_modes_are_sorted_and_truncated(nomap_model: Path, zara1_frame: dgan.Frame) -> None:
    predictor = dgan.Predictor(nomap_model, modes=3)
    top3 = predictor.predict(zara1_frame)
    assert top3.trajectories.shape == (len(zara1_frame), 3, 12, 2)
    assert np.all(np.diff(top3.probabilities, axis=1) <= 0)
    full = predictor.predict(zara1_frame, modes=7)
    np.testing.assert_allclose(full.probabilities.sum(axis=1), 1.0, atol=1e-9)
    np.testing.assert_allclose(full.class_probabilities.sum(axis=1), 1.0, atol=1e-9)
    np.testing.assert_array_equal(full.trajectories[:, :3], top3.trajectories)
    np.testing.assert_array_equal(full.most_likely, full.trajectories[:, 0])
    assert full.classes == dgan.CLASSES
    with pytest.raises(exc.InvalidSpecError, match="modes"):
        predictor.predict(zara1_frame, modes=0)
    with pytest.raises(exc.InvalidSpecError, match="modes"):
        dgan.Predictor(nomap_model, modes=8)
    # Issue 28: modes of the wrong type are refused where they are given, not at the first predict.
    for bad in (2.5, "3", True, None.__class__):
        with pytest.raises(exc.InvalidSpecError, match="whole number"):
            dgan.Predictor(nomap_model, modes=bad)  # type: ignore[arg-type]
        with pytest.raises(exc.InvalidSpecError, match="whole number"):
            predictor.predict(zara1_frame, modes=bad)  # type: ignore[arg-type]
    two_modes = dgan.Predictor(nomap_model, modes=np.int64(2))  # type: ignore[arg-type]
    assert two_modes.predict(zara1_frame).trajectories.shape[1] == 2


def test_empty_scene_returns_an_empty_prediction(map_model: Path) -> None:
    p = dgan.Predictor(map_model).predict(dgan.Frame(np.zeros((0, 8, 2))))
    assert len(p) == 0
    assert p.trajectories.shape == (0, 7, 12, 2)
    assert p.edges.shape == (0, 2)


def test_frame_that_does_not_fit_the_model(nomap_model: Path) -> None:
    predictor = dgan.Predictor(nomap_model)
    with pytest.raises(exc.InvalidFrameError, match="T_obs = 8"):
        predictor.predict(dgan.Frame(np.zeros((2, 5, 2))))


@pytest.mark.parametrize(
    ("name", "error", "match"),
    [
        ("does_not_exist.onnx", exc.ModelNotFoundError, "not found"),
        ("bad_truncated.onnx", exc.ModelLoadError, "cannot load model"),
        ("make_fixtures.py", exc.ModelLoadError, "cannot load model"),
        ("bad_no_metadata.onnx", exc.ContractError, 'no "dgan_contract" metadata'),
        ("bad_metadata_json.onnx", exc.ContractError, "not a valid contract"),
        ("bad_contract_version.onnx", exc.ContractError, "contract_version 99"),
        ("bad_fixed_agent_axis.onnx", exc.ContractError, "must be dynamic"),
        ("bad_anchor_count.onnx", exc.ContractError, "anchor_logits"),
        ("bad_missing_input.onnx", exc.ContractError, 'missing input "edge_features"'),
        ("bad_map_without_input.onnx", exc.ContractError, 'missing input "map"'),
    ],
)
def test_bad_models_fail_at_load(name: str, error: type[Exception], match: str) -> None:
    with pytest.raises(error, match=match):
        dgan.Predictor(FIXTURES / name)


def test_model_errors_are_builtin_subclasses() -> None:
    with pytest.raises(FileNotFoundError):
        dgan.Predictor(FIXTURES / "nope.onnx")
    with pytest.raises(ValueError, match="contract"):
        dgan.Predictor(FIXTURES / "bad_no_metadata.onnx")


@pytest.mark.parametrize("sessions", [1, 3])
def test_threads_share_one_predictor(nomap_model: Path, zara1_frame: dgan.Frame, sessions: int) -> None:
    # Eight threads, several sessions: every result bit-identical to the serial one.
    predictor = dgan.Predictor(nomap_model, sessions=sessions)
    assert predictor.sessions == sessions
    want = predictor.predict(zara1_frame).trajectories
    results: list[np.ndarray] = []
    errors: list[BaseException] = []

    def work() -> None:
        try:
            for _ in range(20):
                results.append(predictor.predict(zara1_frame).trajectories)
        except BaseException as e:  # pragma: no cover - reported below
            errors.append(e)

    threads = [threading.Thread(target=work) for _ in range(8)]
    for t in threads:
        t.start()
    for t in threads:
        t.join()
    assert not errors
    assert len(results) == 160
    for r in results:
        np.testing.assert_array_equal(r, want)


def test_session_count_is_checked(nomap_model: Path) -> None:
    with pytest.raises(exc.InvalidSpecError, match=r"sessions must be a positive integer, got 0"):
        dgan.Predictor(nomap_model, sessions=0)
    with pytest.raises(exc.InvalidSpecError, match=r"sessions must be in 1\.\.=64, got 65"):  # the engine's range
        dgan.Predictor(nomap_model, sessions=65)
    assert dgan.Predictor(nomap_model).sessions >= 1


def test_contract_is_exposed(nomap_model: Path) -> None:
    predictor = dgan.Predictor(nomap_model)
    assert predictor.spec.t_obs == 8
    assert predictor.spec.t_f == 12
    assert predictor.spec.map is None
    assert {k: v.shape for k, v in predictor.anchors.items()} == {
        "vehicle": (3, 12, 2),
        "cyclist": (2, 12, 2),
        "pedestrian": (2, 12, 2),
    }
    assert "contract-fixture" in repr(predictor.contract["name"])


def test_a_required_map_is_a_typed_error_that_names_the_fix(map_model: Path, zara1_frame: dgan.Frame) -> None:
    # A contract-1 map model cannot run without a map: never a silent black crop.
    predictor = dgan.Predictor(map_model)
    assert not predictor.spec.map.optional  # type: ignore[union-attr]
    with pytest.raises(exc.MapRequiredError, match=r"pass the scene's map") as info:
        predictor.predict(zara1_frame)
    assert isinstance(info.value, exc.InvalidFrameError)
    assert isinstance(info.value, ValueError)


def test_bundled_map_models_also_serve_frames_without_a_map(zara1_frame: dgan.Frame) -> None:
    predictor = dgan.Predictor("zara1")
    spec = predictor.spec
    assert spec.map is not None
    assert spec.map.optional
    with_map = dgan.Frame(zara1_frame.positions, mask=zara1_frame.mask, map=dgan.scene_map("zara1"))
    x = dgan.preprocess(with_map, spec)
    assert x["map_present"].tolist() == [1.0] * len(with_map)
    blank = dgan.preprocess(with_map.without_map(), spec)
    assert blank["map_present"].tolist() == [0.0] * len(with_map)
    assert not blank["map"].any()
    a, b = predictor.predict(with_map), predictor.predict(with_map.without_map())
    assert a.trajectories.shape == b.trajectories.shape
    assert not np.allclose(a.trajectories, b.trajectories)  # the map is used when it is there


def test_the_prior_and_temperature_are_declared(zara1_frame: dgan.Frame) -> None:
    predictor = dgan.Predictor("zara1")
    c = predictor.contract
    assert dgan._dgan.CONTRACT_VERSION == 16
    assert c["contract_version"] == 13  # the scene's features kept with the map (map.scene.tile_px)
    assert c["denoise_gate_m"] == predictor.spec.denoise_gate_m == 0.1
    assert c["graph"] == "padded"
    assert c["prior"]["kind"] == "constant_velocity"
    assert 0.001 <= c["temperature"] <= 1000
    # The engine's prior is constant velocity along the direction of motion: v · t · dt in the agent frame.
    x = dgan.preprocess(zara1_frame.without_map(), predictor.spec)
    speed, cos, sin = x["state"][:, 0], x["state"][:, 3], x["state"][:, 4]
    t = np.arange(1, 13) * 0.4
    want = np.stack([np.outer(speed * cos, t), np.outer(speed * sin, t)], axis=-1)
    np.testing.assert_allclose(x["prior"], want, rtol=1e-5, atol=1e-5)
    np.testing.assert_allclose(
        dgan.kinematic_prior(x["trajectory"], x["trajectory_mask"], x["state"], predictor.spec), x["prior"]
    )


def test_predict_batch_equals_predict_per_frame() -> None:
    from dgan.demo import scene_for

    for name in ("zara1", "apolloscape"):
        predictor = dgan.Predictor(name)
        first = scene_for(predictor.spec)
        # 5 real frames of up to 26 agents, three times over: more than one network call (256 agents at most), an
        # empty frame among them and a frame of 300 agents that runs alone.
        frames = [scene_for(predictor.spec, first.default_now + k * first.time_step).frame for k in range(5)] * 3
        frames.insert(2, dgan.Frame(np.zeros((0, predictor.spec.t_obs, 2))))
        big = np.cumsum(np.full((300, predictor.spec.t_obs, 2), 0.3), axis=1) + np.arange(300)[:, None, None] * 7.0
        frames.insert(9, dgan.Frame(big, map=frames[0].map))
        assert sum(len(f) for f in frames) > 2 * 256
        batch = predictor.predict_batch(frames, modes=5)
        assert len(batch) == len(frames)
        for frame, got in zip(frames, batch, strict=True):
            want = predictor.predict(frame, modes=5)
            assert got.agent_ids.tolist() == want.agent_ids.tolist()
            np.testing.assert_allclose(got.trajectories, want.trajectories, atol=1e-5)
            np.testing.assert_allclose(got.probabilities, want.probabilities, atol=1e-5)
            np.testing.assert_array_equal(got.edges, want.edges)
    assert dgan.Predictor("zara1").predict_batch([]) == []
    with pytest.raises(exc.InvalidFrameError):
        dgan.Predictor("zara1").predict_batch([dgan.Frame(np.zeros((2, 3, 2)))])


def test_the_crops_memory_kept_between_calls_leaves_nothing_behind() -> None:
    """A Predictor draws a call's map crops into the memory of the last call's: larger, smaller, empty and map-less
    frames in turn give what a fresh Predictor gives, bit for bit."""
    from dgan.demo import scene_for

    predictor = dgan.Predictor("zara1")
    scene = scene_for(predictor.spec)
    small = [scene_for(predictor.spec, scene.default_now + k * scene.time_step).frame for k in range(3)]
    big = np.cumsum(np.full((300, predictor.spec.t_obs, 2), 0.3), axis=1) + np.arange(300)[:, None, None] * 7.0
    empty = dgan.Frame(np.zeros((0, predictor.spec.t_obs, 2)), map=small[0].map)
    unmapped = dgan.Frame(small[1].positions)
    frames = [dgan.Frame(big, map=small[0].map), small[0], empty, small[1], unmapped, small[2], small[0]]
    for frame in frames:
        got = predictor.predict(frame)
        want = dgan.Predictor("zara1").predict(frame)
        np.testing.assert_array_equal(got.trajectories, want.trajectories)
        np.testing.assert_array_equal(got.probabilities, want.probabilities)


def test_last_timings_split_each_call_into_its_phases() -> None:
    from dgan.demo import scene_for

    keys = {"preprocess", "crops", "network", "decode", "parts", "total"}
    for name, threads in (("zara1", 1), ("apolloscape", 1), ("hdmap", 2)):
        predictor = dgan.Predictor(name, threads=threads)
        assert predictor.last_timings is None
        frame = scene_for(predictor.spec).frame
        predictor.predict_batch([frame])
        assert predictor.last_timings is None, "predict_batch is not timed"
        predictor.predict(frame)
        t = predictor.last_timings
        assert t is not None
        assert set(t) == keys
        assert all(v >= 0.0 for v in t.values())
        phases = sum(v for k, v in t.items() if k != "total")
        assert t["total"] > 0.0
        assert 0.9 * t["total"] <= phases <= t["total"] + 1e-3, t
        drawn = predictor.spec.map is not None and t["parts"] == 0.0
        assert (t["crops"] > 0.0) == drawn, t
        assert t["network"] > 0.0 or t["parts"] > 0.0, t
    # The latest call's: an empty frame then a real one.
    predictor = dgan.Predictor("zara1")
    predictor.predict(dgan.Frame(np.zeros((0, predictor.spec.t_obs, 2))))
    empty = predictor.last_timings
    assert empty is not None
    assert empty["network"] == 0.0
    predictor.predict(scene_for(predictor.spec).frame)
    latest = predictor.last_timings
    assert latest is not None
    assert latest["network"] > 0.0


@pytest.mark.skipif((os.cpu_count() or 1) < 2, reason="threads=2 needs two cores")
def test_two_threads_split_frames_and_batches_with_the_one_thread_results() -> None:
    from dgan.demo import scene_for

    for name in ("hdmap", "zara1"):
        one, two = dgan.Predictor(name), dgan.Predictor(name, threads=2)
        assert (one.lanes, two.lanes) == (0, 2)
        first = scene_for(one.spec)
        frames = [scene_for(one.spec, first.default_now + k * first.time_step).frame for k in range(4)]
        # The real scene twice, 2 km apart: two components that share out evenly, so the frame runs as two calls.
        base = frames[0]
        doubled = dgan.Frame(
            np.concatenate([base.positions, base.positions + 2000.0]),
            mask=np.concatenate([base.mask, base.mask]),
            classes=list(base.classes) * 2,
            headings=None if base.headings is None else np.concatenate([base.headings, base.headings]),
            lengths=None if base.lengths is None else np.concatenate([base.lengths, base.lengths]),
            widths=None if base.widths is None else np.concatenate([base.widths, base.widths]),
            map=base.map,
        )
        # 160 walkers 1 m apart near the scene's agents: one component, one call on two intra-op threads, its
        # decoding shared over both (from 128 agents).
        grid = np.stack(np.meshgrid(np.arange(16.0), np.arange(10.0)), axis=-1).reshape(-1, 1, 2)
        steps = np.arange(one.spec.t_obs)[None, :, None] * np.array([0.5, 0.1]) * one.spec.dt_s
        crowd = dgan.Frame(base.positions[:, -1].mean(axis=0) + grid + steps, map=base.map)
        for frame in [*frames, doubled, doubled.without_map(), crowd]:
            want, got = one.predict(frame), two.predict(frame)
            if frame is doubled:  # two parts, each drawing (or, zara1, reading the kept tiles of) its own agents
                assert (two.last_timings or {}).get("parts", 0.0) > 0.0
            np.testing.assert_allclose(got.trajectories, want.trajectories, atol=1e-5)
            np.testing.assert_allclose(got.probabilities, want.probabilities, atol=1e-6)
            np.testing.assert_array_equal(got.edges, want.edges)
            np.testing.assert_array_equal(got.mode_classes, want.mode_classes)
        batch = two.predict_batch([*frames, doubled] * 3, modes=4)
        for frame, got in zip([*frames, doubled] * 3, batch, strict=True):
            np.testing.assert_allclose(got.trajectories, one.predict(frame, modes=4).trajectories, atol=1e-5)


def test_a_still_cyclist_is_held_at_its_prior_on_every_path() -> None:
    """Contract 15: `hdmap` holds a cyclist whose history stays within 0.02 m: its most probable mode is its kinematic
    prior in predict, on two threads (a frame split in two calls) and in predict_batch; no other agent is held."""
    from dgan.demo import scene_for

    one, two = dgan.Predictor("hdmap"), dgan.Predictor("hdmap", threads=2)
    assert one.contract["still_radius_m"] == {"cyclist": 0.02, "pedestrian": 0.02}
    radii = [one.contract["still_radius_m"].get(c, 0.0) for c in one.classes]
    base = scene_for(one.spec).frame
    history = np.broadcast_to(base.positions[0, -1] + 3.0, (1, one.spec.t_obs, 2)).copy()
    history[0, ::2, 0] += 0.005  # jitter within the radius
    still = dgan.Frame(
        np.concatenate([base.positions, history]),
        mask=np.concatenate([base.mask, np.ones((1, one.spec.t_obs), bool)]),
        classes=[*base.classes, "cyclist"],
        map=base.map,
    )
    doubled = dgan.Frame(
        np.concatenate([still.positions, still.positions + 2000.0]),
        mask=np.concatenate([still.mask, still.mask]),
        classes=list(still.classes) * 2,
        map=still.map,
    )

    def held_at_prior(frame: dgan.Frame, got: dgan.Prediction) -> None:
        x = dgan.preprocess(frame, one.spec)
        held = dgan.still_agents(x["trajectory"], x["trajectory_mask"], x["state"], radii)
        assert held.sum() == len(frame) // len(still)  # the added cyclist (twice in the doubled frame)
        prior = dgan.to_world_frame(x["prior"].astype(np.float64), x["origin"], x["heading"])
        np.testing.assert_allclose(got.trajectories[held, 0], prior[held], atol=1e-5)
        assert np.abs(got.trajectories[~held, 0] - prior[~held]).max() > 0.01  # the others keep the network's

    held_at_prior(still, one.predict(still))
    held_at_prior(doubled, two.predict(doubled))
    assert (two.last_timings or {}).get("parts", 0.0) > 0.0
    held_at_prior(still, one.predict_batch([base, still])[1])


def test_execution_providers_and_thread_bounds(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    assert dgan.available_execution_providers()[0] == "cpu"
    assert dgan.Predictor("zara1", execution_provider="CPU").num_modes > 0
    if "cuda" not in dgan.available_execution_providers():
        # The CPU wheel's library has no CUDA: refused at load with the fix, never a silent fall-back to the CPU.
        fix = r"CUDA execution provider .* install onnxruntime-gpu.*LD_LIBRARY_PATH"
        with pytest.raises(exc.RuntimeLibraryError, match=fix):
            dgan.Predictor("zara1", execution_provider="cuda:0")
    for bad in ("tpu", "cuda:-1", "cuda:x", ""):
        with pytest.raises(exc.InvalidSpecError, match="execution provider"):
            dgan.Predictor("zara1", execution_provider=bad)
    cores = os.cpu_count() or 1
    for threads in (0, 2**31 + 1, True, 1.5):
        with pytest.raises(exc.InvalidSpecError, match="threads must be a positive integer"):
            dgan.Predictor("zara1", threads=threads)  # type: ignore[arg-type]
    for threads in (cores + 1, 100_000, 2**31):
        with pytest.raises(exc.InvalidSpecError, match=rf"threads must be in 1\.\.={cores} \(this machine's cores\)"):
            dgan.Predictor("zara1", threads=threads)
    for sessions in (0, 65, 2**31):
        with pytest.raises(exc.InvalidSpecError, match="sessions"):
            dgan.Predictor("zara1", sessions=sessions)
    with pytest.raises(exc.ModelNotFoundError, match="path or a bundled model"):
        dgan.Predictor(None)  # type: ignore[arg-type]
    # A folder in the working directory named like a bundled model does not shadow it.
    (tmp_path / "sdd").mkdir()
    monkeypatch.chdir(tmp_path)
    assert dgan.Predictor("sdd").path.name == "sdd.onnx"


def test_eight_threads_with_maps_are_bit_identical_to_serial(zara1_frame: dgan.Frame) -> None:
    # A map model: concurrent predictions share the cores for drawing crops differently, the crops stay the same.
    predictor = dgan.Predictor("zara1", sessions=2)
    frame = zara1_frame.with_map(dgan.scene_map("zara1"))
    want = predictor.predict(frame)
    results: list[dgan.Prediction] = []

    def work() -> None:
        for _ in range(10):
            results.append(predictor.predict(frame))

    threads = [threading.Thread(target=work) for _ in range(8)]
    for t in threads:
        t.start()
    for t in threads:
        t.join()
    assert len(results) == 80
    for r in results:
        np.testing.assert_array_equal(r.trajectories, want.trajectories)
        np.testing.assert_array_equal(r.probabilities, want.probabilities)


def test_headings_in_another_convention_are_warned_about_once() -> None:
    from dgan.demo import scene_for

    predictor = dgan.Predictor("hdmap")
    frame = scene_for(predictor.spec).frame  # real Waymo headings, radians along the motion

    def with_headings(h: np.ndarray) -> dgan.Frame:
        return dgan.Frame(
            frame.positions,
            mask=frame.mask,
            classes=list(frame.classes),
            headings=h,
            lengths=frame.lengths,
            widths=frame.widths,
            map=frame.map,
            dt=frame.dt,
        )

    with warnings.catch_warnings():
        warnings.simplefilter("error")
        predictor.predict(frame)
        predictor.predict(frame.without_map())
        dgan.Predictor("apolloscape").predict(scene_for(dgan.Predictor("apolloscape").spec).frame)
    # Radians unwrapped past 2π (as some logs store them) still follow the motion: no warning.
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        dgan.Predictor("hdmap").predict(with_headings(frame.headings + 4 * np.pi))
    # ... also when only one agent moves (issue 28: "disagree by 0°, some exceed 2π" was a false warning). A
    # parked car and a driving one, headings unwrapped by +2π:
    t = np.arange(10)[:, None] * 0.2
    two = np.stack([np.hstack([t * 3.0, 0 * t]), np.full((10, 2), [0.0, 20.0])])
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        dgan.Predictor("hdmap").predict(dgan.Frame(two, headings=[2 * np.pi, 8.95], classes=["vehicle"] * 2))
    # ... and when nobody moves, as at a quiet moment of a Waymo log (radians unwrapped up to 10.5): no warning, but
    # headings beyond 6π there are named as likely degrees.
    parked = np.stack([np.full((10, 2), [0.0, 0.0]), np.full((10, 2), [0.0, 20.0])])
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        dgan.Predictor("hdmap").predict(dgan.Frame(parked, headings=[10.52, 7.9], classes=["vehicle"] * 2))
    with pytest.warns(exc.HeadingWarning, match=r"reach 90, beyond radians unwrapped by three turns .* \(0\)"):
        dgan.Predictor("hdmap").predict(dgan.Frame(parked, headings=[90.0, 7.9], classes=["vehicle"] * 2))
    for bad in (np.degrees(frame.headings), frame.headings + np.pi):
        fresh = dgan.Predictor("hdmap")
        with pytest.warns(exc.HeadingWarning, match="disagree with its agents' direction of motion"):
            fresh.predict(with_headings(bad))
        with warnings.catch_warnings():
            warnings.simplefilter("error")  # once per predictor
            fresh.predict_batch([with_headings(bad)] * 2)
    # A model that takes headings from the motion ignores them, and says nothing.
    apollo = dgan.Predictor("apolloscape")
    f = scene_for(apollo.spec).frame
    reversed_frame = dgan.Frame(f.positions, mask=f.mask, classes=list(f.classes), headings=f.headings + np.pi, dt=f.dt)
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        a = apollo.predict(reversed_frame)
    b = apollo.predict(dgan.Frame(f.positions, mask=f.mask, classes=list(f.classes), dt=f.dt))
    np.testing.assert_allclose(a.trajectories, b.trajectories, atol=1e-5)


def test_a_prediction_crosses_from_the_engine_typed_with_its_heading_check() -> None:
    """The engine returns a typed ``_dgan.Prediction`` and checks the headings within the same call: no second
    call across the FFI re-derives the states (the bindings offer no separate heading check)."""
    from dgan.demo import scene_for

    predictor = dgan.Predictor("hdmap", sessions=1)
    frame = scene_for(predictor.spec).frame
    native = predictor._predictor.predict(frame._frame, 3, True)
    assert isinstance(native, dgan._dgan.Prediction)
    assert native.trajectories.shape[:2] == (len(frame), 3)
    assert native.headings is not None
    assert native.headings[4]  # enough agents move to judge the headings by the motion
    assert not native.headings[5]  # and real headings agree with it
    assert predictor._predictor.predict(frame._frame, 3).headings is None  # not asked
    degrees = dgan.Frame(
        frame.positions,
        mask=frame.mask,
        classes=list(frame.classes),
        headings=np.degrees(frame.headings),
        map=frame.map,
        dt=frame.dt,
    )

    assert not hasattr(dgan._dgan, "check_headings")
    with pytest.warns(exc.HeadingWarning):
        predictor.predict(degrees)
    with pytest.warns(exc.HeadingWarning):
        dgan.Predictor("hdmap", sessions=1).predict_batch([frame, degrees])


def test_speeds_too_fast_for_metres_are_warned_about_once() -> None:
    """The bundled zara1 scene in pixels (30 to the metre, an ETH/UCY camera's order) makes every walker implausibly
    fast in metres: a UnitWarning naming the class and the median, once per predictor; in metres, none. The engine
    checks within the same call and returns its verdict typed."""
    from dgan.demo import scene_for

    predictor = dgan.Predictor("zara1", sessions=1)
    frame = scene_for(predictor.spec).frame.without_map()
    pixels = dgan.Frame(frame.positions * 30.0, mask=frame.mask, classes=list(frame.classes), dt=frame.dt)
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        predictor.predict(frame)
        predictor.predict_batch([frame, frame])
    native = predictor._predictor.predict(frame._frame, 3, False, True)
    assert native.speeds is not None
    cls, moving, median, bound, implausible = native.speeds
    assert (cls, bound, implausible) == ("pedestrian", 6.0, False)
    assert moving >= 3
    assert 0.5 < median < 2.0  # walkers, in metres a second
    assert predictor._predictor.predict(frame._frame, 3).speeds is None  # not asked
    in_pixels = predictor._predictor.predict(pixels._frame, 3, False, True).speeds
    assert in_pixels is not None
    assert in_pixels[4]
    with pytest.warns(exc.UnitWarning, match=r"moving pedestrian agents go at a median \d+(\.\d+)? units a second"):
        predictor.predict(pixels)
    with warnings.catch_warnings():
        warnings.simplefilter("error")  # once per predictor
        predictor.predict(pixels)
        predictor.predict_batch([pixels])
    with pytest.warns(exc.UnitWarning, match="beyond the 6 m/s that pedestrian agents reach"):
        dgan.Predictor("zara1", sessions=1).predict_batch([frame, pixels])


def test_predictor_frame_and_prediction_pickle(tmp_path: Path) -> None:
    import pickle

    p = dgan.Predictor("hdmap", modes=3, sessions=1)
    vm = dgan.VectorMap([("lane_centerline", [[0.0, 0.0], [30.0, 0.0]]), ("crosswalk", [[5, -3], [8, -3], [8, 3]])])
    frame = dgan.Frame(
        np.cumsum(np.full((3, 10, 2), 0.5), axis=1), classes=list(dgan.CLASSES), ids=["car", 7, "p"]
    ).with_map(vm)
    pred = p.predict(frame)
    q, f2, pred2 = (pickle.loads(pickle.dumps(x)) for x in (p, frame, pred))
    assert q._options == p._options
    assert q.path == p.path
    assert q.num_modes == p.num_modes
    assert f2.agent_ids.tolist() == ["car", 7, "p"]
    assert isinstance(f2.map, dgan.VectorMap)
    assert len(f2.map) == 2
    np.testing.assert_array_equal(q.predict(f2).trajectories, pred.trajectories)
    np.testing.assert_array_equal(pred2.trajectories, pred.trajectories)
    assert pred2.agent_ids.tolist() == ["car", 7, "p"]
    local = dgan.Predictor(dgan.models.path("zara1"), sessions=1)
    assert pickle.loads(pickle.dumps(local)).path == local.path
    raster = pickle.loads(pickle.dumps(dgan.scene_map("zara1")))
    np.testing.assert_array_equal(raster.image, dgan.scene_map("zara1").image)


def test_a_failed_parquet_write_leaves_the_path_as_it_was(tmp_path: Path) -> None:
    p = dgan.Predictor("zara1", sessions=1)
    pred = p.predict(dgan.Frame(np.cumsum(np.full((2, 8, 2), 0.3), axis=1), ids=[1, "a"]), modes=1)
    kept = tmp_path / "kept.parquet"
    kept.write_bytes(b"old")
    with pytest.raises(exc.OutputError, match="mix int and str"):
        pred.to_parquet(kept)
    assert kept.read_bytes() == b"old"
    assert [x.name for x in tmp_path.iterdir()] == ["kept.parquet"]
    with pytest.raises(OSError, match="No space left"):
        p.predict(dgan.Frame(np.zeros((1, 8, 2))), modes=1).to_parquet("/dev/full")
    assert Path("/dev/full").exists()
    assert not Path("/dev/full").is_file()


def test_predict_batch_splits_what_does_not_fit_one_call_and_names_a_bad_frame() -> None:
    p = dgan.Predictor("zara1", max_input_bytes=10**6, sessions=1)
    frame = dgan.Frame(np.cumsum(np.full((30, 8, 2), 0.4), axis=1) + np.arange(30)[:, None, None] * 50)
    one = p.predict(frame)
    for out in p.predict_batch([frame] * 4):  # 120 agents joined exceed 10⁶ bytes: split, not refused
        np.testing.assert_allclose(out.trajectories, one.trajectories, atol=1e-5)
    with pytest.raises(exc.InvalidFrameError, match=r"frame 2 of the batch: expected a dgan\.Frame"):
        p.predict_batch([frame, frame, "frame"])  # type: ignore[list-item]


def test_unknown_classes_ignore_predicts_the_model_s_own() -> None:
    p = dgan.Predictor("zara1", sessions=1)
    pos = np.cumsum(np.full((3, 8, 2), 0.4), axis=1) + np.arange(3)[:, None, None]
    street = dgan.Frame(pos, classes=["pedestrian", "vehicle", "pedestrian"], ids=["a", "car", "b"])
    with pytest.raises(exc.UnknownClassError, match="unknown_classes='ignore'"):
        p.predict(street)
    with pytest.raises(exc.UnknownClassError, match=r"frame 1 of the batch.*unknown_classes='ignore'"):
        p.predict_batch([dgan.Frame(pos[[0, 2]]), street])
    pred = p.predict(street, unknown_classes="ignore")
    assert pred.agent_ids.tolist() == ["a", "b"]
    alone = p.predict(dgan.Frame(pos[[0, 2]], ids=["a", "b"]))
    np.testing.assert_array_equal(pred.trajectories, alone.trajectories)
    assert [x.agent_ids.tolist() for x in p.predict_batch([street], unknown_classes="ignore")] == [["a", "b"]]
    with pytest.raises(exc.InvalidSpecError, match="'error' or 'ignore'"):
        p.predict(street, unknown_classes="drop")
