"""Shared fixtures: the contract models of ``tests/fixtures`` and a real frame from the bundled zara1 excerpt."""

from __future__ import annotations

import functools
import inspect
import os
import sys
from pathlib import Path

import numpy as np
import pytest

import dgan

ROOT = Path(__file__).resolve().parents[2]
FIXTURES = ROOT / "tests" / "fixtures"
DATA = ROOT / "python" / "dgan" / "data" / "zara1"
SCENES = ROOT / "python" / "dgan" / "data" / "scenes"
sys.path.insert(0, str(FIXTURES))


def shared_data(needs: str) -> Path:
    """The shared data root (``DGAN_DATA_ROOT``, default ``../shared/data`` beside the clone), which must hold
    ``needs``."""
    root = Path(os.environ.get("DGAN_DATA_ROOT", ROOT.parent / "shared" / "data"))
    if not (root / needs).is_dir():
        pytest.fail(f"shared data not found under {root}; set DGAN_DATA_ROOT to the folder holding {needs}/")
    return root


def _source(f: object) -> str:
    try:
        return inspect.getsource(f)  # type: ignore[arg-type]
    except (TypeError, OSError):
        return ""


@functools.cache
def _data_calls(module: object) -> frozenset[str]:
    """``shared_data(`` and the calls of the module's functions that reach it (directly or through each other)."""
    own = {n: _source(f) for n, f in vars(module or object()).items() if inspect.isfunction(f)}
    calls = {"shared_data("}
    while more := {f"{n}(" for n, text in own.items() if any(c in text for c in calls)} - calls:
        calls |= more
    return frozenset(calls)


def _reads_shared_data(item: pytest.Item) -> bool:
    """Whether a test, a fixture it uses or a function of its module that it calls (directly or through another)
    calls :func:`shared_data`."""
    calls = _data_calls(getattr(item, "module", None))
    funcs: list[object] = [getattr(item, "function", None)]
    info = getattr(item, "_fixtureinfo", None)
    if info is not None:
        funcs += [d.func for defs in info.name2fixturedefs.values() for d in defs]
    return any(call in _source(f) for f in funcs for call in calls)


def pytest_collection_modifyitems(items: list[pytest.Item]) -> None:
    """Marks every test that reads the shared data ``needs_data`` (``./dev test --quick`` deselects them)."""
    for item in items:
        if _reads_shared_data(item):
            item.add_marker(pytest.mark.needs_data)


@pytest.fixture(scope="session")
def nomap_model() -> Path:
    return FIXTURES / "contract_nomap.onnx"


@pytest.fixture(scope="session")
def map_model() -> Path:
    return FIXTURES / "contract_map.onnx"


def zara1_records() -> dict[str, np.ndarray]:
    rows = np.loadtxt(DATA / "frames_5430_5620.txt")
    return {"time": rows[:, 0], "agent_id": rows[:, 1].astype(np.int64), "x": rows[:, 2], "y": rows[:, 3]}


def zara1_raster_map() -> dgan.RasterMap:
    return dgan.RasterMap.from_pixel_to_world(SCENES / "zara1" / "rgb.jpg", np.loadtxt(SCENES / "zara1" / "H.txt"))


@pytest.fixture
def zara1_frame() -> dgan.Frame:
    """Every pedestrian seen at frame 5500 of zara1, 8 steps of 0.4 s (frame ids step by 10)."""
    return dgan.Frame.from_records(zara1_records(), t_obs=8, dt=0.4, time_unit=0.04, current_time=5500.0)


def interaction_recording(folder: Path) -> tuple[Path, Path]:
    """The format sample's vehicle file and a pedestrian file of the same recording beside it (INTERACTION's
    pedestrian columns; frames 3-40, so the two files start on different frames): two walkers and a cyclist."""
    folder.mkdir(parents=True, exist_ok=True)
    vehicles = folder / "vehicle_tracks_000.csv"
    sample = shared_data("interaction_format_sample") / "interaction_format_sample"
    vehicles.write_text((sample / "recorded_trackfiles/TestScenarioForScripts/vehicle_tracks_000.csv").read_text())
    rows = ["track_id,frame_id,timestamp_ms,agent_type,x,y,vx,vy"]
    for track, kind, x0, speed in (("P1", "pedestrian", 10.0, 1.2), ("P2", "pedestrian/bicycle", 30.0, -1.0)):
        rows += [f"{track},{f},{100 * f},{kind},{x0 + speed * 0.1 * f:.2f},-1.5,{speed},0" for f in range(3, 41)]
    rows += [f"P7,{f},{100 * f},bicycle,{5 + 0.4 * f:.2f},8.0,4.0,0" for f in range(10, 36)]
    pedestrians = folder / "pedestrian_tracks_000.csv"
    pedestrians.write_text("\n".join(rows) + "\n")
    return vehicles, pedestrians
