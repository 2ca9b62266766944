"""training.ensemble and training.model.ConsensusEnsemble: the consensus of the members' most probable modes, its
export under the contract (engine–PyTorch parity) and float16 weight storage."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import onnx
import pytest
import torch
from onnx import TensorProto, helper, numpy_helper
from test_training import assert_parity, randomised_batch_norm

import dgan
from training.config import Config
from training.ensemble import ensemble_checkpoint
from training.export import export_model, load_checkpoint, store_half
from training.model import ConsensusEnsemble
from training.train import build_model, input_spec

ROOT = Path(__file__).resolve().parents[2]


def test_the_top_mode_of_the_top_class_is_the_mean_of_the_members_top_modes() -> None:
    g = torch.Generator().manual_seed(0)
    n, c, kc, t = 6, 3, 4, 6
    anchors = [torch.randn(c * kc, t, 2, generator=g) for _ in range(3)]
    outs = [
        (torch.randn(n, c, generator=g), torch.randn(n, c * kc, generator=g), torch.randn(n, c * kc, t, 2, generator=g))
        for _ in range(3)
    ]
    ens = ConsensusEnsemble([torch.nn.Identity() for _ in range(3)], anchors, c)
    cl, al, off = ens.combine(outs)
    assert torch.equal(cl, outs[0][0])  # the ranking is the first member's
    assert torch.equal(al, outs[0][1])
    for i in range(n):
        b = int(outs[0][0][i].argmax())  # the agent's most probable class
        block = slice(b * kc, (b + 1) * kc)
        tops = []
        for m, (_, a, o) in enumerate(outs):
            k = b * kc + int(a[i, block].argmax())
            tops.append(anchors[m][k] + o[i, k])
        k0 = b * kc + int(outs[0][1][i, block].argmax())
        torch.testing.assert_close(anchors[0][k0] + off[i, k0], torch.stack(tops).mean(0))
        others = [k for k in range(c * kc) if k != k0]
        assert torch.equal(off[i, others], outs[0][2][i, others])  # every other mode is the first member's


def test_members_need_the_same_anchor_layout() -> None:
    with pytest.raises(ValueError, match="same anchors per class"):
        ConsensusEnsemble([torch.nn.Identity()] * 2, [torch.zeros(6, 3, 2), torch.zeros(4, 3, 2)], 2)
    with pytest.raises(ValueError, match="one anchor set per member"):
        ConsensusEnsemble([torch.nn.Identity()] * 2, [torch.zeros(6, 3, 2)], 2)


def _members(tmp_path: Path, seeds: tuple[int, ...]) -> tuple[list[Path], dgan.InputSpec]:
    """Untrained hdmap networks saved as training runs (``best.pt``, ``config.json``), different anchors each."""
    runs = []
    spec = None
    for seed in seeds:
        torch.manual_seed(seed)
        cfg = Config.load(ROOT / "training" / "configs" / "hdmap.toml", {"train.seed": seed})
        spec = input_spec(cfg)
        kc = 3
        k = kc * len(spec.classes)
        model = randomised_batch_norm(build_model(cfg, spec, k).eval())
        rng = np.random.default_rng(seed)
        anchors = np.cumsum(rng.normal(0.4, 0.2, (k, spec.t_f, 2)), axis=1).astype(np.float32)
        run = tmp_path / f"run{seed}"
        run.mkdir()
        from dataclasses import asdict

        ckpt = {
            "model": model.state_dict(),
            "anchors": anchors,
            "class_of": np.repeat(np.arange(len(spec.classes)), kc),
            "config": asdict(cfg),
            "epoch": 0,
            "temperature": 1.2,
        }
        torch.save(ckpt, run / "best.pt")
        (run / "config.json").write_text(json.dumps({"config": asdict(cfg)}))
        runs.append(run)
    assert spec is not None
    return runs, spec


def test_a_float16_ensemble_exports_and_matches_pytorch(tmp_path: Path) -> None:
    runs, spec = _members(tmp_path, (0, 1))
    ckpt = ensemble_checkpoint(runs, tmp_path / "ensemble.pt", half=True)
    model, spec2, anchors, class_of, _, temperature = load_checkpoint(ckpt)
    assert isinstance(model, ConsensusEnsemble)
    assert len(model.members) == 2
    assert spec2.to_json() == spec.to_json()
    assert temperature == pytest.approx(1.2)
    path = export_model(model, spec, anchors, class_of, tmp_path / "e.onnx", "ensemble", temperature=temperature)
    stored = {i.data_type for i in onnx.load(str(path)).graph.initializer}
    assert TensorProto.FLOAT16 in stored
    assert_parity(model, spec, anchors, class_of, path, temperature)
    # The same two members at float32: the float16 file is much smaller.
    full = load_checkpoint(ensemble_checkpoint(runs, tmp_path / "full.pt"))
    path32 = export_model(full[0], spec, anchors, class_of, tmp_path / "f.onnx", "ensemble32")
    assert path.stat().st_size < 0.7 * path32.stat().st_size


def test_members_of_different_configurations_are_refused(tmp_path: Path) -> None:
    runs, _ = _members(tmp_path, (0,))
    other = tmp_path / "other"
    other.mkdir()
    ckpt = torch.load(runs[0] / "best.pt", weights_only=False)
    ckpt["config"]["data"]["prior_window_s"] = 1.0  # another kinematic prior: other inputs
    torch.save(ckpt, other / "best.pt")
    with pytest.raises(ValueError, match="different inputs"):
        ensemble_checkpoint([runs[0], other], tmp_path / "bad.pt")


def test_store_half_keeps_only_exact_weights(tmp_path: Path) -> None:
    exact = np.arange(32, dtype=np.float32).reshape(4, 8) / 4
    inexact = np.full((8, 4), 0.1, dtype=np.float32)
    graph = helper.make_graph(
        [helper.make_node("MatMul", ["x", "a"], ["y"]), helper.make_node("MatMul", ["y", "b"], ["z"])],
        "g",
        [helper.make_tensor_value_info("x", TensorProto.FLOAT, [1, 4])],
        [helper.make_tensor_value_info("z", TensorProto.FLOAT, [1, 4])],
        [numpy_helper.from_array(exact, "a"), numpy_helper.from_array(inexact, "b")],
    )
    m = helper.make_model(graph, opset_imports=[helper.make_opsetid("", 17)], ir_version=9)
    assert store_half(m) == 1
    kinds = {i.name: i.data_type for i in m.graph.initializer}
    assert kinds == {"a__f16": TensorProto.FLOAT16, "b": TensorProto.FLOAT}
    onnx.checker.check_model(m)
    import onnxruntime as ort  # type: ignore[import-untyped]

    x = np.ones((1, 4), dtype=np.float32)
    session = ort.InferenceSession(m.SerializeToString(), providers=["CPUExecutionProvider"])
    np.testing.assert_allclose(session.run(None, {"x": x})[0], x @ exact @ inexact, rtol=1e-6)
