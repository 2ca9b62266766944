"""Bundling trained models into the package: slim checkpoints, ONNX exports, model cards."""
