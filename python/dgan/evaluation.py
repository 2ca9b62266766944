"""Does a model beat physics on your data? A model scored on your own table of tracks, beside constant velocity.

Every time of the table is a current time t_obs; every agent fully observed over the model's window and the
``T_f`` steps after it (its past and future resampled from the same rows onto the model's grid by the engine,
:func:`dgan.series.frames_with_futures`) is a target, standing ones too, the protocol of ``docs/results.md``: top-1
and best-of-K ADE/FDE, and constant velocity on the same targets (the better of its two variants, ``last2`` and
``mean1s`` of :func:`dgan.metrics.constant_velocity_variants`, for each error), per class, and for moving and
standing agents (moved less than ``standing_m`` from their first observed to their last true position) apart.

>>> import dgan
>>> from dgan.demo import SCENE_FILE
>>> from dgan.scenefiles import read_scene
>>> rows = read_scene(SCENE_FILE)[0]                       # a Social-GAN file: frame ids 0.04 s apart
>>> result = dgan.evaluate("zara1", rows, time_unit=0.04)
>>> len(result), result.times, result.rows()[0]["cv"]
(14, 1, 'last2')

``dgan evaluate MODEL SCENE`` prints the same table for a scene file (``--out`` every target, ``--plot`` a chart).
"""

from __future__ import annotations

import os
from collections.abc import Sequence
from dataclasses import dataclass, field, replace
from typing import Any

import numpy as np
import numpy.typing as npt

from dgan import metrics
from dgan._progress import progress as progress_bar
from dgan._values import checked_real
from dgan.exceptions import InvalidSpecError, NoTargetError
from dgan.frame import Frame
from dgan.predictor import Predictor
from dgan.series import Future, frames_with_futures

__all__ = ["Evaluation", "evaluate", "joined"]

Arr = npt.NDArray[Any]
#: Frames predicted per call of :meth:`~dgan.Predictor.predict_batch` (and per step of the progress bar).
CHUNK = 64
MOTIONS = ("all", "moving", "standing")
#: The keys of :attr:`Evaluation.steps` that are the model's: its top mode, and its mode of least ADE.
TOP, BEST = "top-1", "best"
#: What each target carries, in :class:`Evaluation` and in the parts :func:`evaluate` and :func:`joined` join.
_PER_TARGET = ("time", "agent_ids", "classes", "moving", "min_ade", "min_fde", "steps")


@dataclass(frozen=True)
class Evaluation:
    """A model's errors on every target of a table, one entry per target, with constant velocity's.

    Units are the table's (metres for metric tracks). :meth:`rows` and ``str()`` give the table by class and motion;
    :meth:`to_records` the targets one by one; :meth:`plot` a chart.
    """

    model: str
    modes: int
    dt_s: float
    t_obs: int
    t_f: int
    standing_m: float
    #: How many current times were scored (those with at least one target).
    times: int
    time: Arr  # each target's current time, as the table wrote it
    agent_ids: Arr
    classes: Arr  # str
    moving: npt.NDArray[np.bool_]
    #: Best of ``modes``: the least ADE and the least FDE, each over the modes.
    min_ade: npt.NDArray[np.float64]
    min_fde: npt.NDArray[np.float64]
    #: ``(targets, T_f)`` displacement at each predicted step: ``top-1``, ``best`` (the mode of least ADE), and
    #: constant velocity's variants (``last2``, ``mean1s``; :meth:`by_horizon`).
    steps: dict[str, npt.NDArray[np.float64]]
    scene: Arr = field(default_factory=lambda: np.zeros(0, dtype=object))

    def __len__(self) -> int:
        return len(self.min_ade)

    @property
    def ade(self) -> npt.NDArray[np.float64]:
        """Top-1 ADE of each target."""
        mean: npt.NDArray[np.float64] = self.steps[TOP].mean(axis=1)
        return mean

    @property
    def fde(self) -> npt.NDArray[np.float64]:
        """Top-1 FDE of each target."""
        return self.steps[TOP][:, -1]

    @property
    def cv(self) -> dict[str, tuple[npt.NDArray[np.float64], npt.NDArray[np.float64]]]:
        """Constant velocity's ADE and FDE of each target, by variant (``last2``, ``mean1s``)."""
        return {name: (d.mean(axis=1), d[:, -1]) for name, d in self.steps.items() if name not in (TOP, BEST)}

    def rows(self) -> list[dict[str, Any]]:
        """The table: for each class (and ``all`` when there are several) and motion (``all``, ``moving``,
        ``standing``), the targets, top-1 and best-of-``modes`` ADE/FDE, constant velocity's (``cv``: the variant
        of lower ADE; each error the lower of the two variants') and top-1 over constant velocity."""
        groups = sorted(set(self.classes.tolist()))
        out = []
        for cls in groups + (["all"] if len(groups) > 1 else []):
            of_class = np.ones(len(self), dtype=bool) if cls == "all" else self.classes == cls
            for motion in MOTIONS:
                sel = of_class & (True if motion == "all" else self.moving == (motion == "moving"))
                out.append({"class": cls, "motion": motion, **self._summary(sel)})
        return out

    def _summary(self, sel: npt.NDArray[np.bool_]) -> dict[str, Any]:
        n = int(np.count_nonzero(sel))
        if n == 0:
            return {"targets": 0}
        mean = {k: float(v[sel].mean()) for k, v in (("ade", self.ade), ("fde", self.fde))}
        mean |= {"min_ade": float(self.min_ade[sel].mean()), "min_fde": float(self.min_fde[sel].mean())}
        cv = {name: (float(a[sel].mean()), float(f[sel].mean())) for name, (a, f) in self.cv.items()}
        best = min(cv, key=lambda name: cv[name][0])
        cv_ade, cv_fde = cv[best][0], min(f for _, f in cv.values())
        ratios = {"ade_vs_cv": _ratio(mean["ade"], cv_ade), "fde_vs_cv": _ratio(mean["fde"], cv_fde)}
        return {"targets": n, **mean, "cv": best, "cv_ade": cv_ade, "cv_fde": cv_fde, **ratios}

    def __str__(self) -> str:
        head = (
            f"{self.model}: {len(self)} targets at {self.times} times (every agent seen over the {self.t_obs} "
            f"observed and {self.t_f} predicted steps, {self.dt_s:g} s apart; standing: moved < {self.standing_m:g} m)"
        )
        cols = f"{'class':<11} {'motion':<9} {'targets':>7}  {'top-1 ADE/FDE':>13}  {f'min{self.modes} ADE/FDE':>13}"
        lines = [head, cols + f"  {'constant velocity':<24} top-1 / CV (ADE, FDE)"]
        for r in self.rows():
            if r["targets"] == 0:
                lines.append(f"{r['class']:<11} {r['motion']:<9} {0:>7}")
                continue
            cv = f"{r['cv_ade']:.3f}/{r['cv_fde']:.3f} ({r['cv']})"
            lines.append(
                f"{r['class']:<11} {r['motion']:<9} {r['targets']:>7}  {r['ade']:>6.3f}/{r['fde']:<6.3f}  "
                f"{r['min_ade']:>6.3f}/{r['min_fde']:<6.3f}  {cv:<24} {r['ade_vs_cv']:.3f}, {r['fde_vs_cv']:.3f}"
            )
        return "\n".join(lines)

    def by_horizon(self, cls: str = "all", motion: str = "all") -> dict[str, npt.NDArray[np.float64]]:
        """The mean displacement at each predicted step (``time_s`` after the current time) of the targets of class
        ``cls`` (``"all"``: every class) and ``motion`` (``"all"``, ``"moving"``, ``"standing"``): ``top-1``,
        ``best`` (best of ``modes`` by ADE) and constant velocity's ``last2`` and ``mean1s``."""
        if motion not in MOTIONS:
            raise InvalidSpecError(f"motion must be one of {MOTIONS}, got {motion!r}")
        sel = np.ones(len(self), dtype=bool) if cls == "all" else self.classes == cls
        sel &= True if motion == "all" else self.moving == (motion == "moving")
        if not sel.any():
            raise InvalidSpecError(f"no target of class {cls!r} and motion {motion!r}; classes: {set(self.classes)}")
        out = {"time_s": self.dt_s * np.arange(1, self.t_f + 1)}
        return out | {name: d[sel].mean(axis=0) for name, d in self.steps.items()}

    def to_records(self) -> dict[str, Arr]:
        """The targets one by one: scene (when joined), time, agent_id, class, moving, and each error."""
        out: dict[str, Arr] = {"scene": self.scene} if len(self.scene) else {}
        out |= {"time": self.time, "agent_id": self.agent_ids, "class": self.classes, "moving": self.moving}
        out |= {"ade": self.ade, "fde": self.fde, f"min{self.modes}_ade": self.min_ade}
        out |= {f"min{self.modes}_fde": self.min_fde}
        for name, (a, f) in self.cv.items():
            out |= {f"cv_{name}_ade": a, f"cv_{name}_fde": f}
        return out

    def plot(self, ax: Any = None, kind: str = "classes") -> Any:
        """Top-1 ADE beside constant velocity's for each class and motion (``kind="classes"``), or the mean error
        at each predicted step (``kind="horizon"``, :meth:`by_horizon`), with ``dgan[plot]``; returns the figure."""
        from dgan.viz import _pyplot

        if kind not in ("classes", "horizon"):
            raise InvalidSpecError(f"kind must be 'classes' or 'horizon', got {kind!r}")
        plt = _pyplot()
        if kind == "horizon":
            return self._plot_horizon(plt, ax)
        rows = [r for r in self.rows() if r["targets"]]
        labels = [f"{r['class']}\n{r['motion']}\n({r['targets']})" for r in rows]
        fig, ax = plt.subplots(figsize=(max(6.0, 0.9 * len(rows)), 4.0)) if ax is None else (ax.figure, ax)
        x, w = np.arange(len(rows)), 0.38
        ax.bar(x - w / 2, [r["ade"] for r in rows], w, label=f"{self.model} top-1", color="tab:red")
        ax.bar(x + w / 2, [r["cv_ade"] for r in rows], w, label="constant velocity", color="tab:gray")
        for xi, r in zip(x, rows, strict=True):
            ax.annotate(f"{r['ade_vs_cv']:.2f}×", (xi, max(r["ade"], r["cv_ade"])), ha="center", va="bottom")
        ax.set_xticks(x, labels, fontsize=8)
        ax.set_ylabel(f"ADE over {self.t_f * self.dt_s:g} s (the table's unit)")
        ax.set_ylim(0, 1.25 * max(max(r["ade"], r["cv_ade"]) for r in rows))
        ax.set_title(f"{self.model} against constant velocity: {len(self)} targets, {self.times} times", fontsize=10)
        ax.legend(loc="upper right", ncol=2, fontsize=8)
        fig.tight_layout()
        return fig

    def _plot_horizon(self, plt: Any, ax: Any) -> Any:
        fig, ax = plt.subplots(figsize=(6.0, 4.0)) if ax is None else (ax.figure, ax)
        h = self.by_horizon()
        styles = {"top-1": ("tab:red", "-"), "best": ("tab:red", ":"), "last2": ("tab:gray", "-")}
        styles["mean1s"] = ("tab:gray", "--")
        names = {"top-1": f"{self.model} top-1", "best": f"{self.model} best of {self.modes}"}
        for key, (colour, line) in styles.items():
            label = names.get(key, f"constant velocity ({key})")
            ax.plot(h["time_s"], h[key], line, color=colour, marker=".", label=label)
        ax.set_xlabel("seconds ahead")
        ax.set_ylabel("mean displacement (the table's unit)")
        ax.set_title(f"{self.model}: error by horizon, {len(self)} targets, {self.times} times", fontsize=10)
        ax.legend(fontsize=8)
        fig.tight_layout()
        return fig


def _ratio(a: float, b: float) -> float:
    return a / b if b > 0 else float("inf") if a > 0 else 1.0


def evaluate(
    model: Predictor | str | os.PathLike[str],
    records: Any,
    *,
    modes: int | None = None,
    stride: int = 1,
    standing_m: float = 1.0,
    min_targets: int = 1,
    unknown_classes: str = "error",
    progress: bool = False,
    **options: Any,
) -> Evaluation:
    """Scores ``model`` (a :class:`~dgan.Predictor`, a bundled name or an ONNX file) on a long table of tracks.

    Args:
        records: any table :meth:`dgan.Frame.from_records` reads (one row per agent and time).
        modes: K of best-of-K (default: 20, or the model's modes if fewer).
        stride: score every ``stride``-th time of the table (1: every time).
        standing_m: an agent that moved less than this from its first observed to its last true position is
            standing (in the table's unit).
        min_targets: times with fewer targets are not scored (2: the Social-GAN protocol of the ETH/UCY tables in
            ``docs/results.md``, which leaves out windows of one target).
        unknown_classes: agents of classes the model does not predict: refused (``"error"``) or left out.
        progress: a progress bar on stderr.
        **options: :meth:`~dgan.Frame.from_records`' keywords (``time_unit``, column names, ``map`` ...); the time
            base is the model's.

    Raises:
        InvalidFrameError: a table the frames cannot be read from; :class:`~dgan.exceptions.NoTargetError` (one):
            no target at any time.
        InvalidSpecError: wrong ``modes``, ``stride``, ``standing_m`` or ``unknown_classes``.
    """
    predictor = model if isinstance(model, Predictor) else Predictor(model)
    k = min(20, predictor.num_modes) if modes is None else predictor._check_modes(modes)
    for name, value in (("stride", stride), ("min_targets", min_targets)):
        if isinstance(value, bool) or not isinstance(value, (int, np.integer)) or value < 1:
            raise InvalidSpecError(f"{name} must be a whole number ≥ 1, got {value!r}")
    standing = checked_real("standing_m", standing_m, InvalidSpecError)
    if not (np.isfinite(standing) and standing >= 0):
        raise InvalidSpecError(f"standing_m must be a non-negative distance, got {standing_m!r}")
    if unknown_classes not in ("error", "ignore"):
        raise InvalidSpecError(f"unknown_classes must be 'error' or 'ignore', got {unknown_classes!r}")
    taken = sorted({"spec", "t_obs", "dt"} & set(options))
    if taken:
        raise InvalidSpecError(f"{', '.join(taken)}: the time base is the model's; evaluate takes none")
    spec = predictor.spec
    pairs = frames_with_futures(records, spec.t_f, spec=predictor, **options)[::stride]
    parts = []
    chunks = [pairs[i : i + CHUNK] for i in range(0, len(pairs), CHUNK)]
    for chunk in progress_bar(chunks, "chunks of 64 times") if progress else chunks:
        chunk = [_known(f, fut, predictor) for f, fut in chunk] if unknown_classes == "ignore" else chunk
        preds = predictor.predict_batch([f for f, _ in chunk], modes=k, unknown_classes=unknown_classes)
        parts += [
            _scored(f, fut, p.trajectories, spec.dt_s, standing) for (f, fut), p in zip(chunk, preds, strict=True)
        ]
    parts = [p for p in parts if len(p["min_ade"]) >= min_targets]
    if not parts:
        raise NoTargetError(
            f"no target: no agent of the table is seen over {spec.t_obs + spec.t_f} consecutive steps of "
            f"{spec.dt_s:g} s (is time_unit right?)"
        )
    path = getattr(predictor, "path", None)
    return Evaluation(
        model=str(model) if isinstance(model, str) else (path.stem if path is not None else "model"),
        modes=k,
        dt_s=spec.dt_s,
        t_obs=spec.t_obs,
        t_f=spec.t_f,
        standing_m=standing,
        times=len(parts),
        **_concatenated(parts),
    )


def _known(frame: Frame, future: Future, predictor: Predictor) -> tuple[Frame, Future]:
    """The frame and future of its agents of the model's classes."""
    keep = predictor._known_rows(frame)
    return (frame, future) if keep.all() else (frame.select(keep), (future[0][keep], future[1][keep]))


def _scored(frame: Frame, future: Future, modes: Arr, dt_s: float, standing_m: float) -> dict[str, Any]:
    """One frame's targets (agents seen at every past and future step) and their errors."""
    positions, (truth, seen) = frame.positions, future
    full = frame.mask.all(axis=1) & seen.all(axis=1)
    gt, past = truth[full], positions[full]
    n = int(np.count_nonzero(full))
    d = metrics.displacement(modes[full], gt)  # (n, M, T_f): every error below is read from it
    steps = {TOP: d[:, 0], BEST: d[np.arange(n), d.mean(axis=-1).argmin(axis=1)]}
    for name, rollout in metrics.constant_velocity_variants(past, frame.mask[full], gt.shape[1], dt_s).items():
        steps[name] = metrics.displacement(rollout, gt)[:, 0]
    return {
        "time": np.full(n, frame.time),
        "agent_ids": np.asarray(frame.agent_ids)[full],
        "classes": np.asarray(frame.classes, dtype=object)[full],
        "moving": np.linalg.norm(gt[:, -1] - past[:, 0], axis=-1) >= standing_m,
        "min_ade": d.mean(axis=2).min(axis=1),  # as dgan.metrics.min_ade_fde over every mode
        "min_fde": d[:, :, -1].min(axis=1),
        "steps": steps,
    }


def _concatenated(parts: Sequence[dict[str, Any]]) -> dict[str, Any]:
    """The per-target fields of several parts (frames, or evaluations) one after the other."""
    out = {key: np.concatenate([p[key] for p in parts]) for key in _PER_TARGET if key != "steps"}
    return out | {"steps": {name: np.concatenate([p["steps"][name] for p in parts]) for name in parts[0]["steps"]}}


def joined(evaluations: Sequence[Evaluation], scenes: Sequence[str]) -> Evaluation:
    """Several evaluations of one model (one per scene) as one, each target with its ``scene``."""
    if not evaluations or len(evaluations) != len(scenes):
        raise InvalidSpecError("joined takes one scene name per evaluation, and at least one")
    cat = _concatenated([{key: getattr(e, key) for key in _PER_TARGET} for e in evaluations])
    scene = np.concatenate([np.full(len(e), s, dtype=object) for e, s in zip(evaluations, scenes, strict=True)])
    times = sum(e.times for e in evaluations)
    return replace(evaluations[0], times=times, scene=scene, **cat)
