"""Tracker-like corruption (training.data.augment), the robust kinematic prior it motivates (dgan.PriorSpec's
``fit`` and ``standing_mps``, through the engine), and the moving / standing split of the evaluation."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest
from conftest import shared_data

import dgan
from training.data.augment import tracker_noise

ROOT = Path(__file__).resolve().parents[3]


def test_tracker_noise_keeps_the_current_step_and_the_inputs() -> None:
    rng = np.random.default_rng(0)
    pos = np.cumsum(np.ones((200, 10, 2)), axis=1)
    mask = np.ones((200, 10), bool)
    mask[:5, 9] = False  # agents whose current step is already missing keep their last valid one
    noisy, keep = tracker_noise(pos, mask, 0.3, 0.1, rng)
    assert noisy is not pos
    assert np.all(pos == np.cumsum(np.ones((200, 10, 2)), axis=1))
    assert keep[5:, 9].all()
    assert keep[:5, 8].all()
    assert not keep[:5, 9].any()
    dropped = 1 - keep[5:, :9].mean()
    assert 0.07 < dropped < 0.13, dropped
    err = (noisy - pos)[keep]
    assert abs(err.std() - 0.3) < 0.02
    assert abs(err.mean()) < 0.02
    same, same_keep = tracker_noise(pos, mask, 0.0, 0.0, rng)
    assert np.array_equal(same, pos)
    assert np.array_equal(same_keep, mask)
    for sigma, drop in ((-0.1, 0.1), (float("nan"), 0.1), (0.1, 1.0), (0.1, -0.5)):
        with pytest.raises(ValueError, match=r"sigma_m|drop"):
            tracker_noise(pos, mask, sigma, drop, rng)


def _prior(
    fit: str, standing: float, traj: np.ndarray, mask: np.ndarray, dt: float = 0.5, window_s: float = 2.0
) -> np.ndarray:
    spec = dgan.InputSpec(dt, traj.shape[1], 4, classes=("vehicle",))
    prior = dgan.PriorSpec("constant_velocity", window_s, fit, standing)
    spec_p = dgan.InputSpec(dt, traj.shape[1], 4, classes=("vehicle",), prior=prior)
    frame = dgan.Frame(traj, mask=mask, classes=["vehicle"] * len(traj))
    x = dgan.preprocess(frame, spec)
    return np.asarray(dgan.kinematic_prior(x["trajectory"], x["trajectory_mask"], x["state"], spec_p))


def test_the_robust_prior_through_the_engine() -> None:
    rng = np.random.default_rng(1)
    t = np.arange(5) * 0.5
    still = np.zeros((300, 5, 2)) + rng.normal(0, 0.1, (300, 5, 2))  # parked, tracked with 0.1 m noise
    mask = np.ones((300, 5), bool)
    clamp = _prior("least_squares", 0.3, still, mask)
    free = _prior("least_squares", 0.0, still, mask)
    ends = _prior("endpoints", 0.0, still, mask)
    # Standing: almost every noisy parked car stays put, and the line moves it less than the endpoints do.
    assert np.mean(np.abs(clamp).max(axis=(1, 2)) == 0) > 0.9
    assert np.linalg.norm(free[:, -1], axis=1).mean() < np.linalg.norm(ends[:, -1], axis=1).mean()
    # Moving at 2 m/s with steady acceleration 1 m/s²: the parabola's slope is the current velocity (4 m/s at 2 s).
    moving = np.stack([2 * t + t**2 / 2, 0 * t], axis=1)[None]
    quad = _prior("quadratic", 0.3, moving, np.ones((1, 5), bool))
    assert np.linalg.norm(quad[0, 0]) == pytest.approx(4.0 * 0.5, abs=1e-4)
    # The adaptive line: the last two steps of that clean accelerating track, the whole window of a noisy parked car.
    long_t = np.arange(10) * 0.5
    accelerating = np.stack([long_t**2 / 2, 0 * long_t], axis=1)[None]
    ones = np.ones((1, 10), bool)
    adaptive = _prior("adaptive", 0.0, accelerating, ones, window_s=4.5)
    np.testing.assert_allclose(adaptive, _prior("endpoints", 0.0, accelerating, ones, window_s=0.5), atol=1e-5)
    parked = np.zeros((1, 10, 2))
    parked[0, :, 0] = 0.3 * (-1.0) ** np.arange(10)  # ±0.3 m of jitter, no motion
    lsq = _prior("least_squares", 0.0, parked, ones, window_s=4.5)
    np.testing.assert_allclose(_prior("adaptive", 0.0, parked, ones, window_s=4.5), lsq, atol=1e-5)
    with pytest.raises(dgan.exceptions.InvalidSpecError, match="standing_mps"):
        dgan.InputSpec(0.5, 5, 4, prior=dgan.PriorSpec("constant_velocity", 1.0, "least_squares", -1.0))
    with pytest.raises(dgan.exceptions.InvalidSpecError, match="fit"):
        dgan.InputSpec(0.5, 5, 4, prior=dgan.PriorSpec("constant_velocity", 1.0, "spline", 0.0))
    with pytest.raises(dgan.exceptions.InvalidSpecError, match="window"):
        dgan.InputSpec(0.5, 5, 4, prior=dgan.PriorSpec("constant_velocity", 0.0, "quadratic", 0.0))


def test_each_class_takes_its_own_prior_through_the_engine() -> None:
    """``PriorSpec.by_class``: pedestrians on a least-squares line, vehicles on the last two steps, in one frame."""
    from training.build import class_priors

    rng = np.random.default_rng(2)
    t = np.arange(8) * 0.5
    track = np.stack([1.0 * t, 0 * t], axis=1) + rng.normal(0, 0.1, (8, 2))
    traj = np.stack([track, track + np.array([0.0, 30.0])])  # far apart: no edges, the same history
    by_class = class_priors("pedestrian=least_squares:4:0")
    assert by_class == {"pedestrian": dgan.ClassPrior(4.0, "least_squares", 0.0)}
    prior = dgan.PriorSpec("constant_velocity", 0.5, "endpoints", 0.0, by_class)
    spec = dgan.InputSpec(0.5, 8, 4, classes=("vehicle", "pedestrian"), prior=prior)
    frame = dgan.Frame(traj, classes=["vehicle", "pedestrian"])
    x = dgan.preprocess(frame, spec)
    line = dgan.InputSpec(
        0.5, 8, 4, classes=("vehicle", "pedestrian"), prior=dgan.PriorSpec("constant_velocity", 4.0, "least_squares")
    )
    two = dgan.InputSpec(0.5, 8, 4, classes=("vehicle", "pedestrian"), prior=dgan.PriorSpec("constant_velocity", 0.5))
    want_line, want_two = (dgan.preprocess(frame, s)["prior"] for s in (line, two))
    np.testing.assert_allclose(x["prior"][1], want_line[1], atol=1e-6)
    np.testing.assert_allclose(x["prior"][0], want_two[0], atol=1e-6)
    # The spec's JSON round trip keeps it, and the engine refuses a class the model does not predict.
    assert dgan.InputSpec.from_dict(json.loads(spec.to_json())) == spec
    with pytest.raises(dgan.exceptions.InvalidSpecError, match="not among the model's classes"):
        dgan.InputSpec(0.5, 8, 4, classes=("vehicle",), prior=prior)
    with pytest.raises(dgan.exceptions.InvalidSpecError, match="by_class"):
        dgan.PriorSpec("constant_velocity", by_class={"pedestrian": "fast"})  # type: ignore[dict-item]
    for bad in ("pedestrian=least_squares:4", "pedestrian=least_squares:x:0", "a=b:1:0,a=b:1:0"):
        with pytest.raises(ValueError, match="prior_by_class"):
            class_priors(bad)


def test_augment_levels_are_checked() -> None:
    from training.data.splits import augment_sigmas

    assert augment_sigmas("") == []
    assert augment_sigmas("0.1, 0.3") == [0.1, 0.3]
    for bad in ("0.1,x", "0", "-0.2", "9"):
        with pytest.raises(ValueError, match="augment_noise"):
            augment_sigmas(bad)


@pytest.mark.slow
def test_evaluation_scores_standing_agents_apart() -> None:
    """ApolloScape's test recordings with the bundled model: every target is moving or standing, and the two splits
    add up to the whole, overall and per class; a noisy evaluation is worse for constant velocity too."""
    from training.evaluate import evaluate

    root = shared_data("apolloscape_trajectory")
    predictor = dgan.Predictor("apolloscape")
    clean = evaluate(predictor, "apolloscape", root)
    moving, standing = clean["by_motion"]["moving"], clean["by_motion"]["standing"]
    assert moving["agents"] + standing["agents"] == clean["agents"]
    assert standing["agents"] > 50
    mean = (moving["ade"] * moving["agents"] + standing["ade"] * standing["agents"]) / clean["agents"]
    assert mean == pytest.approx(clean["ade"], rel=1e-9)
    for c, row in clean["by_class"].items():
        assert row["moving"]["agents"] + row["standing"]["agents"] == row["agents"], c
    noisy = evaluate(predictor, "apolloscape", root, noise=(0.3, 0.1))
    assert noisy["agents"] == clean["agents"]
    assert noisy["cv_last2_ade"] > clean["cv_last2_ade"] + 0.1


def test_still_agents_are_held_at_their_current_position_and_movers_kept() -> None:
    from training.data.augment import held_still

    rng = np.random.default_rng(0)
    still = np.array([5.0, 2.0]) + rng.normal(0.0, 0.05, (8, 2))  # annotation jitter of a parked car
    moving = np.cumsum(np.full((8, 2), 0.4), axis=0)
    pos = np.stack([still, moving])
    mask = np.ones((2, 8), bool)
    mask[0, 7] = False  # its last valid step is the 7th
    pos[0, 7] = [99.0, 99.0]  # an invalid step keeps what it held
    out = held_still(pos, mask, 0.5)
    np.testing.assert_array_equal(out[0, :7], np.broadcast_to(pos[0, 6], (7, 2)))
    np.testing.assert_array_equal(out[0, 7], [99.0, 99.0])
    np.testing.assert_array_equal(out[1], pos[1])
    assert not np.shares_memory(out, pos)
    with pytest.raises(ValueError, match="within_m"):
        held_still(pos, mask, 0.0)


def test_a_held_copy_joins_the_training_sets_flagged_and_cached_apart() -> None:
    from dataclasses import replace

    from training.config import DataConfig
    from training.data.splits import window_sets

    d = replace(DataConfig(), dataset="apolloscape", augment_hold_m=0.5)
    sets = window_sets(d, "train")
    assert [s.hold for s in sets] == [0.0, 0.5]
    assert [s.hold for s in window_sets(d, "val")] == [0.0]
    with pytest.raises(ValueError, match="augment_hold_m"):
        window_sets(replace(d, augment_hold_m=-1.0), "train")


def test_a_held_copy_with_futures_holds_the_still_agents_whole_window() -> None:
    """``data.augment_hold_future``: an agent still over its whole window (a parked car's jittering box) is held at
    one point throughout, so its future in its own frame is zero; a walker keeps its recorded window; without a held
    copy the option is refused, and the cache keys the two held copies apart."""
    from dataclasses import replace

    from training.config import DataConfig
    from training.data.cache import cache_path
    from training.data.datasets import DATASETS
    from training.data.recording import Located, Recording
    from training.data.splits import window_sets
    from training.data.windows import build_windows

    spec = dgan.Predictor("apolloscape").spec
    steps = spec.t_obs + spec.t_f
    rng = np.random.default_rng(1)
    step = np.repeat(np.arange(steps), 2)
    agent = np.tile([0, 1], steps)
    xy = np.c_[step * 1.5 * (agent == 1), 3.0 * agent] + (agent == 0)[:, None] * rng.normal(0.0, 0.05, (2 * steps, 2))
    rec = Recording.sorted(name="toy", step=step, agent=agent, xy=xy, label=np.full(2 * steps, 2))
    info = DATASETS["apolloscape"]
    held = build_windows([rec], info, spec, stride=1, progress=False, hold=0.5, hold_future=True)
    plain = build_windows([rec], info, spec, stride=1, progress=False, hold=0.5)
    assert held.num_windows == plain.num_windows == 1
    np.testing.assert_array_equal(held.future[0], 0.0)
    assert np.abs(plain.future[0]).max() > 0.01
    np.testing.assert_allclose(held.future[1], plain.future[1])
    d = replace(DataConfig(), dataset="apolloscape", augment_hold_m=0.5, augment_hold_future=True)
    assert [(s.hold, s.hold_future) for s in window_sets(d, "train")] == [(0.0, False), (0.5, True)]
    with pytest.raises(ValueError, match="augment_hold_future"):
        window_sets(replace(d, augment_hold_m=0.0), "train")
    parts = window_sets(d, "train")[1], window_sets(replace(d, augment_hold_future=False), "train")[1]
    keys = {cache_path(Located(p, [], info, list), spec, Path("/tmp")).name for p in parts}
    assert len(keys) == 2
