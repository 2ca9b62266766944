"""The scorecard of ``docs/results.md``: every test set and every class against constant velocity, with and without
the map, and the calibration of the mode probabilities before and after the temperature.

Each test set is one evaluation (:func:`training.evaluate.evaluate`) of a bundled model on held-out data, and, for a
model with a map branch, a second evaluation of the same model on the same frames without their map. Constant
velocity is the better of its two variants (the last two steps; the mean velocity over the last second) on the same
targets, for each error separately.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from training.metrics import MIN_BIN_MODES, worst_gap

#: A class counts in the claim "at or below constant velocity" when it has at least this many targets.
MIN_TARGETS = 50
#: The largest gap allowed in a checked calibration bin (``training.metrics.worst_gap``).
MAX_GAP = 0.1


#: The two groups every target falls in (``training.evaluate.STANDING_M``).
MOTIONS = ("moving", "standing")


@dataclass(frozen=True)
class TestSet:
    """One test set: its name, unit, the model's results with its map (or without a map branch) and, for a map
    model, the same model's results on the same frames without the map."""

    name: str
    unit: str
    res: dict[str, Any]
    nomap: dict[str, Any] | None = None


def mean_of(results: list[dict[str, Any]], name: str) -> dict[str, Any]:
    """The unweighted mean of several results (the ETH/UCY protocol averages its five scenes), class by class."""
    keys = [k for k, v in results[0].items() if isinstance(v, float)]
    out: dict[str, Any] = {k: float(np.mean([r[k] for r in results])) for k in keys}
    out["agents"] = sum(r["agents"] for r in results)
    out["windows"] = sum(r.get("windows", 0) for r in results)
    out["cv_variant"] = "per scene"
    classes = set.intersection(*(set(r.get("by_class", {})) for r in results))
    out["by_class"] = {c: mean_of([r["by_class"][c] for r in results], name) for c in sorted(classes)}
    for motion in MOTIONS:
        if all(motion in r.get("by_motion", {}) for r in results):
            out.setdefault("by_motion", {})[motion] = mean_of([r["by_motion"][motion] for r in results], name)
        for c in classes:
            if all(motion in r["by_class"][c] for r in results):
                out["by_class"][c][motion] = mean_of([r["by_class"][c][motion] for r in results], name)
    out["name"] = name
    return out


def _rel(a: float, b: float) -> float:
    """How far ``a`` is below ``b``, in percent of ``b`` (positive: ``a`` is better)."""
    return 100.0 * (b - a) / b


def rows(ts: TestSet) -> list[dict[str, Any]]:
    """One row per class with targets, then 'all'."""
    groups = [(c, r) for c, r in ts.res.get("by_class", {}).items()]
    if len(groups) != 1:
        groups.append(("all", ts.res))
    out = []
    for cls, r in groups:
        row: dict[str, Any] = {"test": ts.name, "class": cls, "n": r["agents"], "r": r}
        row["gain_ade"] = _rel(r["ade"], r["cv_ade"])
        row["gain_fde"] = _rel(r["fde"], r["cv_fde"])
        if ts.nomap is not None:
            n = ts.nomap if cls == "all" else ts.nomap["by_class"].get(cls)
            if n is not None:
                row["nomap"] = n
                row["nomap_vs_map_ade"] = -_rel(n["ade"], r["ade"])
                row["nomap_vs_map_fde"] = -_rel(n["fde"], r["fde"])
                row["nomap_gain_ade"] = _rel(n["ade"], n["cv_ade"])
                row["nomap_gain_fde"] = _rel(n["fde"], n["cv_fde"])
        out.append(row)
    return out


def _pair(r: dict[str, Any], a: str, b: str) -> str:
    return f"{r[a]:.2f}/{r[b]:.2f}" if a in r and np.isfinite(r[a]) else ""


def table(tests: list[TestSet]) -> str:
    head = (
        "| test set | class | targets | top-1 ADE/FDE | min5 | min20 (min K if K < 20) | Brier-minFDE | "
        "constant velocity | "
        "top-1 below CV (ADE, FDE) | without the map: top-1 | no map vs map |"
    )
    lines = [head, "|---|---|---|---|---|---|---|---|---|---|---|"]
    for ts in tests:
        for row in rows(ts):
            r = row["r"]
            brier = r.get("brier_min_fde20", r.get("brier_min_fde5", float("nan")))
            k = min(20, int(ts.res.get("num_modes", 20))) if "brier_min_fde20" in r else 5
            nm = row.get("nomap")
            cells = [
                ts.name,
                row["class"],
                str(row["n"]),
                f"**{_pair(r, 'ade', 'fde')}**",
                _pair(r, "min_ade5", "min_fde5"),
                _pair(r, "min_ade20", "min_fde20"),
                f"{brier:.2f} (K={k})",
                f"{_pair(r, 'cv_ade', 'cv_fde')} ({r.get('cv_variant', '')})",
                f"{row['gain_ade']:+.1f}%, {row['gain_fde']:+.1f}%",
                _pair(nm, "ade", "fde") if nm else "",
                f"{row['nomap_vs_map_ade']:+.1f}%, {row['nomap_vs_map_fde']:+.1f}%" if nm else "",
            ]
            lines.append("| " + " | ".join(cells) + " |")
    return "\n".join(lines)


def motion_table(tests: list[TestSet]) -> str:
    """Moving and standing targets apart, per test set and class (and all of its targets): how many, and top-1
    ADE/FDE against constant velocity on the same targets."""
    head = "| test set | class | moving | top-1 | constant velocity | standing | top-1 | constant velocity |"
    lines = [head, "|---|---|---|---|---|---|---|---|"]
    for ts in tests:
        groups = [(c, r) for c, r in ts.res.get("by_class", {}).items()] + [("all", ts.res)]
        for cls, r in groups:
            m, st = r.get("by_motion", r).get("moving"), r.get("by_motion", r).get("standing")
            if m is None or st is None:
                continue
            cells = [ts.name, cls]
            for g in (m, st):
                cells += [str(g["agents"]), _pair(g, "ade", "fde"), _pair(g, "cv_ade", "cv_fde")]
            lines.append("| " + " | ".join(cells) + " |")
    return "\n".join(lines)


def findings(tests: list[TestSet]) -> dict[str, Any]:
    """The issue's checks, computed: classes of ≥ MIN_TARGETS targets whose top-1 is above constant velocity; the
    mean gain over the test sets; map models without their map against constant velocity and against the map."""
    per_test = {ts.name: rows(ts) for ts in tests}
    all_rows = [row for ts_rows in per_test.values() for row in ts_rows]
    counted = [row for row in all_rows if row["n"] >= MIN_TARGETS]
    behind = [
        f"{row['test']} {row['class']} (ADE {row['gain_ade']:+.1f}%, FDE {row['gain_fde']:+.1f}%)"
        for row in counted
        if row["gain_ade"] < 0 or row["gain_fde"] < 0
    ]
    # One overall row per test set; the per-scene rows of a protocol that also has an average row ("X average")
    # count through that average only.
    averaged = {ts.name.removesuffix(" average") for ts in tests if ts.name.endswith(" average")}
    sets = [ts for ts in tests if not any(ts.name.startswith(a + " ") and ts.name != a + " average" for a in averaged)]
    # rows() ends with the 'all' row, or has a single class row.
    overall = [per_test[ts.name][-1] for ts in sets]
    mean_ade = float(np.mean([row["gain_ade"] for row in overall]))
    mean_fde = float(np.mean([row["gain_fde"] for row in overall]))
    nomap = [row for row in counted if "nomap" in row]
    nomap_behind_cv = [
        f"{row['test']} {row['class']}" for row in nomap if row["nomap_gain_ade"] < 0 or row["nomap_gain_fde"] < 0
    ]
    nomap_far = [
        f"{row['test']} {row['class']} (ADE {row['nomap_vs_map_ade']:+.1f}%, FDE {row['nomap_vs_map_fde']:+.1f}%)"
        for row in nomap
        if row["nomap_vs_map_ade"] > 10 or row["nomap_vs_map_fde"] > 10
    ]
    return {
        "test_sets_averaged": [ts.name for ts in sets],
        "behind_cv": behind,
        "mean_gain_ade": mean_ade,
        "mean_gain_fde": mean_fde,
        "nomap_behind_cv": nomap_behind_cv,
        "nomap_more_than_10pct_worse": nomap_far,
    }


def summary(tests: list[TestSet]) -> str:
    f = findings(tests)

    def side(gain: float) -> str:
        return f"{abs(gain):.1f}% {'below' if gain >= 0 else 'above'}"

    lines = [
        f"- **Top-1 against constant velocity**: on average over the {len(f['test_sets_averaged'])} test sets "
        f"({', '.join(f['test_sets_averaged'])}), top-1 is {side(f['mean_gain_ade'])} constant velocity in ADE and "
        f"{side(f['mean_gain_fde'])} it in FDE.",
        "- Classes with at least "
        f"{MIN_TARGETS} targets whose top-1 ADE or FDE is above constant velocity: "
        + (", ".join(f["behind_cv"]) if f["behind_cv"] else "**none**")
        + ".",
        "- Map models without their map: behind constant velocity on "
        + (", ".join(f["nomap_behind_cv"]) if f["nomap_behind_cv"] else "**no test set or class**")
        + "; more than 10% worse than with the map on "
        + (", ".join(f["nomap_more_than_10pct_worse"]) if f["nomap_more_than_10pct_worse"] else "**none**")
        + ".",
    ]
    return "\n".join(lines)


# ---- calibration -----------------------------------------------------------------------------------------------------


def pooled(cals: list[dict[str, Any]]) -> dict[str, Any]:
    """Several reliability tables (same bins) as one."""
    count = np.sum([c["count"] for c in cals], axis=0)
    w = np.maximum(count, 1)
    mean_p = np.sum([np.array(c["mean_probability"]) * c["count"] for c in cals], axis=0) / w
    freq = np.sum([np.array(c["frequency"]) * c["count"] for c in cals], axis=0) / w
    ece = float(np.sum(count * np.abs(mean_p - freq)) / max(1, count.sum()))
    return {
        "edges": cals[0]["edges"],
        "count": count.tolist(),
        "mean_probability": mean_p.tolist(),
        "frequency": freq.tolist(),
        "ece": ece,
    }


def calibration_table(cals: dict[str, tuple[dict[str, Any], dict[str, Any], float]]) -> str:
    """``cals``: test set → (before, after, temperature)."""
    lines = [
        f"| test set | temperature | ECE before → after | worst gap in a bin with p ≥ 0.3 and ≥ {MIN_BIN_MODES} modes, "
        "before → after |",
        "|---|---|---|---|",
    ]

    def gap(cal: dict[str, Any]) -> str:
        g, p = worst_gap(cal)
        return "no such bin" if np.isnan(p) else f"{g:.2f} (p≈{p:.2f})"

    for name, (before, after, t) in cals.items():
        ok = "" if worst_gap(after)[0] <= MAX_GAP else " (**over 0.1**)"
        lines.append(
            f"| {name} | {t:.2f} | {before['ece']:.4f} → {after['ece']:.4f} | {gap(before)} → {gap(after)}{ok} |"
        )
    return "\n".join(lines)


def reliability_figure(cals: dict[str, tuple[dict[str, Any], dict[str, Any], float]], out: Path) -> Path:
    """One panel per test set: the reliability curve at temperature 1 and at the fitted temperature."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    n = len(cals)
    fig, axes = plt.subplots(1, n, figsize=(4.2 * n, 4.4), dpi=90, squeeze=False)
    for ax, (name, (before, after, t)) in zip(axes[0], cals.items(), strict=True):
        ax.fill_between([0, 1], [-MAX_GAP, 1 - MAX_GAP], [MAX_GAP, 1 + MAX_GAP], color="0.92", label="±0.1")
        ax.plot([0, 1], [0, 1], ":", color="grey")
        for cal, style, label in ((before, "s--", "T = 1"), (after, "o-", f"T = {t:.2f}")):
            count = np.array(cal["count"])
            keep = count > 0
            ax.plot(
                np.array(cal["mean_probability"])[keep],
                np.array(cal["frequency"])[keep],
                style,
                label=f"{label} (ECE {cal['ece']:.3f})",
            )
        ax.set_xlim(0, 1)
        ax.set_ylim(0, 1)
        ax.set_xlabel("mode probability p(c)·p(k|c)")
        ax.set_title(name, fontsize=10)
        ax.legend(loc="upper left", fontsize=7)
    axes[0][0].set_ylabel("fraction that was the best mode")
    fig.tight_layout()
    out.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(out)
    plt.close(fig)
    return out
