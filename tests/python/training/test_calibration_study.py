"""training.studies.calibration: the calibration maps, fitted on synthetic modes whose truth is known."""

from __future__ import annotations

import json
import math
from pathlib import Path

import numpy as np
import pytest

pytest.importorskip("sklearn")
pytest.importorskip("scipy")
pytest.importorskip("torch")

from training.evaluate import per_class_normalised
from training.studies import calibration as cs


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
    m.speed = rng.uniform(0.0, 3.0, size=n)  # the temperature does not depend on it
    return m


def test_probabilities_are_renormalised_within_each_class() -> None:
    m = synthetic(50, 1.0)
    for q in (cs.tempered(m.pk, m.mc, 2.0), cs.platt(m.pk, m.mc, 0.5, -1.0)):
        np.testing.assert_allclose(np.where(m.mc == 0, q, 0).sum(axis=1), 1.0)
        np.testing.assert_allclose(np.where(m.mc == 1, q, 0).sum(axis=1), 1.0)
    # Temperature 1 and Platt (1, 0) leave p(k | c) as it is.
    np.testing.assert_allclose(cs.tempered(m.pk, m.mc, 1.0), m.pk, atol=1e-12)
    np.testing.assert_allclose(cs.platt(m.pk, m.mc, 1.0, 0.0), m.pk, atol=1e-9)


@pytest.mark.slow
def test_a_fitted_temperature_calibrates_the_best_mode() -> None:
    val, test = synthetic(4000, 2.0, seed=1), synthetic(4000, 2.0, seed=2)
    raw = test.reliability(test.pk * test.pc)
    for family in cs.FAMILIES:
        f = cs.fit(family, val)
        assert val.nll(f(val)) < val.nll(val.pk * val.pc)  # the data were drawn at T = 2, not 1
        assert test.reliability(f(test))["ece"] < raw["ece"]
    # Every temperature fit recovers the temperature the data were drawn at: the likelihood's, the Brier score's, the
    # one beside a class temperature (every agent is of class 0 for certain) and the one that may vary with speed.
    for family in ("temperature", "temperature_brier", "class_temperature", "temperature_by_speed"):
        p = cs.fit(family, val)(val)
        np.testing.assert_allclose(p, cs.tempered(val.pk, val.mc, 2.0) * val.pc, atol=0.05, err_msg=family)


def test_a_class_temperature_renormalises_over_the_classes_of_a_row() -> None:
    mc = np.array([[0, 0, 1, 2], [0, 1, 1, 1]])
    pc = np.array([[0.7, 0.7, 0.2, 0.1], [0.5, 0.5, 0.5, 0.5]])
    q = cs.class_tempered(pc, mc, 2.0)
    w = np.sqrt([0.7, 0.2, 0.1])
    np.testing.assert_allclose(q[0], (w / w.sum())[[0, 0, 1, 2]])
    np.testing.assert_allclose(q[1], 0.5)  # classes 0 and 1 alike
    np.testing.assert_allclose(cs.class_tempered(pc[:1], mc[:1], 1.0), pc[:1] / 1.0)


def test_the_brier_score_is_lowest_for_the_true_probabilities() -> None:
    m = synthetic(4000, 2.0, seed=3)
    scores = {t: m.brier(cs.tempered(m.pk, m.mc, t) * m.pc) for t in (1.0, 2.0, 4.0)}
    assert scores[2.0] < scores[1.0]
    assert scores[2.0] < scores[4.0]


def test_diagnostics_count_other_classes_and_speeds(tmp_path: Path) -> None:
    m = synthetic(6, 1.0)
    m.classes, m.temperature = ("vehicle", "cyclist"), 1.0
    m.own = np.array([0, 0, 0, 0, 1, 1])
    m.margin = np.array([0.0, 0.5, 0.3, 0.0, 0.0, 0.2])  # two vehicles and a cyclist best served by another class
    m.speed = np.array([0.1, 0.1, 1.0, 5.0, 5.0, 5.0])
    m.pk = np.tile([0.7, 0.2, 0.1, 0.5, 0.5], (6, 1))
    m.pc = np.where(m.mc == 0, 1.0, 0.0)
    m.best = np.array([0, 1, 0, 0, 2, 0])
    d = cs.diagnostics(m)
    assert d["classes"]["vehicle"] == {"targets": 4, "other_class": 0.5, "closer": pytest.approx(0.4)}
    assert d["classes"]["cyclist"] == {"targets": 2, "other_class": 0.5, "closer": pytest.approx(0.2)}
    standing, fast = d["speeds"]["standing, under 0.2 m/s"], d["speeds"]["faster than 3 m/s"]
    assert (standing["targets"], standing["top_wins"], standing["top_p"]) == (2, 0.5, pytest.approx(0.7))
    assert (fast["targets"], fast["top_wins"]) == (3, pytest.approx(2 / 3))
    path = tmp_path / "why.json"
    assert "not run" in cs.diagnostics_section(path)
    path.write_text(json.dumps({"apolloscape": d}))
    text = cs.diagnostics_section(path)
    assert "| apolloscape | vehicle | 4 | 50% | 0.40 m |" in text
    assert "| apolloscape | vehicle | 4 | 50% | 0.40 m |" in text
    for band in d["speeds"].values():
        band["targets"] *= 10  # bands of fewer than 30 targets are left out of the table
    path.write_text(json.dumps({"apolloscape": d}))
    text = cs.diagnostics_section(path)
    assert "| apolloscape | faster than 3 m/s | 30 | 67% | 0.70 |" in text
    assert "| apolloscape | 0.2 to 3 m/s | 10 |" not in text


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
