"""Ship a trained run: export its best checkpoint into ``python/dgan/models/<name>.onnx``, keep a slim checkpoint
for the parity test in ``training/checkpoints/<name>.pt``, evaluate it with the engine and write its model card.

    python -m training.release.bundle runs/ethucy_zara1 --name zara1 --data-root ../shared/data
    python -m training.release.bundle runs/sdd --name sdd
    python -m training.release.bundle runs/apollo_s0 runs/apollo_s1 --name apolloscape \
        --calibration-fold runs/fold1_s0 runs/fold1_s1 --calibration-fold ...   # a cross-fitted temperature
    python -m training.release.bundle --reexport zara1 sdd      # the kept checkpoints, exported again (a new contract)
    python -m training.release.bundle --denoise zara1 0.1       # histories denoised first (contract 10), exported again
    python -m training.release.bundle --restate zara1           # its card's test metrics measured again
    python -m training.release.bundle --map-classes hdmap cyclist,pedestrian   # only they read the map
"""

from __future__ import annotations

import argparse
import json
import tempfile
from collections.abc import Sequence
from dataclasses import replace
from pathlib import Path
from typing import Any

import torch

import dgan
from training.calibrate import calibrate_checkpoint
from training.evaluate import evaluate
from training.export import SLIM_KEYS, export_checkpoint
from training.release.cards import card, declared_folds, ensemble_line, restated
from training.release.multiclass_card import MULTICLASS, multiclass_card

ROOT = Path(__file__).resolve().parents[2]
MODELS = ROOT / "python" / "dgan" / "models"
CHECKPOINTS = ROOT / "training" / "checkpoints"


def slim_checkpoint(run: Path, out: Path) -> Path:
    """Keeps what export and the parity test need of a run's best checkpoint (no optimizer state)."""
    ckpt = torch.load(run / "best.pt", weights_only=False)
    out.parent.mkdir(parents=True, exist_ok=True)
    torch.save({k: ckpt[k] for k in SLIM_KEYS if k in ckpt}, out)
    return out


def model_checkpoint(runs: list[Path], out: Path, consensus: bool = False) -> Path:
    """The checkpoint of one run (slimmed) or of several runs' consensus (``training.ensemble``, float16) at ``out``;
    ``consensus``: one run kept as a consensus of one too (one network, which can then take a top-mode scale)."""
    if len(runs) > 1 or consensus:
        from training.ensemble import ensemble_checkpoint

        return ensemble_checkpoint(runs, out, half=True)
    return slim_checkpoint(runs[0], out)


def with_scale(path: Path, scale: list[float] | None) -> None:
    """Stores the top-mode scales ``scale`` (``training.ensemble.fit_top_scale``) in the ensemble checkpoint at
    ``path``; nothing for ``None``."""
    from training.checkpoint import save_atomic

    if scale is None:
        return
    ckpt = torch.load(path, weights_only=False)
    if "members" not in ckpt:
        raise ValueError(f"{path}: a top-mode scale needs an ensemble checkpoint (training.ensemble)")
    ckpt["top_scale"] = scale
    save_atomic(ckpt, path)


#: The checkpoint keys of the engine's decoding that :func:`bundle` sets (one value per class): contract 14's
#: ``top_scale`` (of one network; a consensus's is fitted), 15's ``still_radius``, 16's ``top_mean_power``.
DECODING_KEYS = ("top_scale", "still_radius", "top_mean_power")


def check_decoding(name: str, decoding: dict[str, list[float]], consensus: bool) -> None:
    """Raises a ValueError, before anything is written, for a key of ``decoding`` (:func:`bundle`) outside
    :data:`DECODING_KEYS` or a top-mode scale given for a consensus (whose scale :func:`bundle` fits)."""
    unknown = sorted(set(decoding) - set(DECODING_KEYS))
    if unknown:
        raise ValueError(f"{name}: decoding keys must be among {', '.join(DECODING_KEYS)}, got {', '.join(unknown)}")
    if consensus and "top_scale" in decoding:
        raise ValueError(f"{name}: a consensus's top-mode scale is fitted on validation when it is bundled, not given")


def decoding_lines(classes: Sequence[str], decoding: dict[str, list[float]]) -> str:
    """A model card's lines for its ``decoding`` (:func:`bundle`), each class named with its value."""

    def per_class(key: str, unit: str = "", skip: float = 0.0) -> str:
        values = [f"{c} {v:g}{unit}" for c, v in zip(classes, decoding[key], strict=True) if v != skip]
        return ", ".join(values) or "none"

    lines = []
    if "top_scale" in decoding:
        lines.append(
            "- **Top-mode scale** (contract 14, `training.ensemble.fit_top_scale`, chosen on validation): the most "
            "probable mode keeps this share of its refinement over the kinematic prior: "
            f"{per_class('top_scale', skip=1.0)}."
        )
    if "still_radius" in decoding:
        lines.append(
            "- **Still history** (contract 15, `training.still`, chosen on validation): an agent whose every observed "
            "step lies within r of its last position has its most probable mode at the kinematic prior: "
            f"{per_class('still_radius', ' m')}."
        )
    if "top_mean_power" in decoding:
        lines.append(
            "- **Mean top mode** (contract 16, `training.top_mean`, chosen on validation by the engine): the most "
            f"probable mode is the mean of the agent's modes weighted by p^β: β for {per_class('top_mean_power')}."
        )
    return "".join(line + "\n" for line in lines)


def check_folds(cfg: dict[str, Any], folds: list[list[Path]]) -> None:
    """The fold runs must hold out exactly the validation splits the configuration declares, each once."""
    held = sorted(
        json.loads((f[0] / "config.json").read_text())["config"]["data"].get("val_recordings", "") for f in folds
    )
    want = sorted(declared_folds(cfg))
    if held != want:
        raise ValueError(
            f"train.calibration_folds declares the validation splits {want or 'none'}; the fold runs given hold out "
            f"{held or 'none'} (pass --calibration-fold RUN [RUN ...] once per declared split)"
        )


def test_metrics(predictor: dgan.Predictor, dataset: str, data_root: Path, fold: str) -> dict[str, Any]:
    """A bundled model's card metrics on its test split (``training.evaluate``), for an ETH/UCY model whose map is
    optional also on the same frames without their map (``without_map``)."""
    metrics = evaluate(predictor, dataset, data_root, fold)
    if dataset == "ethucy" and predictor.spec.map is not None and predictor.spec.map.optional:
        metrics["without_map"] = evaluate(predictor, dataset, data_root, fold, with_map=False)
    return metrics


def bundle(
    runs: list[Path],
    name: str,
    data_root: Path,
    folds: list[list[Path]] | None = None,
    top_scale: bool = False,
    decoding: dict[str, list[float]] | None = None,
) -> dict[str, Any]:
    """Bundles a run (or several runs of one configuration as their consensus, ``training.ensemble``, with the
    weights kept as float16 and the temperature fitted on validation anew): checkpoint, ONNX model and card.

    ``folds``: for a configuration with ``train.calibration_folds``, the runs of each of its folds (seeds, built into
    a model as ``runs`` are); their predictions on their validation splits join the temperature's fit.
    ``top_scale``: one run is kept as a consensus of one (one network's cost) with a top-mode scale fitted on
    validation, as a consensus of several always is.
    ``decoding``: the engine's decoding the model carries beyond its network (keys of :data:`DECODING_KEYS`, one
    value per class), chosen on validation once it was trained; stored before export and named on its card."""
    run = runs[0]
    cfg = json.loads((run / "config.json").read_text())["config"]
    dataset = cfg["data"].get("dataset", "ethucy")
    check_folds(cfg, folds or [])
    consensus = len(runs) > 1 or top_scale
    check_decoding(name, decoding or {}, consensus)
    MODELS.mkdir(parents=True, exist_ok=True)
    model_checkpoint(runs, CHECKPOINTS / f"{name}.pt", consensus)
    scale = None
    if consensus:
        from training.ensemble import fit_top_scale

        fit = fit_top_scale(CHECKPOINTS / f"{name}.pt", data_root)
        print(f"{name}: {fit}", flush=True)
        scale = list(fit.scale)
    with tempfile.TemporaryDirectory() as tmp:
        fold_ckpts = [model_checkpoint(f, Path(tmp) / f"fold{i}.pt", consensus) for i, f in enumerate(folds or [])]
        for fold_ckpt in fold_ckpts:  # the folds stand in for the model: the same top-mode scales
            with_scale(fold_ckpt, scale)
        print(f"{name}: {calibrate_checkpoint(CHECKPOINTS / f'{name}.pt', data_root, folds=fold_ckpts)}", flush=True)
    if decoding:
        from training.checkpoint import update_checkpoint

        update_checkpoint(CHECKPOINTS / f"{name}.pt", **decoding)
    if dataset == "ethucy":
        description = (
            f"DGAN trained leave-one-scene-out on ETH/UCY, test scene {cfg['data']['scene']}; "
            "non-commercial research use only (ETH/UCY licence)."
        )
    else:
        description = (
            f"DGAN for vehicles, cyclists and pedestrians trained on {MULTICLASS[dataset]['title']}; "
            "non-commercial research use only (dataset licence)."
        )
    model_name = f"dgan-ethucy-{name}" if dataset == "ethucy" else f"dgan-{name}"
    onnx_path = export_checkpoint(CHECKPOINTS / f"{name}.pt", MODELS / f"{name}.onnx", model_name, description)
    predictor = dgan.Predictor(onnx_path)
    fold = cfg["data"]["scene"] if dataset == "ethucy" else ""
    metrics = test_metrics(predictor, dataset, data_root, fold)
    text = card(name, run, metrics, cfg) if dataset == "ethucy" else multiclass_card(name, run, metrics, cfg)
    if consensus:
        text = text.replace("- **Test metrics**", ensemble_line(runs, predictor, cfg, scale) + "- **Test metrics**", 1)
    if decoding:
        text = text.replace("- **Test metrics**", decoding_lines(predictor.classes, decoding) + "- **Test metrics**", 1)
    (MODELS / f"{name}.md").write_text(text)
    (run / "metrics.json").write_text(json.dumps(metrics, indent=2))
    return metrics


def reexport(name: str) -> Path:
    """Exports a bundled model again from its kept checkpoint under the current contract, keeping its name and
    description (its card's metrics hold: the engine–PyTorch parity test checks the new file against the
    checkpoint)."""
    old = dgan.Predictor(name).contract
    ckpt = CHECKPOINTS / f"{name}.pt"
    return export_checkpoint(ckpt, MODELS / f"{name}.onnx", old.get("name", name), old.get("description", ""))


def rerender(name: str, render: str) -> Path:
    """Sets how the bundled model ``name``'s vector map becomes its crops (``data.map_render``, ``dgan.MapSpec.render``)
    in its kept checkpoint and exports it again (:func:`reexport`); its weights and temperature are unchanged. Whether
    a network trained on one way's crops keeps its accuracy on the other's is measured on validation before
    bundling (``python -m training.evaluate MODEL --dataset D --split val``)."""
    if render not in ("agent", "tiles"):
        raise ValueError(f"render must be 'agent' or 'tiles', got {render!r}")
    return _reexport_with(name, "map_render", render)


def redenoise(name: str, gate_m: float) -> Path:
    """Sets the bundled model ``name``'s denoising gate (``data.denoise_gate_m``, ``dgan.InputSpec.denoise_gate_m``,
    contract 10) in its kept checkpoint and exports it again (:func:`reexport`); its weights and temperature are
    unchanged. The gate is chosen on validation before bundling (``docs/results.md``, noisy tracks); the engine checks
    it (:class:`dgan.exceptions.InvalidSpecError`) before the checkpoint is touched."""
    replace(dgan.Predictor(name).spec, denoise_gate_m=gate_m)
    return _reexport_with(name, "denoise_gate_m", gate_m)


def regroup(name: str, groups: bool) -> Path:
    """Sets whether the bundled model ``name``'s exported attention splits its neighbours in two groups by degree
    (``model.neighbor_groups``: the same outputs, another cost; chosen by measurement, docs/speed.md) in its kept
    checkpoint and exports it again (:func:`reexport`)."""
    return _reexport_with(name, "neighbor_groups", groups, section="model")


def regate(name: str, classes: str, data_root: Path) -> Path:
    """Sets which classes of the bundled model ``name`` read its map (``model.map_classes``: the others' map_present
    is 0 inside the network, and their crops are left blank, contract 11) in its kept checkpoint, refits its
    calibration as one temperature per class (``train.calibration = "per_class"``) on its validation split and exports
    it again; its weights are unchanged. Which classes read the map is chosen on validation before bundling
    (docs/results.md)."""
    values = {("model", "map_classes"): classes, ("train", "calibration"): "per_class"}
    ckpt = _set_config(name, values, why="model.map_classes and a per-class temperature are for one network")
    print(f"{name}: {calibrate_checkpoint(ckpt, data_root)}", flush=True)
    return reexport(name)


def _reexport_with(name: str, key: str, value: Any, section: str = "data") -> Path:
    """Sets ``<section>.<key>`` in the bundled model ``name``'s kept checkpoint (:func:`_set_config`) and exports it
    again (:func:`reexport`)."""
    _set_config(name, {(section, key): value})
    return reexport(name)


def _set_config(name: str, values: dict[tuple[str, str], Any], why: str = "") -> Path:
    """Sets each ``(section, key)`` of ``values`` in the bundled model ``name``'s kept checkpoint's configuration (in
    each member's too, for a consensus: ``training.ensemble``) and returns the checkpoint's path. ``why``: a consensus
    is refused with that reason, before anything is written."""
    from training.checkpoint import update_checkpoint

    ckpt = CHECKPOINTS / f"{name}.pt"
    loaded = torch.load(ckpt, weights_only=False)
    if why and "members" in loaded:
        raise ValueError(f"{name} is a consensus; {why}")
    for holder in [loaded, *loaded.get("members", [])]:
        if "config" in holder:
            for (section, key), value in values.items():
                holder["config"][section][key] = value
    update_checkpoint(ckpt, **{k: loaded[k] for k in ("config", "members") if k in loaded})
    return ckpt


def restate(name: str, data_root: Path) -> dict[str, Any]:
    """Evaluates the bundled ETH/UCY model ``name`` again with the engine on its test scene and rewrites its card's
    test metrics and denoising sentence (:func:`training.release.cards.restated`): after :func:`redenoise`, when the
    run it was trained in is no longer at hand."""
    ckpt = torch.load(CHECKPOINTS / f"{name}.pt", weights_only=False)
    cfg = ckpt["config"] if "config" in ckpt else ckpt["members"][0]["config"]
    if cfg["data"].get("dataset", "ethucy") != "ethucy":
        raise ValueError(f"{name}: restate rewrites ETH/UCY cards; bundle a multi-class model again instead")
    predictor = dgan.Predictor(MODELS / f"{name}.onnx")
    metrics = test_metrics(predictor, "ethucy", data_root, cfg["data"]["scene"])
    card_path = MODELS / f"{name}.md"
    card_path.write_text(restated(card_path.read_text(), metrics, cfg))
    return metrics


def main() -> None:
    ap = _parser()
    a = ap.parse_args()
    if a.map_classes:
        print(regate(a.map_classes[0], a.map_classes[1], a.data_root.expanduser()))
        return
    if a.neighbor_groups:
        model, on = a.neighbor_groups
        if on not in ("on", "off"):
            ap.error(f"--neighbor-groups takes on or off, got {on!r}")
        print(regroup(model, on == "on"))
        return
    if a.denoise:
        print(redenoise(a.denoise[0], float(a.denoise[1])))
        return
    if a.restate:
        for name in a.restate:
            print(json.dumps({name: restate(name, a.data_root.expanduser())}, indent=2))
        return
    if a.render:
        print(rerender(*a.render))
        return
    if a.reexport:
        for name in a.reexport:
            print(reexport(name))
        return
    if not a.run or a.name is None:
        ap.error("give a run folder (or several) and --name (or --reexport MODEL ...)")
    print(json.dumps(bundle(a.run, a.name, a.data_root.expanduser(), a.calibration_fold), indent=2))


def _parser() -> argparse.ArgumentParser:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument(
        "run", type=Path, nargs="*", help="a run folder, or several runs of one configuration (an ensemble)"
    )
    ap.add_argument("--name")
    ap.add_argument("--data-root", type=Path, default=Path("../shared/data"))
    ap.add_argument(
        "--calibration-fold",
        nargs="+",
        type=Path,
        action="append",
        metavar="RUN",
        help="the runs of one fold of a cross-fitted temperature (train.calibration_folds); once per fold",
    )
    ap.add_argument("--reexport", nargs="+", metavar="MODEL", help="export bundled models again from their checkpoints")
    ap.add_argument(
        "--render", nargs=2, metavar=("MODEL", "RENDER"), help="set a bundled model's map.render and export it again"
    )
    ap.add_argument(
        "--denoise",
        nargs=2,
        metavar=("MODEL", "GATE_M"),
        help="set a bundled model's denoise_gate_m (contract 10) and export it again",
    )
    ap.add_argument(
        "--restate", nargs="+", metavar="MODEL", help="evaluate bundled ETH/UCY models again and rewrite their cards"
    )
    ap.add_argument(
        "--neighbor-groups",
        nargs=2,
        metavar=("MODEL", "ON"),
        help="export a bundled model again with its attention in two degree groups (on) or one (off); same outputs",
    )
    ap.add_argument(
        "--map-classes",
        nargs=2,
        metavar=("MODEL", "CLASSES"),
        help="set which classes read a bundled model's map (comma-separated), refit a temperature per class, export",
    )
    return ap


if __name__ == "__main__":
    main()
