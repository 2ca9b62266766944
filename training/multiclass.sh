#!/usr/bin/env bash
# Train the multi-class models and their per-class baselines (issue 4): for each dataset in DATASETS (default
# "sdd apolloscape"), one model for all classes, then the same code on one class at a time. A run whose model.onnx
# exists is skipped. Outputs: runs/<dataset>[-<class>]/. Extra arguments go to every training.train call.
set -euo pipefail
cd "$(dirname "$0")/.."
PY="${PYTHON:-python}"
for ds in ${DATASETS:-sdd apolloscape}; do
  for cls in "" ${CLASSES:-vehicle cyclist pedestrian}; do
    out="runs/${ds}${cls:+-$cls}"
    [ -f "$out/model.onnx" ] && { echo "skip $out"; continue; }
    echo "== $out"
    "$PY" -m training.train --config "training/configs/$ds.toml" --out "$out" ${cls:+--set data.target_class=$cls} "$@"
  done
done
