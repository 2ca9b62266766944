"""How much do training runs that differ only in their seed differ, and what does averaging them give?

    python -m training.studies.seed RUN [RUN ...] [--data-root ../shared/data] [--jobs 2] [--out docs/seed_study.json]

Each RUN is a ``training.train`` output folder (``best.pt``, exported to ``model.onnx`` here if missing), typically one
configuration trained with several seeds (``--set train.seed=N``), beside another. Runs are grouped by their model
name (``hdmap``, ``hdmap-nomap`` ...), members ordered by seed. Every group is run with the engine, all members on the
same windows and targets, on its validation split and on its test sets (``TEST_SETS``), with and without the map
where its members have one. Per class:

- the spread over members of top-1 ADE/FDE (mean, standard deviation, minimum, maximum): what any single run's figure
  carries, and the map against no map (must-show 4 of ``docs/results.md``) beyond it;
- the member chosen on validation (the lowest validation top-1 ADE of every target, with its map), fixed before any
  test set is read;
- *averaged*: the mean of the top-1 trajectories of the first n members (n = 3, 5 and all): an ensemble that averages
  its members' most probable futures;
- constant velocity on the same targets (the better of ``last2`` and ``mean1s`` per error, as everywhere).
"""

from __future__ import annotations

import argparse
import json
import statistics
from concurrent.futures import ProcessPoolExecutor
from pathlib import Path
from typing import Any

import numpy as np

import dgan
from training import metrics
from training.build import run_name
from training.config import Config
from training.data.datasets import DATASETS
from training.evaluate import scored_windows

#: The test sets of a training dataset (the driving models are also measured on Argoverse 2, never trained on).
TEST_SETS = {"hdmap": ("hdmap", "argoverse2")}
#: Where ``python -m training.results`` reads the study (``--out``).
STUDY = Path(__file__).resolve().parents[2] / "docs" / "seed_study.json"
#: Ensemble sizes measured (the first n members by seed; "all" is every member).
ENSEMBLES = (3, 5)


class Group:
    """Runs of one model name: their exported models, ordered by seed."""

    def __init__(self, name: str, runs: list[Path], seeds: list[int], dataset: str, fold: str) -> None:
        self.name, self.runs, self.seeds, self.dataset, self.fold = name, runs, seeds, dataset, fold


def exported(run: Path) -> tuple[Path, dict[str, Any]]:
    """``run/model.onnx`` (exported from ``best.pt`` if missing) and the run's training configuration."""
    model = run / "model.onnx"
    if not model.is_file():
        from training.export import export_checkpoint

        export_checkpoint(run / "best.pt", model, name=f"dgan-seed-study-{run.name}")
    return model, json.loads((run / "config.json").read_text())["config"]


def groups_of(runs: list[Path]) -> list[Group]:
    """The runs grouped by model name, each group's members ordered by seed."""
    found: dict[str, list[tuple[int, Path, str, str]]] = {}
    for run in runs:
        _, config = exported(run)
        name = run_name(Config.from_dict(config))
        dataset = config["data"]["dataset"]
        fold = config["data"]["scene"] if dataset == "ethucy" else ""
        found.setdefault(name, []).append((int(config["train"]["seed"]), run, dataset, fold))
    out = []
    for name, members in sorted(found.items()):  # the name holds the dataset and the fold (run_name)
        members.sort()
        _, _, dataset, fold = members[0]
        out.append(Group(name, [r for _, r, _, _ in members], [s for s, _, _, _ in members], dataset, fold))
    return out


def top1_on(group: Group, split: str, dataset: str, with_map: bool, root: Path) -> dict[str, Any]:
    """Every member's top-1 trajectory ``(M, n, T, 2)`` on the targets of a split, the truth ``(n, T, 2)``, constant
    velocity's variants ``{name: (n, 1, T, 2)}`` and the targets' classes ``(n,)``."""
    predictors = [dgan.Predictor(exported(r)[0]) for r in group.runs]
    tops, truth, classes = [], [], []
    cvs: dict[str, list[np.ndarray]] = {}
    info = DATASETS[dataset]
    for sw in scored_windows(predictors[0].spec, dataset, root, split, group.fold, with_map):
        tops.append(np.stack([p.predict(sw.frame).trajectories[sw.target, 0] for p in predictors]) / sw.unit)
        truth.append(sw.truth)
        for k, v in sw.cvs.items():
            cvs.setdefault(k, []).append(v)
        classes.append(np.array([info.label_class[k] for k in sw.label]))
    return {
        "top1": np.concatenate(tops, axis=1),
        "truth": np.concatenate(truth),
        "cv": {k: np.concatenate(v) for k, v in cvs.items()},
        "classes": np.concatenate(classes),
    }


def spread(values: list[float]) -> dict[str, float]:
    """Mean, sample standard deviation (0 for one value), minimum and maximum."""
    sd = statistics.stdev(values) if len(values) > 1 else 0.0
    return {"mean": statistics.fmean(values), "sd": sd, "min": min(values), "max": max(values)}


def figures(top1: np.ndarray, truth: np.ndarray, cv: dict[str, np.ndarray], classes: np.ndarray) -> dict[str, Any]:
    """Per class (and ``"all"``): the members' top-1 ADE/FDE each, their spread, the averaged ensembles' and
    constant velocity's, and the number of targets."""
    per_member = [metrics.ade_fde_top1(top1[m][:, None], truth) for m in range(len(top1))]
    sizes = sorted({n for n in ENSEMBLES if n < len(top1)} | {len(top1)})
    averaged = {n: metrics.ade_fde_top1(top1[:n].mean(axis=0)[:, None], truth) for n in sizes}
    cv_errors = {k: metrics.ade_fde_top1(v, truth) for k, v in cv.items()}
    out: dict[str, Any] = {}
    for cls in ["all", *sorted(set(classes.tolist()))]:
        sel = np.ones(len(classes), dtype=bool) if cls == "all" else classes == cls
        ade = [float(a[sel].mean()) for a, _ in per_member]
        fde = [float(f[sel].mean()) for _, f in per_member]
        out[cls] = {
            "agents": int(sel.sum()),
            "member_ade": ade,
            "member_fde": fde,
            "ade": spread(ade),
            "fde": spread(fde),
            "averaged": {
                str(n): {"ade": float(a[sel].mean()), "fde": float(f[sel].mean())} for n, (a, f) in averaged.items()
            },
            "cv_ade": min(float(a[sel].mean()) for a, _ in cv_errors.values()),
            "cv_fde": min(float(f[sel].mean()) for _, f in cv_errors.values()),
        }
    return out


def measure(group: Group, split: str, dataset: str, with_map: bool, root: Path) -> dict[str, Any]:
    got = top1_on(group, split, dataset, with_map, root)
    return figures(got["top1"], got["truth"], got["cv"], got["classes"])


def study(runs: list[Path], root: Path, jobs: int = 2) -> dict[str, Any]:
    """Every group's figures on validation and its test sets, with and without the map, and the member chosen."""
    groups = groups_of(runs)
    tasks = []
    for g in groups:
        has_map = dgan.Predictor(g.runs[0] / "model.onnx").spec.map is not None
        for split, dataset in [("val", g.dataset), *[("test", d) for d in TEST_SETS.get(g.dataset, (g.dataset,))]]:
            for with_map in (True, False) if has_map else (False,):
                tasks.append((g, split, dataset, with_map))
    from tqdm import tqdm

    with ProcessPoolExecutor(max(1, jobs)) as pool:
        futures = [pool.submit(measure, g, split, d, m, root) for g, split, d, m in tasks]
        results = [f.result() for f in tqdm(futures, desc="seed study", unit="set")]
    out: dict[str, Any] = {}
    for (g, split, dataset, with_map), res in zip(tasks, results, strict=True):
        entry = out.setdefault(g.name, {"runs": [r.name for r in g.runs], "seeds": g.seeds})
        entry.setdefault(split, {}).setdefault(dataset, {})["map" if with_map else "no_map"] = res
    for entry in out.values():
        val = next(iter(entry["val"].values()))
        first = val["map"] if "map" in val else val["no_map"]
        best = int(np.argmin(first["all"]["member_ade"]))
        entry["chosen"] = {"run": entry["runs"][best], "seed": entry["seeds"][best], "index": best}
    return out


def markdown(result: dict[str, Any], cls: str = "vehicle") -> str:
    """``cls``'s top-1 ADE/FDE per model, split, set and map: the members' spread, the member chosen on validation,
    the averaged ensembles and constant velocity."""
    lines = [
        "| model | split | set | map | members: top-1 ADE mean ± sd (min–max) | chosen on val | averaged "
        "(n members): ADE/FDE | constant velocity |",
        "|---|---|---|---|---|---|---|---|",
    ]
    for name, g in result.items():
        for split in ("val", "test"):
            for dataset, by_map in g.get(split, {}).items():
                for key, by_class in by_map.items():
                    if cls not in by_class:
                        continue
                    c = by_class[cls]
                    a = c["ade"]
                    chosen = g["chosen"]["index"]
                    avg = ", ".join(f"{n}: {v['ade']:.3f}/{v['fde']:.3f}" for n, v in c["averaged"].items())
                    lines.append(
                        f"| {name} ({len(g['runs'])}) | {split} | {dataset} | {key.replace('_', ' ')} | "
                        f"{a['mean']:.3f} ± {a['sd']:.3f} ({a['min']:.3f}–{a['max']:.3f}) | "
                        f"{c['member_ade'][chosen]:.3f}/{c['member_fde'][chosen]:.3f} | {avg} | "
                        f"{c['cv_ade']:.3f}/{c['cv_fde']:.3f} |"
                    )
    return "\n".join(lines)


def section(path: Path = STUDY, classes: tuple[str, ...] = ("all", "vehicle")) -> str:
    """The study as Markdown tables for ``docs/results.md`` (one per class), or a line saying how to run it."""
    if not path.is_file():
        return "*(not run: `python -m training.studies.seed RUN ... --out docs/seed_study.json`)*"
    result = json.loads(path.read_text())
    return "\n\n".join(f"*{c}*:\n\n{markdown(result, c)}" for c in classes)


def main(argv: list[str] | None = None) -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("runs", nargs="+", type=Path)
    ap.add_argument("--data-root", type=Path, default=Path("../shared/data"))
    ap.add_argument("--jobs", type=int, default=2, help="sets measured at once")
    ap.add_argument("--out", type=Path, help="write every figure here (JSON)")
    ap.add_argument("--update", action="store_true", help="keep the other groups already in --out")
    ap.add_argument("--classes", default="vehicle,all", help="classes printed (comma-separated)")
    a = ap.parse_args(argv)
    missing = [str(r) for r in a.runs if not (r / "best.pt").is_file() and not (r / "model.onnx").is_file()]
    if missing:
        ap.error(f"not training runs (no best.pt or model.onnx): {', '.join(missing)}")
    result = study(a.runs, a.data_root.expanduser(), a.jobs)
    if a.out:
        kept = json.loads(a.out.read_text()) if a.update and a.out.is_file() else {}
        a.out.write_text(json.dumps(kept | result, indent=1))
    for cls in a.classes.split(","):
        print(f"\n{cls}:\n{markdown(result, cls)}")
    for name, g in result.items():
        print(f"{name}: {len(g['runs'])} runs, chosen on validation: {g['chosen']['run']}")


if __name__ == "__main__":
    main()
