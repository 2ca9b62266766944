"""dgan.RasterMap and dgan.VectorMap, and the crops the engine draws from them."""

from __future__ import annotations

import dataclasses
import gc
from pathlib import Path

import numpy as np
import pytest
from conftest import SCENES, zara1_raster_map, zara1_records

import dgan
from dgan import exceptions as exc


def test_raster_map_from_a_real_scene() -> None:
    m = zara1_raster_map()
    assert m.image.shape == (576, 720, 3)
    h = np.loadtxt(SCENES / "zara1" / "H.txt")
    np.testing.assert_allclose(m.world_to_pixel @ h, np.eye(3), atol=1e-9)


def test_raster_map_errors(tmp_path: Path) -> None:
    with pytest.raises(exc.InvalidMapError, match=r"\(H, W, 3\)"):
        dgan.RasterMap(np.zeros((4, 4), dtype=np.uint8), np.eye(3))
    with pytest.raises(exc.InvalidMapError, match="3×3"):
        dgan.RasterMap(np.zeros((4, 4, 3), dtype=np.uint8), np.eye(2))
    with pytest.raises(exc.InvalidMapError, match="singular"):
        dgan.RasterMap(np.zeros((4, 4, 3), dtype=np.uint8), np.zeros((3, 3)))
    with pytest.raises(exc.InvalidMapError, match="cannot read image"):
        dgan.RasterMap.from_file(tmp_path / "missing.png", np.eye(3))
    bad = tmp_path / "bad.png"
    bad.write_bytes(b"not a png")
    with pytest.raises(exc.InvalidMapError, match="cannot read image"):
        dgan.RasterMap.from_file(bad, np.eye(3))


def test_maps_moved_to_another_origin_keep_their_content_under_the_moved_points() -> None:
    shift = np.array([512345.678, 4123456.789])
    lines = dgan.VectorMap([("lane_centerline", [[0.0, 0.0], [40.0, 4.0]]), ("crosswalk", [[0, 0], [1, 0], [1, 1]])])
    far = lines.moved(shift)
    assert [k for k, _ in far.elements()] == [k for k, _ in lines.elements()]
    for (_, there), (_, here) in zip(far.elements(), lines.elements(), strict=True):
        np.testing.assert_array_equal(there, here + shift)
    h = np.array([[2.0, 0.1, 5.0], [-0.1, 2.0, 7.0], [1e-4, 0.0, 1.0]])  # a projective world → pixel map
    image = dgan.RasterMap(np.arange(48, dtype=np.uint8).reshape(4, 4, 3), h)
    moved = image.moved(shift)
    np.testing.assert_array_equal(moved.image, image.image)
    points = np.array([[0.0, 0.0], [1.5, -2.0], [30.0, 12.0]])
    here = h @ np.c_[points, np.ones(3)].T
    there = moved.world_to_pixel @ np.c_[points + shift, np.ones(3)].T
    np.testing.assert_allclose(there[:2] / there[2], here[:2] / here[2], rtol=0, atol=1e-6)
    for bad in ([1.0, np.nan], [1.0, 2.0, 3.0], [[1.0, 2.0]], "east"):
        with pytest.raises(exc.InvalidMapError, match="shift_m"):
            lines.moved(bad)
        with pytest.raises(exc.InvalidMapError, match="shift_m"):
            image.moved(bad)


def test_vector_map_kinds_and_errors() -> None:
    m = dgan.VectorMap([("lane_centerline", [[0, 0], [1, 0]]), ("crosswalk", [[0, 0], [1, 0], [1, 1]])])
    assert len(m) == 2
    assert [k for k, _ in m.elements()] == ["crosswalk", "lane_centerline"]  # regions drawn under lines
    with pytest.raises(exc.InvalidMapError, match="unknown map element kind"):
        dgan.VectorMap([("river", [[0, 0], [1, 0]])])
    with pytest.raises(exc.InvalidMapError, match="at least 3 points"):
        dgan.VectorMap([("obstacle", [[0, 0], [1, 0]])])
    with pytest.raises(exc.InvalidMapError, match=r"\(P, 2\)"):
        dgan.VectorMap([("road_edge", [0, 1, 2])])
    with pytest.raises(exc.InvalidMapError, match="NaN"):
        dgan.VectorMap([("road_edge", np.array([[0, 0], [np.nan, 1]]))])
    with pytest.raises(exc.InvalidMapError, match="pair"):
        dgan.VectorMap([("road_edge",)])  # type: ignore[list-item]


SPEC = dgan.InputSpec(
    dt_s=0.4,
    t_obs=2,
    t_f=12,
    classes=("pedestrian", "vehicle"),
    map=dgan.MapSpec(height_px=20, width_px=20, resolution_m=1.0, agent_row=10, agent_col=10, draw_agents=False),
)


def test_crop_colours_and_orientation() -> None:
    # An agent at the origin walking +x: ahead is image-up, its left (+y) is image-left.
    vmap = dgan.VectorMap(
        [
            ("lane_centerline", [[-30, 0], [30, 0]]),  # along the agent's path: column 10
            ("road_edge", [[-30, 6.0], [30, 6.0]]),  # 6 m to its left: continuous column 4.5, pixel 4
            ("obstacle", [[4.5, -6.5], [6.5, -6.5], [6.5, -4.5], [4.5, -4.5]]),  # ahead-right: rows 4..5, cols 15..16
        ]
    )
    frame = dgan.Frame([[[-1.0, 0.0], [0.0, 0.0]]], map=vmap)
    crop = dgan.preprocess(frame, SPEC)["map"][0]

    def rgb(r: int, c: int) -> tuple[int, ...]:
        return tuple(int(v) for v in np.round(crop[:, r, c] * 255))

    assert rgb(2, 10) == (0, 255, 0)
    assert rgb(15, 4) == (255, 255, 0)
    assert rgb(4, 15) == (255, 105, 180)
    assert rgb(5, 16) == (255, 105, 180)
    assert rgb(15, 15) == (0, 0, 0)


def test_agents_are_drawn_as_blue_boxes() -> None:
    spec = dgan.InputSpec(dt_s=0.4, t_obs=2, t_f=12, classes=("vehicle",), map=dgan.MapSpec(20, 20, 1.0, 10, 10, True))
    frame = dgan.Frame(
        [[[-1.0, 0.0], [0.0, 0.0]], [[3.0, -3.0], [4.0, -3.0]]], classes=["vehicle", "vehicle"], map=dgan.VectorMap()
    )
    crop = dgan.preprocess(frame, spec)["map"][0]
    blue = (crop[0] == 0) & (crop[1] == 0) & (crop[2] > 0.99)
    # The 4.5 × 1.9 m car at the origin spans continuous rows 8.25..12.75 (the agent's pixel centre is 10.5):
    # rows 9..11 are fully blue and rows 8 and 12 three-quarters, anti-aliased.
    assert blue[9, 10]
    assert blue[10, 10]
    assert blue[11, 10]
    assert 0.6 < crop[2, 8, 10] < 0.9
    assert 0.6 < crop[2, 12, 10] < 0.9
    # The other car is 4 m ahead and 3 m to the right: centred on pixel (6, 13).
    assert blue[6, 13]
    assert not blue[10, 5]


def test_raster_crop_resamples_the_real_image() -> None:
    frame = dgan.Frame([[[5.0, 5.0], [6.0, 5.0]]], map=zara1_raster_map())
    crop = dgan.preprocess(frame, SPEC)["map"][0]
    assert crop.shape == (3, 20, 20)
    assert 0.05 < crop.mean() < 0.95
    # A crop far outside the image is black.
    far = dgan.Frame([[[500.0, 500.0], [501.0, 500.0]]], map=zara1_raster_map())
    assert dgan.preprocess(far, SPEC)["map"].max() == 0.0


def test_tiled_crops_match_the_drawn_ones_and_the_bundled_hdmap_serves_them() -> None:
    import warnings

    from dgan.datasets.hdmaps import read_scenario
    from dgan.demo import WAYMO_FILE

    with warnings.catch_warnings():
        warnings.simplefilter("ignore")  # elements of kinds the engine does not draw (driveways)
        waymo_frame = read_scenario(WAYMO_FILE).frame(40, t_obs=10, every=2)
    # The bundled hdmap draws its crops from tiles of the map (contract 7); the same crops drawn per agent differ
    # only by the resampling, and a second call (the tiles kept with the map) gives the very same crops.
    predictor = dgan.Predictor("hdmap")
    tiles = predictor.spec
    assert tiles.map is not None
    assert tiles.map.render == "tiles"
    agent = dataclasses.replace(tiles, map=dataclasses.replace(tiles.map, render="agent"))
    drawn = dgan.preprocess(waymo_frame, agent)["map"]
    first = dgan.preprocess(waymo_frame, tiles)["map"]
    assert np.abs(drawn - first).mean() < 0.03  # 0.023: the same lines and regions, anti-aliased a little otherwise
    assert abs(drawn.sum() - first.sum()) < 0.05 * drawn.sum()
    np.testing.assert_array_equal(dgan.preprocess(waymo_frame, tiles)["map"], first)
    assert isinstance(waymo_frame.map, dgan.VectorMap)
    kept = waymo_frame.map.tiles_kept
    assert 4 <= kept <= 64
    dgan.preprocess(waymo_frame, tiles)
    assert waymo_frame.map.tiles_kept == kept  # drawn once: a second call reuses them
    assert dgan.VectorMap(waymo_frame.map.elements()).tiles_kept == 0
    a, b = predictor.predict(waymo_frame), predictor.predict(waymo_frame)
    np.testing.assert_array_equal(a.trajectories, b.trajectories)


def test_the_bundled_hdmap_reads_only_the_crops_the_engine_draws_for_it() -> None:
    """Contract 11: `hdmap` declares the classes that read its map; the engine leaves the other agents' crops blank,
    and the network gives the very same outputs as from every crop drawn."""
    import onnxruntime as ort  # type: ignore[import-untyped]

    from dgan.demo import scene_for

    predictor = dgan.Predictor("hdmap")
    readers = predictor.spec
    assert readers.map is not None
    assert readers.map.classes == ("cyclist", "pedestrian")
    every = dataclasses.replace(readers, map=dataclasses.replace(readers.map, classes=()))
    frame = scene_for(readers).frame
    x, y = dgan.preprocess(frame, readers), dgan.preprocess(frame, every)
    reads = np.isin(np.asarray(frame.classes), readers.map.classes)
    assert 0 < reads.sum() < len(frame)
    assert not x["map"][~reads].any()
    assert y["map"][~reads].any()
    np.testing.assert_array_equal(x["map"][reads], y["map"][reads])
    session = ort.InferenceSession(str(predictor.path), providers=["CPUExecutionProvider"])
    names = [i.name for i in session.get_inputs()]
    drawn_for_readers = session.run(None, {k: x[k] for k in names})
    drawn_for_every_agent = session.run(None, {k: y[k] for k in names})
    for a, b in zip(drawn_for_readers, drawn_for_every_agent, strict=True):
        np.testing.assert_array_equal(a, b)


def test_tiles_are_refused_for_large_crops_and_unknown_ways() -> None:
    assert SPEC.map is not None
    big = dataclasses.replace(SPEC.map, height_px=300, agent_row=150, render="tiles")
    with pytest.raises(exc.InvalidSpecError, match="at most 256 pixels a side"):
        dataclasses.replace(SPEC, map=big)
    dataclasses.replace(SPEC, map=dataclasses.replace(big, render="agent"))  # drawn per agent: any size
    with pytest.raises(exc.InvalidSpecError, match="unknown variant `tile`"):
        dataclasses.replace(SPEC, map=dataclasses.replace(SPEC.map, render="tile"))


def test_preprocess_threads_bound_the_crops_not_the_tensors(zara1_frame: dgan.Frame) -> None:
    spec = dgan.Predictor("zara1").spec
    every = dgan.preprocess(zara1_frame, spec)
    one = dgan.preprocess(zara1_frame, spec, threads=1)
    assert every.keys() == one.keys()
    for k in every:
        np.testing.assert_array_equal(every[k], one[k], err_msg=k)
    for bad in (0, -1, 1.5, True, 10**6):
        with pytest.raises(exc.InvalidSpecError, match="threads"):
            dgan.preprocess(zara1_frame, spec, threads=bad)  # type: ignore[arg-type]


def test_a_scene_models_features_are_kept_with_the_map_for_later_calls() -> None:
    """Contract 13 (the bundled zara1): the first call on a map computes the tiles its agents read and keeps them
    with the map; later frames holding the same map (``dgan.scene_map`` gives the same object every time) read them,
    while another predictor keeps its own; a map's copy starts with none."""
    predictor = dgan.Predictor("zara1")
    scene = dgan.demo.scene_for(predictor.spec)
    frame = scene.frame
    assert dgan.scene_map("zara1") is dgan.scene_map("zara1")
    local = dgan.RasterMap(frame.map.image, frame.map.world_to_pixel)  # type: ignore[union-attr]
    first = predictor.predict(frame.with_map(local))
    kept = local.features_kept
    assert kept > 0
    moved = dgan.Frame(frame.positions + 0.5, classes=frame.classes, map=local)
    predictor.predict(moved)
    assert local.features_kept == kept  # the same tiles, read
    again = predictor.predict(frame.with_map(local))
    np.testing.assert_array_equal(again.trajectories, first.trajectories)
    dgan.Predictor("zara1").predict(frame.with_map(local))
    assert local.features_kept == 2 * kept
    assert dgan.RasterMap(local.image, local.world_to_pixel).features_kept == 0


def test_a_photo_given_to_a_model_that_reads_masks_warns_once(tmp_path: Path) -> None:
    """The ETH/UCY models read a colourised semantic mask; the scene's photo in its place (an easy mistake: it is an
    image with the same homography) warns once, while the mask, a JPEG of the mask and a model that reads photos
    (sdd) do not."""
    import warnings

    from dgan.scenes import palette_share

    rec = zara1_records()
    frame = dgan.Frame.from_records(rec, t_obs=8, dt=0.4, time_unit=0.04, current_time=5500.0)
    h = np.loadtxt(SCENES / "zara1" / "H.txt")
    photo = dgan.RasterMap.from_pixel_to_world(SCENES / "zara1" / "rgb.jpg", h)
    mask = dgan.scene_map("zara1")
    pil = pytest.importorskip("PIL.Image")
    pil.fromarray(mask.image).save(tmp_path / "mask.jpg", quality=75)
    jpeg_mask = dgan.RasterMap.from_file(tmp_path / "mask.jpg", mask.world_to_pixel)
    assert palette_share(mask.image) == 1.0
    assert palette_share(jpeg_mask.image) > 0.95
    assert palette_share(photo.image) < 0.5
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        zara1 = dgan.Predictor("zara1")
        zara1.predict(frame.with_map(mask))
        zara1.predict(frame.with_map(jpeg_mask))
        zara1.predict(frame)
        sdd = dgan.Predictor("sdd")  # reads reference photos
        sdd.predict(
            dgan.Frame.from_records(rec, spec=sdd, time_unit=0.04, current_time=5500.0, upsample=True, map=photo)
        )
    with pytest.warns(exc.MapWarning, match=r"zara1.onnx reads its map as a semantic mask .* 2\d% of this map's"):
        zara1.predict(frame.with_map(photo))
    with warnings.catch_warnings():
        warnings.simplefilter("error")  # once per Predictor
        zara1.predict(frame.with_map(photo))
    with pytest.warns(exc.MapWarning):
        dgan.Predictor("eth").predict_batch([frame.with_map(mask), frame.with_map(photo)])


def test_a_predictor_forgets_the_maps_it_checked_once_they_are_freed() -> None:
    """The maps a predictor has checked are remembered by reference, not by ``id()``: a freed map's id goes to the
    next object made, so a photo could have passed unchecked (seen in a script: 30 masks made and freed one by one,
    then a photo whose id was one of theirs)."""
    rec = zara1_records()
    frame = dgan.Frame.from_records(rec, t_obs=8, dt=0.4, time_unit=0.04, current_time=5500.0)
    mask, photo_image = dgan.scene_map("zara1"), zara1_raster_map().image
    zara1 = dgan.Predictor("zara1")
    masks = [dgan.RasterMap(mask.image, mask.world_to_pixel) for _ in range(30)]
    for m in masks:
        zara1.predict(frame.with_map(m))
    assert len(zara1._maps_checked) == 30
    del masks, m
    gc.collect()
    assert len(zara1._maps_checked) == 0  # nothing left whose id a new map could take
    with pytest.warns(exc.MapWarning):
        zara1.predict(frame.with_map(dgan.RasterMap(photo_image, mask.world_to_pixel)))
