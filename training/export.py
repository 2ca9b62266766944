"""Export a checkpoint to ONNX under the dgan model contract (``docs/model-contract.md``)."""

from __future__ import annotations

import argparse
import json
from dataclasses import replace
from pathlib import Path
from typing import Any, NamedTuple, cast

import numpy as np
import onnx
import torch

import dgan
from dgan import _dgan
from dgan.contract import KEPT_OUTPUT, PADDED_INPUTS, PREPROCESS_VERSION, RASTER_VERSION
from dgan.contract import OUTPUTS as CONTRACT_OUTPUTS
from training.config import Config
from training.losses import Calibration
from training.modules.consensus import ConsensusEnsemble
from training.modules.dgan import DGAN

OUTPUTS = list(CONTRACT_OUTPUTS)
#: What a bundled checkpoint keeps of a run's ``best.pt`` (export and the parity test need no optimizer state).
SLIM_KEYS = (
    "model",
    "anchors",
    "class_of",
    "config",
    "epoch",
    "temperature",
    *Calibration.KEYS,
    "anchor_logit_scale",
    "anchor_entropy_temperature",
)
#: The inputs of an exported model (contract 3, the padded neighbour layout), in ``DGAN.forward_padded``'s order.
INPUTS = PADDED_INPUTS


class Checkpoint(NamedTuple):
    """A checkpoint loaded for inference (:func:`load_checkpoint`)."""

    model: DGAN | ConsensusEnsemble
    spec: dgan.InputSpec
    anchors: np.ndarray
    class_of: np.ndarray
    config: Config
    calibration: Calibration


def load_checkpoint(path: Path) -> Checkpoint:
    """The model (eval mode), its input spec, anchors ``(K, T_f, 2)``, the class of each anchor, the config and the
    calibration fitted on validation after training (:meth:`Calibration.of`: a single temperature of 1 for a
    checkpoint without one). An ensemble's checkpoint (``training.ensemble``) holds its members' checkpoints: its
    anchors and config are its first member's, and its ``top_scale`` (per class, ``training.ensemble.fit_top_scale``)
    if fitted."""
    return checkpoint_of(torch.load(path, weights_only=False), path)


def checkpoint_of(ckpt: dict[str, Any], path: Path) -> Checkpoint:
    """:func:`load_checkpoint` of a checkpoint's dict already loaded from ``path`` (named in errors)."""
    calibration = Calibration.of(ckpt)
    if "members" in ckpt:
        members = [network_of(m) for m in ckpt["members"]]
        first = members[0]
        for other in members[1:]:
            if other[1].to_json() != first[1].to_json() or not np.array_equal(other[3], first[3]):
                raise ValueError(f"{path}: the ensemble's members take different inputs or classes")
        tables = [torch.from_numpy(np.asarray(m[2], dtype=np.float32)) for m in members]
        ensemble = ConsensusEnsemble(
            [m[0] for m in members], tables, len(first[1].classes), ckpt.get("top_scale")
        ).eval()
        return Checkpoint(ensemble, kept_side_by_side(first[1], len(members)), *first[2:], calibration)
    return Checkpoint(*network_of(ckpt), calibration)


def kept_side_by_side(spec: dgan.InputSpec, members: int) -> dgan.InputSpec:
    """The spec of ``members`` networks of ``spec`` in one consensus: where they keep their map's features (contract
    13), the kept rows hold every member's channels side by side (:meth:`ConsensusEnsemble.forward`)."""
    m = spec.map
    if m is None or m.scene is None or not m.scene.tile_px:
        return spec
    return replace(spec, map=replace(m, scene=replace(m.scene, channels=m.scene.channels * members)))


def network_of(ckpt: dict[str, Any]) -> tuple[DGAN, dgan.InputSpec, np.ndarray, np.ndarray, Config]:
    """One trained network of a checkpoint's dict (a run's, or an ensemble's member): the model (eval mode), spec,
    anchors, class of each anchor, config (also a soup's, ``training.soup``)."""
    from training.build import build_model, input_spec

    cfg = Config.from_dict(
        {"name": ckpt["config"]["name"], **{k: ckpt["config"][k] for k in ("data", "model", "train")}}
    )
    spec = input_spec(cfg)
    model = build_model(cfg, spec, len(ckpt["anchors"]))
    model.load_state_dict(ckpt["model"])
    model.set_anchor_logit_scale(ckpt.get("anchor_logit_scale"))  # a per-class temperature (training.calibrate)
    model.set_entropy_temperature(ckpt.get("anchor_entropy_temperature"))  # one by the anchors' entropy
    model.eval()
    anchors = np.asarray(ckpt["anchors"])
    # Checkpoints from before multi-class training have one class and no class_of.
    class_of = np.asarray(ckpt.get("class_of", np.zeros(len(anchors), np.int64)))
    return model, spec, anchors, class_of, cfg


def contract(
    spec: dgan.InputSpec,
    anchors: np.ndarray,
    class_of: np.ndarray,
    name: str,
    description: str,
    temperature: float | Calibration = 1.0,
    top_scale: list[float] | None = None,
    still_radius: list[float] | None = None,
    top_mean: list[float] | None = None,
) -> dict[str, Any]:
    """The contract of an export: ``temperature`` a single temperature of the anchor logits or a contract-9
    :class:`~training.losses.Calibration` (its keys written only where they differ from a single temperature);
    ``top_scale`` each class's top-mode scale (contract 14; written for the classes whose scale is not 1);
    ``still_radius`` each class's still radius (contract 15, ``training.still``; written for the classes above 0);
    ``top_mean`` each class's top-mean power (contract 16, ``training.top_mean``; written for the classes above 0)."""
    cal = temperature if isinstance(temperature, Calibration) else Calibration(float(temperature))
    pairs = zip(spec.classes, top_scale, strict=True) if top_scale else ()
    scaled = {c: float(s) for c, s in pairs if float(s) != 1.0}
    radii = zip(spec.classes, still_radius, strict=True) if still_radius else ()
    held = {c: float(r) for c, r in radii if float(r) > 0.0}
    powers = zip(spec.classes, top_mean, strict=True) if top_mean else ()
    averaged = {c: float(b) for c, b in powers if float(b) > 0.0}
    d: dict[str, Any] = json.loads(spec.to_json())
    rounded = np.round(anchors.astype(np.float64), 6)
    d.update(
        contract_version=_dgan.CONTRACT_VERSION,
        raster_version=RASTER_VERSION,
        preprocess_version=PREPROCESS_VERSION,
        units="m",
        anchors={c: rounded[class_of == i].tolist() for i, c in enumerate(spec.classes)},
        **cal.keys(),
        **({"top_scale": scaled} if scaled else {}),
        **({"still_radius_m": held} if held else {}),
        **({"top_mean_power": averaged} if averaged else {}),
        name=name,
        description=description,
        weights_sha256=UNSEALED,
    )
    return d


#: The digest's placeholder in a contract before :func:`seal` writes the file's SHA-256 in its place.
UNSEALED = "0" * 64


def seal(path: Path) -> str:
    """Seals an exported model: the engine's :func:`dgan_core::integrity::seal` writes the SHA-256 of the file into
    its contract (which must hold :data:`UNSEALED`); the engine refuses the file at load if any byte changes."""
    digest: str = _dgan.seal_model(str(path))
    return digest


def upgrade(path: Path) -> str:
    """Rewrites a contract-3 model's metadata as contract 4 and seals it (the graph and weights unchanged)."""
    m = onnx.load(str(path))
    props = {p.key: p.value for p in m.metadata_props}
    meta = json.loads(props["dgan_contract"])
    if meta.get("contract_version") != 3:
        raise ValueError(f"{path}: contract_version {meta.get('contract_version')}, expected 3")
    meta.update(contract_version=4, weights_sha256=UNSEALED)
    onnx.helper.set_model_props(m, {**props, "dgan_contract": json.dumps(meta)})
    onnx.save(m, str(path))
    return seal(path)


def example_inputs(spec: dgan.InputSpec, n: int = 3) -> dict[str, torch.Tensor]:
    """Inputs of the padded layout to trace the exported graph with, by name in the contract's order: ``n`` agents,
    each hearing itself and the next (D = 2, unlike N, so that the tracer cannot mistake one axis for the other); a
    scene model's two frames (F = 2, M = 2 agents each, a raster of 24 px)."""
    g = torch.Generator().manual_seed(0)
    rows = torch.arange(n)
    args = {
        "trajectory": torch.randn(n, spec.t_obs, 2, generator=g),
        "trajectory_mask": torch.ones(n, spec.t_obs),
        "state": torch.randn(n, spec.state_dim, generator=g),
        "neighbor_index": torch.stack([rows, (rows + 1) % n], dim=1),
        "neighbor_mask": torch.ones(n, 2),
        "neighbor_features": torch.randn(n, 2, 6, generator=g),
    }
    m = spec.map
    if m is not None and m.scene is not None and m.scene.tile_px:
        side = m.scene.tile_px + 2 * m.scene.halo_px
        args["map"] = torch.rand(2, 3, side, side, generator=g)
    elif m is not None and m.scene is not None:
        args["map"] = torch.rand(2, 3, 24, 24, generator=g)
    elif m is not None:
        args["map"] = torch.rand(n, 3, m.height_px, m.width_px, generator=g)
    if m is not None and m.optional:
        args["map_present"] = torch.ones(n)
    grid = m.scene_grid if m is not None else None
    if m is not None and m.scene is not None and grid is not None and m.scene.tile_px:
        args["map_patches"] = torch.randn(n, m.scene.channels, *grid, generator=g)
    elif grid is not None:
        gh, gw = grid
        args["map_grid"] = torch.rand(2, 2, gh, gw, 2, generator=g) * 2 - 1
        args["map_slot"] = torch.arange(n) % 4
    return args


def export_model(
    model: DGAN | ConsensusEnsemble,
    spec: dgan.InputSpec,
    anchors: np.ndarray,
    class_of: np.ndarray,
    path: Path,
    name: str,
    description: str = "",
    temperature: float | Calibration = 1.0,
    still_radius: list[float] | None = None,
    top_scale: list[float] | None = None,
    top_mean: list[float] | None = None,
) -> Path:
    """Exports under the contract (version 3: the padded neighbour layout, whatever layout the model trained on);
    anchors must be grouped by class in the spec's class order. ``temperature``, ``still_radius``, ``top_scale`` (of a
    single network), ``top_mean``: as :func:`contract`. A consensus of
    one network is exported as that network, its top-mode scale in the contract (contract 14: the engine's decoding
    applies it), so that the file runs one network and nothing around it."""
    from training.modules.dgan import PaddedDGAN

    if isinstance(model, ConsensusEnsemble) and top_scale is not None:
        raise ValueError("a consensus applies its own top-mode scale (ConsensusEnsemble.top_scale)")
    if isinstance(model, ConsensusEnsemble) and len(model.members) == 1:
        top_scale = [float(s) for s in model.top_scale]
        model = cast(DGAN, model.members[0])

    scene = any(getattr(m, "scene", False) for m in getattr(model, "members", [model]))
    if scene != (spec.map is not None and spec.map.scene is not None):
        raise ValueError(
            'a model with model.map_mode = "scene" exports under a spec whose map reads the scene (map.scene), and '
            "only such a model does"
        )
    spec = replace(spec, graph="padded")
    if not np.all(np.diff(class_of) >= 0) or (len(class_of) and class_of[-1] >= len(spec.classes)):
        raise ValueError("anchors must be grouped by class, in the order of spec.classes")
    inputs = example_inputs(spec)
    args, names = tuple(inputs.values()), list(inputs)
    kept = "map_patches" in names
    outputs = [*OUTPUTS, KEPT_OUTPUT] if kept else OUTPUTS
    dyn = input_axes(spec)
    dynamic_axes = {k: dyn[k] for k in names} | {o: {0: "N"} for o in outputs} | {KEPT_OUTPUT: {0: "R"}}
    dynamic_axes = {k: v for k, v in dynamic_axes.items() if k in names or k in outputs}
    torch.onnx.export(
        PaddedDGAN(model, names).eval(),
        args,
        str(path),
        input_names=names,
        output_names=outputs,
        dynamic_axes=dynamic_axes,
        opset_version=17,
        dynamo=False,
    )
    m = onnx.load(str(path))
    store_half(m)
    meta = contract(spec, anchors, class_of, name, description, temperature, top_scale, still_radius, top_mean)
    onnx.helper.set_model_props(m, {"dgan_contract": json.dumps(meta)})
    onnx.save(m, str(path))
    seal(path)
    dgan.Predictor(path)  # the engine checks the contract and the seal
    return path


def input_axes(spec: dgan.InputSpec) -> dict[str, dict[int, str]]:
    """Every input's dynamic axes, by name."""
    return {
        "trajectory": {0: "N"},
        "trajectory_mask": {0: "N"},
        "state": {0: "N"},
        "neighbor_index": {0: "N", 1: "D"},
        "neighbor_mask": {0: "N", 1: "D"},
        "neighbor_features": {0: "N", 1: "D"},
        "map": map_axes(spec),
        "map_present": {0: "N"},
        "map_grid": {0: "F", 1: "M"},
        "map_slot": {0: "N"},
        "map_patches": {0: "N"},
    }


def map_axes(spec: dgan.InputSpec) -> dict[int, str]:
    """The dynamic axes of the input ``map``: the agents' crops (N), a scene model's rasters (F of side S, contract
    12) or the tiles a call computes (T, contract 13)."""
    scene = spec.map.scene if spec.map is not None else None
    if scene is not None and scene.tile_px:
        return {0: "T"}
    return {0: "F", 2: "S", 3: "S"} if scene is not None else {0: "N"}


def store_half(m: onnx.ModelProto) -> int:
    """Stores every float32 weight of the graph whose values are all float16 numbers (a checkpoint rounded by
    ``training.ensemble``'s ``half``) as float16, cast back to float32 by a Cast node that ONNX Runtime folds when
    the session starts: half the file, the same arithmetic. Returns how many weights it stored so."""
    from onnx import TensorProto, helper, numpy_helper

    g = m.graph
    kept, casts = [], []
    for init in g.initializer:
        a = numpy_helper.to_array(init) if init.data_type == TensorProto.FLOAT else None
        if a is None or a.size < 16 or not np.array_equal(a.astype(np.float16).astype(np.float32), a):
            kept.append(init)
            continue
        kept.append(numpy_helper.from_array(a.astype(np.float16), f"{init.name}__f16"))
        casts.append(helper.make_node("Cast", [f"{init.name}__f16"], [init.name], to=TensorProto.FLOAT))
    if casts:
        del g.initializer[:]
        g.initializer.extend(kept)
        nodes = list(g.node)
        del g.node[:]
        g.node.extend(casts + nodes)
    return len(casts)


def export_checkpoint(
    ckpt: Path, path: Path, name: str, description: str = "", top_mean: list[float] | None = None
) -> Path:
    """Exports the checkpoint at ``ckpt`` with the calibration, still radius (``training.still``), top-mean power
    (``training.top_mean``; ``top_mean`` in its place if given) and, for a single network, top-mode scale
    (``training.ensemble.fit_top_scale``) it holds."""
    held = torch.load(ckpt, weights_only=False)
    model, spec, anchors, class_of, _, calibration = checkpoint_of(held, ckpt)
    top = None if "members" in held else held.get("top_scale")  # a consensus's is in its graph
    power = held.get("top_mean_power") if top_mean is None else top_mean
    args = (calibration, held.get("still_radius"), top, power)
    return export_model(model, spec, anchors, class_of, path, name, description, *args)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__)
    ap.add_argument("checkpoint", help="a checkpoint to export, or with --upgrade the contract-3 .onnx files")
    ap.add_argument("out", nargs="*")
    ap.add_argument("--name", default="dgan")
    ap.add_argument("--description", default="")
    ap.add_argument("--upgrade", action="store_true", help="rewrite contract-3 models as contract 4, sealed")
    a = ap.parse_args()
    if a.upgrade:
        for path in [a.checkpoint, *a.out]:
            print(path, upgrade(Path(path)))
        return
    if len(a.out) != 1:
        ap.error("give the checkpoint and one output path")
    print(export_checkpoint(Path(a.checkpoint), Path(a.out[0]), a.name, a.description))


if __name__ == "__main__":
    main()
