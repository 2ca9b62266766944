"""Dataset readers, kept outside the runtime's import path: ``import dgan`` loads the engine, frames, maps and the
predictor, and none of these; a reader module is imported when it is first used.

The registry maps a format name to its reader (``module:function``). Each reader turns a source's file or folder into
a :class:`dgan.datasets.scenario.Scenario` (every agent's states on the source's grid and the scene's vector map),
whose :meth:`~dgan.datasets.scenario.Scenario.frame` cuts a :class:`dgan.Frame` at any step:

>>> from dgan import datasets
>>> datasets.formats()
('argoverse2_scenario', 'argoverse2_sensor_log', 'interaction', 'scenarionet', 'waymo_json')
>>> scenario = datasets.read("waymo_motion_samples/gpudrive_json/<id>.json.gz")  # doctest: +SKIP

The ETH/UCY, Stanford Drone and ApolloScape readers that training uses live in ``training.data.datasets``.
"""

from __future__ import annotations

import importlib
import os
from collections.abc import Callable
from pathlib import Path
from typing import TYPE_CHECKING, Any, Final

from dgan.exceptions import InvalidFrameError

if TYPE_CHECKING:
    from dgan.datasets.scenario import Scenario

__all__ = ["JSON_SUFFIXES", "PICKLE_SUFFIXES", "formats", "is_scenario", "read", "reader", "register"]

#: The file names :func:`read` guesses as ScenarioNet / MetaDrive pickles.
PICKLE_SUFFIXES: Final = (".pkl", ".pkl.gz")
#: The file names :func:`read` guesses as JSON scenarios (GPUDrive / Nocturne, or ScenarioNet's JSON).
JSON_SUFFIXES: Final = (".json", ".json.gz")

#: Format name → ``"module:function"`` of its reader.
_REGISTRY: dict[str, str] = {
    "scenarionet": "dgan.datasets.scenarionet:read_scenarionet",
    "waymo_json": "dgan.datasets.waymo_json:read_waymo_json",
    "argoverse2_scenario": "dgan.datasets.argoverse2:read_av2_scenario",
    "argoverse2_sensor_log": "dgan.datasets.argoverse2:read_av2_sensor_log",
    "interaction": "dgan.datasets.lanelet2:read_interaction",
}


def register(name: str, target: str) -> None:
    """Adds a reader: ``target`` is ``"package.module:function"``, a function of one path returning a Scenario."""
    module, sep, function = target.partition(":")
    if not (name and module and sep and function):
        raise ValueError(f"a reader is registered as 'module:function', got {target!r} for {name!r}")
    _REGISTRY[name] = target


def formats() -> tuple[str, ...]:
    """The registered format names."""
    return tuple(sorted(_REGISTRY))


def reader(name: str) -> Callable[[str | os.PathLike[str]], Scenario]:
    """The reader of a format, imported now."""
    if name not in _REGISTRY:
        raise InvalidFrameError(f"unknown scenario format {name!r}; registered: {', '.join(formats())}")
    module, _, function = _REGISTRY[name].partition(":")
    fn: Callable[[str | os.PathLike[str]], Scenario] = getattr(importlib.import_module(module), function)
    return fn


def is_scenario(path: str | os.PathLike[str]) -> bool:
    """Whether :func:`read` takes ``path`` for a scenario by its name: a pickle or JSON file, an Argoverse 2 sensor-log
    folder (``annotations.feather``) or scenario folder (``scenario_*.parquet``). No reader is imported."""
    path = Path(path)
    if path.is_dir():
        return (path / "annotations.feather").is_file() or any(path.glob("scenario_*.parquet"))
    return path.name.lower().endswith(PICKLE_SUFFIXES + JSON_SUFFIXES)


def read(path: str | os.PathLike[str], format: str | None = None) -> Scenario:
    """A scenario from ``path``, by its registered ``format``, or guessed from the path when None (``*.pkl``:
    ScenarioNet; ``*.json[.gz]``: Waymo GPUDrive JSON; an Argoverse 2 scenario or sensor-log folder)."""
    if format is not None:
        return reader(format)(path)
    hdmaps: Any = importlib.import_module("dgan.datasets.hdmaps")
    scenario: Scenario = hdmaps.read_scenario(path)
    return scenario
