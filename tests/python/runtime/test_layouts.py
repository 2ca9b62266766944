"""The headerless layouts of public datasets that ``dgan predict`` and ``dgan evaluate`` read (dgan.layouts)."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest
from conftest import shared_data

import dgan
from dgan.cli import main
from dgan.exceptions import InvalidFrameError
from dgan.layouts import LAYOUTS, layout_of, read

BUNDLED = Path(dgan.__file__).parent / "data"
APOLLO = BUNDLED / "apolloscape" / "result_9048_1_frames_10_25.txt"
SDD = BUNDLED / "sdd" / "hyang_0" / "frames_824_853.txt"
HYANG0_M_PER_PX = dgan.demo.SDD_SCALE  # hyang video0 in estimated_scales.yaml


def test_each_layout_is_told_by_its_first_row() -> None:
    rows = {
        "social-gan": "0.0 1.0 8.46 3.59",
        "sdd-steps": "824 2.0 758.5 1148.5 Pedestrian",
        "sdd-annotations": '0 473 208 504 235 0 0 0 0 "Pedestrian"',
        "apolloscape": "0 1 2 119.459 64.591 39.448 11.101 3.134 3.276 -3.116",
    }
    assert [layout.name for layout in LAYOUTS] == list(rows)
    for name, row in rows.items():
        layout = layout_of(row)
        assert layout is not None
        assert layout.name == name
    # OpenTraj's ETH obsmat (frame id x z y vx vz vy): eight numbers, whose third and fourth are not x and y.
    assert layout_of("780 1 8.46 0 3.59 1.2 0 0.3") is None
    assert layout_of("1 2 3") is None
    assert layout_of("1 2 3 Pedestrian") is None


def test_apolloscape_rows_become_the_columns_of_their_fields() -> None:
    cols, unit, layout = read(APOLLO)
    raw = np.loadtxt(APOLLO)
    assert layout.name == "apolloscape"
    assert unit == 0.5
    np.testing.assert_array_equal(cols["time"], raw[:, 0])
    np.testing.assert_array_equal(cols["agent_id"], raw[:, 1].astype(np.int64))
    for name, column in (("x", 3), ("y", 4), ("length", 6), ("width", 7), ("heading", 9)):
        np.testing.assert_array_equal(cols[name], raw[:, column])
    classes = {1: "vehicle", 2: "vehicle", 3: "pedestrian", 4: "cyclist", 5: "cyclist"}
    assert list(cols["class"]) == [classes[int(t)] for t in raw[:, 2]]


def test_the_bundled_excerpts_predict_as_the_demo_scenes() -> None:
    """Read by their layouts, the bundled ApolloScape and Stanford Drone excerpts give the demo's frames exactly."""
    for model, path, scale, scene, now in (
        ("apolloscape", APOLLO, None, dgan.demo.apollo_scene, 17.0),
        ("sdd", SDD, HYANG0_M_PER_PX, dgan.demo.sdd_scene, 841.0),
    ):
        p = dgan.Predictor(model)
        cols, unit, _ = read(path, scale)
        frame = dgan.Frame.from_records(cols, t_obs=p.spec.t_obs, dt=p.spec.dt_s, time_unit=unit, current_time=now)
        demo = scene(p.spec.t_obs, p.spec.t_f, now).frame
        assert frame.ids.tolist() == demo.ids.tolist()
        assert frame.classes == demo.classes
        for got, want in ((frame.positions, demo.positions), (frame.mask, demo.mask), (frame.lengths, demo.lengths)):
            np.testing.assert_array_equal(got, want)
        np.testing.assert_array_equal(frame.headings, demo.headings)
        ours, theirs = p.predict(frame.with_map(demo.map)), p.predict(demo)
        np.testing.assert_array_equal(ours.trajectories, theirs.trajectories)


def test_a_stanford_drone_videos_annotations_give_its_steps_frames() -> None:
    """The annotations.txt of quad video0 (30 frames a second, boxes) and Multiclass-SGCN's steps of the same video
    (every 10th frame, box centres): each step's agents at the same metres, and the same frame. The annotations
    marked lost (outside the view) are left out; the steps file keeps them."""
    root = shared_data("sdd")
    scale = 0.043606807  # quad video0 in estimated_scales.yaml
    steps_path = root / "sdd" / "multiclass_step10" / "test" / "stan_quad_0.txt"
    notes_path = root / "sdd" / "raw_annotations" / "quad" / "video0" / "annotations.txt"
    steps, step_unit, _ = read(steps_path, scale)
    notes, note_unit, layout = read(notes_path, scale)
    assert layout.name == "sdd-annotations"
    assert (step_unit, note_unit) == (1 / 3, 1 / 30)
    lost = {(int(r[5]), int(r[0])) for r in np.loadtxt(notes_path, dtype=str) if r[6] == "1"}
    named = (notes[k] for k in ("time", "agent_id", "x", "y"))
    at = {(int(t), int(i)): (x, y) for t, i, x, y in zip(*named, strict=True)}
    assert len(at) + len(lost) == len(notes_path.read_text().splitlines())
    for t, i, x, y in zip(*(steps[k] for k in ("time", "agent_id", "x", "y")), strict=True):
        key = (int(t) * 10, int(i))
        assert key in lost or at[key] == pytest.approx((x, y), abs=1e-9)
    spec = dgan.Predictor("sdd").spec
    now = 20.0  # a step whose window holds no lost annotation of the steps' agents; its frame is 200
    by_steps = dgan.Frame.from_records(steps, t_obs=spec.t_obs, dt=spec.dt_s, time_unit=step_unit, current_time=now)
    by_notes = dgan.Frame.from_records(
        notes, t_obs=spec.t_obs, dt=spec.dt_s, time_unit=note_unit, current_time=now * 10
    )
    assert len(by_steps.ids) >= 3
    assert set(by_steps.ids.tolist()) <= set(by_notes.ids.tolist())
    rows = [by_notes.ids.tolist().index(i) for i in by_steps.ids.tolist()]
    np.testing.assert_array_equal(by_notes.mask[rows], by_steps.mask)
    np.testing.assert_allclose(by_notes.positions[rows], by_steps.positions, atol=1e-9)


def test_the_command_line_reads_the_layouts_and_says_which(capsys: pytest.CaptureFixture[str]) -> None:
    assert main(["predict", "apolloscape", str(APOLLO), "--time", "17", "--json"]) == 0
    captured = capsys.readouterr()
    assert "read as apolloscape (frame id type x y z length width height heading" in captured.err
    assert '"agents"' in captured.out or '"ids"' in captured.out
    assert main(["predict", "sdd", str(SDD)]) == 2
    assert "give --metres-per-pixel S" in capsys.readouterr().err
    assert main(["evaluate", "sdd", str(SDD), "--metres-per-pixel", str(HYANG0_M_PER_PX)]) == 0
    out = capsys.readouterr().out
    assert "pedestrian" in out


@pytest.mark.parametrize(
    ("text", "message"),
    [
        ("780 1 8.46 0 3.59 1.2 0 0.3\n", "its first row has 8 fields"),
        ("1 2 3 4\n1 2 3\n", "row 2 has 3 fields where the social-gan layout has 4"),
        ("1 2 3 x4\n", "its first row has 4 fields"),
        ("1 2.5 3 4\n", "agent ids must be whole numbers"),
        ("0 1 7 1 2 0 4 2 1 0\n", "ApolloScape object types are 1..5, found [7.0]"),
        ("0 1 2 1 x 0 4 2 1 0\n", "a field of the apolloscape layout is not a number"),
        ("", "its first row has 0 fields"),
    ],
)
def test_a_file_of_no_known_layout_is_refused(tmp_path: Path, text: str, message: str) -> None:
    path = tmp_path / "scene.txt"
    path.write_text(text)
    with pytest.raises(InvalidFrameError, match="^" + str(path).replace(".", r"\.")) as e:
        read(path)
    assert message in str(e.value)


@pytest.mark.parametrize("scale", [0.0, -1.0, float("nan"), float("inf"), "0.03", True])
def test_a_pixel_layout_takes_a_positive_scale(scale: object) -> None:
    with pytest.raises(InvalidFrameError, match="metres per pixel must be a positive number"):
        read(SDD, scale)  # type: ignore[arg-type]


def test_a_path_of_the_wrong_kind_is_refused() -> None:
    with pytest.raises(InvalidFrameError, match="a scene file's path must be a str or a path, got int"):
        read(5)  # type: ignore[arg-type]
    with pytest.raises(InvalidFrameError, match="cannot read scene"):
        read(BUNDLED)


def test_files_of_one_name_in_several_folders_are_told_apart(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    """Every Stanford Drone video's annotations are called annotations.txt: a glob of them names each scene by its
    path from their common folder, and the layout is said once."""
    import pyarrow.parquet as pq

    for video in ("video0", "video1"):
        (tmp_path / "hyang" / video).mkdir(parents=True)
        (tmp_path / "hyang" / video / "frames.txt").write_text(SDD.read_text())
    out = tmp_path / "all.parquet"
    pattern = str(tmp_path / "hyang" / "video*" / "frames.txt")
    assert main(["predict", "sdd", pattern, "--metres-per-pixel", str(HYANG0_M_PER_PX), "--out", str(out)]) == 0
    assert capsys.readouterr().err.count("read as sdd-steps") == 1
    assert set(pq.read_table(out).column("scene").to_pylist()) == {"video0/frames.txt", "video1/frames.txt"}
    assert main(["evaluate", "sdd", pattern, "--metres-per-pixel", str(HYANG0_M_PER_PX), "--json"]) == 0
    assert json.loads(capsys.readouterr().out)["scenes"] == ["video0/frames.txt", "video1/frames.txt"]
