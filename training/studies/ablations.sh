#!/usr/bin/env bash
# The ablations of docs/results.md on one fold (default zara1), each trained for the same budget (10 epochs):
# the full model; without the map branch; without the GAT (map and anchors alone, close to MultiPath); without
# neighbour geometry on the edges; K_c = 5 and 10 anchors; and the paper's loss alone (no top-mode term, β = 0).
# Then each is evaluated with the engine. SEEDS (default "0") repeats the variants in VARIANTS (default all) with
# other seeds, in runs/ablation_<scene>_<variant>_s<seed>; docs/results.md averages over them.
#   bash training/studies/ablations.sh [SCENE] [DATA_ROOT]
#   SEEDS="1" VARIANTS="full no_edge_geometry" bash training/studies/ablations.sh zara1
set -euo pipefail
scene="${1:-zara1}"
root="${2:-../shared/data}"
py="${PYTHON:-python}"
cd "$(dirname "${BASH_SOURCE[0]}")/../.."
declare -A variants=(
  [full]=""
  [no_map]="--set model.use_map=false"
  [no_gat]="--set model.use_gat=false"
  [no_edge_geometry]="--set model.use_edge_features=false"
  [k5]="--set train.anchors_per_class=5"
  [k10]="--set train.anchors_per_class=10"
  [paper_loss]="--set train.beta=0"
)
for seed in ${SEEDS:-0}; do
  for name in ${VARIANTS:-full no_map no_gat no_edge_geometry k5 k10 paper_loss}; do
    out="runs/ablation_${scene}_${name}"
    [ "$seed" = 0 ] || out="${out}_s${seed}"
    if [ ! -f "$out/model.onnx" ]; then
      # shellcheck disable=SC2086
      PYTHONPATH=. "$py" -m training.train --config "training/configs/ethucy_${scene}.toml" --out "$out" \
        --set train.epochs=10 --set "train.seed=$seed" --set "data.root=$root" ${variants[$name]}
    fi
    PYTHONPATH=. "$py" -m training.evaluate "$out/model.onnx" --scene "$scene" --data-root "$root" --json "$out/metrics.json" >/dev/null
    echo "ablation $name seed $seed done"
  done
done
