"""training.studies.standing: the end-point errors and their summary on hand-made tracks."""

from __future__ import annotations

import numpy as np

from training.studies.standing import end_errors, summary


def test_end_errors_read_the_last_step_of_each_candidate() -> None:
    truth = np.zeros((2, 3, 2))
    truth[:, -1] = [[3.0, 4.0], [0.0, 0.1]]
    modes = np.zeros((2, 25, 3, 2))
    modes[0, 1, -1] = [3.0, 4.0]  # agent 0: the second mode ends on the truth, the top one at the origin (5 m off)
    modes[1, 0, -1] = [0.0, 1.1]  # agent 1: the top mode 1 m off, mode 21 on the truth (beyond the best of 20)
    modes[1, 1:, -1] = [0.0, 0.6]
    modes[1, 21, -1] = [0.0, 0.1]
    last = np.array([[3.0, 0.0], [0.0, 0.0]])
    cv = {"last2": np.zeros((2, 1, 3, 2))}
    e = end_errors(modes, truth, last, cv)
    np.testing.assert_allclose(e["top1"], [5.0, 1.0])
    np.testing.assert_allclose(e["min20"], [0.0, 0.5])
    np.testing.assert_allclose(e["stay"], [4.0, 0.1])
    np.testing.assert_allclose(e["cv_last2"], [5.0, 0.1])


def test_summary_takes_the_better_constant_velocity_and_counts_the_bound() -> None:
    errors = {
        "top1": np.array([0.5, 0.3]),
        "min20": np.array([0.1, 0.1]),
        "stay": np.array([0.1, 0.3]),
        "stay_m": np.array([0.1, 0.3]) * 2.0,
        "cv_last2": np.array([0.4, 0.4]),
        "cv_mean1s": np.array([0.2, 0.4]),
    }
    s = summary(errors, 0.3)
    assert s["targets"] == 2
    np.testing.assert_allclose([s["top1_fde"], s["cv_fde"], s["stay_fde"]], [0.4, 0.3, 0.2])
    assert s["share_within_bound"] == 0.5  # in metres: 0.2 and 0.6 against 0.3
    assert s["bound_m"] == 0.3
