"""The ``dgan`` command line (also ``python -m dgan``).

- ``dgan info MODEL``: the model's contract: classes, time base, anchors, map crop.
- ``dgan demo [--model zara1|sdd|apolloscape]``: a bundled real scene and model, printed and drawn
  (``dgan_demo.png``).
- ``dgan predict MODEL SCENE --time T``: predict every agent seen at time T of a scene file, either the
  Social-GAN layout (``frame agent_id x y``, whitespace-separated) or a CSV with a header
  (``agent_id,time,x,y[,class,heading,length,width,vx,vy]``).
"""

from __future__ import annotations

import argparse
import csv
import json
import sys
import time
from collections.abc import Sequence
from pathlib import Path
from typing import Any

import numpy as np

import dgan
from dgan.exceptions import DganError, InvalidFrameError


def read_scene(path: Path) -> dict[str, Any]:
    """A scene file as columns."""
    try:
        text = path.read_text()
    except OSError as e:
        raise InvalidFrameError(f"cannot read scene {path}: {e}") from None
    first = text.lstrip().split("\n", 1)[0]
    if "," in first and any(c.isalpha() for c in first):
        rows = list(csv.DictReader(text.splitlines()))
        if not rows:
            return {"agent_id": np.zeros(0, np.int64), "time": np.zeros(0), "x": np.zeros(0), "y": np.zeros(0)}
        cols: dict[str, Any] = {k: [r[k] for r in rows] for k in rows[0]}
        for k in list(cols):
            if k != "class":
                cols[k] = np.asarray(cols[k], dtype=np.float64)
        cols["agent_id"] = cols["agent_id"].astype(np.int64)
        return cols
    try:
        data = np.loadtxt(path, ndmin=2)
    except ValueError as e:
        raise InvalidFrameError(f"{path} is neither a CSV with a header nor `frame id x y` rows: {e}") from None
    if data.shape[1] < 4:
        raise InvalidFrameError(f"{path}: expected 4 columns (frame id x y), found {data.shape[1]}")
    return {"time": data[:, 0], "agent_id": data[:, 1].astype(np.int64), "x": data[:, 2], "y": data[:, 3]}


def _info(args: argparse.Namespace) -> int:
    p = dgan.Predictor(args.model)
    c = p.contract
    spec = p.spec
    print(f"model      {p.path}")
    print(f"name       {c.get('name') or '-'}")
    print(
        f"time base  dt = {spec.dt_s} s, observes {spec.t_obs} steps, predicts {spec.t_f} ({spec.t_f * spec.dt_s:g} s)"
    )
    print(f"classes    {', '.join(f'{k} ({len(v)} anchors)' for k, v in p.anchors.items())}")
    print(f"attention  r = speed * {spec.t_f * spec.dt_s:g} s + {spec.attention_lambda} * length")
    if spec.map is None:
        print("map        none (no map branch)")
    else:
        m = spec.map
        where = f"agent at pixel ({m.agent_row}, {m.agent_col})"
        needed = "optional (runs without a map too)" if m.optional else "required"
        print(f"map        {m.height_px}x{m.width_px} px at {m.resolution_m} m/px, {where}; {needed}")
    prior = spec.prior
    if prior.kind == "none":
        print("prior      none (absolute anchors, contract 1)")
    else:
        how = f"mean velocity over {prior.window_s:g} s" if prior.window_s else "velocity of the last two steps"
        print(f"prior      {prior.kind} ({how})")
    print(f"temperature {c.get('temperature', 1.0):g} (of the anchor logits; contract {c['contract_version']})")
    if c.get("description"):
        print(f"about      {c['description']}")
    return 0


def _predict(args: argparse.Namespace) -> int:
    p = dgan.Predictor(args.model, modes=args.modes)
    cols = read_scene(Path(args.scene))
    frame = dgan.Frame.from_records(cols, t_obs=p.spec.t_obs, dt=args.dt, current_time=args.time)
    started = time.perf_counter()
    pred = p.predict(frame)
    ms = (time.perf_counter() - started) * 1e3
    if args.json:
        out = {
            "agent_ids": pred.agent_ids.tolist(),
            "trajectories": pred.trajectories.tolist(),
            "probabilities": pred.probabilities.tolist(),
            "classes": list(pred.classes),
        }
        json.dump(out, sys.stdout)
        print()
        return 0
    print(f"{len(frame)} agents, {len(pred.edges)} attention edges, predicted in {ms:.1f} ms")
    for i, agent in enumerate(pred.agent_ids):
        ends = pred.trajectories[i, :, -1]
        modes = "  ".join(
            f"p={pred.probabilities[i, m]:.2f} -> ({ends[m, 0]:.2f}, {ends[m, 1]:.2f})" for m in range(len(ends))
        )
        print(f"agent {agent:>5}  {modes}")
    return 0


def _demo(args: argparse.Namespace) -> int:
    from dgan.demo import run

    return run(args.model, args.time, args.modes, Path(args.out))


def build_parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(prog="dgan", description="DGAN multi-modal trajectory prediction")
    parser.add_argument("--version", action="version", version=f"dgan {dgan.__version__}")
    sub = parser.add_subparsers(dest="command", required=True)
    info = sub.add_parser("info", help="show a model's contract")
    info.add_argument("model")
    info.set_defaults(func=_info)
    pred = sub.add_parser("predict", help="predict the agents of a scene file at one time")
    pred.add_argument("model")
    pred.add_argument("scene", help="Social-GAN txt (frame id x y) or CSV with agent_id,time,x,y[,...]")
    pred.add_argument("--time", type=float, default=None, help="current time t_obs (default: the last in the file)")
    pred.add_argument(
        "--dt", type=float, default=None, help="time between steps in the file's unit (default: inferred)"
    )
    pred.add_argument("--modes", type=int, default=3, help="modes per agent (default 3)")
    pred.add_argument("--json", action="store_true", help="print JSON instead of a table")
    pred.set_defaults(func=_predict)
    demo = sub.add_parser("demo", help="predict a bundled real scene with a bundled model and draw it")
    demo.add_argument(
        "--model", default="zara1", help="a bundled model name (zara1, sdd, apolloscape ...) or an .onnx path"
    )
    demo.add_argument(
        "--time",
        type=float,
        default=None,
        help="t_obs step of the bundled excerpt: zara1 5500..5510, sdd 831..841, apolloscape 15..19",
    )
    demo.add_argument("--modes", type=int, default=3)
    demo.add_argument("--out", default="dgan_demo.png", help="where to write the picture")
    demo.set_defaults(func=_demo)
    return parser


def main(argv: Sequence[str] | None = None) -> int:
    args = build_parser().parse_args(argv)
    try:
        code: int = args.func(args)
    except DganError as e:
        print(f"dgan: error: {e}", file=sys.stderr)
        return 2
    except BrokenPipeError:  # e.g. `dgan predict ... | head`
        sys.stderr.close()
        return 0
    return code


if __name__ == "__main__":
    raise SystemExit(main())
