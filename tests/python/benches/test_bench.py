"""benches/bench.py times the figures of a row in interleaved rounds, the slow ones in fewer of them, and builds the
bare sessions its option variants name."""

from __future__ import annotations

from itertools import pairwise

import numpy as np
import onnxruntime as ort  # type: ignore[import-untyped]
import pytest

import dgan
from benches.bench import SESSION_VARIANTS, bare_session, interleaved_ms
from dgan.demo import scene_for


def test_rounds_interleave_and_slow_pipelines_run_less_often() -> None:
    calls: list[str] = []
    ms = interleaved_ms(
        {"a": lambda: calls.append("a"), "b": lambda: calls.append("b"), "slow": lambda: calls.append("slow")},
        repeat=20,
        warmup=2,
        every={"slow": 5},
    )
    assert set(ms) == {"a", "b", "slow"}
    assert all(v >= 0 for v in ms.values())
    assert calls[:4] == ["a", "b", "slow", "a"]  # the slow one warmed up once
    assert calls.count("a") == calls.count("b") == 22
    timed_slow = calls.count("slow") - 1
    assert 3 <= timed_slow <= 20 // 5 + 3  # its first three timed rounds, then every fifth
    # Every round calls the fast ones in turn: never twice in a row.
    fast = [c for c in calls if c != "slow"]
    assert all(x != y for x, y in pairwise(fast))


def test_each_session_variant_sets_what_it_names_beside_one_thread() -> None:
    path = dgan.Predictor("zara1").path
    base = bare_session(path).get_session_options()
    assert (base.intra_op_num_threads, base.inter_op_num_threads) == (1, 1)
    assert base.execution_mode == ort.ExecutionMode.ORT_SEQUENTIAL
    parallel = bare_session(path, SESSION_VARIANTS["parallel executor, two inter-op threads"]).get_session_options()
    assert parallel.execution_mode == ort.ExecutionMode.ORT_PARALLEL
    assert (parallel.intra_op_num_threads, parallel.inter_op_num_threads) == (1, 2)
    basic = bare_session(path, SESSION_VARIANTS["basic optimisations only"]).get_session_options()
    assert basic.graph_optimization_level == ort.GraphOptimizationLevel.ORT_ENABLE_BASIC
    assert bare_session(path, SESSION_VARIANTS["two intra-op threads"]).get_session_options().intra_op_num_threads == 2


@pytest.mark.parametrize("name", ["sdd", "hdmap", "apolloscape"])
def test_the_torch_pipeline_decodes_as_the_engine_does(name: str) -> None:
    """The PyTorch-eager pipeline the benchmark times does the engine's work: the same most probable modes, with the
    contract's top-mode scale, still radius and mean top mode (each of these three models declares some of them)."""
    from benches.bench import call_inputs, torch_pipeline

    pytest.importorskip("torch")
    predictor = dgan.Predictor(name)
    frame = scene_for(predictor.spec).frame
    run = torch_pipeline(name)
    assert run is not None
    x = call_inputs(predictor, frame)
    modes, p = run(x)
    n, k = modes.shape[:2]
    flat = modes.astype(np.float64).reshape(n, -1, 2)
    world = dgan.to_world_frame(flat, x["origin"], x["heading"]).reshape(n, k, -1, 2)
    got = predictor.predict(frame)
    np.testing.assert_allclose(world[:, 0], got.trajectories[:, 0], atol=1e-3)
    np.testing.assert_allclose(p, got.probabilities, atol=1e-4)
