"""Reproduce ``docs/results.md``: evaluate every bundled ETH/UCY model with the engine on its held-out scene, beside
constant velocity on the same windows and the paper's numbers; the multi-class models (Stanford Drone, ApolloScape)
beside their per-class baselines (``training.multiclass``); add the ablations found under ``runs/``.

    python -m training.results                 # evaluate the shipped models (about 10 minutes on 2 cores)
    python -m training.results --train         # first train and bundle the five ETH/UCY folds (about an hour)
    python -m training.results --train-multiclass  # first train the SDD and ApolloScape models (about 80 minutes)
    python -m training.results --train-hdmap   # first train hdmap with and without the map (about 25 minutes)
    python -m training.results --ablations     # first run training/ablations.sh on zara1 (about 40 minutes)
"""

from __future__ import annotations

import argparse
import json
import subprocess
import sys
from pathlib import Path
from typing import Any

import dgan
from training import calibration_study, hdmap, multiclass, scorecard, seed_study
from training.evaluate import evaluate

ROOT = Path(__file__).resolve().parents[1]
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


#: What was tried on the five ETH/UCY folds, in order, with the validation figures each choice was made on and the
#: test figures measured after it; the page prints it under the per-scene table.
ETHUCY_HISTORY = (
    "Pedestrians mostly "
    "keep their pace and heading for the whole 4.8 s, and constant velocity is hard to beat with a single mode "
    "on a scene the model never saw (Schöller et al. 2020 make the same point); best-of-K is where the "
    "multi-modal anchors pay off. On each fold's validation split (the other four scenes) every model is 7–9% "
    "ahead of constant velocity. Tried on validation and not kept: a prior from the mean velocity over the last "
    "0.8 s instead of the last two steps (hotel fold 0.432/0.939 m against 0.429/0.934, univ fold 0.368/0.791 "
    "against 0.362/0.776), although the mean velocity over the last second is the better constant velocity on "
    "hotel's test scene. Each fold was trained twice (the second run after a change in float order, so the "
    "runs differ as seeds do), the second keeping the epoch of the lowest validation top-1 ADE; it was bundled "
    "where its validation top-1 ADE was more than 1% lower (eth 0.411 → 0.405 m, hotel 0.429 → 0.421, univ "
    "0.362 → 0.347; zara1 and zara2 within 1%, kept). On their test scenes hotel and univ came out worse than "
    "the runs they replaced (hotel 0.33/0.62 → 0.35/0.67 m, univ 0.55/1.21 → 0.58/1.27) and eth better "
    "(0.85/1.87 → 0.84/1.84): the validation split comes from the four training scenes, so an epoch that fits "
    "them better need not transfer to the held-out scene. A validation scene held out of training would measure "
    "that; it is not in this protocol's splits. Then all five folds were trained again with the most probable "
    "mode's error weighing 3 instead of 1 (`train.beta`), which was lower on every validation split (top-1 ADE "
    "eth 0.406 → 0.397 m, hotel 0.421 → 0.407, univ 0.347 → 0.340, zara1 0.421 → 0.409, zara2 0.468 → 0.447; "
    "standing pedestrians now at constant velocity's error there), and those runs are bundled. On the test "
    "scenes hotel and zara1 improved (0.35/0.67 → 0.32/0.62, 0.42/0.92 → 0.40/0.86), eth, univ and zara2 fell "
    "back (0.84/1.84 → 0.86/1.87, 0.58/1.27 → 0.59/1.31, 0.33/0.75 → 0.36/0.82) and the average stayed where it "
    "was: between runs and settings the held-out scenes move by more than validation can rank. Then each fold "
    "became the consensus of three runs (seeds 0–2, `training.ensemble`: its most probable mode is the mean of "
    "the runs' most probable modes), 3.3–4.4% below its runs on every validation split (docs/seed_study.json); on "
    "the test scenes every fold improved on the single run before it (eth 0.86/1.87 → 0.80/1.72 m, hotel "
    "0.32/0.62 → 0.31/0.58, univ 0.59/1.31 → 0.53/1.17, zara1 0.40/0.86 → 0.38/0.81, zara2 0.36/0.82 → "
    "0.31/0.70). Why hotel stays behind: 592 of its 1053 test targets stand (under 0.2 m/s over the last "
    "second), and on them top-1 is 0.160 m against 0.112 for constant velocity from the last second's mean "
    "velocity, more than the whole gap (the moving targets are level with it); the top mode follows the "
    "two-step velocity's jitter (24% of those top modes move more than 0.3 m in 4.8 s, 3% of the targets do). "
    "So windowed priors were tried again, on the validation splits of all five folds with β = 3 (one run each, "
    "seed 0, on a lent 16-core machine; training's own validation pass, where seeds 0–2 of the two-step prior "
    "span 0.001–0.005 m): the mean velocity over the last 0.8, 1.2 and 2.0 s gave top-1 ADE eth "
    "0.399/0.395/0.407 m against 0.394–0.397, hotel 0.409/0.415/0.426 against 0.406–0.407, univ "
    "0.342/0.353/0.353 against 0.340–0.345, zara1 0.411/0.410/0.417 against 0.404, zara2 0.456/0.457/0.459 "
    "against 0.445–0.451; over the five folds +1.0%, +1.7% and +3.3% against the two-step prior's mean. The "
    "two-step prior stays: the standing pedestrians of the training scenes start walking far more often than "
    "hotel's (35% against 3%), which no validation split drawn from them shows. "
    "**More pedestrians.** So the training data were widened instead of the prior: the pedestrians of Stanford "
    "Drone's 30 training videos (none of its test videos) join the training windows (`data.extra_pedestrians`: "
    "resampled from 1/3 s to 0.4 s, in metres, without their maps, windows at every third step; about 43,000 "
    "targets beside the four scenes' 9,000–29,000). Single runs (seed 0, engine, validation top-1 ADE) were "
    "lower than every run without them on the four folds measured: hotel 0.398 m against 0.406–0.407, univ 0.329 "
    "against 0.340–0.345, zara1 0.403 against 0.404–0.409, zara2 0.435 against 0.447–0.452 (eth was not run). As "
    "the consensus of seeds 0–2, hotel's validation top-1 went 0.392/0.854 → 0.388/0.842 m and univ's 0.327/0.702 "
    "→ 0.317/0.679; their best of 20 got worse there (hotel 0.191/0.342 → 0.216/0.412, univ 0.173/0.306 → "
    "0.189/0.356), zara1's 0.392/0.847 → 0.384/0.834 and zara2's 0.432/0.926 → 0.421/0.904 (best of 20 "
    "0.215/0.410 and 0.238/0.454), with must-show 5's bound (0.295/0.514 on the test average) far off, so "
    "`hotel`, `univ`, `zara1` and `zara2` are now these consensus models. On their test scenes top-1 went hotel "
    "0.31/0.58 → 0.27/0.51 m (constant velocity 0.27/0.52), univ 0.53/1.17 → 0.53/1.15 (0.52/1.17), zara1 "
    "0.38/0.81 → 0.38/0.81 (0.43/0.96) and zara2 0.31/0.70 → 0.28/0.63 (0.33/0.73); without the map hotel is "
    "0.25/0.47, ahead of constant velocity. eth followed (three runs on a lent 16-core machine): single runs "
    "0.385–0.389 m against 0.394–0.397 without the extra pedestrians, the consensus 0.383/0.828 → 0.375/0.812 "
    "(best of 20 0.209/0.393), and on its test scene top-1 went 0.79/1.72 → 0.71/1.48 m (constant velocity "
    "0.96/2.18). Without its map eth also improved (0.85/1.86 → 0.78/1.61 m), but less than with it, so it "
    "is now 10.5% above its own top-1 with the map in ADE (9.2% in FDE), over must-show 3's 10%; on the "
    "validation split the gap is 7.4% (0.403 against 0.375 m), so nothing chosen there would have flagged it. "
    "**Anchors from the scenes' own windows.** Best of 20 got worse with the extra pedestrians because "
    "the anchors were fitted on their futures too; `data.extra_in_anchors = false` fits them on the four scenes' "
    "windows alone while the network still trains on all. One run per fold (seed 0, lent machine, stopped "
    "after 13–15 of the 15 epochs by the time it had), against the bundled configuration's seed-0 run at the "
    "same epoch of the same schedule, validation minADE20/FDE20: eth 0.185/0.333 against 0.209/0.396, hotel "
    "0.191/0.343 against 0.216/0.409, univ 0.169/0.301 against 0.189/0.359, zara1 0.189/0.342 against "
    "0.212/0.400, zara2 0.209/0.377 against 0.236/0.447 (10–15% lower everywhere); top-1 ADE is mixed, higher on "
    "three folds by up to 1.2% and lower on two (eth 0.391 against 0.387, hotel 0.403 against 0.398, univ 0.328 "
    "against 0.329, zara1 0.394 against 0.397, zara2 0.440 against 0.436). Not bundled: top-1 is the measure "
    "the models are chosen by, these are single unfinished runs, and the bundled models are consensus models "
    "of three seeds each (fifteen runs did not fit this session). "
    "**Five runs.** Each fold is now the consensus of five runs (seeds 0–4) instead of three. The rule was set "
    "before the two new runs of each fold were evaluated: five replace three if validation top-1 ADE is lower "
    "on average and on at least four folds of five. It was lower on all five (eth 0.3753/0.812 → 0.3732/0.808 m, "
    "hotel 0.3878/0.842 → 0.3840/0.836, univ 0.3166/0.679 → 0.3139/0.673, zara1 0.3844/0.834 → 0.3791/0.820, "
    "zara2 0.4214/0.904 → 0.4184/0.897; best of 20 within 0.001 m), at 5/3 of the cost of a prediction. On "
    "the test scenes top-1 went eth 0.710/1.476 → 0.709/1.486 m, hotel 0.272/0.506 → 0.271/0.501 (constant "
    "velocity 0.271/0.519), univ 0.527/1.149 → 0.522/1.139 (0.524/1.165), zara1 0.376/0.812 → 0.363/0.782 and "
    "zara2 0.283/0.629 → 0.278/0.616. Without the map univ went 0.531 → 0.524 m (level with constant velocity "
    "at 0.5236 against 0.5242) and eth 0.784/1.611 → 0.772/1.594, 8.9% above its top-1 with the map (it was "
    "10.5%). hotel is 0.0002 m behind constant velocity in ADE (0.2713 against 0.2711) and 3.5% ahead in FDE. "
    "zara1 gained more with its map than without (0.812 → 0.782 m FDE against 0.873 → 0.863), so without it "
    "zara1 is now 10.3% above its own FDE with the map (9.7% in ADE), over must-show 3's 10%. On the validation "
    "splits the map is worth 7.9–9.0% in ADE and 8.5–9.7% in FDE to the five-run models (7.4–8.4% and 7.7–8.8% "
    "to the three-run ones): the consensus helps the map path a little more, and map dropout (0.3 of the crops) "
    "sets how far apart the two stay. **Map dropout 0.5, a pilot.** Two runs per fold (seeds 0–1) with half the "
    "crops blanked instead of 0.3, as their consensus, against the consensus of seeds 0–1 of the bundled "
    "configuration, on the validation splits (top-1 ADE with the map; without it; the gap in ADE/FDE): eth "
    "0.3776 → 0.3807 m, 0.4038 → 0.4018, 6.9/7.6% → 5.5/6.3%; hotel 0.3911 → 0.3930, 0.4187 → 0.4144, 7.1/8.0% → "
    "5.5/5.8%; univ 0.3179 → 0.3191, 0.3421 → 0.3377, 7.6/7.7% → 5.8/5.8%; zara1 0.3896 → 0.3854, 0.4206 → "
    "0.4049, 8.0/8.1% → 5.1/5.4%; zara2 0.4219 → 0.4277, 0.4575 → 0.4501, 8.4/9.3% → 5.2/5.7%. Without the map "
    "every fold is better (1.6% on average), with it four folds of five are worse (0.4% on average, within "
    "what two seeds can rank), and the gap narrows to 5–6% everywhere. Not bundled: top-1 with the map is the "
    "figure the models are chosen by, and adopting it means retraining all 25 runs (five folds, five seeds). "
    "**zara1 with map dropout 0.5.** A rule written down before any further run: a fold goes on if the pilot's 0.5 "
    "consensus is at or below the 0.3 one on validation both with the map and without it (zara1 alone), and the "
    "five-run consensus of 0.5 (seeds 0–4) replaces the bundled zara1 if its validation top-1 ADE is at or below "
    "the bundled model's with the map and lower without it. Seeds 2–4 ran on a lent 16-core machine. On "
    "validation: with the map 0.3784/0.820 m against 0.3791/0.820, without it 0.4021/0.876 against 0.4133/0.900 "
    "(the gap 6.3/6.9% instead of 9.0/9.7%), best of 20 0.213/0.406 against 0.215/0.408; so `zara1` is now that "
    "model. On its test scene, measured after the decision: top-1 0.363/0.782 → 0.365/0.787 m with the map "
    "(constant velocity 0.431/0.960), 0.399/0.863 → 0.397/0.859 without it, 8.5/9.1% above with-map instead of "
    "9.7/10.3%."
)


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
        f"{', '.join(better) or 'none'} and behind on {', '.join(worse) or 'none'} in ADE or FDE. " + ETHUCY_HISTORY
    )
    return "\n".join(lines)


#: The measured ablations: written by :func:`ablation_runs` whenever ``runs/`` holds them, read when it does not.
ABLATIONS_JSON = ROOT / "docs" / "ablations.json"
ABLATION_KEYS = ("ade", "fde", "min_ade5", "min_fde5", "min_ade20", "min_fde20", "brier_min_fde20", "cv_ade", "cv_fde")


def ablation_runs(
    scene: str, runs_dir: Path = ROOT / "runs", store: Path = ABLATIONS_JSON
) -> dict[str, list[dict[str, float]]]:
    """Each variant's test metrics, one entry per seed run (``<runs_dir>/ablation_<scene>_<variant>[_s<seed>]``,
    written by ``training/ablations.sh``); kept in ``store``, and read from it where no run is found."""
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


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--data-root", type=Path, default=Path("../shared/data"))
    ap.add_argument("--train", action="store_true", help="train and bundle all five folds first")
    ap.add_argument(
        "--train-multiclass", action="store_true", help="train the SDD and ApolloScape models and baselines first"
    )
    ap.add_argument("--train-hdmap", action="store_true", help="train the HD-map model with and without its map first")
    ap.add_argument("--ablations", action="store_true", help="run training/ablations.sh on zara1 first")
    ap.add_argument("--out", type=Path, default=ROOT / "docs" / "results.md")
    a = ap.parse_args()
    root = a.data_root.expanduser().resolve()
    if a.train:
        from training.bundle import bundle

        for s in SCENES:
            toml = ROOT / "training" / "configs" / f"ethucy_{s}.toml"
            bundle(_seed_runs(toml, root, ENSEMBLE_SEEDS["ethucy"], f"ethucy_{s}"), s, root)
    if a.train_multiclass:
        train_multiclass(root)
    if a.train_hdmap:
        train_hdmap(root)
    if a.ablations:
        subprocess.run(
            ["bash", str(ROOT / "training" / "ablations.sh"), "zara1", str(root)],
            check=True,
            env={"PYTHON": sys.executable, "PATH": "/usr/bin:/bin"},
        )
    from tqdm import tqdm

    res, res_nomap = {}, {}
    for s in tqdm(SCENES, desc="ETH/UCY"):
        predictor = dgan.Predictor(s)
        res[s] = evaluate(predictor, "ethucy", root, s)
        if predictor.spec.map is not None and predictor.spec.map.optional:
            res_nomap[s] = evaluate(predictor, "ethucy", root, s, with_map=False)
    multi = {
        ds: multiclass.evaluate_dataset(ds, root) for ds in tqdm(multiclass.MULTICLASS_DATASETS, desc="SDD, Apollo")
    }
    (ROOT / "docs").mkdir(exist_ok=True)
    multiclass.reliability_plot(multi, ROOT / "docs" / "images" / "reliability.png")
    hd = hdmap.evaluate_hdmap(root)
    hdmap.sources_figure(root, ROOT / "docs" / "images" / "hdmap_sources.png")
    tests = test_sets(res, res_nomap, multi, hd)
    noisy = noisy_results(root)
    cals = calibrations(res, multi, hd)
    scorecard.reliability_figure(cals, ROOT / "docs" / "images" / "calibration.png")
    text = RESULTS_TEMPLATE.format(
        scorecard=scorecard.table(tests),
        scorecard_summary=scorecard.summary(tests),
        motion=scorecard.motion_table(tests),
        noise=noise_table(noisy),
        calibration=scorecard.calibration_table(cals),
        calibration_study=calibration_study.section(),
        calibration_diagnostics=calibration_study.diagnostics_section(),
        seed_study=seed_study.section(),
        table=main_table(res),
        ablations=ablation_table("zara1", ablation_runs("zara1")),
        multiclass=multiclass.sections(multi),
        hdmap=hdmap.section(hd),
        hdmap_reading=hdmap.reading(hd),
    )
    a.out.write_text(text)
    (a.out.with_suffix(".json")).write_text(json.dumps({"with_map": res, "without_map": res_nomap}, indent=2))
    a.out.with_name("results_scorecard.json").write_text(json.dumps(scorecard.findings(tests), indent=2))
    multiclass.save(multi, a.out.with_name("results_multiclass.json"))
    a.out.with_name("results_hdmap.json").write_text(json.dumps(hd, indent=2))
    a.out.with_name("results_noisy.json").write_text(json.dumps(noisy, indent=2))
    print(text)


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


def train_multiclass(root: Path) -> None:
    """Trains each multi-class model and its per-class baselines, bundles the multi-class models and keeps the
    baselines' checkpoints (``training/checkpoints/baselines``). A baseline has as many runs as its multi-class
    model (:data:`ENSEMBLE_SEEDS`), kept as their consensus when there are several, so the two are compared alike."""
    from training.bundle import bundle, calibration_folds, model_checkpoint
    from training.calibrate import calibrate_checkpoint
    from training.config import Config
    from training.ensemble import fit_top_scale

    for ds in multiclass.MULTICLASS_DATASETS:
        toml = ROOT / "training" / "configs" / f"{ds}.toml"
        seeds = ENSEMBLE_SEEDS.get(ds, (0,))
        members = _seed_runs(toml, root, seeds, ds)
        folds = [
            _seed_runs(toml, root, seeds, f"{ds}_val{fold.replace(',', '_')}", "--set", f"data.val_recordings={fold}")
            for fold in calibration_folds(Config.load(toml).train.calibration_folds)
        ]
        bundle(members, ds, root, folds)
        for cls in multiclass.DATASETS[ds].classes:  # the per-class baselines
            runs = _seed_runs(toml, root, seeds, f"{ds}-{cls}", "--set", f"data.target_class={cls}")
            path = model_checkpoint(runs, multiclass.BASELINES / f"{ds}-{cls}.pt")
            if len(seeds) > 1:
                fit_top_scale(path, root)
                calibrate_checkpoint(path, root)


def _seed_runs(toml: Path, root: Path, seeds: tuple[int, ...], tag: str, *args: str) -> list[Path]:
    """One training run of the configuration ``toml`` (with ``args``) per seed, under ``runs/<tag>_s<seed>``."""
    from training.train import main as train

    out = []
    for seed in seeds:
        run = ROOT / "runs" / f"{tag}_s{seed}"
        config = ["--config", str(toml), "--set", f"data.root={root}", "--set", f"train.seed={seed}"]
        train([*config, "--out", str(run), *args, "--no-export"])
        out.append(run)
    return out


#: The seeds of each bundled ensemble's members (``training.ensemble``), chosen on validation (`docs/seed_study.json`).
#: HD map: one network since the standing agents, the robust prior and the noisy copies (issue 26: one network per
#: model); its single run was below the earlier five-run consensus on validation, all targets (0.476 against 0.576 m).
#: ETH/UCY: three runs were 3.3–4.4% below their
#: members on every fold's validation split, five runs 0.6–1.4% below three on every fold's (rule set before the
#: runs: lower on average and on four folds of five). ApolloScape: three runs, 2.8% below its members on validation.
ENSEMBLE_SEEDS = {"hdmap": (0,), "ethucy": (0, 1, 2, 3, 4), "apolloscape": (0, 1, 2)}


def train_hdmap(root: Path) -> None:
    """Trains the HD-map model with and without its map, one run per seed of :data:`ENSEMBLE_SEEDS`; bundles the first
    configuration's consensus as ``hdmap`` and keeps the second's as ``training/checkpoints/baselines/hdmap-nomap.pt``.
    """
    from training.bundle import bundle, slim_checkpoint
    from training.calibrate import calibrate_checkpoint
    from training.ensemble import ensemble_checkpoint, fit_top_scale

    runs = {
        config: _seed_runs(ROOT / "training" / "configs" / f"{config}.toml", root, ENSEMBLE_SEEDS["hdmap"], config)
        for config in ("hdmap", "hdmap_nomap")
    }
    bundle(runs["hdmap"], "hdmap", root)
    if len(runs["hdmap_nomap"]) > 1:
        ensemble_checkpoint(runs["hdmap_nomap"], hdmap.NOMAP, half=True)
        fit_top_scale(hdmap.NOMAP, root)
    else:
        slim_checkpoint(runs["hdmap_nomap"][0], hdmap.NOMAP)
    calibrate_checkpoint(hdmap.NOMAP, root)


RESULTS_TEMPLATE = """# Results

Produced by `python -m training.results` (add `--train` to retrain the five ETH/UCY models first,
`--train-multiclass` for the Stanford Drone and ApolloScape models, `--train-hdmap` for the HD-map models,
`--ablations` for the ablation table). Every
number is measured by the Rust engine on exported ONNX models (`dgan.Predictor`) on held-out data: the held-out scene
of each ETH/UCY fold, the test videos of Stanford Drone, the test recordings of ApolloScape, the held-out driving
scenes of nuScenes mini and Waymo and the Argoverse 2 scenes.

## Against physics, on every test set

Every bundled model on its held-out data, beside constant velocity on the same targets, class by class. The
network predicts relative to a kinematic prior (constant velocity along the direction of motion, computed by the
engine; `docs/model-contract.md`), its mode probabilities carry a temperature fitted on the validation split, and
every map model was trained with map dropout, so the same model also runs without a map (*without the map*: the same
model on the same frames, given none). *Constant velocity* is the better of two variants on these targets, for each
error separately (*last2*: the last two observed steps; *mean1s*: the mean velocity over the last second; the name
is the one with the lower ADE). *top-1 below CV*: how much lower top-1's ADE and FDE are, in percent (negative:
above constant velocity). *no map vs map*: how much higher the error is without the map (negative: lower). Units:
metres, pixels for Stanford Drone. *Brier-minFDE*: minFDE over K modes plus (1 − p)² of that mode. Each model was
chosen (configuration, epoch, temperature) on validation splits only; the test sets below were not used for tuning.

{scorecard}

{scorecard_summary}

### Moving and standing targets

Every fully observed agent is a target, standing ones too. Here the same targets are split by how far they move
from their first observed to their last true position (*moving*: at least 1 m; *standing*: less), with top-1 ADE/FDE
against constant velocity (the same variant as above, chosen on each group) on each group. A parked car or a waiting
pedestrian is most of many scenes; a model that sets them moving is worse than physics there, whatever it does for the
moving agents. `docs/prior_study.json` (`python -m training.prior_study --velocity`) measures the velocity estimates
the prior can take on the validation splits, clean and with tracker-like noise.

{motion}

### Noisy tracks

A user's tracker is not a dataset's smoothed tracks. The same test sets with Gaussian noise (0.1 m, 0.3 m) added to
every observed position and 10% of the observed steps before the current one dropped
(`training.augment.tracker_noise`, seeded), the truth as recorded; constant velocity is computed from the same noisy
history (the better of its two variants, as above).

{noise}

### What was tried for standing agents and real trackers (validation splits)

Before this, `hdmap` scored and trained only agents that move more than 1 m, and on its validation scenes (6,310
fully observed agents, 3,246 of them standing) the bundled five-run consensus moved standing agents by 0.92 m at 3 s
(top-1 FDE; constant velocity 0.02 m), so over every agent it was behind constant velocity (top-1 ADE 0.576 against
0.509 m), and with tracker-like histories far behind it (noise 0.1 m: 1.710 against 0.887; 0.3 m: 4.417 against
1.550), its two-step prior taking the noise in full. The velocity study (`python -m training.prior_study --velocity`,
the prior alone on validation, `docs/prior_study.json`) ranks the estimates; its rule, written before it ran (the
lowest validation ADE over all targets, averaged over clean, 0.1 m and 0.3 m histories), chose a least-squares line
over 1.2 s with a 0.3 m/s standing threshold for `hdmap` and over 2 s for `apolloscape` and `sdd`. One network
trained on every target with that prior and two noisy training copies (0.1 m, 0.3 m, 10% of steps dropped) was, over
all validation targets, 0.603 m clean (moving 1.194, behind constant velocity's 1.040: the line lags behind
accelerating vehicles), 0.672 with 0.1 m noise and 1.064 with 0.3 m. A least-squares parabola over 2 s (its slope at
t_obs; standing still judged on the line, which the engine now does for every fit: rerun that way, the study's
rule ranks this parabola first for `hdmap`, 0.867 against 0.899 m for the line) lags less, and the same training
with it gave 0.476 m clean (moving 0.963,
standing FDE 0.027 m), 0.555 and 0.821 m with noise: below constant velocity in all three and below the consensus it
replaces (the rule, set before these runs: lower validation top-1 ADE over all targets than the bundled model, clean
and with 0.3 m noise), so `hdmap` is now that single network. On the moving validation agents alone it is 11% behind
the five-run consensus (0.963 against 0.868 m). ApolloScape, the same way (least-squares line over 2 s, its validation
recordings' own temperature, one run): 2.164 m clean against 1.998 for the bundled three-run consensus and 2.503
against 2.498 with 0.3 m noise; not bundled.

On the test sets, measured after that decision, against the consensus it replaced (the same targets, every agent):
the held-out nuScenes + Waymo scenes 0.505/1.314 → 0.403/0.956 m top-1 (constant velocity 0.414/1.004), standing
agents' FDE 0.961 → 0.038 m, moving agents 0.704/1.701 → 0.822/1.964 (constant velocity 0.843/2.059); Argoverse 2
(never trained on) 0.486/1.251 → 0.56/1.23 (constant velocity 0.448/1.082), standing FDE 0.809 → 0.25, but moving
agents 0.744/1.872 → 1.14/2.61 (constant velocity 0.88/2.19): on that unseen source the single network is 30% behind
constant velocity on the moving agents, where the consensus was 16% ahead. With 0.3 m noise the held-out scenes went
4.34 → 0.83 m (constant velocity 1.43) and Argoverse 2 4.39 → 0.92 (1.46). Its probabilities are less well
calibrated than the consensus's (worst checked bin 0.11 and 0.15 off on the two driving test sets, table below).
Left for the distilled single network of issue 26: the moving agents and the calibration, without losing the
standing agents or the noise.
One more run on validation, after that decision, tested whether the noisy copies cost the moving agents: with one
copy (0.1 m) instead of two, 0.486 m clean (moving 0.985), 0.597 and 1.241 with noise; worse everywhere, so the two
copies stay (rule: replace the bundled network only if lower clean and not higher with 0.3 m noise).

## Calibration of the mode probabilities

The temperature T of the anchor logits, p(k | c) = softmax(logits / T), is fitted on each model's validation split
(`apolloscape`'s cross-fitted over five validation folds, below) and written into the model; the engine applies it
(`training.calibrate`). Two proper scores of the best mode are minimised over T there: its negative log-likelihood,
and the Brier score of the best-mode indicator, which weighs the probable modes more. Each model keeps the temperature
whose reliability on validation is closer in the bins that must-show 6 checks (p ≥ 0.3, at least 30 modes). That is
the Brier score's temperature for hotel, `sdd`, `apolloscape` and `hdmap`, and the likelihood's for eth, univ, zara1
and zara2. Before: the same predictions at T = 1. The reliability of a bin is how often a mode of that probability
was the best of all K modes (smallest ADE).

{calibration}

![Reliability before and after the temperature](images/calibration.png)

**Calibration maps compared.** A temperature fitted by the likelihood leaves bins with p ≥ 0.3 more than 0.1 off
even on the validation split it was fitted on. So other maps were fitted there and measured on the test sets
(`python -m training.calibration_study`):
- *temperature*: fitted by the best mode's likelihood, what the models carried before;
- *temperature_brier*: the same map fitted by the Brier score;
- *platt*: Platt scaling of each mode's p(k | c);
- *isotonic*: isotonic regression of the tempered probabilities, renormalised per class, three rounds;
- *class_temperature*: a second temperature on the class probabilities p(c) beside p(k | c)'s;
- *temperature_by_speed*: T = exp(a + b · log(1 + v)) for an agent of speed v at the last observed step.

Platt scaling and isotonic regression are fitted by the likelihood, the last two by the Brier score. The worst gap
in a bin with p ≥ 0.3 and at least 30 modes:

{calibration_study}

The Brier-fitted temperature is closer than the likelihood's on validation for `sdd` and `hdmap`, and for hotel in
the bundle's own fit (this table's refit puts the Brier score's at 0.14, the likelihood's at 0.13), so those models
carry it; eth, univ, zara1 and zara2 keep the likelihood's (validation 0.11 against 0.12, 0.17 against 0.19, 0.05
level and 0.12 against 0.15). On
the test sets the Brier temperature closes Stanford Drone's gap (0.14 → 0.08) and narrows both driving sets'. Where
the likelihood's was kept, the Brier score's would have given univ 0.16 against 0.18 on the test scenes, zara1 0.11
against 0.09 and zara2 0.31 against 0.30; the rule was fixed on validation. (The rows above are each model's single
validation split, `apolloscape`'s included; the ETH/UCY rows are the five-run models'.)
Isotonic regression closes the gaps on the ETH/UCY validation splits (0.08 or less), but on the test sets it beats the
temperature only for hotel and univ (0.30 and 0.11 against 0.33 and 0.18), is level for zara1 and zara2 and worse
for Stanford Drone, ApolloScape and both driving sets; Platt scaling beats the temperature for univ and zara1 (0.14
and 0.06 against 0.18 and 0.09) and is level or worse elsewhere.
**ApolloScape: a cross-fitted temperature.** Its validation split is two recordings (1,305 targets), no map above
gets it within 0.1 (0.18 at best), and on it the rule chose the likelihood's temperature (1.57), which left the test
recordings 0.15 off. So the temperature is now cross-fitted (`train.calibration_folds`, `training.bundle
--calibration-fold`): the eight training recordings were held out two at a time by four more folds, each the
consensus of three runs (seeds 0–2) of the bundled configuration trained on the other recordings
(`data.val_recordings`; the test recordings never enter). Their predictions on the recordings they held out join the
bundled model's on its validation split: 15,512 targets instead of 1,305. On them the rule chooses the Brier score's
temperature, 1.82 (worst checked bin 0.13 on the pooled folds), over the likelihood's, 1.42 (0.15); on the test
recordings the worst bin is then 0.08 (table above). Top-1 does not move (a temperature within a class keeps its
order); Brier-minFDE20 went 1.76 → 1.78. Even pooled, no single temperature brings the validation folds within 0.1.
Two causes were measured on its validation recordings. First, 43% of the vehicles' and 42% of the cyclists' best
modes (of all 60) are another class's anchors, 0.16 m and 0.12 m closer (median) than their own class's best, while
the class probability, the class being an input, gives those modes almost nothing: a second temperature on p(c)
(*class_temperature*) moves probability onto them and gives 0.09 on the test recordings, but 0.20 on validation, so
the rule does not pick it. Second, how often the top mode wins depends on speed: on validation it is the best of the
60 for 71% of the agents standing at the last observed step and for 9% of those faster than 3 m/s, while it is given
0.47 and 0.20 on average (at the model's temperature); a temperature that grows with speed (*temperature_by_speed*)
still leaves 0.23 there. Neither is carried by the models. Tried on the model side too (validation recordings): 40
anchors per class instead of 20 (three seeds, as a consensus: top-1 2.026/3.706 m against the bundled model's
2.015/3.670, worst gap 0.12 against 0.19, best of 20 0.81 against 0.86 m but best of 5 1.34 against 1.21 m), and
teaching the classifier the best decoded mode instead of the closest anchor (`train.cls_target = "best_mode"`, one
run each with 20 and 40 anchors: top-1 2.137 and 2.188 m against 2.067–2.084 for single runs of the bundled
configuration, gaps 0.14 and 0.16). Single runs of one configuration leave gaps from 0.10 to 0.21 on this split
(seeds 0–2 of 40 anchors 0.10, 0.12, 0.16; seeds 0–1 of 20 anchors 0.21, 0.12), so it cannot rank such changes; none
was kept. Then the first cause was taken at its word: `train.anchor_pool = "all_classes"` seeks the closest anchor
among every class's anchors, so that p(c) learns which class's anchors hold the future instead of the input class.
Three runs (seeds 0–2) had validation top-1 2.144, 2.201 and 2.098 m against 2.067–2.084, worst gaps 0.12, 0.18 and
0.36; seed 0 was behind for every class (vehicles 2.53 against 2.48 m, cyclists 1.80 against 1.65, pedestrians 0.61
against 0.57) and in best of 5 (1.39 against 1.20 m). Not kept. Both causes, per model, on the validation splits:

{calibration_diagnostics}

How often the most probable mode wins depends on the
scene: of the pedestrians standing (under 0.2 m/s) at the last observed step, 3% (hotel) and 12% (zara2) move more
than 0.3 m in the next 4.8 s in those test scenes, against 35% and 44% in the validation splits of the same folds.
The bundled models keep one temperature.

## ETH/UCY, leave one scene out (8 observed, 12 predicted)

ADE/FDE in metres. *top-1*: the most probable mode; *min5*, *min20*: the best of the 5 or 20 most probable modes,
minimum taken per agent (ADE and FDE minimised separately); *Brier-minFDE20*: minFDE20 plus (1 − p)² of that mode.
Constant velocity is the better of its two variants (the last two steps; the mean velocity over the last second)
on the very same windows and agents. Windows: every start
frame with at least two agents present at all 20 steps (Social-GAN's rule); agents: those targets.

{table}

The paper's and Social-GAN's figures are copied from the paper's Table 4; both follow Social-GAN's best-of-20
protocol, so they compare with **min20**. Social-GAN's own paper reports 0.61/1.21 (S-GAN-P) on average.

## Ablations (zara1 fold)

{ablations}

The table is the bundled zara1 configuration (kinematic prior, map dropout 0.3, β = 3, Stanford Drone's training
pedestrians), each variant trained for 10 epochs instead of 15 and measured by the engine on the zara1 test scene at
its temperature fitted on validation: single runs, not the bundled three-run consensus (0.38/0.81). Where a row has
two seeds (0 and 1) it is their mean. `python -m training.results --ablations` retrains them; the figures are kept
in `docs/ablations.json`.

**One departure from the paper's loss.** The paper regresses only the offset of the anchor closest to the ground
truth. Its most probable mode then keeps the raw anchor whenever the classifier picks another anchor (about half the
time here: 51.5% top-1 anchor accuracy on the zara1 fold's validation set, in an earlier model), and in our first
zara1 model (the paper's loss alone, 20 epochs) top-1 stayed above constant velocity on the test scene (0.51/1.07
against 0.43/0.96). The trainer therefore adds β times the error of the most probable mode, whose selection carries
no gradient (β = 1 by default, 3 in the ETH/UCY configurations, chosen on validation). The ablation above measures
the trade at equal budget: the paper's loss alone (β = 0) has top-1 0.412/0.882 against 0.376/0.808 with β = 3 (both
seeds of each), and better best of 20 (0.213/0.398 against 0.225/0.432). `train.beta = 0` restores the paper's loss.

**Reading the ablations.** The two seeds of the full model are 0.015 m apart in top-1 ADE (0.369 and 0.384), so a
difference smaller than that is within noise. Every variant is ahead of constant velocity (0.431/0.960).
- *The map branch* helps here: without it top-1 is 0.407 and 0.402 against 0.369 and 0.384, and best of 20 is worse
  too. In the previous release's ablation (no kinematic prior, no map dropout, no extra pedestrians) it did not help
  on zara1 (0.434/0.937 without against 0.443/0.944 with).
- *The GAT*: without it (map, state and anchors alone, close to MultiPath) top-1 is 0.397 and 0.399 against 0.369 and
  0.384.
- *Fewer anchors* (one seed each, against seed 0's 0.369/0.792): K_c = 5 and 10 leave top-1 level (0.369/0.792,
  0.368/0.794) and cost best of K (min20 0.306/0.645 and 0.261/0.529 against 0.224/0.431). Their Brier-minFDE20 is
  lower (0.861 and 0.929 against 1.007) because fewer modes share the probability. K_c = 20 keeps the best min20.

Neighbour geometry reaches the attention on the edges: node features are agent-centric, so each directed edge carries
the sender's position, relative velocity and heading in the receiver's frame, which enter both the attention score and
the message (`training/model.py`, `docs/model-contract.md`). The *without neighbour geometry* row zeroes them. Seed by
seed it raised the top-1 error (0.369/0.792 and 0.384/0.824 with geometry against 0.384/0.839 and 0.393/0.856
without) and best of 20 a little (0.431 and 0.433 m minFDE20 against 0.440 and 0.461), as in the previous release's
two seeds.

# Several classes, one model

The paper's central claim: one model for vehicles, cyclists and pedestrians, each class with its own K_c = 20
anchors and the hierarchical probability p(c) · p(k | c), is at least as good as a model per class. Each table
compares the single model with the same code trained on one class at a time (its loss sees only that class's targets;
the other agents stay in the graph as neighbours), and with constant velocity, on the same windows and agents.
Metrics as above; *min5* and *min20* are the best of the 5 or 20 most probable modes over all classes' anchors.

{multiclass}
![Reliability of the mode probabilities](images/reliability.png)

Each point is a bin of mode probabilities (all K = 60 modes of every test agent); its height is how often a mode of
that probability was the best of the K modes (smallest ADE), and the small number is how many modes fell in the bin.

**Reading these tables (where the claim holds and where it does not).**

- *Stanford Drone.* The single model is ahead of constant velocity for every class on top-1 (the scorecard above)
  and far ahead on best-of-K; against Multiclass-SGCN's published best-of-20, on the very same windows (our constant
  velocity from the last two steps reproduces their published figure), see the table above. The per-class
  baselines are the same code and settings (prior, map dropout) trained on one class at a time, with the 15-epoch
  schedule the single model had before it was retrained with 22 epochs (chosen on the validation videos); the
  comparison with them is therefore a little in the single model's favour.
- *ApolloScape.* Single and per-class models (all retrained with the prior and headings from the motion) are
  compared on the same targets. ApolloScape's heading column follows the direction of motion in some recordings and
  is reversed, mirrored or turned by 90° in others (median disagreement 81–100° for moving agents in the training
  split, 153–166° in the validation split), so an agent-centric frame built on it is turned around arbitrarily.
  Since contract 5 the model takes headings from the motion (`heading = "motion"`); on the validation recordings
  (three seeds each) top-1 stayed level (2.06/3.73 m against 2.05/3.70 m with the measured headings) and best-of-5
  improved from 1.30 to 1.18 m. On the test recordings the single model went from 23% behind constant velocity on
  top-1 ADE to 2% ahead (vehicles and pedestrians ahead, cyclists still 5% behind). As the consensus of three runs
  (seeds 0–2, 2.8% below its runs on the validation recordings) it is 7% ahead and ahead for every class (cyclists
  4%). The per-class baselines are now the consensus of the same three seeds too, so the two are compared alike.
  Compared so, the per-class models were ahead on top-1 for every class (vehicles 1.78 against 1.82 m, cyclists
  1.34 against 1.44, pedestrians 0.83 against 0.85; as single runs they had been behind on vehicles, 1.94 m). With
  the top-mode scale fitted on validation for both (below: the single model's cyclists 0.5; the vehicle model's
  vehicles 0.75, the cyclist model's cyclists 0.5), **the per-class models are ahead on top-1 for vehicles (1.76
  against 1.82 m) and pedestrians (0.83 against 0.85), and level on cyclists (1.36 against 1.36)**. The single model
  is level or ahead on best of 5 and 20 for vehicles. So on ApolloScape the paper's claim holds for best of K but not
  for top-1; the bundled model stays the single one, which serves every class in one call.
  Tried on the validation recordings and not kept: β = 3 and 10 anchors per class (before), and a class-balanced loss
  (`train.class_balance` 0.5 and 1: top-1 2.12 and 2.17 m against 2.05–2.07 m, its cyclists within seed noise); with
  the current headings, three seeds each, against 2.08/3.78 m: β = 3 again (2.06/3.75, within 1%, its cyclists 1.73
  against 1.68 m), a network of 172k parameters (2.12/3.86) and one of 1.5M (2.12/3.85) instead of 481k.
- *Class probability* is trivially right because the class is an input, as in the paper; the interesting
  probability is the mode's, calibrated by the temperature (section *Calibration* above).

# The paper's driving setting: a vector HD map

{hdmap}
![Each source's map beside the engine's raster of it](images/hdmap_sources.png)

Left: each source's map as its file has it, coloured by the source's own element types (read straight from the file,
not through `dgan.datasets.hdmaps`). Right: the same square of the world rasterised by the engine, exactly as the
network's crops are drawn (a virtual agent at the centre heading north): green lane centre lines, white dashed and
solid lane lines, yellow road edges, grey crosswalks, white bike-lane regions, pink medians and static obstacles,
the agents as blue boxes. `python -m training.results` redraws it.

**Reading the HD-map tables: the map against no map (the paper's '20' against '20S').**

{hdmap_reading}

- *Seeds, and what averaging them gives* (`python -m training.seed_study`). The HD-map configuration and the same
  network without the map branch were each trained with 14 seeds (0–13, one CPU thread each, everything else as
  bundled) and measured on the validation scenes and both test sets, every run on the same windows and targets.
  *Chosen on val*: the run of the lowest validation top-1 ADE; *averaged (n members)*: the mean of the top-1
  trajectories of the first n runs by seed.

{seed_study}

  - *Runs differ by more than anything tried.* One run's top-1 ADE on the held-out nuScenes + Waymo scenes has a
    standard deviation of 0.085 m over seeds (0.117 m for vehicles), 10% of its mean. Three validation scenes cannot
    rank such runs: the run lowest on validation (seed 12, 0.871 m against a mean of 0.938) is 0.971 m on that test
    set, against a mean of 0.855 m. The single run bundled before this release (0.79 m there, chosen on validation
    among three) was one of the luckier draws.
  - *The map, over 14 seeds (must-show 4).* For vehicles the map model is no better with its map than without it:
    1.022 ± 0.117 m with the map and 0.984 ± 0.107 m without it on nuScenes + Waymo, 1.259 ± 0.145 and
    1.208 ± 0.134 m on Argoverse 2; the network trained without the branch gives 0.965 ± 0.113 and 1.185 ± 0.092 m.
    On validation the three are level as well (1.679, 1.666 and 1.636 m). The bullets above compare one pair of
    runs; over seeds, with this data, the map branch adds variance and no accuracy. The training set is 34 scenes
    (7 of nuScenes mini, 27 of the Waymo samples): 13k vehicle target windows, but from a few hundred distinct tracks
    on 34 road layouts, where the paper trained on a large driving dataset. Until contract 5 a third of the Waymo
    training scenes had their headings read in the wrong unit (their GPUDrive JSON holds degrees), which turned those
    agents' frames and crops arbitrarily; the runs here are all on the fixed data.
  - *Averaging the runs' most probable futures* is ahead of every single run on validation (14 runs: 0.842 m against
    0.871–0.971 m), and on the test sets: 0.695/1.682 m on nuScenes + Waymo, 17.6% below constant velocity's
    0.843/2.059, and 0.692/1.739 m on Argoverse 2, 21.5% below 0.882/2.187 (5 runs: 0.704 and 0.745 m); vehicles
    0.812 and 0.916 m against 1.010 and 1.208 m. Pedestrians gain about 1%; the 56 held-out cyclists stay behind
    constant velocity. So the bundled `hdmap` and its no-map baseline are now each the consensus of the first five
    runs by seed (`training.ensemble`: one ONNX graph under the same contract whose most probable mode, in the
    agent's most probable class, is the mean of the runs' most probable modes; weights stored as float16, 9 MB),
    which the scorecard above measures; a prediction runs five networks. Measured the same way with three runs, the
    consensus is 2–4% below its runs on every ETH/UCY validation split and on ApolloScape's, so those six models are
    now three-run consensus models too (the seed study's tables above). The consensus takes the place of the first
    run's most probable mode, so best of K loses that mode. Tried on validation and not kept: moving it into the
    class's least probable slot (logits unchanged). ApolloScape's minADE20/FDE20 went 0.863/1.084 → 0.857/1.060 m,
    but the temperature refitted for it went 1.57 → 3.31, because that near-twin of the top mode is often the best
    mode at a low probability. Brier-minFDE20 went 1.74 → 1.90 m and the ECE 0.013 → 0.016. Stanford Drone showed
    the same: minADE20 4.37 against 4.50 px, temperature 5.19, ECE 0.004 → 0.017.
- *Tried*: the kinematic prior (top-1 errors fell by a fifth and best-of-5 errors by more than a third against the
  first release's 1.14/2.60 and 0.67/1.42 m), map dropout (the map model runs without its map and stays close to
  itself), a 6-epoch schedule chosen on validation (the epoch of the lowest validation loss kept), 10 anchors per
  class instead of 20 (validation top-1 ADE 0.968 against 1.032 m; β = 3, alone or with it, was not better), joint
  training across nuScenes and Waymo, the heading fix above, and three runs compared on validation (seed 0 kept by
  validation loss 0.940 m, bundled; seed 0 again by validation top-1 ADE 0.955 m; seed 1 by validation top-1 ADE
  0.905 m, best-of-5 0.468 against 0.426 m). The seed-1 run, lowest on validation, was not bundled: on the bundled
  held-out Waymo excerpt its top mode erred 0.57 times as much as standing still, failing the project's check (at
  most 0.5, `tests/python/test_models.py`); since that excerpt is a held-out scene, this choice is disclosed here.
  Tried on validation and not kept: a class-balanced
  loss (`train.class_balance = 0.5`: top-1 0.967 m against 0.940, its cyclists 0.483 against 0.469). For the
  cyclists behind constant velocity, β = 3 (the most probable mode's error weighing 3, as for the ETH/UCY models),
  as the consensus of seeds 0–4 against the bundled one: validation top-1 0.864/2.018 m against 0.870/2.038, cyclists
  0.419 against 0.445 (constant velocity 0.430), pedestrians 0.263 against 0.269 (0.265), vehicles 1.538 against
  1.543; but best of 5 0.473 against 0.451 m, and its probabilities cannot be calibrated there: the worst checked
  bin is 0.19 off after its temperature (modes given 0.44 win 25% of the time) against 0.07. Must-show 6 would fail
  on validation to move 94 validation cyclists, so it was not bundled. β = 2, the same way, was behind both (0.897/2.108
  m, cyclists 0.459): between five-run consensus models the cyclists move by more than β explains. The cyclists'
  top mode is behind the model's own prior there (0.445 against 0.430 m for the last two steps' velocity), so one
  anchor of each class was held at a zero residual, the prior itself, for the classifier to pick
  (`train.zero_anchor`; the other anchors k-means around it), as the consensus of seeds 0–4: validation top-1
  0.861/2.004 m against 0.870/2.038, vehicles 1.525 against 1.543, cyclists 0.447 against 0.445, but best of 5 0.463
  against 0.451 and the worst checked bin 0.21 off after its temperature against 0.07. Not bundled. A
  constant-turn-rate prior, measured as physics alone on the validation scenes (`python -m training.prior_study`),
  is worse than constant velocity for every class: vehicles 2.15/5.37 m turning at the engine's estimated yaw rate,
  1.97/4.87 at half of it and 2.63/6.65 keeping the estimated acceleration too, against 1.91/4.69 (ApolloScape's
  validation recordings likewise: vehicles 2.68/4.96, 2.62/4.77 and 6.05/13.22 against 2.63/4.77). Yaw rate and
  acceleration estimated from a few noisy steps extrapolate worse than the direction of motion alone, so no model was
  trained on such a prior. How much of the network's refinement helps each class, measured by scaling the top
  mode's residual over the engine's prior, `prior + s (top mode − prior)`, on the validation scenes
  (`python -m training.prior_study --residual-scale`): for the cyclists the prior alone is best (0.430 m at s = 0,
  0.445 at s = 1, rising steadily in between), for the vehicles the network (1.909 m at s = 0, 1.543 at s = 1), and
  the pedestrians are within 0.002 m at every s. **So the consensus models now scale their most probable mode's
  residual per class** (`training.ensemble.fit_top_scale`, inside the exported graph, so the engine and the parity
  test run it), by a rule written down before any scaled model was built or tested: per class s from 0, 0.25, 0.5,
  0.75 and 1, the lowest validation top-1 ADE of that class, kept only if at least 1% below s = 1; the temperature
  is refitted after it. For `hdmap` that gave the cyclists s = 0 (the prior; 0.430 against 0.445 m on validation)
  and vehicles and pedestrians 1 (the pedestrians' best, 0.267 against 0.269 m, is under 1%); for `apolloscape` the
  cyclists 0.5 (1.592 against 1.652 m; its vehicles' best, 0.75, is 0.9% and stays 1); for the no-map baseline the
  cyclists 0.25; every ETH/UCY model keeps 1 everywhere (s = 1 is its best). On the held-out scenes, measured after:
  the 56 cyclists went 0.65/1.36 → 0.62/1.34 m (best of 5 0.46/0.92 → 0.46/0.95), and ApolloScape's 768 test
  cyclists 1.44/2.46 → 1.36/2.31 (constant velocity 1.49/2.57). The held-out cyclists stay behind constant velocity
  because the prior itself, constant velocity from the last two steps (0.62/1.33 m), is 7% behind the mean velocity
  over the last second there (0.58/1.26), which validation ranks second (0.436 against 0.430 m): no scale and no
  choice between the two velocities made on validation reaches it. *Not tried*:
  more driving data (only the mini sets are shared), map augmentation, a smaller map encoder.
"""


if __name__ == "__main__":
    main()
