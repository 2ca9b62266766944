"""dgan.ray: a dataset of scenes on a local Ray cluster of two workers equals the serial loop."""

from __future__ import annotations

import pickle

import numpy as np
import pytest
from conftest import zara1_records

import dgan
from dgan.ray import Predict, predict_scenes


def scenes(n: int) -> dict[str, np.ndarray]:
    """``n`` scenes: the bundled zara1 excerpt, each shifted in space and ending at another time."""
    rec = zara1_records()
    parts = []
    for k in range(n):
        end = 5500.0 + 10.0 * (k % 8)
        keep = rec["time"] <= end
        parts.append({"scene_id": np.full(keep.sum(), f"s{k}", dtype=object), **{c: v[keep] for c, v in rec.items()}})
        parts[-1]["x"] = parts[-1]["x"] + 100.0 * k
    return {c: np.concatenate([p[c] for p in parts]) for c in parts[0]}


def test_predict_scenes_equals_a_loop_of_predict() -> None:
    p = dgan.Predictor("zara1", sessions=1)
    table = scenes(3)
    out = predict_scenes(p, table, modes=2, time_unit=0.04)
    rows = table["scene_id"] == "s1"
    one = p.predict(dgan.Frame.from_records({k: v[rows] for k, v in table.items()}, spec=p, time_unit=0.04), modes=2)
    mine = out["scene_id"] == "s1"
    np.testing.assert_array_equal(out["x"][mine], one.to_records()["x"])
    assert list(dict.fromkeys(out["scene_id"].tolist())) == ["s0", "s1", "s2"]
    callable_ = pickle.loads(pickle.dumps(Predict("zara1", modes=2, time_unit=0.04)))
    np.testing.assert_array_equal(callable_(table)["y"], out["y"])
    with pytest.raises(dgan.exceptions.InvalidFrameError, match="no scene column 'scene'"):
        predict_scenes(p, table, scene_column="scene")


@pytest.mark.slow
def test_two_ray_workers_equal_the_serial_loop() -> None:
    ray = pytest.importorskip("ray")
    import pyarrow as pa

    table = scenes(12)
    serial = predict_scenes(dgan.Predictor("zara1", sessions=1), table, modes=3, time_unit=0.04)
    ray.init(num_cpus=4, include_dashboard=False, log_to_driver=False, configure_logging=False)
    try:
        ray.data.DataContext.get_current().enable_progress_bars = False
        ds = ray.data.from_arrow(pa.table(table))
        out = ds.groupby("scene_id", num_partitions=2).map_groups(
            Predict,
            fn_constructor_kwargs={"model": "zara1", "modes": 3, "time_unit": 0.04},
            concurrency=2,
            batch_format="pyarrow",
        )
        got = out.to_pandas()
    finally:
        ray.shutdown()
    assert len(got) == len(serial["x"])
    got = got.sort_values(["scene_id", "agent_id", "mode", "step"]).reset_index(drop=True)
    order = np.lexsort((serial["step"], serial["mode"], serial["agent_id"], serial["scene_id"].astype(str)))
    for col in ("agent_id", "mode", "step", "x", "y", "probability"):
        np.testing.assert_allclose(got[col].to_numpy(), serial[col][order], atol=1e-6)
    assert got["scene_id"].tolist() == serial["scene_id"][order].tolist()
