"""training.reports.multiclass: the single-against-per-class table marks the better model cell by cell."""

from __future__ import annotations

from typing import Any

from training.data.datasets import DATASETS
from training.reports import multiclass


def metrics(ade: float, min20: float, agents: int) -> dict[str, Any]:
    return {
        "agents": agents,
        "ade": ade,
        "fde": 2 * ade,
        "min_ade5": min20 + 0.1,
        "min_fde5": 2 * min20 + 0.2,
        "min_ade20": min20,
        "min_fde20": 2 * min20,
        "brier_min_fde20": 2 * min20 + 0.5,
        "cv_ade": 9.0,
        "cv_fde": 18.0,
        "cv_variant": "last2",
    }


def test_the_lower_of_the_single_and_the_per_class_model_is_bold() -> None:
    classes = DATASETS["apolloscape"].classes
    # The single model is better at best of 20 and worse at top-1 for every class.
    multi = {**metrics(1.0, 0.5, 30), "by_class": {c: metrics(1.0, 0.5, 10) for c in classes}}
    per = {c: metrics(0.9, 0.6, 10) for c in classes}
    table = multiclass.class_table("apolloscape", {"multi": multi, "per_class": per})
    for c in classes:
        single = next(line for line in table.splitlines() if line.startswith(f"| {c} |"))
        assert "| 1.00/2.00 |" in single  # top-1 not bold
        assert "| **0.50/1.00** |" in single
        own = next(line for line in table.splitlines() if f"trained on {c}s only" in line)
        assert "| **0.90/1.80** |" in own
        assert "| 0.60/1.20 |" in own
    whole = next(line for line in table.splitlines() if "per-class models, each on its class" in line)
    assert "| **0.90/1.80** |" in whole


def test_relative_says_level_below_a_twentieth_of_a_percent() -> None:
    text = multiclass.relative({"a": 1.0003, "b": 1.2}, {"a": 1.0, "b": 1.0}, (("x", "a"), ("y", "b")), "worse better")
    assert text == "x level, y worse by 20.0%"
