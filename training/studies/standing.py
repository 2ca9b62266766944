"""How close can a model come to a standing agent's end point? Issue 25 item 3's bounds against the data.

    python -m training.studies.standing [--data-root ../shared/data] [--out docs/standing_study.json]

On each test set, the bundled model that serves it and every *standing* target (moved less than
:data:`training.data.windows.STANDING_M` from its first observed to its last true position, as every accuracy table
splits them), per class, the final displacement error (FDE, the dataset's unit) of:

- the model's most probable mode (*top-1*) and its best of 20 (*min20*);
- constant velocity, the better of its two variants (as everywhere);
- *staying put* at the last observed position. The group is chosen by the truth (where the agent ends), so this is
  not a baseline anyone could run; it says how far the tracks of agents that end where they stood still drift from
  their last observed position by the horizon: the data's own jitter and creep, which a prediction of *standing*
  cannot remove.

The share of standing targets whose true end lies within the item's bound of their last observed position (0.2 m for
vehicles, 0.35 m for pedestrians and cyclists) is reported beside it.
"""

from __future__ import annotations

import argparse
import json
from pathlib import Path
from typing import Any

import numpy as np

import dgan
from training import metrics
from training.data.datasets import DATASETS
from training.evaluate import rows_of, scored_windows

#: Where ``--out`` writes the study by default.
STUDY = Path(__file__).resolve().parents[2] / "docs" / "standing_study.json"
#: Issue 25 item 3's bound on a standing agent's top-1 FDE, metres, per class.
BOUND_M = {"vehicle": 0.2, "cyclist": 0.35, "pedestrian": 0.35}
#: (bundled model, dataset, fold) of every test set measured.
TEST_SETS = (
    *((s, "ethucy", s) for s in ("eth", "hotel", "univ", "zara1", "zara2")),
    ("sdd", "sdd", ""),
    ("apolloscape", "apolloscape", ""),
    ("hdmap", "hdmap", ""),
    ("hdmap", "argoverse2", ""),
)


def end_errors(
    modes: np.ndarray, truth: np.ndarray, last_observed: np.ndarray, cvs: dict[str, np.ndarray]
) -> dict[str, np.ndarray]:
    """Per target, the final displacement of the top mode (``modes[:, 0]``), of the best of the first 20 modes, of
    staying at ``last_observed`` ``(n, 2)`` and of each constant-velocity variant ``{name: (n, 1, T_f, 2)}``, against
    ``truth`` ``(n, T_f, 2)``; ``modes`` is ``(n, M, T_f, 2)``, most probable first."""
    out = {
        "top1": metrics.ade_fde_top1(modes, truth)[1],
        "min20": metrics.min_ade_fde(modes, truth, 20)[1],
        "stay": np.linalg.norm(last_observed - truth[:, -1], axis=-1),
    }
    out.update({f"cv_{k}": metrics.ade_fde_top1(v, truth)[1] for k, v in cvs.items()})
    return out


def summary(errors: dict[str, np.ndarray], bound_m: float) -> dict[str, Any]:
    """Means of :func:`end_errors`' columns over one group (constant velocity: its better variant), the median and
    90th percentile of staying put's error, and the share of the group within ``bound_m`` metres of where it stood
    (``errors["stay_m"]``: staying put's error in metres, for a dataset whose unit differs by recording), and the top
    mode's mean error in metres where ``errors["top1_m"]`` gives it."""
    stay = errors["stay"]
    cv = [float(v.mean()) for k, v in errors.items() if k.startswith("cv_")]
    return {
        "targets": len(stay),
        "top1_fde": float(errors["top1"].mean()),
        "min20_fde": float(errors["min20"].mean()),
        "cv_fde": min(cv) if cv else float("nan"),
        "stay_fde": float(stay.mean()),
        "stay_median": float(np.median(stay)),
        "stay_p90": float(np.percentile(stay, 90)),
        "bound_m": bound_m,
        "share_within_bound": float((errors["stay_m"] <= bound_m).mean()),
        **({"top1_fde_m": float(errors["top1_m"].mean())} if "top1_m" in errors else {}),
    }


def measure(model: str, dataset: str, fold: str, root: Path) -> dict[str, Any]:
    """:func:`summary` of one test set's standing targets, per class, in the dataset's unit."""
    predictor = dgan.Predictor(model)
    info = DATASETS[dataset]
    groups: dict[str, list[dict[str, np.ndarray]]] = {}
    for sw in scored_windows(predictor.spec, dataset, root, "test", fold):
        standing = ~sw.moving
        if not standing.any():
            continue
        pred = rows_of(predictor.predict(sw.frame), sw.target, sw.unit)
        last = np.asarray(sw.frame.positions)[sw.target, predictor.spec.t_obs - 1] / sw.unit
        errors = end_errors(pred.trajectories, sw.truth, last, sw.cvs)
        errors["stay_m"] = errors["stay"] * sw.unit
        errors["top1_m"] = errors["top1"] * sw.unit
        classes = np.array([info.label_class[k] for k in sw.label])
        for c in np.unique(classes[standing]):
            sel = standing & (classes == c)
            groups.setdefault(str(c), []).append({k: v[sel] for k, v in errors.items()})
    out: dict[str, Any] = {"model": model, "unit": info.unit}
    for c, rows in sorted(groups.items()):
        joined = {k: np.concatenate([r[k] for r in rows]) for k in rows[0]}
        out[c] = summary(joined, BOUND_M[c])
    return out


def main(argv: list[str] | None = None) -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--data-root", type=Path, default=Path("../shared/data"))
    ap.add_argument("--out", type=Path, default=STUDY)
    a = ap.parse_args(argv)
    from tqdm import tqdm

    result = {}
    for model, dataset, fold in tqdm(TEST_SETS, desc="standing study", unit="test set"):
        result[f"{dataset}:{fold}" if fold else dataset] = measure(model, dataset, fold, a.data_root)
    a.out.write_text(json.dumps(result, indent=1) + "\n")
    print(f"wrote {a.out}")


if __name__ == "__main__":
    main()
