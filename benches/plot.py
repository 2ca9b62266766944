"""Pictures of a benchmark run (``benches/bench.py --plot``): the time of one call against the number of agents, per
model, for the engine and the pipelines it replaces, every line from the same run; and the rows as JSON
(``--json``), from which :func:`main` draws the picture again (``python -m benches.plot RUN.json PICTURE.png``)."""

from __future__ import annotations

import argparse
import json
import math
from collections.abc import Sequence
from pathlib import Path
from typing import Any

#: What each line of a panel shows: the row's key, its label, colour and dash.
SERIES = (
    ("predict", "dgan predict", "C0", "-"),
    ("ort", "bare ONNX Runtime (network only)", "C1", "--"),
    ("torch_pipeline", "PyTorch-eager pipeline", "C2", "-."),
    ("research", "research-style pipeline", "C3", ":"),
)


def latency_figure(rows: Sequence[dict[str, Any]], title: str) -> Any:
    """One log-log panel per model of ``rows`` (:func:`benches.bench.bench_model`'s): milliseconds per call against
    N, a line for each of :data:`SERIES` that the rows hold. Returns the matplotlib figure."""
    import matplotlib
    import matplotlib.ticker

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    models = list(dict.fromkeys(r["model"] for r in rows))
    if not models:
        raise ValueError("no benchmark rows to draw")
    cols = min(4, len(models))
    fig, axes = plt.subplots(
        math.ceil(len(models) / cols), cols, figsize=(3.3 * cols, 2.9 * math.ceil(len(models) / cols)), squeeze=False
    )
    for ax, model in zip(axes.flat, models, strict=False):
        ours = sorted((r for r in rows if r["model"] == model), key=lambda r: int(r["N"]))
        for key, label, colour, dash in SERIES:
            points = [(int(r["N"]), float(r[key])) for r in ours if key in r]
            if points:
                n, ms = zip(*points, strict=True)
                ax.plot(n, ms, color=colour, linestyle=dash, marker="o", markersize=3, label=label)
        ax.set_xscale("log", base=2)
        ax.set_yscale("log")
        ax.set_xticks(sorted({int(r["N"]) for r in ours}))
        ax.xaxis.set_major_formatter(matplotlib.ticker.ScalarFormatter())
        ax.xaxis.set_minor_locator(matplotlib.ticker.NullLocator())
        ax.set_title(model, fontsize=10)
        ax.grid(True, which="both", alpha=0.3)
        ax.tick_params(labelsize=8)
    for ax in axes.flat[len(models) :]:
        ax.axis("off")
    for ax in axes[:, 0]:
        ax.set_ylabel("ms per call", fontsize=9)
    for ax in axes[-1, :]:
        ax.set_xlabel("agents N", fontsize=9)
    handles, labels = axes.flat[0].get_legend_handles_labels()
    fig.legend(handles, labels, loc="lower center", ncol=len(labels), fontsize=9, frameon=False)
    fig.suptitle(title, fontsize=10)
    fig.tight_layout(rect=(0, 0.05, 1, 0.97))
    return fig


def save_run(rows: Sequence[dict[str, Any]], about: dict[str, Any], path: Path) -> None:
    """The run's rows and what describes it (date, sgemm, repeats) as JSON."""
    path.write_text(json.dumps({"about": about, "rows": list(rows)}, indent=1) + "\n")


def title_of(about: dict[str, Any]) -> str:
    return f"one thread, medians of {about['repeat']} calls; {about['date']}, sgemm {about['sgemm_gflops']:.0f} GFLOP/s"


def main(argv: Sequence[str] | None = None) -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("run", type=Path, help="a run's JSON (bench.py --json)")
    ap.add_argument("picture", type=Path, help="the PNG to write")
    a = ap.parse_args(argv)
    run = json.loads(a.run.read_text())
    latency_figure(run["rows"], title_of(run["about"])).savefig(a.picture, dpi=110)


if __name__ == "__main__":
    main()
