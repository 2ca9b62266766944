"""Models shipped with dgan, by name: ``dgan.Predictor("zara1")``.

The ETH/UCY models (``eth``, ``hotel``, ``univ``, ``zara1``, ``zara2``) are each trained leave-one-scene-out:
on the other four scenes, never on the one they are named after, which is their test scene. Each has a model card
(:func:`card`). They are trained on ETH/UCY, which is for non-commercial research use only.
"""

from __future__ import annotations

import json
import os
from dataclasses import dataclass
from importlib import resources
from pathlib import Path

from dgan import _dgan
from dgan._runtime import onnxruntime_library
from dgan.exceptions import ModelNotFoundError

__all__ = ["ModelInfo", "card", "info", "list", "map_kind", "path"]

#: The map each bundled model was trained with (the contract says only the crop's size).
MAP_KINDS = {
    "eth": "raster: ETH/UCY scene mask",
    "hotel": "raster: ETH/UCY scene mask",
    "univ": "raster: ETH/UCY scene mask",
    "zara1": "raster: ETH/UCY scene mask",
    "zara2": "raster: ETH/UCY scene mask",
    "sdd": "raster: SDD reference image",
    "apolloscape": "none",
    "hdmap": "vector: HD map (lanes, edges)",
}

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


@dataclass(frozen=True)
class ModelInfo:
    """What ``dgan models`` lists of a bundled model."""

    name: str
    dt_s: float
    t_obs: int
    t_f: int
    classes: tuple[str, ...]
    map_kind: str
    map_optional: bool
    licence: str


def map_kind(name: str, contract: dict[str, object]) -> str:
    """The kind of map a model takes: a bundled model's own, or what its contract says."""
    if name in MAP_KINDS:
        return MAP_KINDS[name]
    return "none" if contract.get("map") is None else "raster or vector (crop in the contract)"


def info(name: str) -> ModelInfo:
    """A bundled model's time base, classes, map kind and licence, from its contract and card."""
    spec = json.loads(_dgan.Predictor(os.fspath(path(name)), os.fspath(onnxruntime_library())).contract_json)
    licence = "see the model card"
    for line in card(name).splitlines():
        if "Licence" in line:
            licence = "non-commercial research only" if "non-commercial" in line.lower() else line.split(":", 1)[-1]
            break
    return ModelInfo(
        name=name,
        dt_s=float(spec.get("dt_s", float("nan"))),
        t_obs=int(spec.get("t_obs", 0)),
        t_f=int(spec.get("t_f", 0)),
        classes=tuple(spec.get("classes", ())),
        map_kind=map_kind(name, spec),
        map_optional=bool((spec.get("map") or {}).get("optional", False)),
        licence=licence.strip(),
    )
