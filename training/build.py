"""What a configuration builds: the model's input specification (the engine's :class:`dgan.InputSpec`), its run
name and the untrained network."""

from __future__ import annotations

import dgan
from training.config import Config
from training.data.datasets import DATASETS
from training.modules.dgan import DGAN
from training.modules.scene import SCENE_MIN_PX, SCENE_STRIDE, scene_halo_px


def input_spec(cfg: Config) -> dgan.InputSpec:
    d = cfg.data
    if d.dataset not in DATASETS:
        raise ValueError(f"unknown data.dataset {d.dataset!r}; known: {', '.join(DATASETS)}")
    info = DATASETS[d.dataset]
    map_spec = None
    if d.use_map and cfg.model.use_map and info.has_map:
        map_spec = dgan.MapSpec(
            d.map_height_px,
            d.map_width_px,
            d.map_resolution_m,
            d.map_agent_row,
            d.map_width_px // 2,
            draw_agents=d.map_draw_agents,
            optional=cfg.train.map_dropout > 0,
            render=d.map_render,
            classes=tuple(x.strip() for x in cfg.model.map_classes.split(",") if x.strip()),
            scene=scene_spec(cfg) if cfg.model.map_mode == "scene" else None,
        )
    return dgan.InputSpec(
        dt_s=info.dt_s,
        t_obs=info.t_obs,
        t_f=info.t_f,
        classes=info.classes,
        attention_lambda=0.5,
        map=map_spec,
        prior=dgan.PriorSpec(
            d.prior, d.prior_window_s, d.prior_fit, d.prior_standing_mps, class_priors(d.prior_by_class)
        ),
        heading=d.heading,
        denoise_gate_m=d.denoise_gate_m,
    )


def scene_spec(cfg: Config) -> dgan.SceneSpec:
    """A scene model's :class:`dgan.SceneSpec`: its features kept with the map in tiles of ``data.map_scene_tile_px``
    (contract 13; a halo of the scene CNN's reach, its channels) or, with 0, rasters per call (contract 12)."""
    tile = cfg.data.map_scene_tile_px
    if not tile:
        return dgan.SceneSpec(SCENE_MIN_PX, SCENE_STRIDE)
    halo = scene_halo_px(cfg.model.map_res_blocks)
    return dgan.SceneSpec(SCENE_MIN_PX, SCENE_STRIDE, tile, halo, 2 * cfg.model.map_channels)


def class_priors(declared: str) -> dict[str, dgan.ClassPrior]:
    """``data.prior_by_class`` (comma-separated ``class=fit:window_s:standing_mps``) as the prior's ``by_class``."""
    out: dict[str, dgan.ClassPrior] = {}
    for item in (s.strip() for s in declared.split(",")):
        if not item:
            continue
        name, _, how = item.partition("=")
        parts = how.split(":")
        try:
            fit, window, standing = parts[0].strip(), float(parts[1]), float(parts[2])
        except (IndexError, ValueError):
            raise ValueError(
                f"data.prior_by_class: {item!r} is not class=fit:window_s:standing_mps "
                "(e.g. pedestrian=least_squares:2:0.3)"
            ) from None
        if len(parts) != 3 or name.strip() in out:
            raise ValueError(f"data.prior_by_class: {item!r} has extra fields or repeats its class")
        out[name.strip()] = dgan.ClassPrior(window, fit, standing)
    return out


def run_name(cfg: Config) -> str:
    """``ethucy-zara1``, ``sdd``, ``sdd-pedestrian``, ``hdmap-nomap`` ..."""
    parts = [cfg.data.dataset] + ([cfg.data.scene] if cfg.data.dataset == "ethucy" else [])
    if input_spec(cfg).map is None and DATASETS[cfg.data.dataset].has_map:
        parts.append("nomap")
    return "-".join(parts + ([cfg.data.target_class] if cfg.data.target_class else []))


def build_model(cfg: Config, spec: dgan.InputSpec, num_anchors: int) -> DGAN:
    if (cfg.model.map_mode == "scene") != (cfg.data.map_scene_px > 0):
        raise ValueError(
            'model.map_mode = "scene" and data.map_scene_px > 0 go together (the scene CNN reads the windows\' scene'
            f" rasters); got {cfg.model.map_mode!r} and {cfg.data.map_scene_px}"
        )
    hw = (spec.map.height_px, spec.map.width_px) if spec.map else None
    optional = spec.map is not None and spec.map.optional
    gate = map_gate(cfg.model.map_classes, spec)
    model = DGAN(cfg.model, spec.t_obs, spec.t_f, spec.state_dim, len(spec.classes), num_anchors, hw, optional, gate)
    scene = spec.map.scene if spec.map is not None else None
    if scene is not None and scene.tile_px:
        model.kept_tiles = (scene.tile_px, scene.halo_px)
    return model


def map_gate(declared: str, spec: dgan.InputSpec) -> list[float] | None:
    """``model.map_classes`` (comma-separated class names; "" = every class) as 1 or 0 per class of ``spec``."""
    names = [x.strip() for x in declared.split(",") if x.strip()]
    if not names:
        return None
    if unknown := [x for x in names if x not in spec.classes]:
        raise ValueError(f"model.map_classes names {unknown}, not classes of this model ({', '.join(spec.classes)})")
    return [1.0 if c in names else 0.0 for c in spec.classes]
