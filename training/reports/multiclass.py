"""The multi-class sections of ``docs/results.md`` (Stanford Drone, ApolloScape): the single multi-class model, the
same code trained per class (the paper's baselines), constant velocity, published figures, class accuracy and the
calibration of mode probabilities with a reliability plot.

The multi-class models are bundled (``dgan.Predictor("sdd")``); the per-class baselines are kept as slim checkpoints
in ``training/checkpoints/baselines/<dataset>-<class>.pt`` and exported to a temporary ONNX file to be evaluated by
the same engine. ``python -m training.results --train-multiclass`` retrains and re-bundles all of them.
"""

from __future__ import annotations

import json
import tempfile
from pathlib import Path
from typing import Any

import numpy as np

import dgan
from training.data.datasets import DATASETS

__all__ = ["DATASETS", "MULTICLASS_DATASETS", "evaluate_dataset", "reliability_plot", "save", "sections"]
from training.evaluate import evaluate

ROOT = Path(__file__).resolve().parents[2]
BASELINES = ROOT / "training" / "checkpoints" / "baselines"
MULTICLASS_DATASETS = ("sdd", "apolloscape")
#: Published best-of-20 minADE/minFDE (pixels) on this same SDD split and protocol, from Multiclass-SGCN's paper.
MSGCN = {
    "all": (14.37, 26.03),
    "Pedestrian": (9.87, 16.65),
    "Biker": (32.56, 64.41),
    "Skater": (43.73, 84.23),
    "Cart": (19.42, 39.53),
    "Car": (54.01, 95.94),
    "Bus": (33.15, 64.64),
}
SEMANTICS_STGCNN = (18.20, 29.76)
PUBLISHED_CV = (21.81, 45.12)
METRICS = (("ade", "fde"), ("min_ade5", "min_fde5"), ("min_ade20", "min_fde20"))


def fmt(r: dict[str, Any], a: str, b: str, digits: int = 2) -> str:
    return f"{r[a]:.{digits}f}/{r[b]:.{digits}f}"


def evaluate_dataset(dataset: str, root: Path) -> dict[str, Any]:
    """The bundled multi-class model and each per-class baseline on the dataset's test split."""
    from training.export import export_checkpoint

    predictor = dgan.Predictor(dataset)
    out: dict[str, Any] = {"multi": evaluate(predictor, dataset, root)}
    if predictor.spec.map is not None and predictor.spec.map.optional:
        out["multi_nomap"] = evaluate(predictor, dataset, root, with_map=False)
    out["per_class"] = {}
    for cls in DATASETS[dataset].classes:
        ckpt = BASELINES / f"{dataset}-{cls}.pt"
        if not ckpt.is_file():
            continue
        with tempfile.TemporaryDirectory() as tmp:
            path = export_checkpoint(ckpt, Path(tmp) / "m.onnx", f"dgan-{dataset}-{cls}")
            res = evaluate(dgan.Predictor(path), dataset, root)
        out["per_class"][cls] = res["by_class"][cls]
        for label, r in res["by_label"].items():
            if DATASETS[dataset].label_class[DATASETS[dataset].labels.index(label)] == cls:
                out.setdefault("per_class_labels", {})[label] = r
    return out


def combined(groups: list[dict[str, Any]]) -> dict[str, Any]:
    """Agent-weighted average of several groups' metrics."""
    n = sum(g["agents"] for g in groups)
    keys = [k for k, v in groups[0].items() if isinstance(v, float)]
    out: dict[str, Any] = {k: sum(g[k] * g["agents"] for g in groups) / n for k in keys}
    out["agents"] = n
    return out


def class_table(dataset: str, res: dict[str, Any]) -> str:
    multi, per = res["multi"], res["per_class"]
    info = DATASETS[dataset]
    lines = [
        "| agents | n | model | top-1 ADE/FDE | minADE5/FDE5 | minADE20/FDE20 | Brier-minFDE20 |",
        "|---|---|---|---|---|---|---|",
    ]

    keys = [a for a, _ in METRICS] + ["brier_min_fde20"]

    def row(group: str, n: int, model: str, r: dict[str, Any], other: dict[str, Any] | None = None) -> str:
        """A model's row; a cell is bold where it is lower than ``other``'s (the row it is compared with)."""
        cells = [fmt(r, a, b) for a, b in METRICS] + [f"{r['brier_min_fde20']:.2f}"]
        if other is not None:
            cells = [f"**{c}**" if r[k] < other[k] else c for c, k in zip(cells, keys, strict=True)]
        return f"| {group} | {n} | {model} | " + " | ".join(cells) + " |"

    def pair(group: str, n: int, m: dict[str, Any], p: dict[str, Any] | None, per_name: str) -> None:
        lines.append(row(group, n, "DGAN, one model for all classes", m, p))
        if p is not None:
            lines.append(row("", n, per_name, p, m))

    for cls in info.classes:
        if cls not in multi["by_class"]:
            continue
        m = multi["by_class"][cls]
        pair(cls, m["agents"], m, per.get(cls), f"DGAN trained on {cls}s only")
        lines.append(
            f"| | {m['agents']} | constant velocity ({m['cv_variant']}) | {fmt(m, 'cv_ade', 'cv_fde')} | | | |"
        )
    present = [per[c] for c in info.classes if c in per and c in multi["by_class"]]
    whole = combined(present) if len(present) == len(multi["by_class"]) else None
    pair("**all**", multi["agents"], multi, whole, "DGAN per-class models, each on its class")
    cv = f"constant velocity ({multi['cv_variant']})"
    lines.append(f"| | {multi['agents']} | {cv} | {fmt(multi, 'cv_ade', 'cv_fde')} | | | |")
    return "\n".join(lines)


def verdict(dataset: str, res: dict[str, Any]) -> str:
    """Per class, how the single model's top-1 ADE and minADE20 compare with the per-class model's (relative)."""
    multi, per = res["multi"]["by_class"], res["per_class"]
    parts = []
    for cls, m in multi.items():
        if cls in per:
            parts.append(f"{cls}: {relative(m, per[cls], (('top-1 ADE', 'ade'), ('minADE20', 'min_ade20')))}")
    return "Single model against the per-class models: " + "; ".join(parts) + "."


def relative(
    mine: dict[str, Any], other: dict[str, Any], metrics: tuple[tuple[str, str], ...], words: str = "behind ahead"
) -> str:
    """``"top-1 ADE behind by 1.2%, ..."``: each metric of ``mine`` relative to ``other`` (lower is better)."""
    worse, better = words.split()
    cells = []
    for name, key in metrics:
        rel = 100 * (mine[key] - other[key]) / other[key]
        if abs(rel) < 0.05:
            cells.append(f"{name} level")
        else:
            cells.append(f"{name} {worse if rel > 0 else better} by {abs(rel):.1f}%")
    return ", ".join(cells)


def sdd_published_table(res: dict[str, Any]) -> str:
    multi = res["multi"]
    lines = [
        "| label | agents | DGAN minADE20/FDE20 (px) | Multiclass-SGCN | ahead? |",
        "|---|---|---|---|---|",
    ]
    groups = [("all", multi)] + [(k, multi["by_label"][k]) for k in MSGCN if k in multi["by_label"]]
    for name, r in groups:
        pub = MSGCN[name]
        ahead = "yes" if r["min_ade20"] < pub[0] and r["min_fde20"] < pub[1] else "**no**"
        lines.append(
            f"| {name} | {r['agents']} | {fmt(r, 'min_ade20', 'min_fde20')} | {pub[0]:.2f}/{pub[1]:.2f} | {ahead} |"
        )
    lines.append("")
    lines.append(
        f"Overall, Semantics-STGCNN reports {SEMANTICS_STGCNN[0]:.2f}/{SEMANTICS_STGCNN[1]:.2f} and Multiclass-SGCN's "
        f"constant velocity {PUBLISHED_CV[0]:.2f}/{PUBLISHED_CV[1]:.2f}; our constant velocity from the last two "
        f"steps on our windows is {fmt(multi, 'cv_last2_ade', 'cv_last2_fde')} (the mean velocity over the last "
        f"second: {fmt(multi, 'cv_mean1s_ade', 'cv_mean1s_fde')})."
    )
    return "\n".join(lines)


def reliability_plot(results: dict[str, dict[str, Any]], out: Path) -> Path:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, axes = plt.subplots(1, len(results), figsize=(5.2 * len(results), 4.6), dpi=100, squeeze=False)
    for ax, (dataset, res) in zip(axes[0], results.items(), strict=True):
        cal = res["multi"]["calibration"]
        count = np.array(cal["count"])
        keep = count > 0
        p, f = np.array(cal["mean_probability"])[keep], np.array(cal["frequency"])[keep]
        ax.plot([0, 1], [0, 1], ":", color="grey", label="perfect calibration")
        ax.plot(p, f, "o-", color="tab:blue", label=f"DGAN (ECE {cal['ece']:.3f})")
        for x, y, n in zip(p, f, count[keep], strict=True):
            ax.annotate(f"{n}", (x, y), textcoords="offset points", xytext=(4, -10), fontsize=7, color="0.3")
        ax.set_xlim(0, 1)
        ax.set_ylim(0, 1)
        ax.set_xlabel("mode probability p(c)·p(k|c)")
        ax.set_ylabel("fraction that was the best mode")
        ax.set_title(f"{dataset}: {sum(count)} modes of {res['multi']['agents']} agents")
        ax.legend(loc="upper left")
    fig.tight_layout()
    out.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(out)
    plt.close(fig)
    return out


def sections(results: dict[str, dict[str, Any]]) -> str:
    parts = []
    for dataset, res in results.items():
        multi = res["multi"]
        title = {"sdd": "Stanford Drone, multi-class", "apolloscape": "ApolloScape trajectory, multi-class"}[dataset]
        proto = {
            "sdd": "8 observed, 12 predicted steps of 1/3 s; Multiclass-SGCN's 30/13/17 video split; errors in "
            "**pixels** of each video's reference image",
            "apolloscape": "6 observed, 6 predicted steps of 0.5 s; split by recording (test 9048, 9056, 9058, "
            "9061); errors in **metres**",
        }[dataset]
        text = [f"## {title}", "", f"{proto}. {multi['windows']} test windows, {multi['agents']} agents.", ""]
        text += [class_table(dataset, res), "", verdict(dataset, res), ""]
        if dataset == "sdd":
            text += ["### Against published models on this split (best of 20, per agent, pixels)", ""]
            text += [sdd_published_table(res), ""]
        labels = multi["by_label"]
        text += [
            "Per label (DGAN, one model): "
            + "; ".join(
                f"{k} {r['agents']} agents, min20 {fmt(r, 'min_ade20', 'min_fde20')}" for k, r in labels.items()
            )
            + ".",
            "",
            f"**Class probability.** The most probable class is right for {100 * multi['class_accuracy']:.2f}% of "
            "the test agents; the class is an input (one-hot in the traffic state, as in the paper), so p(c) only "
            "has to pass it through. **Calibration.** Expected calibration error of the mode probabilities "
            f"p(c)·p(k|c) against 'this mode is the best (min ADE) of all K': {multi['calibration']['ece']:.3f} "
            "(reliability plot below).",
            "",
        ]
        parts.append("\n".join(text))
    return "\n".join(parts)


def save(results: dict[str, dict[str, Any]], path: Path) -> None:
    path.write_text(json.dumps(results, indent=2))
