"""Export a checkpoint to ONNX under the dgan model contract (``docs/model-contract.md``)."""

from __future__ import annotations

import argparse
import json
from pathlib import Path
from typing import Any

import numpy as np
import onnx
import torch

import dgan
from training.config import Config
from training.model import DGAN

INPUTS = ["trajectory", "trajectory_mask", "state", "edge_index", "edge_features", "map"]
OUTPUTS = ["class_logits", "anchor_logits", "offsets"]


def load_checkpoint(path: Path) -> tuple[DGAN, dgan.InputSpec, np.ndarray, Config]:
    from training.train import build_model, input_spec

    ckpt = torch.load(path, weights_only=False)
    cfg = Config.from_dict(
        {"name": ckpt["config"]["name"], **{k: ckpt["config"][k] for k in ("data", "model", "train")}}
    )
    spec = input_spec(cfg)
    model = build_model(cfg, spec, len(ckpt["anchors"]))
    model.load_state_dict(ckpt["model"])
    model.eval()
    return model, spec, np.asarray(ckpt["anchors"]), cfg


def contract(spec: dgan.InputSpec, anchors: np.ndarray, name: str, description: str) -> dict[str, Any]:
    d: dict[str, Any] = json.loads(spec.to_json())
    d.update(
        contract_version=1,
        units="m",
        anchors={spec.classes[0]: np.round(anchors.astype(np.float64), 6).tolist()},
        name=name,
        description=description,
    )
    return d


def example_inputs(spec: dgan.InputSpec, n: int = 3) -> tuple[torch.Tensor, ...]:
    g = torch.Generator().manual_seed(0)
    e = torch.tensor([[i, j] for i in range(n) for j in range(n)], dtype=torch.long)
    args = [
        torch.randn(n, spec.t_obs, 2, generator=g),
        torch.ones(n, spec.t_obs),
        torch.randn(n, spec.state_dim, generator=g),
        e,
        torch.randn(len(e), 6, generator=g),
    ]
    if spec.map is not None:
        args.append(torch.rand(n, 3, spec.map.height_px, spec.map.width_px, generator=g))
    return tuple(args)


def export_model(
    model: DGAN, spec: dgan.InputSpec, anchors: np.ndarray, path: Path, name: str, description: str = ""
) -> Path:
    args = example_inputs(spec)
    names = INPUTS[: len(args)]
    dyn = {
        "trajectory": {0: "N"},
        "trajectory_mask": {0: "N"},
        "state": {0: "N"},
        "edge_index": {0: "E"},
        "edge_features": {0: "E"},
        "map": {0: "N"},
    }
    dynamic_axes = {k: dyn[k] for k in names} | {o: {0: "N"} for o in OUTPUTS}
    torch.onnx.export(
        model,
        args,
        str(path),
        input_names=names,
        output_names=OUTPUTS,
        dynamic_axes=dynamic_axes,
        opset_version=17,
        dynamo=False,
    )
    m = onnx.load(str(path))
    onnx.helper.set_model_props(m, {"dgan_contract": json.dumps(contract(spec, anchors, name, description))})
    onnx.save(m, str(path))
    dgan.Predictor(path)  # the engine checks the contract
    return path


def export_checkpoint(ckpt: Path, path: Path, name: str, description: str = "") -> Path:
    model, spec, anchors, _ = load_checkpoint(ckpt)
    return export_model(model, spec, anchors, path, name, description)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__)
    ap.add_argument("checkpoint")
    ap.add_argument("out")
    ap.add_argument("--name", default="dgan")
    ap.add_argument("--description", default="")
    a = ap.parse_args()
    print(export_checkpoint(Path(a.checkpoint), Path(a.out), a.name, a.description))


if __name__ == "__main__":
    main()
