"""dgan.Tracker: a real ETH/UCY test sequence fed tick by tick equals predicting frames built from the history."""

from __future__ import annotations

import copy
import datetime
import pickle

import numpy as np
import pytest
from conftest import shared_data

import dgan
from dgan import exceptions as exc


def test_tracker_equals_predict_on_the_history_at_every_tick() -> None:
    rows = np.loadtxt(shared_data("eth_ucy") / "eth_ucy" / "datasets" / "zara1" / "test" / "crowds_zara01.txt")
    rows = rows[rows[:, 0] <= 3000]  # the first 300 ticks (2 min) of the zara1 test sequence
    predictor = dgan.Predictor("zara1", modes=3)
    scene_map = dgan.scene_map("zara1")
    tracker = dgan.Tracker(predictor, map=scene_map)
    ticks = np.unique(rows[:, 0])
    assert len(ticks) == 287  # frames 0..3000 every 10, a few with nobody in view
    checked = 0
    for t in ticks:
        now = rows[:, 0] == t
        tracker.update(t * 0.04, ids=rows[now, 1].astype(np.int64), positions=rows[now, 2:4])
        streamed = tracker.predict()
        seen = rows[rows[:, 0] <= t]
        history = {"agent_id": seen[:, 1].astype(np.int64), "time": seen[:, 0] * 0.04, "x": seen[:, 2], "y": seen[:, 3]}
        frame = dgan.Frame.from_records(history, spec=predictor, current_time=t * 0.04, map=scene_map)
        once = predictor.predict(frame)
        assert streamed.agent_ids.tolist() == once.agent_ids.tolist()
        np.testing.assert_array_equal(streamed.trajectories, once.trajectories)
        np.testing.assert_array_equal(streamed.probabilities, once.probabilities)
        checked += len(once)
    assert checked > 1000
    # Memory stays bounded: only agents seen within the history window are kept.
    assert len(tracker) <= len(np.unique(rows[rows[:, 0] >= ticks[-1] - 80, 1]))


def test_agents_appear_vanish_and_return_with_string_ids() -> None:
    p = dgan.Predictor("zara1")
    tracker = dgan.Tracker(p)
    for k in range(12):
        ids = ["a", "b"] if not 4 <= k < 6 else ["a"]  # b vanishes for two ticks, then returns
        if k >= 9:
            ids.append("c")
        pos = [[0.5 * k, 0.0], [0.0, 0.4 * k], [1.0, 1.0 + 0.3 * k]][: len(ids)]
        if ids == ["a"]:
            pos = pos[:1]
        tracker.update(0.4 * k, ids=ids, positions=pos)
    frame = tracker.frame()
    assert frame.agent_ids.tolist() == ["a", "b", "c"]
    # b's history has a hole at ticks 4 and 5 (steps 0 and 1 of the window 4..11); c was seen at ticks 9..11.
    np.testing.assert_array_equal(frame.mask[1], [False, False, True, True, True, True, True, True])
    np.testing.assert_array_equal(frame.mask[2], [False] * 5 + [True] * 3)
    assert tracker.predict().agent_ids.tolist() == ["a", "b", "c"]


def test_a_long_stream_of_new_string_ids_keeps_bounded_memory_and_the_right_ids() -> None:
    """A service's stream: every agent lives 6-20 ticks under a fresh id and never returns (and one id returns after
    it was forgotten). The tracker remembers only what its window needs, ids included, and names every agent right."""
    p = dgan.Predictor("zara1")
    tracker = dgan.Tracker(p)
    rng = np.random.default_rng(0)
    alive: dict[str, tuple[int, np.ndarray]] = {}  # id -> (last tick, start position)
    rows: list[tuple[str, float, float, float]] = []
    born = 0
    for k in range(3000):
        while len(alive) < 12:
            alive[f"track-{born:06d}"] = (k + int(rng.integers(6, 21)), rng.uniform(-20, 20, 2))
            born += 1
        if k == 2990:
            alive["track-000000"] = (k + 10, np.zeros(2))  # forgotten long ago: a new agent under an old id
        ids = sorted(alive)
        pos = np.array([alive[i][1] + 0.3 * k for i in ids])
        tracker.update(0.4 * k, ids=ids, positions=pos)
        rows += [(i, 0.4 * k, x, y) for i, (x, y) in zip(ids, pos, strict=True)]
        alive = {i: v for i, v in alive.items() if v[0] > k}
        if k % 500 == 499 or k == 2999:
            recent = [r for r in rows if r[1] >= 0.4 * (k - 12)]
            table = {
                "agent_id": [r[0] for r in recent],
                "time": [r[1] for r in recent],
                "x": [r[2] for r in recent],
                "y": [r[3] for r in recent],
            }
            once = dgan.Frame.from_records(table, spec=p, current_time=0.4 * k)
            streamed = tracker.frame()
            assert sorted(streamed.agent_ids.tolist()) == sorted(once.agent_ids.tolist()) == ids
            order = np.argsort(streamed.agent_ids.astype(str))
            np.testing.assert_array_equal(streamed.positions[order], once.positions)
            np.testing.assert_array_equal(streamed.mask[order], once.mask)
    assert born > 2000
    assert len(tracker._codes) <= 2 * len(tracker) + 64  # the ids of about 2,000 agents gone were forgotten
    assert "track-000000" in tracker.frame().agent_ids.tolist()


@pytest.mark.parametrize("ids", [["a", "b", "c"], [7, 3, 11]], ids=["strings", "integers"])
def test_a_saved_or_copied_tracker_goes_on_as_the_original_and_apart_from_it(ids: list[object]) -> None:
    """Pickled (a service saving its state) or copied, a tracker remembers what the original did: fed the same
    detections, both give the same predictions; fed others, the original is untouched."""
    p = dgan.Predictor("zara1")
    tracker = dgan.Tracker(p, map=dgan.scene_map("zara1"), max_gap=0.9, default_class="pedestrian", denoise=0.2)

    def tick(t: dgan.Tracker, k: int, shift: float = 0.0) -> None:
        pos = [[0.3 * k + shift, 0.0], [0.0, 0.4 * k], [2.0, 1.0 + 0.2 * k]]
        seen = [0, 2] if k % 5 == 3 else [0, 1, 2]  # the second agent drops out now and then
        t.update(0.4 * k, ids=[ids[i] for i in seen], positions=[pos[i] for i in seen], headings=[0.1] * len(seen))

    for k in range(12):
        tick(tracker, k)
    saved = pickle.dumps(tracker)
    copies = [pickle.loads(saved), copy.copy(tracker), copy.deepcopy(tracker)]
    for k in range(12, 20):
        tick(tracker, k)
        for c in copies:
            tick(c, k)
            a, b = tracker.predict(), c.predict()
            assert a.agent_ids.tolist() == b.agent_ids.tolist()
            np.testing.assert_array_equal(a.trajectories, b.trajectories)
            np.testing.assert_array_equal(a.probabilities, b.probabilities)
    before = tracker.predict()
    tick(copies[1], 20, shift=5.0)  # a copy fed other detections leaves the original as it was
    assert tracker.now == pytest.approx(0.4 * 19)
    np.testing.assert_array_equal(tracker.predict().trajectories, before.trajectories)
    restored = pickle.loads(saved)
    assert restored.now == pytest.approx(0.4 * 11)
    assert len(restored) == 3
    state = tracker._native.state()
    state["times"] = state["times"][::-1].copy()
    with pytest.raises(exc.InvalidFrameError, match="cannot restore the tracker"):
        dgan._dgan.Tracker.restore(8, 0.4, None, "pedestrian", state)


def test_a_tracker_fed_datetimes_counts_from_its_first_tick() -> None:
    """Ticks as datetimes (zone-aware or naive, or numpy's) give the frames seconds would, and times as given."""
    p = dgan.Predictor("zara1")
    by_seconds, by_datetimes = dgan.Tracker(p), dgan.Tracker(p)
    start = datetime.datetime(2026, 3, 1, 9, 30, tzinfo=datetime.timezone(datetime.timedelta(hours=1)))
    for k in range(10):
        pos = [[0.4 * k, 0.0], [3.0, 0.3 * k]]
        by_seconds.update(1000.0 + 0.4 * k, ids=["a", "b"], positions=pos)
        when = start + datetime.timedelta(seconds=0.4 * k)
        by_datetimes.update(
            np.datetime64(when.replace(tzinfo=None) - datetime.timedelta(hours=1)) if k % 2 else when,
            ids=["a", "b"],
            positions=pos,
        )
    a, b = by_seconds.predict(), by_datetimes.predict()
    np.testing.assert_allclose(a.trajectories, b.trajectories, atol=1e-9)
    assert by_datetimes.now == np.datetime64("2026-03-01T08:30:03.600")
    assert b.to_records()["time"][0] == np.datetime64("2026-03-01T08:30:04.000")
    saved = pickle.loads(pickle.dumps(by_datetimes))
    assert saved.now == by_datetimes.now
    with pytest.raises(exc.TimeBaseError, match="ticks are datetimes; give a datetime at every tick"):
        saved.update(1004.0, ids=["a"], positions=[[4.0, 0.0]])
    with pytest.raises(exc.TimeBaseError, match="increasing time order"):
        saved.update(start, ids=["a"], positions=[[4.0, 0.0]])


def test_tracker_errors() -> None:
    p = dgan.Predictor("zara1")
    tracker = dgan.Tracker(p)
    with pytest.raises(exc.TimeBaseError, match="no tick"):
        tracker.frame()
    tracker.update(1.0, ids=[1, 2], positions=[[0, 0], [1, 1]])
    with pytest.raises(exc.TimeBaseError, match="increasing time order"):
        tracker.update(1.0, ids=[1], positions=[[0, 0]])
    with pytest.raises(exc.InvalidFrameError, match="appears twice"):
        tracker.update(1.4, ids=[1, 1], positions=[[0, 0], [1, 1]])
    with pytest.raises(exc.InvalidFrameError, match="shape"):
        tracker.update(1.4, ids=[1, 2], positions=[[0, 0]])
    with pytest.raises(exc.InvalidFrameError, match="non-finite"):
        tracker.update(1.4, ids=[1], positions=[[np.nan, 0]])
    with pytest.raises(exc.InvalidFrameError, match="integer ids"):
        tracker.update(1.4, ids=["x"], positions=[[0, 0]])
    with pytest.raises(exc.InvalidFrameError, match="Predictor"):
        dgan.Tracker("zara1")  # type: ignore[arg-type]
    for when in ("1.4", None, True, [1.4], 1.4j):
        with pytest.raises(exc.TimeBaseError, match="time must be seconds, a real number, or a datetime"):
            tracker.update(when, ids=[1], positions=[[0, 0]])  # type: ignore[arg-type]
    with pytest.raises(exc.TimeBaseError, match="this tracker's ticks are seconds; give seconds at every tick"):
        tracker.update(datetime.datetime(2026, 1, 1), ids=[1], positions=[[0, 0]])
    with pytest.raises(exc.TimeBaseError, match="finite"):
        tracker.update(float("inf"), ids=[1], positions=[[0, 0]])
    tracker.update(np.float32(1.2), ids=[1], positions=[[0, 0]])  # numpy numbers are seconds too
    for gate in (-0.1, float("nan"), "0.1"):
        with pytest.raises(exc.InvalidFrameError, match="denoise"):
            dgan.Tracker(p, denoise=gate)  # type: ignore[arg-type]
    # An error loses nothing: the tracker holds its agents (agent 1 at 1.2 s, its history from 1.0 s).
    assert tracker.now == pytest.approx(1.2)
    assert len(tracker.frame()) == 1


def test_a_denoising_tracker_gives_the_denoised_frame() -> None:
    p = dgan.Predictor("zara1")
    plain, smoothing = dgan.Tracker(p), dgan.Tracker(p, denoise=0.1)
    rng = np.random.default_rng(1)
    for k in range(8):
        t = 10.0 + 0.4 * k
        positions = np.array([[0.5 * k, 0.0], [3.0, 0.4 * k]]) + rng.normal(0.0, 0.2, (2, 2))
        for tracker in (plain, smoothing):
            tracker.update(t, ids=[4, 9], positions=positions)
    want = plain.frame().denoised(0.1)
    np.testing.assert_array_equal(smoothing.frame().positions, want.positions)
    assert not np.array_equal(want.positions, plain.frame().positions)
    np.testing.assert_array_equal(smoothing.predict().trajectories, p.predict(want).trajectories)
