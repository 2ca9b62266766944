"""training.studies.seed: the spread over members and the averaged ensemble, on synthetic futures whose errors are
known, and on real runs (the bundled driving model twice, as two members)."""

from __future__ import annotations

import json
from dataclasses import asdict
from pathlib import Path

import numpy as np
import pytest

pytest.importorskip("torch")

from training.config import Config
from training.studies import seed as ss

ROOT = Path(__file__).resolve().parents[3]
DATA = ROOT.parent / "shared" / "data"


def test_averaging_two_members_on_either_side_of_the_truth_is_exact() -> None:
    truth = np.zeros((4, 3, 2))
    truth[:, :, 0] = np.arange(1, 4)
    offset = np.array([0.0, 1.0])
    top1 = np.stack([truth + offset, truth - offset])  # 1 m left and right of the truth at every step
    cv = {"last2": truth[:, None] + 2.0, "mean1s": truth[:, None] + np.array([0.0, 3.0])}
    classes = np.array(["vehicle", "vehicle", "pedestrian", "pedestrian"])
    f = ss.figures(top1, truth, cv, classes)
    assert f["all"]["member_ade"] == pytest.approx([1.0, 1.0])
    assert f["all"]["ade"] == {"mean": 1.0, "sd": 0.0, "min": 1.0, "max": 1.0}
    assert f["all"]["averaged"]["2"] == {"ade": 0.0, "fde": 0.0}
    # Constant velocity: the better variant per error (mean1s is 3 m off, last2 2·√2 m).
    assert f["vehicle"]["cv_ade"] == pytest.approx(2 * np.sqrt(2))
    assert f["vehicle"]["agents"] == 2
    assert f["pedestrian"]["agents"] == 2


def test_the_averaged_ensembles_take_the_first_members_by_seed() -> None:
    truth = np.zeros((2, 2, 2))
    top1 = np.stack([truth + m for m in range(6)])  # member m is m·√2 m off
    f = ss.figures(top1, truth, {"last2": truth[:, None]}, np.array(["pedestrian"] * 2))
    averaged = f["pedestrian"]["averaged"]
    assert set(averaged) == {"3", "5", "6"}
    assert averaged["3"]["ade"] == pytest.approx(np.sqrt(2))  # the mean of members 0, 1, 2 is member 1
    assert averaged["5"]["ade"] == pytest.approx(2 * np.sqrt(2))
    assert f["pedestrian"]["ade"]["sd"] == pytest.approx(np.std(np.arange(6) * np.sqrt(2), ddof=1))


def _run(tmp_path: Path, name: str, config: str, seed: int, model: Path) -> Path:
    run = tmp_path / name
    run.mkdir()
    cfg = Config.load(ROOT / "training" / "configs" / config, {"train.seed": seed})
    (run / "config.json").write_text(json.dumps({"config": asdict(cfg)}))
    (run / "model.onnx").write_bytes(model.read_bytes())
    return run


@pytest.mark.slow
@pytest.mark.skipif(not (DATA / "nuscenes_mini_scenarionet").is_dir(), reason="needs ../shared/data")
def test_two_identical_members_on_the_validation_scenes(tmp_path: Path) -> None:
    model = ROOT / "python" / "dgan" / "models" / "hdmap.onnx"
    runs = [_run(tmp_path, f"hdmap_s{s}", "hdmap.toml", s, model) for s in (3, 1)]
    (group,) = ss.groups_of(runs)
    assert group.name == "hdmap"
    assert group.seeds == [1, 3]
    assert group.dataset == "hdmap"
    f = ss.measure(group, "val", "hdmap", True, DATA)
    a = f["all"]
    # The same model twice: no spread, and the average of its top-1 with itself is its top-1.
    assert a["member_ade"][0] == a["member_ade"][1]
    assert a["ade"]["sd"] == 0.0
    assert a["averaged"]["2"]["ade"] == pytest.approx(a["member_ade"][0], rel=1e-9)
    assert a["agents"] == sum(f[c]["agents"] for c in f if c != "all") > 0
    assert 0 < a["ade"]["mean"] < a["fde"]["mean"]


def test_runs_are_grouped_by_model_name(tmp_path: Path) -> None:
    model = ROOT / "python" / "dgan" / "models" / "zara1.onnx"
    runs = [_run(tmp_path, n, f"ethucy_{scene}.toml", 0, model) for n, scene in (("a", "zara1"), ("b", "hotel"))]
    runs.append(_run(tmp_path, "c", "ethucy_zara1.toml", 7, model))
    groups = {g.name: g for g in ss.groups_of(runs)}
    assert sorted(groups) == ["ethucy-hotel", "ethucy-zara1"]
    assert groups["ethucy-zara1"].seeds == [0, 7]
    assert groups["ethucy-zara1"].fold == "zara1"
