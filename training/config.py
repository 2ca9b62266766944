"""Typed training configuration, read from TOML (see ``training/configs/``)."""

from __future__ import annotations

from dataclasses import dataclass, field, fields, replace
from pathlib import Path
from typing import Any

import tomllib

from training.modules.dgan import ModelConfig


@dataclass(frozen=True)
class DataConfig:
    root: str = "../shared/data"  # the folder holding eth_ucy/, sdd/, apolloscape_trajectory/ ...
    dataset: str = "ethucy"  # ethucy, sdd or apolloscape (training.data.datasets.DATASETS)
    scene: str = "zara1"  # the held-out ETH/UCY scene (ethucy only)
    target_class: str = ""  # train on this class's targets only (a per-class baseline); "" = every class
    window_stride: int = 1  # train and validate on windows ending at every n-th step (the test always uses all)
    cache_dir: str = "~/.cache/dgan/windows"
    use_map: bool = True
    map_height_px: int = 32
    map_width_px: int = 31
    map_resolution_m: float = 0.5
    map_agent_row: int = 24
    # Whether the crops carry the agents' boxes (dgan.MapSpec.draw_agents): most of a raster crop's cost (docs/speed.md)
    map_draw_agents: bool = True
    # How a vector map becomes the crops (dgan.MapSpec.render): "agent" (each crop drawn from the elements) or "tiles"
    # (the map drawn once into tiles kept with it, each crop resampled from them: the map's cost stops growing with N).
    map_render: str = "agent"
    # > 0: each training window also carries its scene raster of this many pixels a side (dgan.scene_raster, at the
    # crops' resolution, centred on its agents, turned at random) and each agent its crop's grid in it (dgan.crop_grid),
    # for model.map_mode = "scene" (issue 26); the exported model's rasters just hold each group of crops (contract 12,
    # training.modules.scene.SCENE_MIN_PX at least). 0: none.
    map_scene_px: int = 0
    # > 0 (with map_scene_px and map_draw_agents = false): the exported model keeps the scene CNN's features with the
    # map, in tiles of this many pixels on a grid fixed in the world (contract 13, dgan_core::kept): each tile is
    # computed once per map and predictor. Training is unchanged (its windows' rasters). 0: rasters per call.
    map_scene_tile_px: int = 0
    # The kinematic prior the network refines (dgan.PriorSpec): "none" (absolute anchors, contract 1) or
    # "constant_velocity"; prior_window_s > 0 estimates its velocity over that many seconds of observed positions.
    prior: str = "none"
    prior_window_s: float = 0.0
    # How that window's velocity is estimated: "endpoints", "least_squares" (a line through every valid position),
    # "quadratic" (a least-squares parabola's slope at t_obs) or "adaptive" (a line through as many recent positions as
    # the track's noise calls for);
    # agents slower than prior_standing_mps (m/s, 0 = never) get a standing prior (dgan.PriorSpec).
    prior_fit: str = "endpoints"
    prior_standing_mps: float = 0.0
    # Classes with their own velocity estimate (dgan.ClassPrior, contract 8), comma-separated
    # "class=fit:window_s:standing_mps", e.g. "pedestrian=least_squares:2:0.3"; the others keep the three above.
    prior_by_class: str = ""
    # Where agents' headings come from (dgan.InputSpec.heading): "measured", "motion_when_moving" or "motion".
    heading: str = "measured"
    # Contract 10 (dgan.InputSpec.denoise_gate_m): histories off their least-squares parabola by this many metres or
    # more (RMS) are smoothed onto it before any input is built, in training and at inference alike; 0 = as given.
    denoise_gate_m: float = 0.0
    # ETH/UCY only: pedestrians of other sources added to the training windows
    # (training.data.datasets.PEDESTRIAN_SOURCES, comma-separated; their training splits only, resampled to 0.4 s,
    # without maps), at windows ending at every extra_stride-th step.
    extra_pedestrians: str = ""
    extra_stride: int = 3
    # Whether those pedestrians' (or sources') futures join the k-means of the anchors; false fits the anchors on the
    # dataset's own training windows alone (the network still trains on all of them).
    extra_in_anchors: bool = True
    # Other sources at this dataset's protocol whose every agent joins training (their train splits) and validation
    # (their val splits), both at windows ending every n-th step ("name:n", else extra_stride): comma-separated names
    # of datasets with the same time base and steps (e.g. "ethucy_5hz:2,sdd_5hz:8,apolloscape_5hz" beside hdmap,
    # training.data.datasets.AT_HDMAP; their maps are not read: a model whose map is optional sees its crop absent).
    extra_sources: str = ""
    # ApolloScape only: the recordings that form the validation split instead of training.data.apolloscape.APOLLO_VAL
    # (comma-separated numbers; never a test recording), for the folds of a cross-fitted temperature
    # (train.calibration_folds, training.release.bundle --calibration-fold).
    val_recordings: str = ""
    # Tracker-like augmentation (training.data.augment.tracker_noise): one noisy copy of the training windows per
    # comma-separated sigma (metres of Gaussian noise on the observed positions), each with augment_drop of the
    # observed steps before the current one dropped; "" = none. Validation and test stay as recorded.
    augment_noise: str = ""
    augment_drop: float = 0.1
    # One held copy of the training windows (training.data.augment.held_still): every agent whose observed positions
    # stay within this many metres of its current one given that position at every observed step, as a tracker
    # holding a static object's box gives it; 0 = none.
    augment_hold_m: float = 0.0
    # Whether that copy holds the futures too: every agent whose whole window (history and future) stays within
    # augment_hold_m of one point is held there throughout, as a tracker holding a static object's box holds it on.
    augment_hold_future: bool = False
    # Faster copies of the training windows (function matching: a student distilled on them learns its teacher's
    # outputs for faster agents too): one copy per comma-separated factor s > 1, every recording resampled onto steps s
    # times as long (training.data.datasets.resampled) and read on the model's grid, so that every agent moves s times
    # as fast over the same map; "" = none; ETH/UCY only. Validation and test stay as recorded.
    augment_speed: str = ""


@dataclass(frozen=True)
class TrainConfig:
    epochs: int = 30
    batch_windows: int = 32
    lr: float = 2e-3
    weight_decay: float = 1e-4
    alpha: float = 1.0
    beta: float = 1.0  # weight of the most probable mode's regression (0 = the paper's loss alone)
    anchors_per_class: int = 20
    mirror: bool = True
    seed: int = 0
    threads: int = 2
    max_train_windows: int = 0  # 0 = all; a positive number subsamples (quick tests)
    # Which epoch's weights are kept as best.pt: "val_loss" (the lowest validation loss), "val_ade" (the lowest
    # validation top-1 ADE) or "last" (the end of the one-cycle schedule; for small data where the validation loss
    # rises with the classifier's confidence while the validation errors keep falling).
    select: str = "val_loss"
    # Map dropout: the share of target agents whose map crop is blanked (and flagged absent through map_present)
    # in each training batch. > 0 makes the model's map optional: it serves frames with and without a map.
    map_dropout: float = 0.0
    # Class balance of the loss: each target weighs (its class's share of the training targets)^-class_balance,
    # normalised to a mean of 1 (0: every target alike, the default; 1: every class alike). Validation stays unweighted.
    class_balance: float = 0.0
    # Fit a temperature of the anchor logits on the validation split after training (written into the model).
    calibrate: bool = True
    # The mode the classifier is taught to pick: "closest_anchor" (the paper's: the anchor of the agent's class
    # closest to its future) or "best_mode" (the decoded mode, anchor plus offset, of that class closest to it; what
    # the reliability of the mode probabilities counts). The regression follows the closest anchor either way.
    cls_target: str = "closest_anchor"
    # Where the closest anchor (and the best mode) is sought: "own_class" (the paper's: among the anchors of the
    # agent's class, so p(c) learns the input class) or "all_classes" (among every class's anchors: p(c) learns which
    # class's anchors hold the future, and the mode probabilities count every mode the engine returns).
    anchor_pool: str = "own_class"
    # Cross-fitted temperature (ApolloScape): the validation splits (data.val_recordings values, ";"-separated) of
    # further runs of this configuration whose out-of-fold predictions join the temperature's fit beside the
    # validation split's own (training.release.bundle --calibration-fold; training.calibrate.calibrate_checkpoint).
    calibration_folds: str = ""
    # The validation windows the temperature is fitted on (training.calibrate.calibration_config): "all" (every
    # window of the validation split, data.extra_sources' included) or "own" (the configuration's own dataset's
    # alone): a model trained on every source but served for one protocol's scenes calibrated on those scenes.
    calibration_split: str = "all"
    # The validation windows the kept epoch is chosen on (train.select): "all" (every window of the validation split,
    # data.extra_sources' included) or "own" (the configuration's own dataset's alone; log.csv's val_* then count
    # those alone).
    select_split: str = "all"
    # What is fitted (training.calibrate.CALIBRATIONS): "temperature" (one temperature of the anchor logits, contract
    # 2), "speed_class" (contract 9: a temperature growing with the prior's speed and one of the class logits,
    # fitted together by the Brier score of the best mode), "per_class", "entropy" or "entropy_class" (folded into a
    # single network; the last with contract 9's class temperature).
    calibration: str = "temperature"
    # One anchor of each class held at a zero residual, the kinematic prior itself, so that "nothing to add" is a mode
    # the classifier can pick (training.anchors.kmeans_anchors); the other anchors are k-means around it.
    zero_anchor: bool = False
    # Ensemble distillation: a teacher checkpoint (a consensus of several runs, training.ensemble, or one run) whose
    # most probable mode on each training batch is a second target of the same loss, weighing distill_weight beside
    # the data's (its inputs must be the student's, the same data settings; its own kinematic prior may differ, its
    # modes are then carried onto the student's). "" = no teacher.
    distill: str = ""
    distill_weight: float = 1.0
    # Whether the teacher also teaches on the noisy copies' windows (data.augment_noise). False: on the clean histories
    # alone, where the teacher is good; the noisy copies then learn from the data alone (a teacher trained on clean
    # tracks is no guide to noisy ones).
    distill_noisy: bool = True
    # Whether the teacher's most probable mode also teaches the classifier (its closest anchor or mode as a second
    # class target). False: it only teaches the offsets; the mode probabilities learn from the data alone, so that a
    # hard window, where the teacher's top mode and the truth disagree, does not push probability onto the top mode.
    distill_classifier: bool = True
    # The weight of a second distillation term: the cross-entropy of the student's mode probabilities against the
    # teacher's whole mode distribution (its temperature applied; each teacher mode counted at the student anchor
    # closest to it), so that the student learns how sure the teacher is, not only its top mode. 0 = off.
    distill_soft: float = 0.0
    # The weights a new run starts from: a checkpoint (a run's, or a consensus's first member) whose parameters of
    # the same name and shape are loaded (training.checkpoint.init_weights; a crop model's map CNN into a scene
    # model's, layer by layer); the others keep their initialisation. "" = none. Not read when resuming.
    init: str = ""


#: ``train.calibration_split`` and ``train.select_split``: every window of the validation split ("all",
#: ``data.extra_sources``' included) or the configuration's own dataset's alone ("own").
VALIDATION_SPLITS = ("all", "own")


def validation_data(d: DataConfig, split: str, key: str) -> DataConfig:
    """The data whose validation windows ``split`` (the value of ``key``, one of :data:`VALIDATION_SPLITS`) names:
    ``d`` itself, or ``d`` without its ``data.extra_sources``. Raises a ValueError naming the choices otherwise."""
    if split not in VALIDATION_SPLITS:
        raise ValueError(f"{key} must be 'all' or 'own', got {split!r}")
    return replace(d, extra_sources="") if split == "own" and d.extra_sources else d


@dataclass(frozen=True)
class Config:
    name: str = "ethucy"
    data: DataConfig = field(default_factory=DataConfig)
    model: ModelConfig = field(default_factory=ModelConfig)
    train: TrainConfig = field(default_factory=TrainConfig)

    @classmethod
    def load(cls, path: str | Path, overrides: dict[str, Any] | None = None) -> Config:
        """Reads a TOML file; unknown keys are errors. ``overrides`` maps ``section.key`` to values."""
        raw = tomllib.loads(Path(path).read_text())
        for dotted, value in (overrides or {}).items():
            section, _, key = dotted.partition(".")
            raw.setdefault(section, {})[key] = value
        return cls.from_dict(raw)

    @classmethod
    def from_dict(cls, raw: dict[str, Any]) -> Config:
        sections = {"data": DataConfig, "model": ModelConfig, "train": TrainConfig}
        kwargs: dict[str, Any] = {}
        for key, value in raw.items():
            if key == "name":
                kwargs["name"] = str(value)
                continue
            if key not in sections:
                raise ValueError(f"unknown config section [{key}]; known: name, {', '.join(sections)}")
            dc = sections[key]
            known = {f.name: f.type for f in fields(dc)}
            unknown = set(value) - set(known)
            if unknown:
                raise ValueError(f"unknown keys in [{key}]: {sorted(unknown)}; known: {sorted(known)}")
            defaults = dc()
            typed = {}
            for k, v in value.items():
                want = type(getattr(defaults, k))
                if want is float and isinstance(v, int) and not isinstance(v, bool):
                    v = float(v)
                if not isinstance(v, want):
                    raise ValueError(f"[{key}] {k} must be {want.__name__}, got {v!r}")
                typed[k] = v
            kwargs[key] = replace(defaults, **typed)
        return cls(**kwargs)
