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
from training.anchors import anchor_windows, fit_anchors
from training.build import build_model, input_spec, run_name
from training.calibrate import (
    TemperatureFit,
    calibration_config,
    check_calibration,
    fit_temperature,
)
from training.checkpoint import init_weights, save_atomic
from training.config import Config
from training.data.arrays import Windows
from training.data.batches import prepared_batch, windows_with_targets
from training.data.splits import only_target_class, split_windows, target_class_index, training_splits
from training.export import export_checkpoint
from training.losses import check_anchor_pool, check_cls_target, class_weights
from training.modules.dgan import DGAN
from training.step import Teacher, forward_loss, teacher_crops, validate

#: ``train.select``: the validation figure (a column of ``log.csv``) whose lowest epoch is kept as ``best.pt``, or
#: ``"last"`` for the final epoch.
SELECT = ("val_loss", "val_ade", "last")


def calibrate(
    path: Path,
    model: DGAN,
    val: Windows,
    spec: dgan.InputSpec,
    anchors: torch.Tensor,
    class_of: torch.Tensor,
    kind: str = "temperature",
) -> TemperatureFit:
    """Fits the kept weights' calibration (``train.calibration``: ``kind``) on the validation split; stores it in
    ``path``."""
    ckpt = torch.load(path, weights_only=False)
    model.load_state_dict(ckpt["model"])
    found = fit_temperature(model, val, spec, anchors, class_of, kind)
    ckpt.update(found.checkpoint_keys())
    save_atomic(ckpt, path)
    print(found, flush=True)
    return found


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
    if cfg.train.distill_soft < 0 or (cfg.train.distill_soft > 0 and not cfg.train.distill):
        raise ValueError(f"train.distill_soft must be >= 0 and needs train.distill, got {cfg.train.distill_soft}")
    check_anchor_pool(cfg.train.anchor_pool)
    if cfg.train.init and not Path(cfg.train.init).is_file():
        raise ValueError(f"train.init must name a checkpoint file, got {cfg.train.init!r} (no such file)")
    calibration_config(cfg)  # refuses an unknown train.calibration_split before any training
    check_calibration(cfg.train.calibration)
    return args, cfg


def optimiser(cfg: Config, model: torch.nn.Module) -> tuple[torch.optim.Optimizer, torch.optim.lr_scheduler.OneCycleLR]:
    """AdamW under a one-cycle schedule over the configured epochs."""
    opt = torch.optim.AdamW(model.parameters(), lr=cfg.train.lr, weight_decay=cfg.train.weight_decay)
    # OneCycleLR divides by pct_start * total - 1, which is 0 at exactly 10 epochs: nudge only that case.
    pct = 0.1 if abs(0.1 * cfg.train.epochs - 1.0) > 1e-9 else 0.15
    sched = torch.optim.lr_scheduler.OneCycleLR(opt, max_lr=cfg.train.lr, total_steps=cfg.train.epochs, pct_start=pct)
    return opt, sched


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
    at the configured rate); the summed loss and its classification and regression parts (and the soft
    distillation term's, ``train.distill_soft``)."""
    totals = {"loss": 0.0, "cls": 0.0, "reg": 0.0, **({"soft": 0.0} if cfg.train.distill_soft > 0 else {})}
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
        if "soft" in totals:
            totals["soft"] += parts["soft"]
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
    weight_of_class = None
    if cfg.train.class_balance > 0:
        train_classes = torch.from_numpy(train.class_index[train.target]).long()
        weight_of_class = class_weights(train_classes, len(spec.classes), cfg.train.class_balance)
    model = build_model(cfg, spec, len(anchors_np))
    teacher = Teacher.load(cfg.train.distill, spec) if cfg.train.distill else None
    if teacher is not None:
        train = teacher_crops(cfg, spec, teacher, train, bars)
    if cfg.train.init and ckpt is None:
        loaded, left = init_weights(model, cfg.train.init)
        if show:
            print(f"train.init: {len(loaded)} tensors from {cfg.train.init}, {len(left)} initialised: {left}")
    opt, sched = optimiser(cfg, model)
    start_epoch, best = resume(ckpt, model, opt, sched)
    net: torch.nn.Module = torch.nn.parallel.DistributedDataParallel(model) if world > 1 else model

    if show:
        (out / "config.json").write_text(
            json.dumps({"config": asdict(cfg), "spec": json.loads(spec.to_json())}, indent=2)
        )
        print(
            f"{run_name(cfg)}: {train.num_windows} train windows ({train.num_targets} targets), "
            f"{val.num_windows} val windows ({val.num_targets} targets); {len(anchors_np)} anchors; "
            f"{sum(p.numel() for p in model.parameters()):,} parameters; {world} process(es)"
        )
    last_epoch = min(cfg.train.epochs, args.stop_after) if args.stop_after else cfg.train.epochs
    run = Run(out, cfg, spec, model, net, opt, sched, train, val, anchors_np, class_of_np, weight_of_class, teacher)
    run_epochs(run, start_epoch, last_epoch, best, rank, world, bars)
    if world > 1:
        dist.barrier()
        dist.destroy_process_group()
    if show and last_epoch == cfg.train.epochs:
        finish(out, cfg, model, val, spec, run.anchors, run.class_of, export=not args.no_export)
    return out


@dataclass
class Run:
    """What the epochs of a run share: its folder, configuration, model (and the DDP wrapper it trains through),
    optimiser and schedule, data, anchors, class weights and teacher."""

    out: Path
    cfg: Config
    spec: dgan.InputSpec
    model: DGAN
    net: torch.nn.Module
    opt: torch.optim.Optimizer
    sched: torch.optim.lr_scheduler.OneCycleLR
    train: Windows
    val: Windows
    anchors_np: np.ndarray
    class_of_np: np.ndarray
    weight_of_class: torch.Tensor | None
    teacher: Teacher | None

    @property
    def anchors(self) -> torch.Tensor:
        """``(K, T_f, 2)`` the anchors, sharing the array's memory."""
        return torch.from_numpy(self.anchors_np)

    @property
    def class_of(self) -> torch.Tensor:
        """``(K,)`` the class of each anchor."""
        return torch.from_numpy(self.class_of_np).long()


def run_epochs(run: Run, start_epoch: int, last_epoch: int, best: float, rank: int, world: int, bars: bool) -> None:
    """The epochs ``start_epoch..last_epoch``: train, then (on rank 0) validate, checkpoint and log each one."""
    from tqdm import tqdm

    cfg, spec, model, opt, sched, out = run.cfg, run.spec, run.model, run.opt, run.sched, run.out
    anchors, class_of, val = run.anchors, run.class_of, run.val
    show = rank == 0
    rng = np.random.default_rng(cfg.train.seed)
    windows = windows_with_targets(run.train)
    if cfg.train.max_train_windows:
        windows = rng.choice(windows, min(cfg.train.max_train_windows, len(windows)), replace=False)
    for epoch in range(start_epoch, last_epoch):
        t0 = time.perf_counter()
        batches = epoch_batches(windows, cfg, epoch, rank, world)
        bar = tqdm(batches, desc=f"epoch {epoch + 1}/{cfg.train.epochs}", disable=not bars, leave=False)
        totals = train_epoch(
            run.net, opt, bar, run.train, spec, anchors, class_of, cfg, run.weight_of_class, rng, run.teacher
        )
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
            **{"epoch": epoch, "best": best, "anchors": run.anchors_np, "class_of": run.class_of_np},
            **{"config": asdict(cfg), "rng": torch.get_rng_state()},
        }
        save_atomic(state, out / "last.pt")
        if improved:
            save_atomic(state, out / "best.pt")
        log_row(out / "log.csv", row, epoch == 0)  # after the checkpoints: a logged epoch is a resumable one


def training_data(
    cfg: Config, spec: dgan.InputSpec, ckpt: dict[str, Any] | None, bars: bool
) -> tuple[Windows, Windows, np.ndarray, np.ndarray]:
    """The training and validation windows (restricted to ``data.target_class`` if set) and the anchors with the
    class of each: a resumed run's ``ckpt`` keeps its own, a new run fits them (:func:`anchor_windows`)."""
    data = training_splits(cfg, spec, bars)
    if ckpt is not None:
        anchors, class_of = ckpt["anchors"], ckpt["class_of"]
    else:
        anchors, class_of = fit_anchors(cfg, anchor_windows(cfg, data.parts, data.train), spec, len(spec.classes))
    for w in (data.train, data.val):  # after the anchors
        only_target_class(w, data.target_class)
    return data.train, data.val, anchors, class_of


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
        own = calibration_config(cfg)
        if own is not cfg:  # train.calibration_split = "own": the own dataset's validation windows alone
            val = split_windows(own, spec, "val", False)
            only_target_class(val, target_class_index(cfg.data.target_class, spec))
        calibrate(out / "best.pt", model, val, spec, anchors, class_of, cfg.train.calibration)
    if export:
        path = export_checkpoint(out / "best.pt", out / "model.onnx", name=f"dgan-{run_name(cfg)}")
        print(f"exported {path}")


if __name__ == "__main__":
    main()
