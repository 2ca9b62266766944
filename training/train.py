"""Train DGAN on a dataset: an ETH/UCY leave-one-scene-out fold, Stanford Drone or ApolloScape.

    python -m training.train --config training/configs/ethucy_zara1.toml --out runs/zara1
    python -m training.train --config training/configs/sdd.toml --out runs/sdd
    torchrun --nproc_per_node 2 -m training.train --config ... --out ...   # DDP on CPU (gloo)

Writes ``<out>/config.json``, ``log.csv`` (one row per epoch), ``last.pt`` and ``best.pt`` (by validation loss).
``--resume`` continues from ``last.pt``. The best checkpoint is exported to ``<out>/model.onnx`` under the model
contract at the end.
"""

from __future__ import annotations

import argparse
import csv
import json
import os
import random
import sys
import time
from dataclasses import asdict, dataclass
from pathlib import Path
from typing import Any

import numpy as np
import torch
import torch.distributed as dist

import dgan
from training.anchors import kmeans_anchors
from training.config import Config
from training.data import Windows, cached_pedestrian_windows, cached_windows, concat_windows
from training.datasets import DATASETS, pedestrian_sources
from training.loss import check_anchor_pool, check_cls_target, class_weights, decode_torch, dgan_loss
from training.model import DGAN

#: ``train.select``: the validation figure (a column of ``log.csv``) whose lowest epoch is kept as ``best.pt``, or
#: ``"last"`` for the final epoch.
SELECT = ("val_loss", "val_ade", "last")


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
            optional=cfg.train.map_dropout > 0,
        )
    return dgan.InputSpec(
        dt_s=info.dt_s,
        t_obs=info.t_obs,
        t_f=info.t_f,
        classes=info.classes,
        attention_lambda=0.5,
        map=map_spec,
        prior=dgan.PriorSpec(d.prior, d.prior_window_s, d.prior_fit, d.prior_standing_mps),
        heading=d.heading,
    )


def run_name(cfg: Config) -> str:
    """``ethucy-zara1``, ``sdd``, ``sdd-pedestrian``, ``hdmap-nomap`` ..."""
    parts = [cfg.data.dataset] + ([cfg.data.scene] if cfg.data.dataset == "ethucy" else [])
    if input_spec(cfg).map is None and DATASETS[cfg.data.dataset].has_map:
        parts.append("nomap")
    return "-".join(parts + ([cfg.data.target_class] if cfg.data.target_class else []))


def load_windows(cfg: Config, spec: dgan.InputSpec, split: str, progress: bool) -> Windows:
    """A split's cached windows; for training, with the pedestrians of ``data.extra_pedestrians`` (ETH/UCY only)."""
    return concat_windows(load_window_parts(cfg, spec, split, progress))


def load_window_parts(cfg: Config, spec: dgan.InputSpec, split: str, progress: bool) -> list[Windows]:
    """A split's cached windows of the dataset itself, then (for training) those of each ``data.extra_pedestrians``
    source."""
    d = cfg.data
    fold = {"ethucy": d.scene, "apolloscape": d.val_recordings}.get(d.dataset, "")
    if d.val_recordings and d.dataset != "apolloscape":
        raise ValueError(f"data.val_recordings is for ApolloScape, not {d.dataset!r}")
    cache, root = Path(d.cache_dir).expanduser(), Path(d.root).expanduser()
    sources = pedestrian_sources(d.extra_pedestrians)
    if sources and d.dataset != "ethucy":
        raise ValueError(f"data.extra_pedestrians is for the ETH/UCY models, not {d.dataset!r}")
    own = cached_windows(d.dataset, root, split, spec, cache, fold, d.window_stride, progress)
    if split != "train":
        return [own]
    noisy = [
        cached_windows(d.dataset, root, split, spec, cache, fold, d.window_stride, progress, (sigma, d.augment_drop))
        for sigma in augment_sigmas(d.augment_noise)
    ]
    extra = [cached_pedestrian_windows(s, root, spec, cache, d.extra_stride, progress) for s in sources]
    return [own, *noisy, *extra]


def augment_sigmas(declared: str) -> list[float]:
    """The noise levels of ``data.augment_noise`` (comma-separated metres; "" = none)."""
    try:
        sigmas = [float(x) for x in declared.split(",") if x.strip()]
    except ValueError:
        raise ValueError(f"data.augment_noise must be comma-separated metres, got {declared!r}") from None
    if any(not (0.0 < x <= 5.0) for x in sigmas):
        raise ValueError(f"data.augment_noise must hold noise levels in (0, 5] metres, got {declared!r}")
    return sigmas


def restrict_targets(w: Windows, spec: dgan.InputSpec, target_class: str) -> None:
    """For a per-class run: only that class's agents stay targets (the others remain neighbours)."""
    if target_class not in spec.classes:
        raise ValueError(f"data.target_class {target_class!r} is not among the classes {spec.classes}")
    w.target &= w.class_index == list(spec.classes).index(target_class)


def windows_with_targets(w: Windows) -> np.ndarray:
    """Indices of the windows that hold at least one target."""
    counts = np.add.reduceat(w.target.astype(np.int64), w.agent_ptr[:-1]) if len(w.target) else np.zeros(0)
    empty = w.agent_ptr[1:] == w.agent_ptr[:-1]  # reduceat repeats the next value for empty slices
    return np.flatnonzero((counts > 0) & ~empty)


def to_tensors(batch: dict[str, Any]) -> dict[str, torch.Tensor]:
    return {k: torch.from_numpy(np.ascontiguousarray(v)) for k, v in batch.items()}


#: The contract's network inputs, in the order of ``DGAN.forward``.
INPUTS = ("trajectory", "trajectory_mask", "state", "edge_index", "edge_features", "map", "map_present")


def forward_inputs(b: dict[str, Any]) -> list[Any]:
    """The network inputs present in a batch, in ``DGAN.forward``'s order."""
    return [b[k] for k in INPUTS if k in b]


def prepared_batch(
    w: Windows,
    idx: np.ndarray,
    spec: dgan.InputSpec,
    flip: np.ndarray | None = None,
    drop: float = 0.0,
    rng: np.random.Generator | None = None,
) -> dict[str, torch.Tensor]:
    """Windows ``idx`` as one graph with the engine's kinematic prior (``prior``, after mirroring) and, for a model
    whose map is optional, ``map_present``: 1, or 0 for the share ``drop`` of agents whose crop is blanked (drawn
    from ``rng``, the trainer's seeded generator)."""
    b = w.batch(idx, flip)
    b["prior"] = dgan.kinematic_prior(b["trajectory"], b["trajectory_mask"], b["state"], spec)
    if spec.map is not None and spec.map.optional:
        present = np.ones(len(b["state"]), dtype=np.float32)
        if drop > 0:
            if rng is None:
                raise ValueError("map dropout needs the trainer's random generator (rng)")
            gone = rng.random(len(present)) < drop
            present[gone] = 0.0
            b["map"][gone] = 0.0
        b["map_present"] = present
    return to_tensors(b)


def build_model(cfg: Config, spec: dgan.InputSpec, num_anchors: int) -> DGAN:
    hw = (spec.map.height_px, spec.map.width_px) if spec.map else None
    optional = spec.map is not None and spec.map.optional
    return DGAN(cfg.model, spec.t_obs, spec.t_f, spec.state_dim, len(spec.classes), num_anchors, hw, optional)


def anchor_windows(cfg: Config, parts: list[Windows], train: Windows) -> Windows:
    """The training windows whose futures the anchors are fitted on: all of ``train`` (the concatenation of
    ``parts``), or with ``data.extra_in_anchors`` false the dataset's own windows ``parts[0]`` alone."""
    return train if cfg.data.extra_in_anchors else parts[0]


def residual_futures(w: Windows, spec: dgan.InputSpec) -> np.ndarray:
    """``(A, T_f, 2)`` every agent's future minus its kinematic prior (agent frame): what the anchors model."""
    prior = dgan.kinematic_prior(w.trajectory, w.trajectory_mask, w.state, spec)
    out: np.ndarray = w.future - prior
    return out


def fit_anchors(cfg: Config, train: Windows, spec: dgan.InputSpec, num_classes: int) -> tuple[np.ndarray, np.ndarray]:
    """K_c k-means anchors of the residuals from the prior for every class (from all of its targets, also in a
    per-class run, so that the model contract holds) and the class of each anchor."""
    out = []
    residual = residual_futures(train, spec)
    for c in range(num_classes):
        fut = residual[train.target & (train.class_index == c)]
        if cfg.train.mirror:
            flipped = fut.copy()
            flipped[..., 1] *= -1
            fut = np.concatenate([fut, flipped])
        k, seed = cfg.train.anchors_per_class, cfg.train.seed
        out.append(kmeans_anchors(fut, k, seed, cfg.train.zero_anchor).astype(np.float32))
    class_of = np.repeat(np.arange(num_classes), cfg.train.anchors_per_class)
    return np.concatenate(out), class_of


@dataclass(frozen=True)
class Teacher:
    """A trained model whose most probable mode is a second target of the student's loss (``train.distill``)."""

    model: torch.nn.Module
    anchors: torch.Tensor
    class_of: torch.Tensor
    temperature: float

    @classmethod
    def load(cls, path: str, spec: dgan.InputSpec) -> Teacher:
        from training.export import load_checkpoint

        model, tspec, anchors, class_of, _, temperature = load_checkpoint(Path(path))
        if tspec.to_json() != spec.to_json():
            raise ValueError(f"train.distill: {path} takes other inputs than this configuration ({tspec.to_json()})")
        return cls(model.eval(), torch.from_numpy(anchors).float(), torch.from_numpy(class_of).long(), temperature)

    @torch.no_grad()
    def top_residual(self, b: dict[str, torch.Tensor]) -> torch.Tensor:
        """``(targets, T_f, 2)`` the teacher's most probable mode of each target, as a residual from the prior."""
        cl, al, off = self.model(*forward_inputs(b))
        t = b["target"]
        modes, _ = decode_torch(cl[t], al[t], off[t], self.anchors, self.class_of, None, self.temperature)
        return modes[:, 0]


def forward_loss(
    net: torch.nn.Module,
    b: dict[str, torch.Tensor],
    anchors: torch.Tensor,
    class_of: torch.Tensor,
    cfg: Config,
    weight_of_class: torch.Tensor | None = None,
    teacher: Teacher | None = None,
) -> tuple[torch.Tensor, dict[str, float], tuple[torch.Tensor, torch.Tensor, torch.Tensor]]:
    """The network on a batch and the loss over its target agents (on their residuals from the kinematic prior),
    each weighted by its class's ``weight_of_class`` if given (``train.class_balance``); also the targets' outputs.
    With a ``teacher``, the same loss towards its most probable mode is added, weighing ``train.distill_weight``."""
    cl, al, off = net(*forward_inputs(b))
    t = b["target"]
    outs = (cl[t], al[t], off[t])
    residual = b["future"][t] - b["prior"][t]
    classes = b["class_index"][t]
    weights = None if weight_of_class is None else weight_of_class[classes]
    tr = cfg.train

    def loss_to(target: torch.Tensor) -> tuple[torch.Tensor, dict[str, float]]:
        return dgan_loss(
            *outs, target, classes, anchors, class_of, tr.alpha, tr.beta, weights, tr.cls_target, tr.anchor_pool
        )

    loss, parts = loss_to(residual)
    if teacher is not None:
        distilled, _ = loss_to(teacher.top_residual(b))
        loss = loss + tr.distill_weight * distilled
    return loss, parts, outs


@torch.no_grad()
def validate(
    model: DGAN, w: Windows, spec: dgan.InputSpec, anchors: torch.Tensor, class_of: torch.Tensor, cfg: Config
) -> dict[str, float]:
    model.eval()
    losses, ade1, fde1, ade20, fde20, n = [], [], [], [], [], 0
    keep = windows_with_targets(w)
    for start in range(0, len(keep), 64):
        b = prepared_batch(w, keep[start : start + 64], spec)
        t = b["target"]
        loss, _, (cl, al, off) = forward_loss(model, b, anchors, class_of, cfg)
        traj, _ = decode_torch(cl, al, off, anchors, class_of, b["prior"][t])
        d = torch.linalg.norm(traj - b["future"][t].unsqueeze(1), dim=-1)  # (n, K, T)
        losses.append(float(loss) * int(t.sum()))
        ade1.append(d[:, 0].mean(-1).sum())
        fde1.append(d[:, 0, -1].sum())
        ade20.append(d[:, :20].mean(-1).min(1).values.sum())
        fde20.append(d[:, :20, -1].min(1).values.sum())
        n += int(t.sum())
    model.train()
    return {
        "val_loss": sum(losses) / n,
        "val_ade": float(sum(ade1)) / n,
        "val_fde": float(sum(fde1)) / n,
        "val_min_ade20": float(sum(ade20)) / n,
        "val_min_fde20": float(sum(fde20)) / n,
    }


def calibrate(
    path: Path, model: DGAN, val: Windows, spec: dgan.InputSpec, anchors: torch.Tensor, class_of: torch.Tensor
) -> float:
    """Fits the temperature of the kept weights' anchor logits on the validation split; stores it in ``path``."""
    from training.calibrate import fit_temperature

    ckpt = torch.load(path, weights_only=False)
    model.load_state_dict(ckpt["model"])
    found = fit_temperature(model, val, spec, anchors, class_of)
    ckpt["temperature"] = found.temperature
    save_atomic(ckpt, path)
    print(found, flush=True)
    return found.temperature


def parse_args(argv: list[str] | None = None) -> tuple[argparse.Namespace, Config]:
    """The command line and the configuration it names, with its ``--set`` overrides (JSON values, else strings)."""
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--config", required=True)
    ap.add_argument("--out", required=True)
    ap.add_argument("--resume", action="store_true")
    ap.add_argument("--set", action="append", default=[], metavar="SECTION.KEY=VALUE", help="override a config value")
    ap.add_argument("--no-export", action="store_true")
    ap.add_argument(
        "--stop-after", type=int, default=0, metavar="EPOCH", help="stop after this epoch (as if preempted)"
    )
    args = ap.parse_args(argv)
    overrides: dict[str, Any] = {}
    for item in args.set:
        key, _, value = item.partition("=")
        try:
            overrides[key] = json.loads(value)
        except json.JSONDecodeError:
            overrides[key] = value
    cfg = Config.load(args.config, overrides)
    if cfg.train.select not in SELECT:
        raise ValueError(f"train.select must be 'val_loss', 'val_ade' or 'last', got {cfg.train.select!r}")
    check_cls_target(cfg.train.cls_target)
    check_anchor_pool(cfg.train.anchor_pool)
    return args, cfg


def optimiser(cfg: Config, model: torch.nn.Module) -> tuple[torch.optim.Optimizer, torch.optim.lr_scheduler.OneCycleLR]:
    """AdamW under a one-cycle schedule over the configured epochs."""
    opt = torch.optim.AdamW(model.parameters(), lr=cfg.train.lr, weight_decay=cfg.train.weight_decay)
    # OneCycleLR divides by pct_start * total - 1, which is 0 at exactly 10 epochs: nudge only that case.
    pct = 0.1 if abs(0.1 * cfg.train.epochs - 1.0) > 1e-9 else 0.15
    sched = torch.optim.lr_scheduler.OneCycleLR(opt, max_lr=cfg.train.lr, total_steps=cfg.train.epochs, pct_start=pct)
    return opt, sched


def save_atomic(state: dict[str, Any], path: Path) -> None:
    """``torch.save`` to a temporary file beside ``path``, then renamed over it: a run stopped while it saves (a
    time limit, a killed job) keeps its previous checkpoint whole, so ``--resume`` still loads. Every rewrite of an
    existing checkpoint goes through it (each epoch's, the temperature's and top-mode scales after training or at
    bundling: :func:`update_checkpoint`)."""
    tmp = path.with_name(path.name + ".tmp")
    torch.save(state, tmp)
    os.replace(tmp, path)


def update_checkpoint(path: Path, **values: Any) -> None:
    """Sets ``values`` (a fitted temperature, top-mode scales) in the checkpoint at ``path``, saved with
    :func:`save_atomic`."""
    ckpt = torch.load(path, weights_only=False)
    ckpt.update(values)
    save_atomic(ckpt, path)


def resume(
    ckpt: dict[str, Any] | None,
    model: torch.nn.Module,
    opt: torch.optim.Optimizer,
    sched: torch.optim.lr_scheduler.OneCycleLR,
) -> tuple[int, float]:
    """Restores a run from its last checkpoint (weights, optimiser, schedule, random state); the epoch to start at
    and the best selection score so far (0 and infinity for a new run)."""
    if ckpt is None:
        return 0, float("inf")
    model.load_state_dict(ckpt["model"])
    opt.load_state_dict(ckpt["optimizer"])
    sched.load_state_dict(ckpt["scheduler"])
    torch.set_rng_state(ckpt["rng"])
    return int(ckpt["epoch"]) + 1, float(ckpt["best"])


def epoch_batches(windows: np.ndarray, cfg: Config, epoch: int, rank: int, world: int) -> list[np.ndarray]:
    """This process's batches of one epoch: the windows shuffled by the epoch's seed, split among the processes, as
    many on every process."""
    order = np.random.default_rng(cfg.train.seed + epoch).permutation(windows)
    batches = [order[i : i + cfg.train.batch_windows] for i in range(0, len(order), cfg.train.batch_windows)]
    batches = batches[rank::world]
    if world > 1:  # equal step counts on every rank
        steps = torch.tensor(len(batches))
        dist.all_reduce(steps, op=dist.ReduceOp.MIN)
        batches = batches[: int(steps)]
    return batches


def train_epoch(
    net: torch.nn.Module,
    opt: torch.optim.Optimizer,
    bar: Any,
    train: Windows,
    spec: dgan.InputSpec,
    anchors: torch.Tensor,
    class_of: torch.Tensor,
    cfg: Config,
    weight_of_class: torch.Tensor | None,
    rng: np.random.Generator,
    teacher: Teacher | None = None,
) -> dict[str, float]:
    """One pass over the batches of training windows that the tqdm ``bar`` iterates (mirrored at random, maps dropped
    at the configured rate); the summed loss and its classification and regression parts."""
    totals = {"loss": 0.0, "cls": 0.0, "reg": 0.0}
    for idx in bar:
        flip = rng.random(len(idx)) < 0.5 if cfg.train.mirror else None
        b = prepared_batch(train, idx, spec, flip, cfg.train.map_dropout, rng)
        loss, parts, _ = forward_loss(net, b, anchors, class_of, cfg, weight_of_class, teacher)
        opt.zero_grad()
        loss.backward()  # type: ignore[no-untyped-call]
        torch.nn.utils.clip_grad_norm_(net.parameters(), 5.0)
        opt.step()
        totals["loss"] += float(loss.detach())
        totals["cls"] += parts["cls"]
        totals["reg"] += parts["reg"]
        bar.set_postfix(loss=f"{float(loss.detach()):.3f}")
    return totals


def log_row(path: Path, row: dict[str, Any], first: bool) -> None:
    """Appends an epoch's row to the CSV log (a new log with its header for the first epoch) and prints it."""
    new = not path.exists() or first
    with path.open("w" if new else "a", newline="") as f:
        wr = csv.DictWriter(f, fieldnames=list(row))
        if new:
            wr.writeheader()
        wr.writerow(row)
    print(" ".join(f"{k}={v:.4f}" if isinstance(v, float) else f"{k}={v}" for k, v in row.items()), flush=True)


def main(argv: list[str] | None = None) -> Path:
    args, cfg = parse_args(argv)
    world = int(os.environ.get("WORLD_SIZE", "1"))
    rank = int(os.environ.get("RANK", "0"))
    if world > 1:
        dist.init_process_group("gloo")
    torch.set_num_threads(max(1, cfg.train.threads // world))
    random.seed(cfg.train.seed)
    torch.manual_seed(cfg.train.seed)

    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    spec = input_spec(cfg)
    show = rank == 0
    bars = show and sys.stderr.isatty()
    ckpt = torch.load(out / "last.pt", weights_only=False) if args.resume and (out / "last.pt").is_file() else None
    train, val, anchors_np, class_of_np = training_data(cfg, spec, ckpt, bars)
    anchors = torch.from_numpy(anchors_np)
    class_of = torch.from_numpy(class_of_np).long()
    weight_of_class = None
    if cfg.train.class_balance > 0:
        train_classes = torch.from_numpy(train.class_index[train.target]).long()
        weight_of_class = class_weights(train_classes, len(spec.classes), cfg.train.class_balance)
    model = build_model(cfg, spec, len(anchors))
    teacher = Teacher.load(cfg.train.distill, spec) if cfg.train.distill else None
    opt, sched = optimiser(cfg, model)
    start_epoch, best = resume(ckpt, model, opt, sched)
    net: torch.nn.Module = torch.nn.parallel.DistributedDataParallel(model) if world > 1 else model

    if show:
        (out / "config.json").write_text(
            json.dumps({"config": asdict(cfg), "spec": json.loads(spec.to_json())}, indent=2)
        )
        print(
            f"{run_name(cfg)}: {train.num_windows} train windows ({train.num_targets} targets), "
            f"{val.num_windows} val windows ({val.num_targets} targets); {len(anchors)} anchors; "
            f"{sum(p.numel() for p in model.parameters()):,} parameters; {world} process(es)"
        )
    from tqdm import tqdm

    rng = np.random.default_rng(cfg.train.seed)
    windows = windows_with_targets(train)
    if cfg.train.max_train_windows:
        windows = rng.choice(windows, min(cfg.train.max_train_windows, len(windows)), replace=False)
    last_epoch = min(cfg.train.epochs, args.stop_after) if args.stop_after else cfg.train.epochs
    for epoch in range(start_epoch, last_epoch):
        t0 = time.perf_counter()
        batches = epoch_batches(windows, cfg, epoch, rank, world)
        bar = tqdm(batches, desc=f"epoch {epoch + 1}/{cfg.train.epochs}", disable=not bars, leave=False)
        totals = train_epoch(net, opt, bar, train, spec, anchors, class_of, cfg, weight_of_class, rng, teacher)
        sched.step()
        if not show:
            continue
        row = {"epoch": epoch + 1, **{k: v / max(1, len(batches)) for k, v in totals.items()}}
        row.update(validate(model, val, spec, anchors, class_of, cfg))
        row["lr"] = sched.get_last_lr()[0]
        row["seconds"] = time.perf_counter() - t0
        key = None if cfg.train.select == "last" else cfg.train.select
        improved = key is None or row[key] < best
        best = row[key] if key is not None and improved else best
        state = {
            **{"model": model.state_dict(), "optimizer": opt.state_dict(), "scheduler": sched.state_dict()},
            **{"epoch": epoch, "best": best, "anchors": anchors_np, "class_of": class_of_np},
            **{"config": asdict(cfg), "rng": torch.get_rng_state()},
        }
        save_atomic(state, out / "last.pt")
        if improved:
            save_atomic(state, out / "best.pt")
        log_row(out / "log.csv", row, epoch == 0)  # after the checkpoints: a logged epoch is a resumable one
    if world > 1:
        dist.barrier()
        dist.destroy_process_group()
    if show and last_epoch == cfg.train.epochs:
        finish(out, cfg, model, val, spec, anchors, class_of, export=not args.no_export)
    return out


def training_data(
    cfg: Config, spec: dgan.InputSpec, ckpt: dict[str, Any] | None, bars: bool
) -> tuple[Windows, Windows, np.ndarray, np.ndarray]:
    """The training and validation windows (restricted to ``data.target_class`` if set) and the anchors with the
    class of each: a resumed run's ``ckpt`` keeps its own, a new run fits them (:func:`anchor_windows`)."""
    parts = load_window_parts(cfg, spec, "train", bars)
    train = concat_windows(parts)
    val = load_windows(cfg, spec, "val", bars)
    if ckpt is not None:
        anchors, class_of = ckpt["anchors"], ckpt["class_of"]
    else:
        anchors, class_of = fit_anchors(cfg, anchor_windows(cfg, parts, train), spec, len(spec.classes))
    if cfg.data.target_class:
        restrict_targets(train, spec, cfg.data.target_class)
        restrict_targets(val, spec, cfg.data.target_class)
    return train, val, anchors, class_of


def finish(
    out: Path,
    cfg: Config,
    model: DGAN,
    val: Windows,
    spec: dgan.InputSpec,
    anchors: torch.Tensor,
    class_of: torch.Tensor,
    export: bool,
) -> None:
    """After the last epoch: the temperature fitted on validation into ``best.pt`` (``train.calibrate``), then the
    ONNX model exported beside it unless ``export`` is false."""
    if cfg.train.calibrate:
        calibrate(out / "best.pt", model, val, spec, anchors, class_of)
    if export:
        from training.export import export_checkpoint

        path = export_checkpoint(out / "best.pt", out / "model.onnx", name=f"dgan-{run_name(cfg)}")
        print(f"exported {path}")


if __name__ == "__main__":
    main()
