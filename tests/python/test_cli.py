"""The ``dgan`` command line."""

from __future__ import annotations

import json
from pathlib import Path

import pytest
from conftest import DATA

import dgan
from dgan.cli import main

SCENE = DATA / "frames_5430_5620.txt"


def test_info(nomap_model: Path, capsys: pytest.CaptureFixture[str]) -> None:
    assert main(["info", str(nomap_model)]) == 0
    out = capsys.readouterr().out
    assert "observes 8 steps, predicts 12 (4.8 s)" in out
    assert "pedestrian (2 anchors)" in out
    assert "no map branch" in out


def test_predict_a_real_scene(nomap_model: Path, capsys: pytest.CaptureFixture[str]) -> None:
    assert main(["predict", str(nomap_model), str(SCENE), "--time", "5500", "--modes", "2"]) == 0
    out = capsys.readouterr().out
    assert out.startswith("18 agents")
    assert len(out.strip().splitlines()) == 19


def test_predict_json_and_csv(nomap_model: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    csv = tmp_path / "scene.csv"
    rows = ["agent_id,time,x,y,class"] + [
        f"{a},{t * 0.4:.1f},{t * 0.5 + a},{a},cyclist" for a in range(3) for t in range(8)
    ]
    csv.write_text("\n".join(rows) + "\n")
    assert main(["predict", str(nomap_model), str(csv), "--json", "--modes", "1"]) == 0
    out = json.loads(capsys.readouterr().out)
    assert out["agent_ids"] == [0, 1, 2]
    assert len(out["trajectories"][0][0]) == 12


def test_errors_exit_2_with_a_message(nomap_model: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    assert main(["predict", str(tmp_path / "none.onnx"), str(SCENE)]) == 2
    assert "model file not found" in capsys.readouterr().err
    bad = tmp_path / "bad.txt"
    bad.write_text("1 2\n3 4\n")
    assert main(["predict", str(nomap_model), str(bad)]) == 2
    assert "expected 4 columns" in capsys.readouterr().err


@pytest.mark.parametrize(
    ("model", "expected"),
    [
        ("zara1", "18 agents of zara1 at step 5500"),
        ("sdd", "22 agents of Stanford Drone hyang video0 at step 841"),
        ("apolloscape", "agents of ApolloScape recording 9048 at step 17"),
        ("hdmap", "45 agents of Waymo Open Motion 2bd577a009790706 at step 40"),
    ],
)
def test_demo_prints_and_draws(model: str, expected: str, tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    out = tmp_path / "demo.png"
    assert main(["demo", "--model", model, "--out", str(out)]) == 0
    text = capsys.readouterr().out
    assert expected in text
    assert out.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    assert out.stat().st_size > 50_000
    crop = out.with_name("demo_crop.png")
    has_map = dgan.Predictor(model).spec.map is not None
    assert crop.is_file() == has_map  # one agent's map crop, for the models with a map branch
    if has_map:
        assert "one agent's map crop" in text
