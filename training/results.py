"""Reproduce ``docs/results.md``: evaluate every bundled ETH/UCY model with the engine on its held-out scene, beside
constant velocity on the same windows and the paper's numbers; the multi-class models (Stanford Drone, ApolloScape)
beside their per-class baselines (``training.reports.multiclass``); add the ablations found under ``runs/``.

    python -m training.results                 # evaluate the shipped models (about 10 minutes on 2 cores)
    python -m training.results --train         # first train and bundle the five ETH/UCY folds (about an hour)
    python -m training.results --train-multiclass  # first train the SDD and ApolloScape models (about 80 minutes)
    python -m training.results --train-hdmap   # first train hdmap with and without the map (about 25 minutes)
    python -m training.results --ablations     # first run training/studies/ablations.sh on zara1 (about 40 minutes)
"""

from __future__ import annotations

import argparse
import json
import subprocess
import sys
from pathlib import Path
from typing import Any

import dgan
from training.evaluate import evaluate
from training.reports import hdmap, multiclass, scorecard
from training.reports.ethucy import SCENES, ablation_runs, ablation_table, main_table
from training.reports.held_out import calibrations, noise_table, noisy_results, test_sets
from training.studies import calibration as calibration_study
from training.studies import seed as seed_study
from training.studies import sources as sources_study

ROOT = Path(__file__).resolve().parents[1]
#: The page's Markdown, with a ``{field}`` for each section (``str.format``).
TEMPLATE = Path(__file__).parent / "reports" / "templates" / "results.md"


def parse_args(argv: list[str] | None = None) -> argparse.Namespace:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--data-root", type=Path, default=Path("../shared/data"))
    ap.add_argument("--train", action="store_true", help="train and bundle all five folds first")
    ap.add_argument(
        "--train-multiclass", action="store_true", help="train the SDD and ApolloScape models and baselines first"
    )
    ap.add_argument("--train-hdmap", action="store_true", help="train the HD-map model with and without its map first")
    ap.add_argument("--ablations", action="store_true", help="run training/studies/ablations.sh on zara1 first")
    ap.add_argument("--out", type=Path, default=ROOT / "docs" / "results.md")
    return ap.parse_args(argv)


def retrain_first(a: argparse.Namespace, root: Path) -> None:
    """The training the flags ask for before the evaluation (``training.release.retrain``, the ablation script)."""
    if a.train or a.train_multiclass or a.train_hdmap:
        from training.release import retrain  # torch and the trainer, only when training

        if a.train:
            retrain.train_ethucy(root)
        if a.train_multiclass:
            retrain.train_multiclass(root)
        if a.train_hdmap:
            retrain.train_hdmap(root)
    if a.ablations:
        subprocess.run(
            ["bash", str(ROOT / "training" / "studies" / "ablations.sh"), "zara1", str(root)],
            check=True,
            env={"PYTHON": sys.executable, "PATH": "/usr/bin:/bin"},
        )


def evaluate_all(root: Path) -> dict[str, Any]:
    """Every bundled model on its test data (ETH/UCY with and without the map, the multi-class and HD-map models,
    the noisy tracks), with the figures the page shows drawn into ``docs/images``."""
    from tqdm import tqdm

    res, res_nomap = {}, {}
    for s in tqdm(SCENES, desc="ETH/UCY"):
        predictor = dgan.Predictor(s)
        res[s] = evaluate(predictor, "ethucy", root, s)
        if predictor.spec.map is not None and predictor.spec.map.optional:
            res_nomap[s] = evaluate(predictor, "ethucy", root, s, with_map=False)
    datasets = tqdm(multiclass.MULTICLASS_DATASETS, desc="SDD, Apollo")
    multi = {ds: multiclass.evaluate_dataset(ds, root) for ds in datasets}
    images = ROOT / "docs" / "images"
    multiclass.reliability_plot(multi, images / "reliability.png")
    hd = hdmap.evaluate_hdmap(root)
    hdmap.sources_figure(root, images / "hdmap_sources.png")
    cals = calibrations(res, multi, hd)
    scorecard.reliability_figure(cals, images / "calibration.png")
    tests = test_sets(res, res_nomap, multi, hd)
    return {
        "res": res,
        "res_nomap": res_nomap,
        "multi": multi,
        "hd": hd,
        "cals": cals,
        "tests": tests,
        "noisy": noisy_results(root),
    }


def page(r: dict[str, Any]) -> str:
    """``docs/results.md`` from the evaluations of :func:`evaluate_all`."""
    tests = r["tests"]
    return TEMPLATE.read_text().format(
        scorecard=scorecard.table(tests),
        scorecard_summary=scorecard.summary(tests),
        motion=scorecard.motion_table(tests),
        noise=noise_table(r["noisy"]),
        calibration=scorecard.calibration_table(r["cals"]),
        calibration_study=calibration_study.section(),
        calibration_diagnostics=calibration_study.diagnostics_section(),
        seed_study=seed_study.section(),
        sources_study=sources_study.section(),
        table=main_table(r["res"]),
        ablations=ablation_table("zara1", ablation_runs("zara1")),
        multiclass=multiclass.sections(r["multi"]),
        hdmap=hdmap.section(r["hd"]),
        hdmap_reading=hdmap.reading(r["hd"]),
    )


def main(argv: list[str] | None = None) -> None:
    a = parse_args(argv)
    root = a.data_root.expanduser().resolve()
    retrain_first(a, root)
    r = evaluate_all(root)
    text = page(r)
    a.out.parent.mkdir(parents=True, exist_ok=True)
    a.out.write_text(text)
    (a.out.with_suffix(".json")).write_text(json.dumps({"with_map": r["res"], "without_map": r["res_nomap"]}, indent=2))
    a.out.with_name("results_scorecard.json").write_text(json.dumps(scorecard.findings(r["tests"]), indent=2))
    multiclass.save(r["multi"], a.out.with_name("results_multiclass.json"))
    a.out.with_name("results_hdmap.json").write_text(json.dumps(r["hd"], indent=2))
    a.out.with_name("results_noisy.json").write_text(json.dumps(r["noisy"], indent=2))
    print(text)


if __name__ == "__main__":
    main()
