"""training.reports.scorecard: the checks of the results page, on hand-made results."""

from __future__ import annotations

from typing import Any

import pytest

from training import metrics
from training.evaluate import CALIBRATION_BINS
from training.reports import scorecard


def result(
    ade: float, fde: float, cv: float, agents: int = 100, by_class: dict[str, Any] | None = None
) -> dict[str, Any]:
    r: dict[str, Any] = {
        "ade": ade,
        "fde": fde,
        "cv_ade": cv,
        "cv_fde": 2 * cv,
        "agents": agents,
        "cv_variant": "last2",
    }
    r["brier_min_fde5"] = 1.0
    r["by_class"] = by_class or {}
    return r


def test_findings_flag_classes_behind_constant_velocity() -> None:
    cls = {"vehicle": result(1.1, 1.8, 1.0, 60), "pedestrian": result(0.5, 0.9, 0.6, 40)}
    tests = [
        scorecard.TestSet("a", "m", result(0.8, 1.5, 1.0, 100, cls), result(0.85, 1.6, 1.0, 100, cls)),
        scorecard.TestSet("b", "m", result(0.45, 0.9, 0.5)),
    ]
    f = scorecard.findings(tests)
    # vehicle has 60 targets and is behind in ADE; pedestrian (40 targets) does not count.
    assert f["behind_cv"] == ["a vehicle (ADE -10.0%, FDE +10.0%)"]
    # Overall rows: a 20% / 25%, b 10% / 10%.
    assert f["mean_gain_ade"] == pytest.approx(15.0)
    assert f["mean_gain_fde"] == pytest.approx(17.5)
    assert f["nomap_behind_cv"] == ["a vehicle"]
    assert f["nomap_more_than_10pct_worse"] == []
    assert "| a | all | 100 |" in scorecard.table(tests)


def test_calibration_gaps_and_pooling() -> None:
    n = len(CALIBRATION_BINS) - 1
    edges = CALIBRATION_BINS.tolist()
    a = {"edges": edges, "count": [10] * n, "mean_probability": [0.5] * n, "frequency": [0.5] * n, "ece": 0.0}
    b = dict(a, frequency=[0.9] * n, count=[30] * n)
    pooled = scorecard.pooled([a, b])
    assert pooled["frequency"][0] == pytest.approx(0.8)
    assert pooled["ece"] == pytest.approx(0.3)
    gap, p = metrics.worst_gap(pooled)
    assert gap == pytest.approx(0.3)
    assert p == pytest.approx(0.5)
