"""Several runs that share their first epochs (a base run resumed with other seeds, ``training.train --resume``) as one
network: the mean of their final weights, a uniform weight soup (Wortsman et al. 2022, "Model soups"), with its
BatchNorm statistics recomputed on training batches. One network's cost, where a consensus
(``training.ensemble``) costs its members' count.

    python -m training.soup RUN [RUN ...] --out SOUP [--batches 200] [--data-root DIR]

Each RUN is a ``training.train`` output folder whose ``last.pt`` ended the same schedule from the same anchors (the
same configuration but for ``train.seed`` and ``train.threads``). SOUP gets ``best.pt`` and ``config.json`` (the
first run's): a run as ``training.release.bundle`` and ``training.calibrate`` take it; its calibration is fitted on
validation there (``train.calibration``).
"""

from __future__ import annotations

import argparse
import shutil
from collections.abc import Iterable, Sequence
from pathlib import Path
from typing import Any

import numpy as np
import torch

from training.checkpoint import save_atomic
from training.data.batches import forward_inputs, prepared_batch, windows_with_targets

#: What the runs of a soup may differ in: their seeds (data order, mirrors, map dropout) and threads.
FREE_KEYS = (("train", "seed"), ("train", "threads"))


def soup_state(states: Sequence[dict[str, torch.Tensor]]) -> dict[str, torch.Tensor]:
    """The mean of the state dicts ``states`` (floating-point tensors; any other, a BatchNorm's batch count, is the
    first's)."""
    if not states:
        raise ValueError("a soup needs at least one run")
    keys = list(states[0])
    for s in states[1:]:
        if list(s) != keys or any(s[k].shape != states[0][k].shape for k in keys):
            raise ValueError("the runs of a soup must share one architecture")
    out = {}
    for k, first in states[0].items():
        if first.is_floating_point():
            out[k] = torch.stack([s[k].double() for s in states]).mean(0).to(first.dtype)
        else:
            out[k] = first.clone()
    return out


def _shared_config(ckpts: Sequence[dict[str, Any]], runs: Sequence[Path]) -> None:
    """The runs must end one schedule from the same anchors under one configuration (but :data:`FREE_KEYS`)."""

    def fixed(c: dict[str, Any]) -> dict[str, Any]:
        cfg = {section: dict(values) if isinstance(values, dict) else values for section, values in c.items()}
        for section, key in FREE_KEYS:
            cfg[section].pop(key, None)
        return cfg

    first = ckpts[0]
    for run, c in zip(runs[1:], ckpts[1:], strict=True):
        if not np.array_equal(c["anchors"], first["anchors"]):
            raise ValueError(f"{run}: its anchors differ from {runs[0]}'s; a soup's runs share their first epochs")
        if fixed(c["config"]) != fixed(first["config"]):
            raise ValueError(f"{run}: its configuration differs from {runs[0]}'s in more than {FREE_KEYS}")
        if c["epoch"] != first["epoch"]:
            raise ValueError(f"{run}: ended at epoch {c['epoch'] + 1}, {runs[0]} at {first['epoch'] + 1}")


@torch.no_grad()
def recompute_batchnorm(model: torch.nn.Module, batches: Iterable[dict[str, torch.Tensor]]) -> int:
    """Sets every BatchNorm layer's running statistics of ``model`` to their plain average over ``batches`` (a
    soup's mean weights fit none of its runs' statistics); returns how many batches that took. The model is left in
    eval mode. (``torch.optim.swa_utils.update_bn`` does the same for a model of one input; this one takes the
    contract's several.)"""
    norms = [m for m in model.modules() if isinstance(m, torch.nn.modules.batchnorm._BatchNorm)]
    momenta = [m.momentum for m in norms]
    for m in norms:
        m.reset_running_stats()
        m.momentum = None  # a cumulative average
    model.train()
    count = 0
    for b in batches:
        model(*forward_inputs(b))
        count += 1
    for m, momentum in zip(norms, momenta, strict=True):
        m.momentum = momentum
    model.eval()
    return count


def training_batches(cfg: Any, spec: Any, count: int, seed: int = 0) -> Iterable[dict[str, torch.Tensor]]:
    """``count`` batches of the configuration's training windows as training draws them (map dropout included)."""
    from training.data.splits import training_splits

    train = training_splits(cfg, spec, False).train
    rng = np.random.default_rng(seed)
    keep = windows_with_targets(train)
    for _ in range(count):
        idx = rng.choice(keep, min(cfg.train.batch_windows, len(keep)), replace=False)
        yield prepared_batch(train, idx, spec, None, cfg.train.map_dropout, rng)


def soup_checkpoint(runs: Sequence[Path], out: Path, batches: int = 200, data_root: Path | None = None) -> Path:
    """Writes the soup of ``runs`` (their ``last.pt``) as a run folder ``out`` (``best.pt``, ``config.json``)."""
    from dataclasses import replace

    from training.export import network_of

    missing = [str(r) for r in runs if not (r / "last.pt").is_file()]
    if missing:
        raise ValueError(f"not training runs (no last.pt): {', '.join(missing)}")
    ckpts = [torch.load(r / "last.pt", weights_only=False) for r in runs]
    _shared_config(ckpts, runs)
    ckpt = {k: ckpts[0][k] for k in ("anchors", "class_of", "config", "epoch") if k in ckpts[0]}
    ckpt["model"] = soup_state([c["model"] for c in ckpts])
    ckpt["runs"] = [r.name for r in runs]
    model, spec, _, _, cfg = network_of(ckpt)
    if data_root is not None:
        cfg = replace(cfg, data=replace(cfg.data, root=str(data_root)))
    recompute_batchnorm(model, training_batches(cfg, spec, batches))
    ckpt["model"] = model.state_dict()
    out.mkdir(parents=True, exist_ok=True)
    save_atomic(ckpt, out / "best.pt")
    shutil.copyfile(runs[0] / "config.json", out / "config.json")
    return out / "best.pt"


def main(argv: list[str] | None = None) -> Path:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("runs", nargs="+", type=Path)
    ap.add_argument("--out", type=Path, required=True, help="the soup's run folder to write")
    ap.add_argument("--batches", type=int, default=200, help="training batches the BatchNorm statistics average")
    ap.add_argument("--data-root", type=Path, help="the data folder for the training windows (the runs' own if unset)")
    ap.add_argument("--no-calibrate", action="store_true", help="keep no calibration (fit it later)")
    a = ap.parse_args(argv)
    if a.batches < 1:
        ap.error("--batches must be at least 1")
    try:
        path = soup_checkpoint(a.runs, a.out, a.batches, a.data_root)
    except ValueError as e:
        ap.error(str(e))
    if not a.no_calibrate:
        from training.calibrate import calibrate_checkpoint

        print(calibrate_checkpoint(path, a.data_root, progress=True))
    print(f"wrote {path}")
    return path


if __name__ == "__main__":
    main()
