"""training.studies.prior: the turning rollout against closed forms."""

from __future__ import annotations

import numpy as np

from training.studies.prior import turning_rollout


def test_without_turning_or_acceleration_it_is_constant_velocity() -> None:
    v = np.array([[2.0, 0.0], [0.6, 0.8]])
    r = turning_rollout(v, np.zeros(2), np.zeros(2), 0.5, 4)
    want = v[:, None, :] * (0.5 * np.arange(1, 5))[None, :, None]
    np.testing.assert_allclose(r, want, atol=1e-12)


def test_a_constant_turn_follows_the_circle_and_braking_stops() -> None:
    # 1 m/s turning left at 1 rad/s: a circle of radius 1 around (0, 1); after π/2 s at (1, 1).
    r = turning_rollout(np.array([[1.0, 0.0]]), np.array([1.0]), np.zeros(1), np.pi / 2, 1, substeps=2000)
    np.testing.assert_allclose(r[0, 0], [1.0, 1.0], atol=1e-3)
    # 2 m/s braking at 1 m/s²: stops after 2 s, 2 m on, and stays there.
    r = turning_rollout(np.array([[2.0, 0.0]]), np.zeros(1), np.array([-1.0]), 1.0, 4, substeps=1000)
    np.testing.assert_allclose(r[0, :, 0], [1.5, 2.0, 2.0, 2.0], atol=2e-3)
