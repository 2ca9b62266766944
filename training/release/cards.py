"""The model cards of bundled models (``python/dgan/models/<name>.md``): provenance, protocol, the measured figures
beside constant velocity, the licence of the data."""

from __future__ import annotations

import csv
import json
from pathlib import Path
from typing import Any

import dgan
from training.build import class_priors
from training.calibrate import FOLDED
from training.data.splits import augment_speeds, pedestrian_sources
from training.modules.dgan import ModelConfig


def training_log(run: Path) -> tuple[list[dict[str, str]], float, dict[str, str]]:
    """A run's epoch rows, its total training seconds and the row of the kept weights (``train.select``)."""
    rows = list(csv.DictReader((run / "log.csv").open()))
    cfg = json.loads((run / "config.json").read_text())["config"]
    select = cfg["train"].get("select", "val_loss")
    kept = rows[-1] if select == "last" else min(rows, key=lambda r: float(r[select]))
    return rows, sum(float(r["seconds"]) for r in rows), kept


#: How a run's kept epoch was chosen (``train.select``), for the cards.
KEPT = {"last": "the last", "val_loss": "lowest validation loss", "val_ade": "lowest validation top-1 ADE"}


def threads_of(cfg: dict[str, Any]) -> str:
    """The CPU threads a run trained on (its ``train.threads``)."""
    n = int(cfg["train"].get("threads", 2))
    return f"{n} CPU thread{'s' if n != 1 else ''}"


def cv_row(metrics: dict[str, Any]) -> str:
    """The card's constant-velocity row: the better of the two variants on the same targets."""
    return (
        f"| constant velocity ({metrics['cv_variant']}) | {metrics['cv_ade']:.3f} | {metrics['cv_fde']:.3f} | | | | | |"
    )


#: The columns of an ETH/UCY card's test metrics, in order.
CARD_METRICS = ("ade", "fde", "min_ade5", "min_fde5", "min_ade20", "min_fde20", "brier_min_fde20")


def dgan_row(metrics: dict[str, Any], label: str = "DGAN") -> str:
    """An ETH/UCY card's table row of ``metrics`` (:data:`CARD_METRICS`), without a line break."""
    return f"| {label} | " + " | ".join(f"{metrics[k]:.3f}" for k in CARD_METRICS) + " |"


def nomap_row(metrics: dict[str, Any]) -> str:
    """The card's row of the same model on the same frames without their map, if it was measured."""
    n = metrics.get("without_map")
    return dgan_row(n, "DGAN without the map") + "\n" if n else ""


def estimate(fit: str, window: float, standing: float) -> str:
    """How a prior's velocity is estimated, in words."""
    how = "the velocity of the last two steps"
    if window:
        how = {
            "least_squares": f"the slope of a least-squares line through the last {window:g} s",
            "quadratic": f"the slope at t_obs of a least-squares parabola through the last {window:g} s",
            "adaptive": f"a least-squares line through as much of the last {window:g} s as the track's noise calls for",
        }.get(fit, f"the mean velocity over the last {window:g} s")
    if standing:
        how += f", standing below {standing:g} m/s"
    return how


def contract_line(cfg: dict[str, Any], metrics: dict[str, Any]) -> str:
    """What the model declares under contract 2: its prior, its optional map and its temperature."""
    d, t = cfg["data"], cfg["train"]
    prior = d.get("prior", "none")
    parts = []
    if prior != "none":
        how = estimate(d.get("prior_fit", "endpoints"), d.get("prior_window_s", 0.0), d.get("prior_standing_mps", 0.0))
        own = class_priors(d.get("prior_by_class", ""))
        for name, c in own.items():
            how += f"; for {name}s {estimate(c.fit, c.window_s, c.standing_mps)}"
        parts.append(f"The network refines a constant-velocity rollout ({how}) computed by the engine.")
    if d.get("augment_noise"):
        parts.append(
            f"Trained also on tracker-like copies of its windows (position noise of "
            f"{' and '.join(x.strip() for x in d['augment_noise'].split(','))} m, "
            f"{100 * d.get('augment_drop', 0.1):g}% of the observed steps dropped)."
        )
    if (hold := d.get("augment_hold_m", 0.0)) > 0:
        whole = "history and future" if d.get("augment_hold_future") else "its history"
        parts.append(
            f"Trained also on a held copy of its windows: each agent that stays within {hold:g} m of one point held "
            f"there over {whole}, as a tracker holding a static object's box."
        )
    if speeds := augment_speeds(str(d.get("augment_speed", ""))):
        parts.append(
            f"Trained also on faster copies of its windows (every agent {' and '.join(f'{x:g}' for x in speeds)} "
            "times as fast over the same map, `data.augment_speed`), on which its teacher taught it too."
        )
    if t.get("map_dropout", 0.0) > 0 and d.get("use_map", True) and cfg["model"].get("use_map", True):
        parts.append(
            f"Trained with map dropout ({t['map_dropout']:g} of the crops blanked), so it also runs without a map "
            "(`map.optional`)."
        )
    if (heading := d.get("heading", "measured")) != "measured":
        parts.append(
            "Agents' headings come from their direction of motion"
            + (" (measured headings below 1 m/s)." if heading == "motion_when_moving" else ", measured ones ignored.")
        )
    if classes := cfg["model"].get("map_classes", ""):
        who = classes.replace(",", " and ")
        parts.append(f"Only its {who} agents read the map (`map.classes`: the engine draws their crops alone).")
    if words := denoise_words(cfg):
        parts.append(words)
    folded = FOLDED.get(t.get("calibration", ""))
    words = f"{folded}, folded into the anchor logits," if folded else temperature_words(metrics)
    parts.append(f"Mode probabilities at {words} {fitted_where(cfg)}.")
    return " ".join(parts)


def denoise_words(cfg: dict[str, Any]) -> str:
    """The card's sentence on a declared denoising gate (contract 10), or "" without one."""
    gate = float(cfg["data"].get("denoise_gate_m", 0.0))
    if not gate:
        return ""
    return (
        f"The engine first smooths histories that lie off their least-squares parabola by {gate:g} m or more (RMS) "
        "onto it (contract 10, `denoise_gate_m`; chosen on validation for noisy trackers, `docs/results.md`)."
    )


def restated(text: str, metrics: dict[str, Any], cfg: dict[str, Any]) -> str:
    """An ETH/UCY card (:func:`card`) with its test metrics replaced by ``metrics`` and its denoising sentence as
    ``cfg`` declares it: for a bundled model exported again with new inference-time keys."""
    header = f"- **Test metrics** (engine, world metres, {metrics['windows']} windows, {metrics['agents']} agents):"
    lines = []
    for line in text.splitlines():
        if line.startswith("- **Test metrics** (engine, world metres"):
            line = header
        elif line.startswith("| DGAN |"):
            line = dgan_row(metrics)
        elif line.startswith("| DGAN without the map |"):
            line = nomap_row(metrics).rstrip("\n")
        elif line.startswith("| constant velocity ("):
            line = cv_row(metrics)
        lines.append(line)
    out = "\n".join(lines) + "\n"
    words = denoise_words(cfg)
    if words and words not in out:
        out = out.replace(" Mode probabilities at ", f" {words} Mode probabilities at ", 1)
    return out


def temperature_words(metrics: dict[str, Any]) -> str:
    """The model's temperatures in the card's words: a single one, or contract 9's speed-dependent anchor temperature
    with its class temperature (``training.evaluate.evaluate`` records them)."""
    words = f"the temperature {metrics.get('temperature', 1.0):.2f}"
    if "temperature_speed_exponent" in metrics:
        words += (
            f" × (1 + speed in m/s)^{metrics['temperature_speed_exponent']:.2f} with a class temperature of "
            f"{metrics['class_temperature']:.2f} (contract 9: the speed-dependent and class temperatures, "
            '`train.calibration = "speed_class"`),'
        )
    return words


def calibration_folds(declared: str) -> list[str]:
    """The validation splits of the further runs a cross-fitted temperature is fitted with, from their
    ``train.calibration_folds`` declaration, each as ``data.val_recordings`` names it."""
    return [f for f in declared.split(";") if f]


def declared_folds(cfg: dict[str, Any]) -> list[str]:
    """:func:`calibration_folds` of a run's configuration (its ``config.json``)."""
    return calibration_folds(str(cfg["train"].get("calibration_folds", "")))


def fitted_where(cfg: dict[str, Any], whom: str = "") -> str:
    """Where the model's temperature was fitted, in the card's words (``whom``: " for the consensus", say)."""
    folds = declared_folds(cfg)
    if not folds:
        own = cfg["data"].get("extra_sources") and cfg["train"].get("calibration_split", "all") == "own"
        alone = " scenes alone, not the other sources' (`train.calibration_split`)" if own else ""
        return f"fitted{whom} on validation{alone}"
    return (
        f"cross-fitted{whom} on {len(folds) + 1} validation folds (its validation split and {len(folds)} more, each "
        "held out in turn by runs of this configuration: `train.calibration_folds`)"
    )


def _with_sdd(cfg: dict[str, Any]) -> bool:
    """Whether the run also trained on Stanford Drone's pedestrians (``data.extra_pedestrians``)."""
    return "sdd" in pedestrian_sources(str(cfg["data"].get("extra_pedestrians", "")))


def extra_data_line(cfg: dict[str, Any]) -> str:
    """The card's words on other sources' pedestrians in training (``data.extra_pedestrians``), if any."""
    if not _with_sdd(cfg):
        return ""
    stride = cfg["data"].get("extra_stride", 3)
    anchors = "" if cfg["data"].get("extra_in_anchors", True) else " The anchors are fitted on ETH/UCY's windows alone."
    return (
        "\n  Also trained on the pedestrians of Stanford Drone's 30 training videos (none of its test videos), "
        f"resampled to 0.4 s, in metres, without a map, in windows ending at steps divisible by {stride} "
        f"(`data.extra_pedestrians`).{anchors}"
    )


def classification_words(cfg: dict[str, Any]) -> str:
    """The card's words on what the classifier is taught (``train.cls_target``)."""
    if cfg["train"].get("cls_target", "closest_anchor") == "best_mode":
        return "hierarchical classification of the decoded mode closest to the future (`train.cls_target`)"
    return "the paper's hierarchical classification"


def extra_licence_line(cfg: dict[str, Any]) -> str:
    """The card's licence words for other sources' pedestrians in training, if any."""
    if not _with_sdd(cfg):
        return ""
    return "\n  Stanford Drone Dataset: **CC BY-NC-SA 3.0**, non-commercial. Cite Robicquet et al. 2016."


def card(name: str, run: Path, metrics: dict[str, Any], cfg: dict[str, Any]) -> str:
    rows, seconds, best = training_log(run)
    kept, distilled = KEPT[cfg["train"].get("select", "val_loss")], distill_words(name, cfg)
    scene = cfg["data"]["scene"]
    others = ", ".join(s for s in ("eth", "hotel", "univ", "zara1", "zara2") if s != scene)
    m = cfg["model"]
    return f"""# Model card: `{name}`

DGAN (Dong et al. 2020) for pedestrians, trained leave-one-scene-out on ETH/UCY: **test scene {scene}**, never seen in
training.

- **Data**: ETH/UCY in the Social-GAN layout (metres, 0.4 s steps). Trained on the train split of {others}; the best
  epoch chosen on their val split. Each scene's semantic mask, colourised (`dgan.scenes.MASK_PALETTE`), is the raster
  map: {map_words(cfg)}. Use it on new frames of a scene with `dgan.scene_map("{scene}")`.{extra_data_line(cfg)}
- **Protocol**: 8 observed steps (3.2 s), 12 predicted (4.8 s); every start frame; all agents seen at t_obs are in the
  graph; targets are the agents present at all 20 steps, in windows with at least two of them.
- **Model**: LSTM({m["lstm_dim"]}) over MLP-embedded positions, traffic-state MLP, map CNN (ResNet-style, width
  {m["map_channels"]}{scene_words(cfg)}),
  {m["gat_layers"]} GAT layers × {m["gat_heads"]} heads over the attention-zone graph (λ = 0.5)
  with neighbour geometry on the edges, {cfg["train"]["anchors_per_class"]} k-means anchors with offset regression.
  Loss: {classification_words(cfg)} and closest-anchor regression (α = {cfg["train"]["alpha"]}), plus
  β = {cfg["train"]["beta"]} times the error of the most probable mode (see `docs/results.md`).
  One class (pedestrian). {contract_line(cfg, metrics)}
- **Training**: {len(rows)} epochs, weights of epoch {best["epoch"]} ({kept}), {seconds / 60:.1f} min on
  {threads_of(cfg)}; seed {cfg["train"]["seed"]}; left-right mirroring.{distilled}
- **Test metrics** (engine, world metres, {metrics["windows"]} windows, {metrics["agents"]} agents):

| | top-1 ADE | top-1 FDE | minADE5 | minFDE5 | minADE20 | minFDE20 | Brier-minFDE20 |
|---|---|---|---|---|---|---|---|
{dgan_row(metrics)}
{nomap_row(metrics)}{cv_row(metrics)}

- **Licence**: the weights are derived from ETH (BIWI) and UCY data, which are for **non-commercial research use
  only**. Cite Pellegrini et al. 2009 and Lerner et al. 2007.{extra_licence_line(cfg)}
- **Reproduce**: `python -m training.results --train` (all five folds) or
  `python -m training.train --config training/configs/ethucy_{scene}.toml --out runs/ethucy_{scene}`.
"""


def map_words(cfg: dict[str, Any]) -> str:
    """The card's words for the map's geometry: each agent's crop, or the scene raster it reads (contract 12)."""
    d = cfg["data"]
    crop = f"{d['map_height_px']}×{d['map_width_px']} px crops at {d['map_resolution_m']} m/px,\n  heading-aligned"
    if cfg.get("model", {}).get("map_mode", "crop") != "scene":
        return crop
    if d.get("map_scene_tile_px", 0):
        return (
            f"the scene at {d['map_resolution_m']} m/px without the agents' boxes, its features kept with the map in "
            f"north-up tiles of {d['map_scene_tile_px']} px (contract 13; {d['map_scene_px']} px rasters in\n  "
            f"training), each agent reading them over its {d['map_height_px']}×{d['map_width_px']} px heading-aligned "
            "crop"
        )
    return (
        f"one north-up raster of the scene at {d['map_resolution_m']} m/px for each group of agents whose crops meet "
        f"({d['map_scene_px']} px a side in\n  training), each agent reading it over its "
        f"{d['map_height_px']}×{d['map_width_px']} px heading-aligned crop"
    )


def scene_words(cfg: dict[str, Any]) -> str:
    """The map CNN's reading of a scene model (``model.map_mode = "scene"``, contract 12); "" for a crop model."""
    if cfg.get("model", {}).get("map_mode", "crop") != "scene":
        return ""
    if cfg["data"].get("map_scene_tile_px", 0):
        return (
            ", its first stages run once per map over tiles of the scene, kept for every later call, each agent "
            "reading their features at its crop's 4 × 4 blocks: a call pays only for the reading"
        )
    return (
        ", its first stages run once per frame over the scene's raster, each agent reading their features at its "
        "crop's 4 × 4 blocks: the map's cost does not grow with the agents"
    )


def distill_words(name: str, cfg: dict[str, Any]) -> str:
    """The card's words for a student (``train.distill``): one network that learned from a consensus."""
    if not cfg["train"].get("distill", ""):
        return ""
    wide, blocks = ModelConfig.head_dim, ModelConfig.map_res_blocks  # the configuration's defaults: the teachers'
    head = int(cfg.get("model", {}).get("head_dim", wide))
    teacher = "a consensus of runs"
    if head != wide:
        teacher += f" whose heads' layers are {wide} wide (this one's {head})"
    if cfg.get("model", {}).get("map_res_blocks", blocks) < blocks:
        teacher = "a larger network (the same configuration with the map CNN's two residual blocks)"
    kept = Path(cfg["train"]["distill"]).name
    if kept.endswith("_crop.pt"):  # a second stage (training.release.retrain.KEPT_STAGE)
        teacher, name = "the crop model it replaced (itself a student; its crops carry the agents' boxes)", kept[:-3]
    soft = float(cfg["train"].get("distill_soft", 0.0))
    also = f" and its mode probabilities (weight {soft:g})" if soft > 0 else ""
    if not cfg["train"].get("distill_classifier", True):
        alone = "" if soft > 0 else ": the mode probabilities learned from the data alone"
        also = f" (its offsets only{alone}){also}"
    return (
        f"\n  **Distilled**: one network that also learned the most probable mode{also} of {teacher} "
        f"(`training/checkpoints/teachers/{name}.pt`, weight {cfg['train']['distill_weight']:g}), "
        "at one network's cost."
    )


def ensemble_line(
    runs: list[Path], predictor: dgan.Predictor, cfg: dict[str, Any], scale: list[float] | None = None
) -> str:
    """The card's line for a model that is the consensus of several runs, or one run kept as one with a top-mode
    scale (``scale``: its top-mode scales)."""
    seeds = [json.loads((r / "config.json").read_text())["config"]["train"]["seed"] for r in runs]
    scaled = [f"{c} {s:g}" for c, s in zip(predictor.classes, scale or [], strict=False) if s != 1.0]
    scale_words = (
        f" The most probable mode keeps this share of its refinement of the prior, fitted on validation "
        f"(`training.ensemble.fit_top_scale`): {', '.join(scaled)}; every other class keeps all of it."
        if scaled
        else ""
    )
    if len(runs) == 1:
        return (
            f"- **Top-mode scale**: one network (seed {seeds[0]}), its weights stored as float16; its checkpoint is a "
            f"consensus of one (`training.ensemble`), exported as the network alone with the scale in its contract "
            f"(contract 14: the engine's decoding applies it).{scale_words}\n"
        )
    return (
        f"- **Ensemble**: the consensus of {len(runs)} runs of this configuration, seeds "
        f"{', '.join(map(str, seeds))} (`training.ensemble`): its most probable mode (of the agent's most probable "
        f"class) is the mean of the runs' most probable modes, its other modes are seed {seeds[0]}'s. Weights "
        f"stored as float16; temperature {float(predictor.contract.get('temperature', 1.0)):.3f}, "
        f"{fitted_where(cfg, ' for the consensus')}. The training line above is seed {seeds[0]}'s run. A prediction "
        f"runs all {len(runs)} networks.{scale_words}\n"
    )
