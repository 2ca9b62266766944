"""Model files are untrusted input: every bundled model is sealed with a SHA-256 digest that the engine verifies
before ONNX Runtime reads it."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import onnx
import pytest

import dgan
from dgan import exceptions as exc

MODELS = Path(dgan.models.__file__).parent


def weight_spans(path: Path) -> list[tuple[int, int]]:
    """Byte ranges of the file that hold the initializers' raw data (the weights)."""
    data = path.read_bytes()
    spans = []
    for init in onnx.load(str(path)).graph.initializer:
        raw = init.raw_data
        if len(raw) >= 64:
            at = data.find(raw)
            assert at >= 0
            spans.append((at, at + len(raw)))
    return spans


@pytest.mark.slow
@pytest.mark.parametrize("name", ["zara1", "hdmap"])
def test_forty_copies_with_one_byte_flipped_in_their_weights_are_refused(name: str, tmp_path: Path) -> None:
    path = MODELS / f"{name}.onnx"
    data = path.read_bytes()
    spans = weight_spans(path)
    assert sum(b - a for a, b in spans) > 0.9 * len(data)  # the weights are most of the file
    rng = np.random.default_rng(13)
    refused = 0
    for k in range(40):
        a, b = spans[rng.integers(len(spans))]
        at = int(rng.integers(a, b))
        bad = bytearray(data)
        bad[at] ^= 1 << int(rng.integers(8))
        copy = tmp_path / f"{name}_{k}.onnx"
        copy.write_bytes(bytes(bad))
        with pytest.raises(exc.ModelLoadError, match=r"SHA-256 .* corrupt or was modified"):
            dgan.Predictor(copy)
        refused += 1
    assert refused == 40


@pytest.mark.slow
def test_every_bundled_model_is_sealed() -> None:
    for name in dgan.models.list():
        contract = dgan.Predictor(name).contract
        assert 4 <= contract["contract_version"] <= dgan._dgan.CONTRACT_VERSION  # sealed from version 4 on
        assert len(contract["weights_sha256"]) == 64


@pytest.mark.slow
def test_a_flip_anywhere_is_refused_with_a_typed_error(tmp_path: Path) -> None:
    data = (MODELS / "zara1.onnx").read_bytes()
    rng = np.random.default_rng(7)
    for k in range(40):
        bad = bytearray(data)
        bad[int(rng.integers(len(data)))] ^= 0x10
        copy = tmp_path / f"any_{k}.onnx"
        copy.write_bytes(bytes(bad))
        with pytest.raises((exc.ModelLoadError, exc.ContractError)):
            dgan.Predictor(copy)


def test_unsealed_and_wrongly_sealed_contracts(tmp_path: Path) -> None:
    m = onnx.load(str(MODELS / "zara1.onnx"))
    meta = json.loads(next(p.value for p in m.metadata_props if p.key == "dgan_contract"))
    # Contract 4 without a digest (e.g. the key's name damaged): refused.
    del meta["weights_sha256"]
    onnx.helper.set_model_props(m, {"dgan_contract": json.dumps(meta)})
    onnx.save(m, str(tmp_path / "unsealed.onnx"))
    with pytest.raises(exc.ContractError, match="must declare weights_sha256"):
        dgan.Predictor(tmp_path / "unsealed.onnx")
    # A placeholder never sealed: the digest is not the file's.
    meta["weights_sha256"] = "0" * 64
    onnx.helper.set_model_props(m, {"dgan_contract": json.dumps(meta)})
    onnx.save(m, str(tmp_path / "placeholder.onnx"))
    with pytest.raises(exc.ModelLoadError, match="corrupt or was modified"):
        dgan.Predictor(tmp_path / "placeholder.onnx")
    # Sealing it makes it load, and predict as the bundled model does.
    dgan._dgan.seal_model(tmp_path / "placeholder.onnx")
    frame = dgan.Frame(np.cumsum(np.full((2, 8, 2), 0.4), axis=1))
    a = dgan.Predictor(tmp_path / "placeholder.onnx").predict(frame)
    np.testing.assert_array_equal(a.trajectories, dgan.Predictor("zara1").predict(frame).trajectories)
    with pytest.raises(exc.ContractError, match="already sealed"):
        dgan._dgan.seal_model(tmp_path / "placeholder.onnx")


def test_a_resealed_model_with_absurd_anchors_is_refused_at_load(tmp_path: Path) -> None:
    """The seal proves integrity, not origin: a re-sealed edit loads unless its contract is out of bounds."""
    model = onnx.load(str(dgan.models.path("zara1")))
    meta = {p.key: p for p in model.metadata_props}
    contract = json.loads(meta["dgan_contract"].value)
    contract["anchors"]["pedestrian"][0][3] = [1.7e308, 0.0]
    contract["weights_sha256"] = "0" * 64  # re-sealed below, as anyone can
    meta["dgan_contract"].value = json.dumps(contract)
    path = tmp_path / "far.onnx"
    onnx.save(model, str(path))
    dgan._dgan.seal_model(str(path))
    with pytest.raises(dgan.exceptions.ContractError, match="anchors are finite metres within"):
        dgan.Predictor(path)
