"""The wheel as a user gets it: built, installed into a fresh virtual environment with only the extras a table needs
(pandas, polars, pyarrow; no torch, no onnx), and fed the same real scene as every kind of table."""

from __future__ import annotations

import os
import subprocess
import sys
import textwrap
from pathlib import Path

import pytest
from conftest import ROOT

SCRIPT = textwrap.dedent(
    """
    import importlib.util, sys
    import numpy as np, pandas as pd, polars as pl, pyarrow as pa
    import dgan
    from dgan.demo import SCENE_FILE

    assert importlib.util.find_spec("torch") is None and importlib.util.find_spec("onnx") is None
    assert "site-packages" in dgan.__file__, dgan.__file__
    rows = np.loadtxt(SCENE_FILE)
    cols = {
        "agent_id": np.array([f"ped-{int(i)}" for i in rows[:, 1]], dtype=object),
        "time": rows[:, 0] * 0.04,
        "x": rows[:, 2],
        "y": rows[:, 3],
    }
    tables = {
        "dict": cols,
        "records": [dict(zip(cols, r)) for r in zip(*(v.tolist() for v in cols.values()))],
        "pandas": pd.DataFrame(cols),
        "polars": pl.DataFrame({k: v.tolist() for k, v in cols.items()}),
        "pyarrow": pa.table({k: v.tolist() for k, v in cols.items()}),
    }
    p = dgan.Predictor("zara1")
    preds = {
        name: p.predict(dgan.Frame.from_records(t, spec=p, current_time=220.0, map=dgan.scene_map("zara1")))
        for name, t in tables.items()
    }
    ref = preds["dict"]
    assert len(ref) == 18 and ref.agent_ids[0] == "ped-76"
    for name, pred in preds.items():
        assert pred.agent_ids.tolist() == ref.agent_ids.tolist(), name
        assert np.array_equal(pred.trajectories, ref.trajectories), name
        assert np.array_equal(pred.probabilities, ref.probabilities), name
    table = pred.to_pandas()
    assert table.shape == (18 * p.num_modes * 12, 10), table.shape
    assert np.allclose(table["time"].to_numpy()[:2], [220.4, 220.8]), table["time"][:2]  # the table's own seconds
    print("identical across", sorted(preds))
    """
)


@pytest.mark.slow
def test_wheel_in_a_fresh_venv_reads_every_table_kind(tmp_path: Path) -> None:
    env = {k: v for k, v in os.environ.items() if k not in ("VIRTUAL_ENV", "PYTHONPATH", "ORT_DYLIB_PATH")}
    maturin = Path(sys.executable).with_name("maturin")
    dist = tmp_path / "dist"
    subprocess.run(
        [str(maturin), "build", "--release", "-q", "-o", str(dist)], cwd=ROOT, env=env, check=True, timeout=900
    )
    (wheel,) = dist.glob("dgan-*.whl")
    venv = tmp_path / "venv"
    subprocess.run([sys.executable, "-m", "venv", str(venv)], check=True)
    py = venv / "bin" / "python"
    pins = [
        line
        for line in (ROOT / "requirements-dev.txt").read_text().splitlines()
        if line.startswith(("pandas", "polars", "pyarrow"))
    ]
    pins += [line for line in (ROOT / "requirements-train.txt").read_text().splitlines() if line.startswith("pyarrow")]
    assert len(pins) == 3, pins
    subprocess.run([str(py), "-m", "pip", "install", "-q", str(wheel), *pins], env=env, check=True, timeout=900)
    out = subprocess.run([str(py), "-c", SCRIPT], cwd=tmp_path, env=env, capture_output=True, text=True, timeout=300)
    if out.returncode:
        pytest.fail(f"the script failed in the fresh venv:\n{out.stdout}\n{out.stderr}")
    assert "identical across ['dict', 'pandas', 'polars', 'pyarrow', 'records']" in out.stdout
