"""dgan.labels: a tracker's labels (car, person, TYPE_VEHICLE ...) read as dgan's classes only when asked, through
Frame.from_records, Tracker and dgan predict; left as they are, a common label is refused with the way to read it."""

from __future__ import annotations

import pickle

import numpy as np
import pytest

import dgan
from dgan import exceptions as exc
from dgan.labels import COMMON_CLASS_NAMES


def table(labels: list[str]) -> dict[str, object]:
    t = np.round(np.arange(0.0, 2.0, 0.2), 9)
    n = len(labels)
    return {
        "agent_id": np.repeat(np.arange(n), t.size),
        "time": np.tile(t, n),
        "x": np.tile(t, n) * 1.5,
        "y": np.repeat(np.arange(n) * 4.0, t.size),
        "class": np.repeat(np.array(labels, dtype=object), t.size),
    }


def test_common_labels_are_read_as_classes_when_asked() -> None:
    rec = table(["Car", " TYPE_VEHICLE", "person", "bicycle", "pedestrian"])
    with pytest.raises(
        exc.UnknownClassError, match=r"'Car' is no dgan class .*COMMON_CLASS_NAMES reads it as 'vehicle'"
    ):
        dgan.Frame.from_records(rec, t_obs=10, dt=0.2)
    frame = dgan.Frame.from_records(rec, t_obs=10, dt=0.2, class_names=COMMON_CLASS_NAMES)
    assert frame.classes == ["vehicle", "vehicle", "pedestrian", "cyclist", "pedestrian"]
    assert dgan.COMMON_CLASS_NAMES is COMMON_CLASS_NAMES
    # A mapping of one's own: without case, to names or codes; what it leaves out is read as given.
    own = dgan.Frame.from_records(
        table(["tram", "pedestrian"]), t_obs=10, dt=0.2, class_names={"TRAM": "vehicle", "x": 2}
    )
    assert own.classes == ["vehicle", "pedestrian"]
    with pytest.raises(exc.UnknownClassError, match=r"'person' is no dgan class"):  # left out, yet common
        dgan.Frame.from_records(table(["car", "person"]), t_obs=10, dt=0.2, class_names={"car": "vehicle"})
    with pytest.raises(exc.UnknownClassError, match="boat"):
        dgan.Frame.from_records(table(["car"]), t_obs=10, dt=0.2, class_names={"car": "boat"})
    with pytest.raises(exc.InvalidSpecError, match="class_names must map labels to dgan classes"):
        dgan.Frame.from_records(table(["car"]), t_obs=10, dt=0.2, class_names=["car"])  # type: ignore[arg-type]


def test_a_tracker_reads_its_detections_labels_and_keeps_the_mapping_when_saved() -> None:
    p = dgan.Predictor("hdmap")
    tracker = dgan.Tracker(p, class_names={"auto": "vehicle", "fussgaenger": "pedestrian"})
    for k in range(10):
        tracker.update(
            0.2 * k, ids=[1, 2], positions=[[1.5 * k * 0.2, 0.0], [0.0, 0.3 * k]], classes=["auto", "fussgaenger"]
        )
    assert tracker.frame().classes == ["vehicle", "pedestrian"]
    copy = pickle.loads(pickle.dumps(tracker))
    copy.update(2.0, ids=[1], positions=[[3.0, 0.0]], classes=["Auto"])
    assert copy.frame().classes == ["vehicle"]
    with pytest.raises(exc.UnknownClassError, match="'truck' is no dgan class"):
        tracker.update(2.0, ids=[1], positions=[[3.0, 0.0]], classes=["truck"])
    with pytest.raises(exc.InvalidSpecError, match="class_names must map"):
        dgan.Tracker(p, class_names="common")  # type: ignore[arg-type]


def test_a_frame_of_arrays_reads_labels_as_asked() -> None:
    positions = np.cumsum(np.full((2, 8, 2), 0.4), axis=1)
    with pytest.raises(exc.UnknownClassError, match="'person' is no dgan class"):
        dgan.Frame(positions, classes=["person", "car"])
    frame = dgan.Frame(positions, classes=["person", "car"], class_names=dgan.COMMON_CLASS_NAMES)
    assert frame.classes == ["pedestrian", "vehicle"]
    assert pickle.loads(pickle.dumps(frame)).classes == ["pedestrian", "vehicle"]
