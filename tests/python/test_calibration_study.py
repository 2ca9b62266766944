"""training.calibration_study: the calibration maps, fitted on synthetic modes whose truth is known."""

from __future__ import annotations

import json
import math
from pathlib import Path

import numpy as np
import pytest

pytest.importorskip("sklearn")
pytest.importorskip("scipy")

from training import calibration_study as cs
from training.evaluate import per_class_normalised


def synthetic(n: int, temperature: float, seed: int = 0) -> cs.Modes:
    """Two classes of 3 and 2 modes; the best mode drawn from p^(1/temperature) renormalised per class (the modes a
    model at T = 1 gives when the true temperature is ``temperature``)."""
    rng = np.random.default_rng(seed)
    mc = np.tile(np.array([0, 0, 0, 1, 1]), (n, 1))
    pk = per_class_normalised(rng.dirichlet(np.ones(5) * 0.7, size=n), mc)
    true = cs.tempered(pk, mc, temperature)
    pc = np.where(mc == 0, 1.0, 0.0)  # every agent of class 0
    best = np.array([rng.choice(3, p=row[:3] / row[:3].sum()) for row in true])
    m = object.__new__(cs.Modes)
    m.pk, m.pc, m.mc, m.best = pk, pc, mc, best
    return m


def test_probabilities_are_renormalised_within_each_class() -> None:
    m = synthetic(50, 1.0)
    for q in (cs.tempered(m.pk, m.mc, 2.0), cs.platt(m.pk, m.mc, 0.5, -1.0)):
        np.testing.assert_allclose(np.where(m.mc == 0, q, 0).sum(axis=1), 1.0)
        np.testing.assert_allclose(np.where(m.mc == 1, q, 0).sum(axis=1), 1.0)
    # Temperature 1 and Platt (1, 0) leave p(k | c) as it is.
    np.testing.assert_allclose(cs.tempered(m.pk, m.mc, 1.0), m.pk, atol=1e-12)
    np.testing.assert_allclose(cs.platt(m.pk, m.mc, 1.0, 0.0), m.pk, atol=1e-9)


def test_a_fitted_temperature_calibrates_the_best_mode() -> None:
    val, test = synthetic(4000, 2.0, seed=1), synthetic(4000, 2.0, seed=2)
    raw = test.reliability(test.pk)
    for family in cs.FAMILIES:
        f = cs.fit(family, val)
        assert val.nll(f(val.pk, val.mc)) < val.nll(val.pk)  # the data were drawn at T = 2, not 1
        assert test.reliability(f(test.pk, test.mc))["ece"] < raw["ece"]
    # Both temperature fits (likelihood and Brier score) recover the temperature the data were drawn at.
    for family in ("temperature", "temperature_brier"):
        q = cs.fit(family, val)(val.pk, val.mc)
        np.testing.assert_allclose(q, cs.tempered(val.pk, val.mc, 2.0), atol=0.05)


def test_the_brier_score_is_lowest_for_the_true_probabilities() -> None:
    m = synthetic(4000, 2.0, seed=3)
    scores = {t: m.brier(cs.tempered(m.pk, m.mc, t)) for t in (1.0, 2.0, 4.0)}
    assert scores[2.0] < scores[1.0]
    assert scores[2.0] < scores[4.0]


def test_section_renders_the_study(tmp_path: Path) -> None:
    path = tmp_path / "study.json"
    assert "not run" in cs.section(path)
    study = {
        "eth": {"temperature": {"validation": [0.19, 0.55], "ethucy": [0.0, math.nan]}},
        "hdmap": {"isotonic": {"validation": [0.31, 0.56], "hdmap": [0.65, 0.94], "argoverse2": [0.34, 0.95]}},
    }
    path.write_text(json.dumps(study))
    text = cs.section(path)
    assert "| eth | temperature | 0.19 (p≈0.55) | no bin of 30 modes |" in text
    assert "| hdmap | isotonic | 0.31 (p≈0.56) | hdmap: 0.65 (p≈0.94), argoverse2: 0.34 (p≈0.95) |" in text
