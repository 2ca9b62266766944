"""training.ensemble and training.modules.dgan.ConsensusEnsemble: the consensus of the members' most probable modes, its
export under the contract (engine–PyTorch parity), float16 weight storage, and the top mode's residual scale per
class fitted on validation."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import onnx
import pytest
import torch
from onnx import TensorProto, helper, numpy_helper
from test_calibrate import _apollo_runs
from test_training import assert_parity, randomised_batch_norm

import dgan
from training.build import build_model, input_spec
from training.config import Config
from training.ensemble import (
    TOP_SCALES,
    choose_scale,
    ensemble_checkpoint,
    fit_top_scale,
    scaled_errors,
    top_mode_errors,
)
from training.export import export_model, load_checkpoint, store_half
from training.losses import Calibration
from training.modules.consensus import ConsensusEnsemble
from training.modules.dgan import DGAN

ROOT = Path(__file__).resolve().parents[3]


Outputs = tuple[torch.Tensor, torch.Tensor, torch.Tensor]


def _random_members(
    seed: int, members: int, n: int, c: int, kc: int, t: int
) -> tuple[list[torch.Tensor], list[Outputs]]:
    """Random anchors ``(c·kc, t, 2)`` and network outputs (class logits, anchor logits, offsets) of ``members``
    members for ``n`` agents."""
    g = torch.Generator().manual_seed(seed)
    anchors = [torch.randn(c * kc, t, 2, generator=g) for _ in range(members)]
    outs = [
        (torch.randn(n, c, generator=g), torch.randn(n, c * kc, generator=g), torch.randn(n, c * kc, t, 2, generator=g))
        for _ in range(members)
    ]
    return anchors, outs


def test_the_top_mode_of_the_top_class_is_the_mean_of_the_members_top_modes() -> None:
    n, c, kc, t = 6, 3, 4, 6
    anchors, outs = _random_members(0, 3, n, c, kc, t)
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


def test_the_top_scale_moves_the_consensus_towards_the_prior_per_class() -> None:
    n, c, kc, t = 9, 3, 4, 5
    anchors, outs = _random_members(1, 2, n, c, kc, t)
    members: list[torch.nn.Module] = [torch.nn.Identity(), torch.nn.Identity()]
    full = ConsensusEnsemble(members, anchors, c).combine(outs)[2]
    scale = [0.0, 0.5, 1.0]
    scaled = ConsensusEnsemble(members, anchors, c, scale).combine(outs)[2]
    for i in range(n):
        b = int(outs[0][0][i].argmax())
        k0 = b * kc + int(outs[0][1][i, b * kc : (b + 1) * kc].argmax())
        # The top mode's residual over the prior (anchor + offset) is scaled by its class's share; 0 is the prior.
        torch.testing.assert_close(anchors[0][k0] + scaled[i, k0], scale[b] * (anchors[0][k0] + full[i, k0]))
        others = [k for k in range(c * kc) if k != k0]
        assert torch.equal(scaled[i, others], full[i, others])


def test_the_top_scale_needs_one_share_per_class() -> None:
    anchors = [torch.zeros(6, 3, 2)]
    for bad in ([1.0], [0.5, 1.5], [-0.1, 1.0], [float("nan"), 1.0]):
        with pytest.raises(ValueError, match="one value in"):
            ConsensusEnsemble([torch.nn.Identity()], anchors, 2, bad)


def test_a_scale_is_kept_only_for_a_gain_of_at_least_one_percent() -> None:
    assert choose_scale([0.43, 0.432, 0.435, 0.44, 0.445]) == 0.0  # 3.4% below scale 1
    assert choose_scale([1.9, 1.77, 1.66, 1.58, 1.543]) == 1.0  # scale 1 is best
    assert choose_scale([0.268, 0.267, 0.2665, 0.268, 0.2688]) == 1.0  # best is 0.9% below: not enough
    assert choose_scale([2.0, 1.9, 1.5, 1.6, 2.0]) == 0.5
    with pytest.raises(ValueError, match="one finite ADE per scale"):
        choose_scale([0.4, 0.4, float("nan"), 0.4, 0.4])
    with pytest.raises(ValueError, match="one finite ADE per scale"):
        choose_scale([0.4, 0.4])


def test_scaled_errors_run_from_the_prior_to_the_top_mode() -> None:
    truth = np.zeros((1, 3, 2))
    prior = np.tile([[[0.0, 2.0]]], (1, 3, 1))  # 2 m off at every step
    top = np.tile([[[0.0, -2.0]]], (1, 3, 1))  # 2 m off the other way
    e = scaled_errors(top, prior, truth, (0.0, 0.5, 1.0, 1.5))
    # s = 0 is the prior, s = 1 the top mode, s = 0.5 halfway (on the truth), s = 1.5 beyond the top mode.
    np.testing.assert_allclose(e, [[2.0, 0.0, 2.0, 4.0]], atol=1e-12)


@pytest.mark.slow
def test_the_top_scale_is_fitted_on_validation_stored_and_exported(tmp_path: Path) -> None:
    ckpt = ensemble_checkpoint(_apollo_runs(tmp_path, (0, 1)), tmp_path / "ensemble.pt")
    errors, klass, classes = top_mode_errors(ckpt)
    assert errors.shape == (len(klass), len(TOP_SCALES))
    assert np.isfinite(errors).all()
    fit = fit_top_scale(ckpt)
    assert fit.classes == classes == dgan.CLASSES
    assert sum(fit.targets) == len(klass)
    for i, (ade, s) in enumerate(zip(fit.ade, fit.scale, strict=True)):
        np.testing.assert_allclose(ade, errors[klass == i].mean(axis=0), rtol=1e-6)
        assert s == choose_scale(ade)
    # Random anchors and untrained networks refine nothing: the prior alone is best for some class.
    assert 0.0 in fit.scale
    assert "top-mode scale on validation" in str(fit)
    model, spec, anchors, class_of, _, cal = load_checkpoint(ckpt)
    assert isinstance(model, ConsensusEnsemble)
    assert model.top_scale.tolist() == list(fit.scale)
    # The scale is part of the exported graph: the engine matches PyTorch with it.
    path = export_model(model, spec, anchors, class_of, tmp_path / "scaled.onnx", "scaled", temperature=cal)
    assert_parity(model, spec, anchors, class_of, path, cal)
    # Fitting again measures the network at scale 1 whatever the checkpoint holds: the same scales.
    assert fit_top_scale(ckpt).scale == fit.scale


def test_a_single_network_keeps_its_top_scale_in_its_contract(tmp_path: Path) -> None:
    import shutil

    from training.checkpoint import update_checkpoint
    from training.export import export_checkpoint

    ckpt = tmp_path / "single.pt"
    shutil.copy(_apollo_runs(tmp_path, (0,))[0] / "best.pt", ckpt)
    errors, _, names = top_mode_errors(ckpt)  # a single network's forward is at scale 1
    assert errors.shape[1] == len(TOP_SCALES)
    scales = [0.5, 1.0, 0.25]
    assert len(names) == len(scales)
    update_checkpoint(ckpt, top_scale=scales)
    path = export_checkpoint(ckpt, tmp_path / "single.onnx", "single")
    assert dgan.Predictor(path).contract["top_scale"] == {n: s for n, s in zip(names, scales, strict=True) if s != 1.0}
    model, spec, anchors, class_of, _, cal = load_checkpoint(ckpt)
    assert isinstance(model, DGAN)  # the engine's decoding applies the scale; the parity check's decoding too
    assert_parity(model, spec, anchors, class_of, path, cal)
    with pytest.raises(ValueError, match="applies its own top-mode scale"):
        export_model(
            ConsensusEnsemble([model], [torch.from_numpy(anchors).float()], len(names)),
            spec,
            anchors,
            class_of,
            tmp_path / "x.onnx",
            "x",
            top_scale=[1.0] * len(names),
        )


def test_members_need_the_same_anchor_layout() -> None:
    with pytest.raises(ValueError, match="same anchors per class"):
        ConsensusEnsemble([torch.nn.Identity()] * 2, [torch.zeros(6, 3, 2), torch.zeros(4, 3, 2)], 2)
    with pytest.raises(ValueError, match="one anchor set per member"):
        ConsensusEnsemble([torch.nn.Identity()] * 2, [torch.zeros(6, 3, 2)], 2)


def _members(
    tmp_path: Path, seeds: tuple[int, ...], calibration: Calibration | None = None
) -> tuple[list[Path], dgan.InputSpec]:
    """Untrained hdmap networks saved as training runs (``best.pt``, ``config.json``), different anchors each, with
    ``calibration`` (a single temperature of 1.2 if not given)."""
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
            **(calibration or Calibration(1.2)).keys(complete=True),
        }
        torch.save(ckpt, run / "best.pt")
        (run / "config.json").write_text(json.dumps({"config": asdict(cfg)}))
        runs.append(run)
    assert spec is not None
    return runs, spec


@pytest.mark.slow
def test_a_float16_ensemble_exports_and_matches_pytorch(tmp_path: Path) -> None:
    runs, spec = _members(tmp_path, (0, 1))
    ckpt = ensemble_checkpoint(runs, tmp_path / "ensemble.pt", half=True)
    model, spec2, anchors, class_of, _, cal = load_checkpoint(ckpt)
    assert isinstance(model, ConsensusEnsemble)
    assert len(model.members) == 2
    assert spec2.to_json() == spec.to_json()
    assert cal == Calibration(cal.temperature)  # a single temperature
    assert cal.temperature == pytest.approx(1.2)
    path = export_model(model, spec, anchors, class_of, tmp_path / "e.onnx", "ensemble", temperature=cal)
    stored = {i.data_type for i in onnx.load(str(path)).graph.initializer}
    assert TensorProto.FLOAT16 in stored
    assert_parity(model, spec, anchors, class_of, path, cal)
    # The same two members at float32: the float16 file is much smaller.
    full = load_checkpoint(ensemble_checkpoint(runs, tmp_path / "full.pt"))
    path32 = export_model(full[0], spec, anchors, class_of, tmp_path / "f.onnx", "ensemble32")
    assert path.stat().st_size < 0.7 * path32.stat().st_size


@pytest.mark.slow
def test_an_ensemble_keeps_its_first_member_s_contract_9_calibration(tmp_path: Path) -> None:
    # Until refitted, the consensus decodes as its first member did: the speed exponent and class temperature too,
    # in PyTorch (load_checkpoint) and in the engine (the exported contract).
    cal = Calibration(0.8, 0.5, 2.0)
    runs, spec = _members(tmp_path, (0, 1), cal)
    model, _, anchors, class_of, _, loaded = load_checkpoint(ensemble_checkpoint(runs, tmp_path / "e.pt"))
    assert loaded == cal
    path = export_model(model, spec, anchors, class_of, tmp_path / "e.onnx", "ensemble", temperature=loaded)
    contract = dgan.Predictor(path).contract
    assert (contract["temperature_speed_exponent"], contract["class_temperature"]) == (0.5, 2.0)
    assert_parity(model, spec, anchors, class_of, path, loaded)


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


def test_fold_checkpoints_take_the_models_top_scale(tmp_path: Path) -> None:
    from training.release.bundle import with_scale

    runs, _ = _members(tmp_path, (0, 1))
    ckpt = ensemble_checkpoint(runs, tmp_path / "fold.pt")
    with_scale(ckpt, None)  # nothing to store: unchanged
    assert "top_scale" not in torch.load(ckpt, weights_only=False)
    with_scale(ckpt, [1.0, 0.5, 0.0])
    model = load_checkpoint(ckpt)[0]
    assert isinstance(model, ConsensusEnsemble)
    assert model.top_scale.tolist() == [1.0, 0.5, 0.0]
    with pytest.raises(ValueError, match="needs an ensemble checkpoint"):
        with_scale(runs[0] / "best.pt", [1.0, 1.0, 1.0])


@pytest.mark.slow
def test_a_consensus_of_one_exports_as_its_network_with_the_scale_in_the_contract(tmp_path: Path) -> None:
    from training.release.bundle import with_scale

    runs, _ = _members(tmp_path, (0,))
    ckpt = ensemble_checkpoint(runs, tmp_path / "one.pt", half=True)
    with_scale(ckpt, [1.0, 0.5, 0.0])
    model, spec, anchors, class_of, _, cal = load_checkpoint(ckpt)
    assert isinstance(model, ConsensusEnsemble)
    path = export_model(model, spec, anchors, class_of, tmp_path / "one.onnx", "one", temperature=cal)
    contract = dgan.Predictor(path).contract
    assert contract["contract_version"] == dgan._dgan.CONTRACT_VERSION >= 14
    assert contract["top_scale"] == {"cyclist": 0.5, "pedestrian": 0.0}  # vehicles keep all of theirs
    # The network alone, exported as its own run: the same graph, nothing of the consensus around it.
    network = model.members[0]
    assert isinstance(network, DGAN)
    alone = export_model(network, spec, anchors, class_of, tmp_path / "alone.onnx", "alone")
    ops = [sorted(n.op_type for n in onnx.load(str(p)).graph.node) for p in (path, alone)]
    assert ops[0] == ops[1]
    assert "top_scale" not in dgan.Predictor(alone).contract
    # The engine's decoding applies the scale as the consensus's graph did: it matches PyTorch.
    assert_parity(model, spec, anchors, class_of, path, cal)
