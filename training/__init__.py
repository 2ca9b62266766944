"""Training, evaluation and export of DGAN models (PyTorch). Install with ``pip install -e ".[train]"`` and run from
the repository root, e.g. ``python -m training.train --config training/configs/ethucy_zara1.toml``.

Preprocessing goes through :func:`dgan.preprocess`, the engine's own code, so training and inference cannot drift.
"""
