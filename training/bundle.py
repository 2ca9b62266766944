"""Ship a trained fold: export its best checkpoint into ``python/dgan/models/<name>.onnx``, keep a slim checkpoint
for the parity test in ``training/checkpoints/<name>.pt``, evaluate it with the engine and write its model card.

    python -m training.bundle runs/ethucy_zara1 --name zara1 --data-root ../shared/data
"""

from __future__ import annotations

import argparse
import csv
import json
from pathlib import Path
from typing import Any

import torch

import dgan
from training.evaluate import evaluate
from training.export import export_checkpoint

ROOT = Path(__file__).resolve().parents[1]
MODELS = ROOT / "python" / "dgan" / "models"
CHECKPOINTS = ROOT / "training" / "checkpoints"


def card(name: str, run: Path, metrics: dict[str, Any], cfg: dict[str, Any]) -> str:
    rows = list(csv.DictReader((run / "log.csv").open()))
    seconds = sum(float(r["seconds"]) for r in rows)
    best = min(rows, key=lambda r: float(r["val_loss"]))
    scene = cfg["data"]["scene"]
    others = ", ".join(s for s in ("eth", "hotel", "univ", "zara1", "zara2") if s != scene)
    m = cfg["model"]
    keys = ("ade", "fde", "min_ade5", "min_fde5", "min_ade20", "min_fde20", "brier_min_fde20")
    row = " | ".join(f"{metrics[k]:.3f}" for k in keys)
    return f"""# Model card: `{name}`

DGAN (Dong et al. 2020) for pedestrians, trained leave-one-scene-out on ETH/UCY: **test scene {scene}**, never seen in
training.

- **Data**: ETH/UCY in the Social-GAN layout (metres, 0.4 s steps). Trained on the train split of {others}; the best
  epoch chosen on their val split. Each scene's semantic mask, colourised (`dgan.scenes.MASK_PALETTE`), is the raster
  map: {cfg["data"]["map_height_px"]}×{cfg["data"]["map_width_px"]} px crops at {cfg["data"]["map_resolution_m"]} m/px,
  heading-aligned. Use it on new frames of a scene with `dgan.scene_map("{scene}")`.
- **Protocol**: 8 observed steps (3.2 s), 12 predicted (4.8 s); every start frame; all agents seen at t_obs are in the
  graph; targets are the agents present at all 20 steps, in windows with at least two of them.
- **Model**: LSTM({m["lstm_dim"]}) over MLP-embedded positions, traffic-state MLP, map CNN (ResNet-style, width
  {m["map_channels"]}), {m["gat_layers"]} GAT layers × {m["gat_heads"]} heads over the attention-zone graph (λ = 0.5)
  with neighbour geometry on the edges, {cfg["train"]["anchors_per_class"]} k-means anchors with offset regression.
  Loss: the paper's hierarchical classification and closest-anchor regression (α = {cfg["train"]["alpha"]}), plus
  β = {cfg["train"]["beta"]} times the error of the most probable mode (see `docs/results.md`).
  One class (pedestrian).
- **Training**: {len(rows)} epochs, best at epoch {best["epoch"]}, {seconds / 60:.1f} min on 2 CPU cores; seed
  {cfg["train"]["seed"]}; left-right mirroring.
- **Test metrics** (engine, world metres, {metrics["windows"]} windows, {metrics["agents"]} agents):

| | top-1 ADE | top-1 FDE | minADE5 | minFDE5 | minADE20 | minFDE20 | Brier-minFDE20 |
|---|---|---|---|---|---|---|---|
| DGAN | {row} |
| constant velocity | {metrics["cv_ade"]:.3f} | {metrics["cv_fde"]:.3f} | | | | | |

- **Licence**: the weights are derived from ETH (BIWI) and UCY data, which are for **non-commercial research use
  only**. Cite Pellegrini et al. 2009 and Lerner et al. 2007.
- **Reproduce**: `python -m training.results --train` (all five folds) or
  `python -m training.train --config training/configs/ethucy_{scene}.toml --out runs/ethucy_{scene}`.
"""


def bundle(run: Path, name: str, data_root: Path) -> dict[str, Any]:
    cfg = json.loads((run / "config.json").read_text())["config"]
    MODELS.mkdir(parents=True, exist_ok=True)
    CHECKPOINTS.mkdir(parents=True, exist_ok=True)
    ckpt = torch.load(run / "best.pt", weights_only=False)
    torch.save({k: ckpt[k] for k in ("model", "anchors", "config", "epoch")}, CHECKPOINTS / f"{name}.pt")
    onnx_path = export_checkpoint(
        CHECKPOINTS / f"{name}.pt",
        MODELS / f"{name}.onnx",
        name=f"dgan-ethucy-{name}",
        description=f"DGAN trained leave-one-scene-out on ETH/UCY, test scene {cfg['data']['scene']}; "
        "non-commercial research use only (ETH/UCY licence).",
    )
    metrics = evaluate(dgan.Predictor(onnx_path), data_root, cfg["data"]["scene"])
    (MODELS / f"{name}.md").write_text(card(name, run, metrics, cfg))
    (run / "metrics.json").write_text(json.dumps(metrics, indent=2))
    return metrics


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("run", type=Path)
    ap.add_argument("--name", required=True)
    ap.add_argument("--data-root", type=Path, default=Path("../shared/data"))
    a = ap.parse_args()
    print(json.dumps(bundle(a.run, a.name, a.data_root.expanduser()), indent=2))


if __name__ == "__main__":
    main()
