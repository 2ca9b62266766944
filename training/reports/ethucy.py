"""The ETH/UCY section of ``docs/results.md``: every fold's bundled model on its held-out scene beside constant
velocity and the paper's figures, and the ablations of ``training/studies/ablations.sh``."""

from __future__ import annotations

import json
from pathlib import Path
from typing import Any

ROOT = Path(__file__).resolve().parents[2]
#: What was tried on the five ETH/UCY folds, in order, with the validation figures each choice was made on and the
#: test figures measured after it; the page prints it under the per-scene table.
ETHUCY_HISTORY = Path(__file__).parent / "templates" / "ethucy_history.md"


SCENES = ("eth", "hotel", "univ", "zara1", "zara2")


#: Table 4 of the paper (ADE/FDE, metres; best-of-20 following Social-GAN's protocol).
PAPER = {"eth": (0.78, 1.50), "hotel": (0.80, 1.71), "univ": (0.59, 1.26), "zara1": (0.31, 0.64), "zara2": (0.39, 0.79)}


PAPER_AVG = (0.57, 1.18)


#: Social-GAN (20VP, best of 20) and linear, as reported in the paper's Table 4.
SGAN = {"eth": (0.81, 1.52), "hotel": (0.72, 1.61), "univ": (0.60, 1.26), "zara1": (0.34, 0.69), "zara2": (0.42, 0.84)}


SGAN_AVG = (0.58, 1.18)


ABLATIONS = {
    "full": "full model",
    "no_map": "without the map branch",
    "no_gat": "without the GAT (map + anchors, close to MultiPath)",
    "no_edge_geometry": "GAT without neighbour geometry on the edges",
    "k5": "K_c = 5 anchors",
    "k10": "K_c = 10 anchors",
    "paper_loss": "the paper's loss alone (β = 0)",
}


def fmt(a: float, b: float, digits: int = 2) -> str:
    return f"{a:.{digits}f}/{b:.{digits}f}"


def main_table(res: dict[str, dict[str, Any]]) -> str:
    keys = [("ade", "fde"), ("min_ade5", "min_fde5"), ("min_ade20", "min_fde20")]
    lines = [
        "| scene | windows | agents | DGAN top-1 | DGAN min5 | DGAN min20 | DGAN Brier-minFDE20 | const. velocity | "
        "paper DGAN | Social-GAN (20) |",
        "|---|---|---|---|---|---|---|---|---|---|",
    ]
    for s in SCENES:
        r = res[s]
        cells = [fmt(r[a], r[b]) for a, b in keys]
        lines.append(
            f"| {s} | {r['windows']} | {r['agents']} | {' | '.join(cells)} | {r['brier_min_fde20']:.2f} | "
            f"{fmt(r['cv_ade'], r['cv_fde'])} | {fmt(*PAPER[s])} | {fmt(*SGAN[s])} |"
        )
    avg = {
        k: sum(res[s][k] for s in SCENES) / len(SCENES) for k in res[SCENES[0]] if isinstance(res[SCENES[0]][k], float)
    }
    cells = [fmt(avg[a], avg[b]) for a, b in keys]
    tot_w = sum(res[s]["windows"] for s in SCENES)
    tot_a = sum(res[s]["agents"] for s in SCENES)
    lines.append(
        f"| **average** | {tot_w} | {tot_a} | {' | '.join(f'**{c}**' for c in cells)} | {avg['brier_min_fde20']:.2f} | "
        f"{fmt(avg['cv_ade'], avg['cv_fde'])} | {fmt(*PAPER_AVG)} | {fmt(*SGAN_AVG)} |"
    )
    worse = [s for s in SCENES if res[s]["ade"] > res[s]["cv_ade"] or res[s]["fde"] > res[s]["cv_fde"]]
    better = [s for s in SCENES if s not in worse]
    lines.append("")
    ahead = avg["ade"] <= avg["cv_ade"] and avg["fde"] <= avg["cv_fde"]
    lines.append(
        f"On the average, DGAN's top-1 is {'ahead of' if ahead else 'not ahead of'} constant velocity "
        f"({fmt(avg['ade'], avg['fde'])} against {fmt(avg['cv_ade'], avg['cv_fde'])}); per scene it is ahead on "
        f"{', '.join(better) or 'none'} and behind on {', '.join(worse) or 'none'} in ADE or FDE. "
        + ETHUCY_HISTORY.read_text().strip()
    )
    return "\n".join(lines)


#: The measured ablations: written by :func:`ablation_runs` whenever ``runs/`` holds them, read when it does not.
ABLATIONS_JSON = ROOT / "docs" / "ablations.json"


ABLATION_KEYS = ("ade", "fde", "min_ade5", "min_fde5", "min_ade20", "min_fde20", "brier_min_fde20", "cv_ade", "cv_fde")


def ablation_runs(
    scene: str, runs_dir: Path = ROOT / "runs", store: Path = ABLATIONS_JSON
) -> dict[str, list[dict[str, float]]]:
    """Each variant's test metrics, one entry per seed run (``<runs_dir>/ablation_<scene>_<variant>[_s<seed>]``,
    written by ``training/studies/ablations.sh``); kept in ``store``, and read from it where no run is found."""
    found: dict[str, list[dict[str, float]]] = {}
    for key in ABLATIONS:
        runs = [runs_dir / f"ablation_{scene}_{key}", *sorted(runs_dir.glob(f"ablation_{scene}_{key}_s*"))]
        for r in runs:
            if (r / "metrics.json").is_file():
                m = json.loads((r / "metrics.json").read_text())
                found.setdefault(key, []).append({k: m[k] for k in ABLATION_KEYS})
    stored: dict[str, dict[str, list[dict[str, float]]]] = json.loads(store.read_text()) if store.is_file() else {}
    if found:
        stored[scene] = found
        store.write_text(json.dumps(stored, indent=2))
    return stored.get(scene, {})


def ablation_table(scene: str, results: dict[str, list[dict[str, float]]]) -> str:
    """Each variant's metrics (:func:`ablation_runs`) averaged over its seeds, and constant velocity on the same
    targets."""
    if not results:
        return f"_No ablation runs for {scene} yet: `python -m training.results --ablations`._"
    rows = []
    for key, label in ABLATIONS.items():
        if key not in results:
            continue
        m = {k: sum(f[k] for f in results[key]) / len(results[key]) for k in ABLATION_KEYS}
        cells = [fmt(m[a], m[b], 3) for a, b in (("ade", "fde"), ("min_ade5", "min_fde5"), ("min_ade20", "min_fde20"))]
        rows.append(f"| {label} | {len(results[key])} | {' | '.join(cells)} | {m['brier_min_fde20']:.3f} |")
    cv = next(iter(results.values()))[0]
    cv_cells = fmt(cv["cv_ade"], cv["cv_fde"], 3)
    rows.append(f"| constant velocity (the better of its two variants), same targets | | {cv_cells} | | | |")
    head = "| variant (10 epochs each) | seeds | top-1 ADE/FDE | minADE5/FDE5 | minADE20/FDE20 | Brier-minFDE20 |\n"
    head += "|---|---|---|---|---|---|"
    return head + "\n" + "\n".join(rows)
