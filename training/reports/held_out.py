"""The test sets of ``docs/results.md``'s scorecard, the same with tracker-like noise, and their calibration."""

from __future__ import annotations

from pathlib import Path
from typing import Any

import dgan
from training.evaluate import evaluate
from training.reports import scorecard
from training.reports.ethucy import SCENES

#: The driving test sets of ``hdmap`` (dataset, the name every table gives it).
DRIVING_TEST_SETS = (("hdmap", "nuScenes + Waymo held out"), ("argoverse2", "Argoverse 2 (never trained on)"))


#: Tracker-like histories of the noisy-track table: Gaussian noise on the observed positions (metres), with this
#: share of the observed steps before the current one dropped.
NOISE_SIGMAS_M = (0.1, 0.3)


NOISE_DROP = 0.1


def noisy_results(root: Path) -> dict[str, dict[str, Any]]:
    """Per test set (named as in :func:`test_sets`) and noise level: the bundled model on the test split with
    tracker-like histories (``training.evaluate.evaluate(noise=...)``), constant velocity on the same noisy ones."""
    from tqdm import tqdm

    jobs = [(f"ETH/UCY {s}", s, "ethucy", s) for s in SCENES]
    jobs += [("Stanford Drone", "sdd", "sdd", ""), ("ApolloScape", "apolloscape", "apolloscape", "")]
    jobs += [(name, "hdmap", dataset, "") for dataset, name in DRIVING_TEST_SETS]
    out: dict[str, dict[str, Any]] = {}
    for name, model, dataset, fold in tqdm(jobs, desc="noisy tracks"):
        predictor = dgan.Predictor(model)
        for sigma in NOISE_SIGMAS_M:
            out.setdefault(name, {})[f"{sigma:g}"] = evaluate(predictor, dataset, root, fold, noise=(sigma, NOISE_DROP))
    return out


def noise_table(noisy: dict[str, dict[str, Any]]) -> str:
    """Top-1 ADE/FDE against constant velocity from the same noisy history, per test set, class and noise level."""
    head = "| test set | class | targets | " + " | ".join(
        f"noise {s:g} m: top-1 | constant velocity" for s in NOISE_SIGMAS_M
    )
    lines = [head + " |", "|---|---|---|" + "---|---|" * len(NOISE_SIGMAS_M)]
    for name, by_sigma in noisy.items():
        first = by_sigma[f"{NOISE_SIGMAS_M[0]:g}"]
        for cls in [*first.get("by_class", {}), "all"]:
            rs = [r if cls == "all" else r["by_class"][cls] for r in by_sigma.values()]
            cells = [name, cls, str(rs[0]["agents"])]
            for r in rs:
                cells += [f"{r['ade']:.2f}/{r['fde']:.2f}", f"{r['cv_ade']:.2f}/{r['cv_fde']:.2f}"]
            lines.append("| " + " | ".join(cells) + " |")
    return "\n".join(lines)


def test_sets(
    res: dict[str, Any], res_nomap: dict[str, Any], multi: dict[str, Any], hd: dict[str, Any]
) -> list[scorecard.TestSet]:
    """Every test set of the scorecard, in the order of the issue: ETH/UCY per scene and on average, Stanford
    Drone, ApolloScape, the held-out nuScenes + Waymo scenes and Argoverse 2."""
    out = [scorecard.TestSet(f"ETH/UCY {s}", "m", res[s], res_nomap.get(s)) for s in SCENES]
    avg_nomap = scorecard.mean_of([res_nomap[s] for s in SCENES], "avg") if len(res_nomap) == len(SCENES) else None
    out.append(scorecard.TestSet("ETH/UCY average", "m", scorecard.mean_of([res[s] for s in SCENES], "avg"), avg_nomap))
    out.append(scorecard.TestSet("Stanford Drone", "px", multi["sdd"]["multi"], multi["sdd"].get("multi_nomap")))
    out.append(scorecard.TestSet("ApolloScape", "m", multi["apolloscape"]["multi"]))
    for key, name in DRIVING_TEST_SETS:
        out.append(scorecard.TestSet(name, "m", hd[key]["map"], hd[key].get("map_absent")))
    return out


def calibrations(
    res: dict[str, Any], multi: dict[str, Any], hd: dict[str, Any]
) -> dict[str, tuple[dict[str, Any], dict[str, Any], float]]:
    """Reliability before (T = 1) and after the fitted temperature, per test set (ETH/UCY pooled over its folds,
    whose temperatures differ: shown as their mean)."""
    out = {
        "ETH/UCY (5 folds)": (
            scorecard.pooled([res[s]["calibration_t1"] for s in SCENES]),
            scorecard.pooled([res[s]["calibration"] for s in SCENES]),
            sum(res[s]["temperature"] for s in SCENES) / len(SCENES),
        )
    }
    for name, r in (
        ("Stanford Drone", multi["sdd"]["multi"]),
        ("ApolloScape", multi["apolloscape"]["multi"]),
        ("nuScenes + Waymo", hd["hdmap"]["map"]),
        ("Argoverse 2", hd["argoverse2"]["map"]),
    ):
        out[name] = (r["calibration_t1"], r["calibration"], r["temperature"])
    return out
