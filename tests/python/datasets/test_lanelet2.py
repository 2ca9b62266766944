"""dgan.datasets.lanelet2: Lanelet2 OSM maps (the INTERACTION format sample) and INTERACTION track files."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
from conftest import interaction_recording, shared_data

import dgan
from dgan.datasets.lanelet2 import PEDESTRIAN_ID_OFFSET, interaction_companion, lanelet2_map, read_interaction
from dgan.exceptions import DatasetWarning, InvalidFrameError, InvalidMapError


def sample() -> Path:
    return shared_data("interaction_format_sample") / "interaction_format_sample"


MAP = "maps/TestScenarioForScripts.osm"
TRACKS = "recorded_trackfiles/TestScenarioForScripts/vehicle_tracks_000.csv"


def test_the_sample_map_projects_onto_its_tracks_frame() -> None:
    m = lanelet2_map(sample() / MAP)  # INTERACTION: UTM about the origin (0, 0), as Lanelet2's UtmProjector
    elements = m.elements()
    kinds = sorted(k for k, _ in elements)
    assert kinds == ["lane_centerline", "lane_centerline", "lane_line_dashed", "road_edge", "road_edge"]
    by_kind = {k: p for k, p in elements if k != "lane_centerline"}
    np.testing.assert_allclose(by_kind["lane_line_dashed"], [[1.0, 4.0], [101.0, 4.0]], atol=0.01)
    centres = sorted(float(p[:, 1].mean()) for k, p in elements if k == "lane_centerline")
    np.testing.assert_allclose(centres, [2.5, 5.5], atol=0.01)
    local = lanelet2_map(sample() / MAP, projection="local")
    gap = max(float(np.abs(a[1] - b[1]).max()) for a, b in zip(m.elements(), local.elements(), strict=True))
    assert 0.01 < gap < 0.2  # the tangent plane within 0.2 m over 100 m, not the same numbers
    sc = read_interaction(sample() / TRACKS, sample() / MAP)
    assert sc.positions[0, 0].tolist() == [1.0, 2.5]  # the vehicle drives on the first lane's centre line
    frame = sc.frame(sc.num_steps - 1, 10, every=5)
    assert len(dgan.Predictor("hdmap", sessions=1).predict(frame)) == len(frame)


def test_local_xy_tags_unmapped_types_and_bad_files(tmp_path: Path) -> None:
    osm = tmp_path / "autoware.osm"
    nodes = "".join(
        f'<node id="{i}" lat="35.0" lon="139.0"><tag k="local_x" v="{x}"/><tag k="local_y" v="{y}"/></node>'
        for i, (x, y) in enumerate([(0, 0), (50, 0), (0, 3.5), (50, 3.5), (20, 0), (20, 3.5)], 1)
    )
    ways = (
        '<way id="10"><nd ref="1"/><nd ref="2"/><tag k="type" v="curbstone"/></way>'
        '<way id="11"><nd ref="3"/><nd ref="4"/><tag k="type" v="line_thin"/><tag k="subtype" v="solid"/></way>'
        '<way id="12"><nd ref="5"/><nd ref="6"/><tag k="type" v="stop_line"/></way>'
    )
    rels = (
        '<relation id="20"><member type="way" ref="11" role="left"/><member type="way" ref="10" role="right"/>'
        '<tag k="type" v="lanelet"/><tag k="subtype" v="crosswalk"/></relation>'
        '<relation id="21"><tag k="type" v="regulatory_element"/><tag k="subtype" v="traffic_light"/></relation>'
    )
    osm.write_text(f'<?xml version="1.0"?><osm version="0.6">{nodes}{ways}{rels}</osm>')
    with pytest.warns(DatasetWarning, match=r"way stop_line ×1, regulatory_element traffic_light ×1"):
        m = lanelet2_map(osm, origin=(35.0, 139.0))
    kinds = {k: p for k, p in m.elements()}
    assert set(kinds) == {"crosswalk", "road_edge", "lane_line_solid"}  # not a contract copy: this map's kinds
    assert kinds["road_edge"].tolist() == [[0.0, 0.0], [50.0, 0.0]]
    bad = tmp_path / "bad.osm"
    bad.write_text("<osm><node")
    with pytest.raises(InvalidMapError, match="cannot read Lanelet2 map"):
        lanelet2_map(bad)
    with pytest.raises(InvalidMapError, match="'utm' or 'local'"):
        lanelet2_map(sample() / MAP, projection="mercator")


def test_a_recordings_two_track_files_are_one_scene(tmp_path: Path) -> None:
    """INTERACTION keeps a recording's pedestrians and cyclists in a file of their own beside its vehicles': reading
    either reads both, on the recording's frames, with the pedestrians' ids P<n> apart from the vehicles'."""
    vehicles, pedestrians = interaction_recording(tmp_path / "rec")
    assert interaction_companion(vehicles) == pedestrians
    assert interaction_companion(pedestrians) == vehicles
    assert interaction_companion(sample() / TRACKS) is None  # the sample has no pedestrian file
    both = read_interaction(vehicles, sample() / MAP)
    ids = [PEDESTRIAN_ID_OFFSET + k for k in (1, 2, 7)]
    assert sorted(both.ids.tolist()) == [1, 2, *ids]
    label = dict(zip(both.ids.tolist(), list(both.labels), strict=True))
    assert [label[i] for i in (1, *ids)] == ["vehicle", "pedestrian", "pedestrian", "cyclist"]
    row = both.ids.tolist().index(ids[0])
    assert both.positions[row, 10 - 1].tolist() == pytest.approx([10.0 + 1.2 * 0.1 * 10, -1.5], abs=1e-9)
    assert not both.valid[row, : 3 - 1].any()  # the vehicles' first frame is the scene's first step
    from_pedestrians = read_interaction(pedestrians)
    order = [from_pedestrians.ids.tolist().index(i) for i in both.ids.tolist()]
    np.testing.assert_array_equal(from_pedestrians.positions[order], both.positions)
    alone = read_interaction(pedestrians, companion=False)
    assert sorted(alone.ids.tolist()) == ids
    assert alone.valid[alone.ids.tolist().index(ids[0]), 0]  # its own first frame (3) is its first step
    frame = both.frame(30, 10, every=5)  # frame 31: vehicle 2 from frame 31, the cyclist P7 on frames 10-35
    assert len(dgan.Predictor("hdmap", sessions=1).predict(frame)) == len(frame) == 5


def test_bad_interaction_rows_are_typed_errors(tmp_path: Path) -> None:
    for field, bad, message in (
        ("track_id", "X9", r"line 3: track_id 'X9' must be a whole number \(P and one for a pedestrian\)"),
        ("frame_id", "2.5", r"frame_id '2.5' a whole number"),
        ("x", "east", r"must be numbers"),
    ):
        vehicles, _ = interaction_recording(tmp_path / field)
        lines = vehicles.read_text().splitlines()
        header = lines[0].split(",")
        cells = lines[2].split(",")
        cells[header.index(field)] = bad
        vehicles.write_text("\n".join([*lines[:2], ",".join(cells), *lines[3:]]) + "\n")
        with pytest.raises(InvalidFrameError, match=message):
            read_interaction(vehicles)
