"""A configuration's training and validation windows, in one pass down the data layers.

The ``data`` section is read here once, into the :class:`~training.data.recording.WindowSet` parts of each split
(the dataset's own windows; for training, copies with tracker-like histories and other sources' pedestrians) and
checked before anything is read. The registry then locates each part's files and hands down a reader
(:func:`~training.data.datasets.locate`), the cache reads or builds each part's windows (:func:`~training.data.cache
.cached`, which calls the window builder and the tracker noise), and the parts are concatenated
(:func:`~training.data.arrays.concat_windows`). No module below is entered twice.
"""

from __future__ import annotations

from dataclasses import dataclass, replace
from pathlib import Path

import numpy as np

import dgan
from training.config import Config, DataConfig, validation_data
from training.data.arrays import Windows, concat_windows
from training.data.cache import cached
from training.data.datasets import DATASETS, PEDESTRIAN_SOURCES, locate
from training.data.recording import Located, WindowSet


@dataclass
class TrainingSplits:
    """What a training run trains and validates on. ``parts`` are the training split's window sets (the dataset's
    own first) and ``train`` their concatenation; ``target_class`` is the class index of ``data.target_class``
    (None: every class), which the trainer applies once the anchors are fitted."""

    parts: list[Windows]
    train: Windows
    val: Windows
    target_class: int | None


def training_splits(cfg: Config, spec: dgan.InputSpec, progress: bool) -> TrainingSplits:
    """The training parts and validation windows of ``cfg`` (each read from the window cache or built into it; the
    validation windows of the dataset alone with ``train.select_split = "own"``)."""
    d = cfg.data
    target = target_class_index(d.target_class, spec)
    val_data = validation_data(d, cfg.train.select_split, "train.select_split")
    train_sets, val_sets = window_sets(d, "train"), window_sets(val_data, "val")
    windows = set_windows(d, train_sets + val_sets, spec, progress)
    parts, val = windows[: len(train_sets)], windows[len(train_sets) :]
    return TrainingSplits(parts, concat_windows(parts), concat_windows(val), target)


def split_windows(cfg: Config, spec: dgan.InputSpec, split: str, progress: bool) -> Windows:
    """One split's windows of ``cfg``, its parts concatenated (calibration and the ensemble's top-mode scales read
    ``val``)."""
    return concat_windows(set_windows(cfg.data, window_sets(cfg.data, split), spec, progress))


def set_windows(d: DataConfig, sets: list[WindowSet], spec: dgan.InputSpec, progress: bool) -> list[Windows]:
    """The windows of each of ``sets``, located under ``data.root`` and cached under ``data.cache_dir``."""
    root, cache = Path(d.root).expanduser(), Path(d.cache_dir).expanduser()
    found = located(sets, root, spec)
    windows = cached(found, spec, cache, progress, d.map_scene_px)
    # A noisy copy's agents are flagged (train.distill_noisy = false keeps the teacher off them).
    return [
        replace(w, noisy=np.ones(len(w.target), bool)) if part.noise != (0.0, 0.0) or part.hold > 0 else w
        for part, w in zip(sets, windows, strict=True)
    ]


def window_set(part: WindowSet, root: Path, spec: dgan.InputSpec, cache_dir: Path, progress: bool = False) -> Windows:
    """The windows of one part under ``root`` (studies and tests that need one set without a configuration)."""
    return cached(located([part], root, spec), spec, cache_dir, progress)[0]


def window_sets(d: DataConfig, split: str) -> list[WindowSet]:
    """The parts of ``split`` that ``d`` asks for: the dataset's own windows; for training, then one noisy copy per
    level of ``data.augment_noise``, a held copy with ``data.augment_hold_m``, a faster copy per factor of
    ``data.augment_speed`` and the pedestrians of each
    ``data.extra_pedestrians`` source; then the split of each ``data.extra_sources`` dataset."""
    fold = {"ethucy": d.scene, "apolloscape": d.val_recordings}.get(d.dataset, "")
    if d.val_recordings and d.dataset != "apolloscape":
        raise ValueError(f"data.val_recordings is for ApolloScape, not {d.dataset!r}")
    sources = pedestrian_sources(d.extra_pedestrians)
    if sources and d.dataset != "ethucy":
        raise ValueError(f"data.extra_pedestrians is for the ETH/UCY models, not {d.dataset!r}")
    own = WindowSet(d.dataset, split, fold, d.window_stride)
    joint = [WindowSet(s, split, stride=k) for s, k in extra_sources(d.extra_sources, d.dataset, d.extra_stride)]
    if split != "train":
        return [own, *joint]
    noisy = [replace(own, noise=(sigma, d.augment_drop)) for sigma in augment_sigmas(d.augment_noise)]
    if d.augment_hold_m < 0:
        raise ValueError(f"data.augment_hold_m must be >= 0 metres, got {d.augment_hold_m}")
    if d.augment_hold_future and d.augment_hold_m <= 0:
        raise ValueError("data.augment_hold_future needs a held copy (data.augment_hold_m > 0)")
    held = replace(own, hold=d.augment_hold_m, hold_future=d.augment_hold_future)
    noisy += [held] if d.augment_hold_m > 0 else []
    fast = [replace(own, speed=s) for s in augment_speeds(d.augment_speed)]
    if fast and d.dataset != "ethucy":  # resampling drops headings and the steps a window may end at
        raise ValueError(f"data.augment_speed is for the ETH/UCY models, not {d.dataset!r}")
    extra = [WindowSet(s, "train", stride=d.extra_stride, pedestrians=True) for s in sources]
    return [own, *noisy, *fast, *extra, *joint]


def extra_sources(names: str, dataset: str, stride: int = 1) -> list[tuple[str, int]]:
    """The datasets named by ``data.extra_sources`` (comma-separated ``name`` or ``name:stride``, the stride of its
    windows, else ``stride``; empty for none) with their strides, each registered, other than ``dataset`` and at its
    protocol (time base, observed and predicted steps)."""
    items = [s.strip() for s in names.split(",") if s.strip()]
    sources, strides = [], []
    for item in items:
        name, _, every = item.partition(":")
        try:
            k = int(every) if every else stride
        except ValueError:
            k = 0
        if k < 1:
            raise ValueError(f"data.extra_sources: {item!r} needs a whole stride of at least 1 after its colon")
        sources.append(name.strip())
        strides.append(k)
    if unknown := [s for s in sources if s not in DATASETS]:
        raise ValueError(f"unknown data.extra_sources {unknown}; known: {', '.join(DATASETS)}")
    if dataset in sources or len(set(sources)) < len(sources):
        raise ValueError(f"data.extra_sources {names!r} repeats a source or names the dataset {dataset!r} itself")
    own = DATASETS[dataset]
    for s in sources:
        info = DATASETS[s]
        if (info.dt_s, info.t_obs, info.t_f) != (own.dt_s, own.t_obs, own.t_f):
            raise ValueError(
                f"data.extra_sources: {s!r} has steps of {info.dt_s:g} s, {info.t_obs} observed and {info.t_f} "
                f"predicted, {dataset!r} {own.dt_s:g} s, {own.t_obs} and {own.t_f}: not one protocol"
            )
        if missing := set(info.classes) - set(own.classes):
            raise ValueError(f"data.extra_sources: {s!r} has classes {sorted(missing)} that {dataset!r} does not")
    return list(zip(sources, strides, strict=True))


def augment_sigmas(declared: str) -> list[float]:
    """The noise levels of ``data.augment_noise`` (comma-separated metres; "" = none)."""
    sigmas = comma_floats(declared, "data.augment_noise", "metres")
    if any(not (0.0 < x <= 5.0) for x in sigmas):
        raise ValueError(f"data.augment_noise must hold noise levels in (0, 5] metres, got {declared!r}")
    return sigmas


def augment_speeds(declared: str) -> list[float]:
    """The speed-up factors of ``data.augment_speed`` (comma-separated, each in (1, 4]; "" = none)."""
    factors = comma_floats(declared, "data.augment_speed", "factors")
    if any(not (1.0 < x <= 4.0) for x in factors) or len(set(factors)) < len(factors):
        raise ValueError(f"data.augment_speed must hold distinct factors in (1, 4], got {declared!r}")
    return factors


def comma_floats(declared: str, key: str, unit: str) -> list[float]:
    """The numbers of the setting ``key`` (comma-separated ``unit``; "" = none); a ValueError naming it otherwise."""
    try:
        return [float(x) for x in declared.split(",") if x.strip()]
    except ValueError:
        raise ValueError(f"{key} must be comma-separated {unit}, got {declared!r}") from None


def pedestrian_sources(names: str) -> list[str]:
    """The sources named by ``data.extra_pedestrians`` (comma-separated; empty for none), each checked."""
    sources = [s.strip() for s in names.split(",") if s.strip()]
    unknown = [s for s in sources if s not in PEDESTRIAN_SOURCES]
    if unknown:
        raise ValueError(f"unknown pedestrian source(s) {unknown}; known: {', '.join(PEDESTRIAN_SOURCES)}")
    return sources


def target_class_index(target_class: str, spec: dgan.InputSpec) -> int | None:
    """The class index of ``data.target_class`` among the model's classes ("" = every class: None)."""
    if not target_class:
        return None
    if target_class not in spec.classes:
        raise ValueError(f"data.target_class {target_class!r} is not among the classes {spec.classes}")
    return list(spec.classes).index(target_class)


def only_target_class(w: Windows, target_class: int | None) -> None:
    """Keeps as targets of ``w`` only the agents of ``target_class`` (a per-class run's, ``data.target_class``:
    :func:`target_class_index`); every target stays for None. The trainer's validation and temperature and
    bundling's temperature (``training.calibrate.validation_logits``) count the same targets through it."""
    if target_class is not None:
        w.target &= w.class_index == target_class


def located(sets: list[WindowSet], root: Path, spec: dgan.InputSpec) -> list[Located]:
    """Each of ``sets`` located under ``root`` by the registry, with a reader at ``spec``'s time base (maps read
    only for a model that takes them)."""
    found = []
    for part in sets:
        found.append(locate(part, root, spec.dt_s, spec.map is not None))
    return found
