"""dgan.plot and dgan.viz.log_rerun on real predictions."""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path

import matplotlib
import numpy as np
import pytest
from conftest import zara1_records

import dgan
from dgan import exceptions as exc
from dgan.demo import waymo_scene, zara1_scene
from dgan.viz import log_rerun, render_map

matplotlib.use("Agg")


def zara1() -> tuple[dgan.Frame, dgan.Prediction, dict[int, np.ndarray]]:
    rec = zara1_records()
    p = dgan.Predictor("zara1", modes=3)
    frame = dgan.Frame.from_records(rec, spec=p, time_unit=0.04, current_time=5500, map=dgan.scene_map("zara1"))
    truth = {a: np.c_[rec["x"], rec["y"]][(rec["agent_id"] == a) & (rec["time"] > 5500)] for a in frame.agent_ids}
    return frame, p.predict(frame), truth


def test_plot_draws_in_metres_with_map_truth_and_legend(tmp_path: Path) -> None:
    frame, pred, truth = zara1()
    fig = dgan.plot(frame, pred, ground_truth=truth, title="zara1")
    ax = fig.axes[0]
    assert ax.get_xlabel() == "x (m)"
    assert ax.get_ylabel() == "y (m)"
    labels = [t.get_text() for t in ax.get_legend().get_texts()]
    assert labels == ["observed pedestrian", "ground truth", "predicted modes (4.8 s)"]
    assert len(ax.images) == 1  # the map underneath
    # 18 observed paths, 18 × 3 modes, 18 truths (plus the legend's proxies and current positions).
    assert len(ax.lines) >= 18 * 5
    out = tmp_path / "plot.png"
    fig.savefig(out)
    assert out.stat().st_size > 20_000


def test_render_map_is_north_up_in_world_metres() -> None:
    # A vector map with one obstacle square east of the centre: it must appear right of the centre, north-up.
    square = np.array([[5.0, -1.0], [7.0, -1.0], [7.0, 1.0], [5.0, 1.0]])
    image, (left, right, bottom, top) = render_map(dgan.VectorMap([("obstacle", square)]), (0.0, 0.0), 20.0, 200)
    assert (left, right) == pytest.approx((-10.05, 9.95))
    assert (bottom, top) == pytest.approx((-9.95, 10.05))
    lit = np.argwhere(image.sum(axis=2) > 0)
    cols = left + (lit[:, 1] + 0.5) * 0.1
    rows = top - (lit[:, 0] + 0.5) * 0.1
    assert cols.min() == pytest.approx(5.0, abs=0.15)
    assert cols.max() == pytest.approx(7.0, abs=0.15)
    assert rows.min() == pytest.approx(-1.0, abs=0.15)
    assert rows.max() == pytest.approx(1.0, abs=0.15)


@pytest.mark.slow
def test_plot_a_vector_map_scene_and_errors(tmp_path: Path) -> None:
    p = dgan.Predictor("hdmap", modes=2)
    scene = waymo_scene(p.spec.t_obs, p.spec.t_f, None)
    pred = p.predict(scene.frame)
    fig = dgan.plot(scene.frame, pred, ground_truth=scene.futures)
    fig.savefig(tmp_path / "hdmap.png")
    other, other_pred, _ = zara1()
    with pytest.raises(exc.InvalidFrameError, match="not of this frame"):
        dgan.plot(scene.frame, other_pred)
    with pytest.raises(exc.InvalidFrameError, match="ground_truth"):
        dgan.plot(other, other_pred, ground_truth=np.zeros((2, 12, 2)))
    for bad in (-1, 0, 1.5, "2", True):  # issue 28: plot(modes=-1) was accepted
        with pytest.raises(exc.InvalidSpecError, match="modes"):
            dgan.plot(other, other_pred, modes=bad)  # type: ignore[arg-type]


def test_plot_over_a_picture_through_its_homography_with_boxes() -> None:
    p = dgan.Predictor("zara1", modes=2)
    scene = zara1_scene(p.spec.t_obs, p.spec.t_f, None)
    assert scene.image is not None
    assert scene.world_to_pixel is not None
    pred = p.predict(scene.frame)
    frame = scene.frame
    headings = {a: 0.5 for a in frame.agent_ids.tolist()}
    camera = dgan.RasterMap(scene.image, scene.world_to_pixel)
    fig = dgan.plot(frame, pred, map=camera, ground_truth=scene.futures, in_pixels=True, headings=headings)
    ax = fig.axes[0]
    rows, cols = scene.image.shape[:2]
    assert ax.get_xlim() == pytest.approx((-0.5, cols - 0.5))
    assert ax.get_ylim() == pytest.approx((rows - 0.5, -0.5))
    assert len(ax.images) == 1  # the picture, not the frame's own map
    # The first line is agent 0's observed path, in the picture's pixels.
    hist = frame.positions[0][frame.mask[0]]
    q = np.c_[hist, np.ones(len(hist))] @ np.asarray(scene.world_to_pixel).T
    np.testing.assert_allclose(ax.lines[0].get_xydata(), q[:, :2] / q[:, 2:], atol=1e-9)
    # One box an agent, centred on its last observed position.
    assert len(ax.patches) == len(frame)
    corners = ax.patches[0].get_xy()[:4]
    centre = np.r_[hist[-1], 1.0] @ np.asarray(scene.world_to_pixel).T
    np.testing.assert_allclose(corners.mean(axis=0), centre[:2] / centre[2], atol=1e-6)


def test_plot_in_pixels_needs_a_valid_raster_map() -> None:
    frame, pred, _ = zara1()
    picture = np.zeros((10, 10, 3), np.uint8)
    with pytest.raises(exc.InvalidMapError, match="in_pixels draws a RasterMap"):
        dgan.plot(frame, pred, map=dgan.VectorMap([]), in_pixels=True)
    # The picture's homography and shape are the RasterMap's own checks.
    with pytest.raises(exc.InvalidMapError, match="singular"):
        dgan.plot(frame, pred, map=dgan.RasterMap(picture, np.zeros((3, 3))), in_pixels=True)
    with pytest.raises(exc.InvalidMapError, match="3×3"):
        dgan.plot(frame, pred, map=dgan.RasterMap(picture, np.eye(2)), in_pixels=True)
    with pytest.raises(exc.InvalidMapError, match=r"\(H, W, 3\)"):
        dgan.plot(frame, pred, map=dgan.RasterMap(np.zeros(5, np.uint8), np.eye(3)), in_pixels=True)


@pytest.mark.slow
def test_rerun_recording(tmp_path: Path) -> None:
    import rerun as rr

    rows = np.loadtxt(Path(dgan.demo.SCENE_FILE))
    p = dgan.Predictor("zara1", modes=3)
    tracker = dgan.Tracker(p, map=dgan.scene_map("zara1"))
    rec = rr.RecordingStream("dgan-test")
    path = tmp_path / "zara1.rrd"
    rec.save(path)
    for t in np.unique(rows[:, 0])[:8]:
        now = rows[:, 0] == t
        tracker.update(t * 0.04, ids=rows[now, 1].astype(np.int64), positions=rows[now, 2:4])
        frame = tracker.frame()
        log_rerun(frame, p.predict(frame), recording=rec, time_s=t * 0.04)
    rec.flush()
    rec.disconnect()
    assert path.stat().st_size > 10_000
    rerun_cli = Path(sys.executable).with_name("rerun")
    out = subprocess.run([str(rerun_cli), "rrd", "print", str(path)], capture_output=True, text=True, check=True)
    for entity in ("/dgan/observed", "/dgan/agents", "/dgan/modes", "/dgan/map"):
        assert entity in out.stdout, entity


@pytest.mark.parametrize(
    ("option", "value", "message"),
    [
        ("margin_m", "5", "margin_m must be a real number"),
        ("margin_m", None, "margin_m must be a real number"),
        ("margin_m", float("nan"), "finite, non-negative number of metres"),
        ("margin_m", -1.0, "finite, non-negative number of metres"),
        ("in_pixels", np.zeros(3), "in_pixels must be True or False"),
        ("headings", [0.1, 0.2], "headings must map agent ids"),
        ("ax", 3, "ax must be a matplotlib Axes"),
        ("ground_truth", "north", "ground_truth must be an array of float64"),
        ("ground_truth", {76: [[1j, 0.0]]}, r"ground_truth\[76\] must be an array of float64"),
    ],
)
def test_plot_refuses_options_it_cannot_draw_with(option: str, value: object, message: str) -> None:
    frame, pred, _ = zara1()
    with pytest.raises(exc.DganError, match=message):
        dgan.plot(frame, pred, **{option: value})  # type: ignore[arg-type]
