"""The leave-one-source-out study (``training.studies.sources``): which sources each model trains on, the verdict
and the page's section, on hand-made figures."""

from __future__ import annotations

import json
from pathlib import Path
from typing import Any

from training.data.datasets import AT_HDMAP, DATASETS
from training.studies import sources


def test_no_model_trains_on_the_source_it_is_tested_on() -> None:
    for held, (dataset, others) in sources.HELD_OUT.items():
        assert held in DATASETS
        assert dataset != held
        assert held not in others
        assert set(others) <= set(AT_HDMAP)
        assert set(others) <= set(sources.STRIDES)
        if held in ("nuscenes", "waymo"):
            assert dataset in ("nuscenes", "waymo")  # the other of hdmap's two sources
        else:
            assert dataset == "hdmap"
    assert set(sources.HELD_OUT) == {"nuscenes", "waymo", "argoverse2", *AT_HDMAP}


def cell(n: int, ade: float, fde: float, cv_ade: float = 1.0, cv_fde: float = 2.0) -> dict[str, Any]:
    return {
        "n": n,
        "ade": ade,
        "fde": fde,
        "cv_ade": cv_ade,
        "cv_fde": cv_fde,
        "ade_ratio": ade / cv_ade,
        "fde_ratio": fde / cv_fde,
    }


def row(vehicle: dict[str, Any], cyclist: dict[str, Any]) -> dict[str, Any]:
    return {
        "all": cell(200, 0.8, 1.6),
        "by_motion": {"moving": cell(150, 0.9, 1.7), "standing": cell(50, 0.1, 0.2)},
        "by_class": {"vehicle": vehicle, "cyclist": cyclist},
    }


def test_the_verdict_counts_every_class_with_enough_targets() -> None:
    assert sources.verdict(row(cell(150, 0.85, 1.7), cell(49, 2.0, 4.0)))  # 49 cyclists: not counted
    assert not sources.verdict(row(cell(150, 0.85, 1.7), cell(50, 2.0, 4.0)))
    assert not sources.verdict(row(cell(150, 0.85, 1.84), cell(10, 0.5, 1.0)))  # FDE 0.92 ×


def test_the_section_names_each_source_and_the_mean(tmp_path: Path) -> None:
    assert "not run" in sources.section(tmp_path / "none.json")
    study = {
        "ethucy_5hz": {"trained without it": row(cell(150, 0.85, 1.7), cell(60, 1.0, 1.0))},
        "sdd_5hz": {
            "trained without it": row(cell(150, 0.5, 1.0), cell(60, 0.5, 1.0)),
            "bundled hdmap": row(cell(150, 0.9, 1.9), cell(60, 0.9, 1.9)),
        },
    }
    path = tmp_path / "study.json"
    path.write_text(json.dumps(study))
    text = sources.section(path)
    assert "- ethucy_5hz (200 targets): over 0.9: cyclist 1.00/0.50." in text
    assert "- sdd_5hz (200 targets): within 0.9 × constant velocity." in text
    assert "Mean over the 2 held-out sources: 0.800/0.800" in text
    assert "| sdd_5hz | bundled hdmap | vehicle | 150 | 0.900/1.900 | 1.000/2.000 | 0.900/0.950 |" in text
    assert sources.mean_ratios(study) == (0.8, 0.8)


def test_variants_are_summarised_apart_with_their_settings_and_validation(tmp_path: Path) -> None:
    base = row(cell(150, 0.85, 1.7), cell(60, 1.0, 1.0))
    variant = {**row(cell(150, 0.5, 1.0), cell(60, 0.5, 1.0)), "sets": [*sources.STUDY_SETS, "data.x=1"]}
    variant["validation"] = {"hdmap": row(cell(150, 0.45, 0.9), cell(60, 0.95, 1.9))}
    name = sources.model_name("x")
    assert name == "trained without it (x)"
    assert sources.model_name() == sources.TRAINED
    study = {"waymo": {sources.TRAINED: base, name: variant}}
    assert sources.trained_models(study) == [sources.TRAINED, name]
    assert sources.sets_of(study, name) == ["`data.x=1`"]
    path = tmp_path / "study.json"
    path.write_text(json.dumps(study))
    text = sources.section(path)
    assert "*trained without it (x)* (`data.x=1`):" in text
    assert text.count("Mean over the 1 held-out sources") == 2
    assert "| trained without it (x) | waymo | hdmap | 0.80/0.80 (200) | 0.45/0.45 (150) | 0.95/0.95 (60) | – |" in text
    assert sources.mean_ratios(study, name) == (0.8, 0.8)
    assert sources.trained_on("argoverse2")[0] == "hdmap"
    assert "argoverse2" not in sources.trained_on("argoverse2")
