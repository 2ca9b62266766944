"""training.results: the ablation table, from the runs when they are there and from the kept figures when not."""

from __future__ import annotations

import json
from pathlib import Path

import pytest

pytest.importorskip("torch")

from training.reports.ethucy import ABLATION_KEYS, ablation_runs, ablation_table


def _run(runs: Path, name: str, ade: float) -> None:
    folder = runs / name
    folder.mkdir(parents=True)
    metrics = {k: ade for k in ABLATION_KEYS} | {"cv_ade": 0.5, "cv_fde": 1.0, "unrelated": 7.0}
    (folder / "metrics.json").write_text(json.dumps(metrics))


def test_the_ablations_are_kept_and_read_back_without_the_runs(tmp_path: Path) -> None:
    runs, store = tmp_path / "runs", tmp_path / "ablations.json"
    _run(runs, "ablation_zara1_full", 0.3)
    _run(runs, "ablation_zara1_full_s1", 0.4)
    _run(runs, "ablation_zara1_k5", 0.2)
    _run(runs, "ablation_eth_full", 9.0)  # another scene's
    found = ablation_runs("zara1", runs, store)
    assert [m["ade"] for m in found["full"]] == [0.3, 0.4]
    assert "unrelated" not in found["full"][0]
    assert json.loads(store.read_text())["zara1"] == found
    again = ablation_runs("zara1", tmp_path / "no_runs", store)
    assert again == found
    table = ablation_table("zara1", again)
    assert "| full model | 2 | 0.350/0.350 |" in table  # the mean of its seeds
    assert "| K_c = 5 anchors | 1 | 0.200/0.200 |" in table
    assert "| constant velocity (the better of its two variants), same targets | | 0.500/1.000 |" in table
    assert "without the map branch" not in table  # not run
    assert "No ablation runs" in ablation_table("zara1", ablation_runs("zara1", tmp_path / "no_runs", tmp_path / "x"))


def test_docs_results_is_its_template_with_the_generated_sections() -> None:
    """Every field of the template is a named section (a stray brace in the prose breaks ``str.format``), and
    ``docs/results.md`` holds the template's prose between them verbatim and in order: prose is edited in both."""
    import string

    from training.results import TEMPLATE

    text = TEMPLATE.read_text()
    fields = [f for _, f, _, _ in string.Formatter().parse(text) if f is not None]
    assert fields
    assert all(f.isidentifier() for f in fields), [f for f in fields if not f.isidentifier()]
    marker = "\x00"
    doc = (Path(__file__).parents[3] / "docs" / "results.md").read_text()
    at = 0
    for chunk in text.format(**dict.fromkeys(fields, marker)).split(marker):
        found = doc.find(chunk, at)
        assert found >= 0, f"docs/results.md lacks the template's prose: {chunk[:300]!r}"
        at = found + len(chunk)
