"""benches/plot.py draws one panel per model with a line per pipeline the rows hold, and draws a saved run again."""

from __future__ import annotations

from pathlib import Path

import pytest

from benches.plot import latency_figure, main, save_run

pytest.importorskip("matplotlib")


def rows() -> list[dict[str, float | str]]:
    out: list[dict[str, float | str]] = []
    for model, scale in (("zara1", 1.0), ("hdmap", 2.0), ("apolloscape", 0.5)):
        for n in (256, 8, 32):  # unsorted, as a user's list may be
            row: dict[str, float | str] = {"model": model, "N": n, "predict": scale * n / 10, "ort": scale * n / 14}
            if model != "apolloscape":  # a model without a checkpoint has no PyTorch pipeline
                row |= {"torch_pipeline": scale * n / 7, "research": scale * n / 2}
            out.append(row)
    return out


def test_one_panel_per_model_and_a_line_per_pipeline_in_the_order_of_n(tmp_path: Path) -> None:
    fig = latency_figure(rows(), "a run")
    panels = [ax for ax in fig.axes if ax.axison]
    assert [ax.get_title() for ax in panels] == ["zara1", "hdmap", "apolloscape"]
    assert [len(ax.get_lines()) for ax in panels] == [4, 4, 2]
    predict = panels[1].get_lines()[0]
    assert predict.get_label() == "dgan predict"
    assert list(predict.get_xdata()) == [8, 32, 256]
    assert list(predict.get_ydata()) == pytest.approx([1.6, 6.4, 51.2])
    assert panels[0].get_xscale() == panels[0].get_yscale() == "log"
    with pytest.raises(ValueError, match="no benchmark rows"):
        latency_figure([], "empty")


def test_a_saved_run_is_drawn_again(tmp_path: Path) -> None:
    run, picture = tmp_path / "run.json", tmp_path / "latency.png"
    save_run(rows(), {"date": "2026-12-07 07:00", "sgemm_gflops": 170.2, "repeat": 30}, run)
    main([str(run), str(picture)])
    assert picture.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    assert picture.stat().st_size > 10_000
