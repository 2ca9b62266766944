"""Models shipped with dgan, by name: ``dgan.Predictor("zara1")``.

The ETH/UCY models (``eth``, ``hotel``, ``univ``, ``zara1``, ``zara2``) are each trained leave-one-scene-out:
on the other four scenes, never on the one they are named after, which is their test scene. Each has a model card
(:func:`card`). They are trained on ETH/UCY, which is for non-commercial research use only.
"""

from __future__ import annotations

from importlib import resources
from pathlib import Path

from dgan.exceptions import ModelNotFoundError

__all__ = ["card", "list", "path"]

_HERE = Path(str(resources.files(__name__)))


def list() -> tuple[str, ...]:
    """Names of the bundled models."""
    return tuple(sorted(p.stem for p in _HERE.glob("*.onnx")))


def path(name: str) -> Path:
    """The ONNX file of a bundled model."""
    p = _HERE / f"{name}.onnx"
    if not p.is_file():
        raise ModelNotFoundError(f"no bundled model named {name!r}; bundled models: {', '.join(list()) or 'none'}")
    return p


def card(name: str) -> str:
    """The model card (Markdown) of a bundled model."""
    path(name)
    return (_HERE / f"{name}.md").read_text()
