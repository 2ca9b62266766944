"""Shared fixtures: the contract models of ``tests/fixtures`` and a real frame from the bundled zara1 excerpt."""

from __future__ import annotations

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
