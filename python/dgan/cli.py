"""The ``dgan`` command line (also ``python -m dgan``).

- ``dgan models``: every bundled model with its time base, horizon, classes, map kind and licence.
- ``dgan info MODEL``: the model's contract: classes, time base, anchors, map crop, prior.
- ``dgan demo [--model zara1|sdd|apolloscape|hdmap]``: a bundled real scene and model, printed and drawn
  (``dgan_demo.png``; the picture needs matplotlib, ``pip install dgan[plot]``).
- ``dgan predict MODEL SCENE [--time T] [--map MAP] [--json | --out FILE]``: predict every agent seen at time T of a
  scene file, resampled to the model's time base: the Social-GAN layout (``frame agent_id x y``, whitespace-separated,
  one annotation every 0.4 s), a table with a header (``agent_id,time,x,y[,class,heading,length,width,vx,vy]``,
  separated by commas, semicolons, tabs or bars; time in seconds unless ``--time-unit`` says otherwise, or ISO 8601
  instants; other names with ``--column ARG=NAME``), or a parquet / feather table.
- ``dgan evaluate MODEL SCENE [--map MAP] [--out FILE] [--plot PNG]``: the model's top-1 and best-of-K errors beside
  constant velocity's on every agent of a scene file seen over its window and horizon, at every time, by class and
  for moving and standing agents (:func:`dgan.evaluate`).
"""

from __future__ import annotations

import argparse
import json
import os
import re
import sys
import time
import warnings
from collections.abc import Sequence
from dataclasses import replace
from pathlib import Path
from typing import Any

import numpy as np

import dgan
from dgan._progress import progress
from dgan._times import iso_text
from dgan.cliargs import evaluate_arguments, predict_arguments
from dgan.exceptions import ColumnWarning, DatasetWarning, DganError, InvalidFrameError, InvalidMapError, NoTargetError
from dgan.predictionfiles import prediction_json, write_columns, write_records, write_table
from dgan.scenefiles import (
    class_names,
    cli_wording,
    column_names,
    read_map,
    read_scene,
    scene_files,
    scene_names,
)


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
    kind = dgan.models.map_kind(args.model, c) if args.model in dgan.models.list() else None
    if spec.map is None:
        print("map        none (no map branch)")
    else:
        m = spec.map
        where = f"agent at pixel ({m.agent_row}, {m.agent_col})"
        needed = "optional (runs without a map too)" if m.optional else "required"
        print(f"map        {m.height_px}x{m.width_px} px at {m.resolution_m} m/px, {where}; {needed}")
        print(f"map kind   {kind or 'a raster image or a vector map (--map of dgan predict)'}")
        if dgan.scenes.reads_masks(c):
            print("map input  a semantic mask coloured in dgan.scenes.MASK_PALETTE (--map <scene>), not a photo")
    prior = spec.prior
    if prior.kind == "none":
        print("prior      none (absolute anchors, contract 1)")
    else:
        how = f"mean velocity over {prior.window_s:g} s" if prior.window_s else "velocity of the last two steps"
        print(f"prior      {prior.kind} ({how})")
    if spec.denoise_gate_m:
        print(f"denoising  tracks off their parabola by >= {spec.denoise_gate_m:g} m are smoothed first (contract 10)")
    temp = f"temperature {c.get('temperature', 1.0):g} (of the anchor logits"
    if c.get("temperature_speed_exponent"):
        temp += f", x (1 + speed in m/s)^{c['temperature_speed_exponent']:g}"
    if c.get("class_temperature", 1.0) != 1.0:
        temp += f"; class logits {c['class_temperature']:g}"
    print(f"{temp}; contract {c['contract_version']})")
    if c.get("top_scale"):
        kept = ", ".join(f"{k} {v:g}" for k, v in c["top_scale"].items())
        print(f"top mode   keeps this share of its residual over the prior: {kept} (contract 14)")
    if c.get("still_radius_m"):
        held = ", ".join(f"{k} {v:g} m" for k, v in c["still_radius_m"].items())
        print(f"still      top mode at the prior for a history within this of its last position: {held} (contract 15)")
    if c.get("top_mean_power"):
        powers = ", ".join(f"{k} {v:g}" for k, v in c["top_mean_power"].items())
        print(f"top mean   top mode as the mean of the modes weighted by p to this power: {powers} (contract 16)")
    print(f"providers  {', '.join(dgan.available_execution_providers())} (in this ONNX Runtime library)")
    if c.get("description"):
        print(f"about      {c['description']}")
    return 0


def _models(args: argparse.Namespace) -> int:
    rows = [dgan.models.info(name) for name in dgan.models.list()]
    if args.json:
        json.dump([r.__dict__ for r in rows], sys.stdout, indent=1)
        print()
        return 0
    print(f"{'model':<12} {'dt':>6} {'T_obs':>5} {'T_f':>4} {'horizon':>7}  {'classes':<29} {'map':<30} licence")
    for r in rows:
        print(
            f"{r.name:<12} {r.dt_s:>5.3g}s {r.t_obs:>5} {r.t_f:>4} {r.t_f * r.dt_s:>6.3g}s  {', '.join(r.classes):<29} "
            f"{r.map_kind:<30} {r.licence}"
        )
    return 0


def _frames_of(
    args: argparse.Namespace,
    p: dgan.Predictor,
    scene: Path,
    scene_map: dgan.RasterMap | dgan.VectorMap | None,
    said: set[str],
) -> list[tuple[dgan.Frame, float | str]]:
    """The frames of a scene file, each with its time: at ``--time`` (its last time by default), or with ``--every``
    at each of its times."""
    cols, options = _table_of(args, scene, scene_map, said)
    options["spec"] = p
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always", ColumnWarning)
        if args.every:  # the table read once for all its times
            read = dgan.series.frames(cols, **options)
        else:
            read = [dgan.Frame.from_records(cols, current_time=args.time, **options)]
        frames = [(_denoised(args, f), _time_text(f.time if f.time is not None else args.time)) for f in read]
    for message in dict.fromkeys(str(w.message) for w in caught if issubclass(w.category, ColumnWarning)):
        print(f"dgan: note: {cli_wording(message)}", file=sys.stderr)
    for w in caught:
        if not issubclass(w.category, ColumnWarning):
            warnings.warn_explicit(w.message, w.category, w.filename, w.lineno)
    return frames


def _map_of(args: argparse.Namespace) -> dgan.RasterMap | dgan.VectorMap | None:
    """``--map``, read once for every scene of a command (a vector map keeps the tiles drawn from it)."""
    if args.no_map and args.map is not None:
        raise InvalidMapError("--map and --no-map ask for opposite things: give one")
    return read_map(args.map, args.pixel_to_world) if args.map is not None else None


def _table_of(
    args: argparse.Namespace, scene: Path, scene_map: dgan.RasterMap | dgan.VectorMap | None, said: set[str]
) -> tuple[dict[str, Any], dict[str, Any]]:
    """A scene file's columns, and the options of :meth:`dgan.Frame.from_records` the command line gives for it (a
    scenario's own map unless ``--map`` names one); the first file of each headerless layout but Social-GAN's, and of
    each kind of scenario, says how it was read (``said``: the layouts said)."""
    names = column_names(args.column)
    read = read_scene(scene, (names.get("cls_column", "class"),), args.metres_per_pixel)
    if read.description is not None and read.layout not in said:
        said.add(str(read.layout))
        print(f"dgan: note: {scene.name} read as {read.description}", file=sys.stderr)
    time_unit = args.time_unit if args.time_unit is not None else (read.time_unit or 1.0)
    options = {"time_unit": time_unit, "duplicates": args.duplicates, "upsample": args.upsample}
    options["map"] = None if args.no_map else scene_map if scene_map is not None else read.map
    return read.columns, options | {"class_names": class_names(args.class_name, args.common_classes), **names}


def _evaluate(args: argparse.Namespace) -> int:
    """``dgan evaluate MODEL SCENE``: the model beside constant velocity on every target of the scene (or scenes)."""
    p = dgan.Predictor(args.model)
    files = scene_files(args.scene) or [Path(args.scene)]
    options = {"modes": args.modes, "stride": args.stride, "standing_m": args.standing_m}
    options |= {"min_targets": args.min_targets, "unknown_classes": args.unknown_classes}
    parts, names, scene_map, said = [], [], _map_of(args), set[str]()
    pairs = list(zip(files, scene_names(files), strict=True))
    for scene, name in progress(pairs, "scenes") if len(files) > 1 else pairs:
        cols, table = _table_of(args, scene, scene_map, said)
        try:
            parts.append(dgan.evaluate(p, cols, progress=len(files) == 1, **options, **table))
            names.append(name)
        except NoTargetError as e:  # one short scene of many: the others are still scored
            if len(files) == 1:
                raise
            print(f"dgan: note: {scene}: left out: {cli_wording(str(e))}", file=sys.stderr)
        except DganError as e:
            if len(files) == 1:
                raise
            raise type(e)(f"{scene}: {e}") from None
    if not parts:
        raise NoTargetError(f"no target in any of the {len(files)} scenes (notes above)")
    result = dgan.evaluation.joined(parts, names) if len(parts) > 1 else parts[0]
    result = replace(result, model=args.model)
    if args.out is not None:
        write_columns(result.to_records(), Path(args.out))
        print(f"wrote {len(result)} targets to {args.out}", file=sys.stderr)
    for path, kind in ((args.plot, "classes"), (args.plot_horizon, "horizon")):
        if path is not None:
            result.plot(kind=kind).savefig(path, dpi=120)
            print(f"drew {path}", file=sys.stderr)
    if args.json:
        json.dump({"model": args.model, "scenes": names, "times": result.times, "rows": result.rows()}, sys.stdout)
        print()
    else:
        print(result)
    return 0


def _time_text(at: Any) -> float | str:
    """A frame's time as the command line prints it: a number, or an instant in ISO 8601 (milliseconds)."""
    if isinstance(at, np.datetime64):
        return str(iso_text(at))
    return at if isinstance(at, str) else float("nan") if at is None else float(at)


def _denoised(args: argparse.Namespace, frame: dgan.Frame) -> dgan.Frame:
    return frame if args.denoise is None else frame.denoised(args.denoise)


def _denoise_note(args: argparse.Namespace, p: dgan.Predictor) -> None:
    gate = p.spec.denoise_gate_m
    if args.denoise is not None and gate and args.denoise > gate:
        print(
            f"note: the model smooths tracks {gate:g} m or more off their parabola itself (contract 10), so "
            f"--denoise {args.denoise:g} leaves no track between {gate:g} and {args.denoise:g} m as given",
            file=sys.stderr,
        )


def _predict_many(args: argparse.Namespace, p: dgan.Predictor, files: list[Path]) -> int:
    """``dgan predict MODEL DIR|GLOB --out TABLE``: every scene file, one table with a ``scene`` column."""
    if args.out is None:
        what = "--every needs" if args.every and len(files) == 1 else "several scenes (a directory or a glob) need"
        raise InvalidFrameError(f"{what} --out TABLE (.parquet, .csv or .jsonl)")
    preds: list[dgan.Prediction] = []
    names: list[str] = []
    scene_map, said = _map_of(args), set[str]()
    for scene, name in progress(list(zip(files, scene_names(files), strict=True)), "scenes"):
        try:
            frames = [f for f, _ in _frames_of(args, p, scene, scene_map, said)]
            preds += p.predict_batch(frames, unknown_classes=args.unknown_classes)
        except DganError as e:
            raise type(e)(f"{scene}: {e}") from None
        names += [name] * len(frames)
    write_records({"scene": names}, preds, Path(args.out))
    agents = sum(len(pr) for pr in preds)
    at = f" at {len(preds)} times" if args.every else ""
    print(f"wrote {agents} agents of {len(files)} scenes{at} to {args.out}", file=sys.stderr)
    return 0


def _predict(args: argparse.Namespace) -> int:
    p = dgan.Predictor(args.model, modes=args.modes, execution_provider=args.provider)
    _denoise_note(args, p)
    files = scene_files(args.scene)
    if files is not None or args.every:
        return _predict_many(args, p, files or [Path(args.scene)])
    ((frame, now),) = _frames_of(args, p, Path(args.scene), _map_of(args), set())
    if p.spec.map is not None and frame.map is None and p.spec.map.optional and not args.no_map:
        print(
            f"dgan: note: no --map given; {args.model} runs without a map (its map is optional; "
            "see `dgan info` for the map it was trained with)",
            file=sys.stderr,
        )
    started = time.perf_counter()
    pred = p.predict(frame, unknown_classes=args.unknown_classes)
    ms = (time.perf_counter() - started) * 1e3
    if args.out is not None:
        write_table(pred, Path(args.out))
        print(f"wrote {len(pred)} agents × {pred.trajectories.shape[1]} modes to {args.out}", file=sys.stderr)
    if args.json:
        json.dump(prediction_json(pred, frame, args.model, now), sys.stdout)
        print()
        return 0
    if args.out is not None:
        return 0
    _print_prediction(pred, frame, p, ms, now)
    return 0


def _timings_text(timings: dict[str, float]) -> str:
    """The engine's phases of a call (``Predictor.last_timings``) as ``"preprocess 0.1, crops 0.9, ... ms"``."""
    shown = [k for k in ("preprocess", "crops", "network", "decode", "parts") if timings[k] > 0.0]
    return ", ".join(f"{k} {timings[k]:.1f}" for k in shown) + " ms"


def _print_prediction(pred: dgan.Prediction, frame: dgan.Frame, p: dgan.Predictor, ms: float, now: float | str) -> None:
    when = now if isinstance(now, str) else format(now, "g")
    print(
        f"{len(frame)} agents at time {when}, {len(pred.edges)} attention edges, predicted in {ms:.1f} ms "
        f"(steps of {p.spec.dt_s:g} s, horizon {p.spec.t_f * p.spec.dt_s:g} s)"
    )
    timings = p.last_timings
    if timings:
        print(f"engine: {_timings_text(timings)}")
    for i, agent in enumerate(pred.agent_ids):
        ends = pred.trajectories[i, :, -1]
        modes = "  ".join(
            f"p={pred.probabilities[i, m]:.2f} -> ({ends[m, 0]:.2f}, {ends[m, 1]:.2f})" for m in range(len(ends))
        )
        print(f"agent {agent!s:>5}  {modes}")


def _demo(args: argparse.Namespace) -> int:
    from dgan.demo import run

    return run(args.model, args.time, args.modes, Path(args.out))


def _predict_parser(sub: Any) -> None:
    """``dgan predict``'s and ``dgan evaluate``'s arguments (:mod:`dgan.cliargs`), run by :func:`_predict` and
    :func:`_evaluate`."""
    predict_arguments(sub).set_defaults(func=_predict)
    evaluate_arguments(sub).set_defaults(func=_evaluate)


def build_parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(prog="dgan", description="DGAN multi-modal trajectory prediction")
    parser.add_argument("--version", action="version", version=f"dgan {dgan.__version__}")
    sub = parser.add_subparsers(dest="command", required=True)
    models = sub.add_parser("models", help="list the bundled models")
    models.add_argument("--json", action="store_true", help="print JSON instead of a table")
    models.set_defaults(func=_models)
    info = sub.add_parser("info", help="show a model's contract")
    info.add_argument("model")
    info.set_defaults(func=_info)
    _predict_parser(sub)
    demo = sub.add_parser("demo", help="predict a bundled real scene with a bundled model and draw it")
    demo.add_argument(
        "--model", default="zara1", help="a bundled model name (zara1, sdd, apolloscape ...) or an .onnx path"
    )
    demo.add_argument(
        "--time",
        type=float,
        default=None,
        help="t_obs of the bundled excerpt, in its time unit: zara1 frames 5430..5620 every 10 (default 5500), "
        "sdd steps 824..853 (841), apolloscape 10..25 (17), hdmap 14..88 (40)",
    )
    demo.add_argument("--modes", type=int, default=3)
    demo.add_argument("--out", default="dgan_demo.png", help="where to write the picture")
    demo.set_defaults(func=_demo)
    return parser


class _Warnings:
    """The command's warnings as its own lines (``dgan: warning: ...``), without Python's source line. A dataset
    warning that repeats one shown for another file (the same words but the file's name and the counts: each Waymo
    scenario's undrawn driveways) is counted instead, and the count told once at the end."""

    def __init__(self) -> None:
        self.kinds: set[str] = set()
        self.repeats = 0

    def show(self, message: Warning | str, category: type[Warning], *_: Any, **__: Any) -> None:
        text = cli_wording(str(message))
        if issubclass(category, DatasetWarning):
            kind = re.sub(r"\d+", "#", text.split(": ", 1)[-1].split(": ", 1)[0])
            if kind in self.kinds:
                self.repeats += 1
                return
            self.kinds.add(kind)
        print(f"dgan: warning: {text}", file=sys.stderr)

    def tell_repeats(self) -> None:
        if self.repeats:
            print(
                f"dgan: note: {self.repeats} more dataset warning(s) like those above, for other files", file=sys.stderr
            )


def main(argv: Sequence[str] | None = None) -> int:
    args = build_parser().parse_args(argv)
    try:
        shown = _Warnings()
        with warnings.catch_warnings():
            warnings.showwarning = shown.show
            try:
                code: int = args.func(args)
            finally:
                shown.tell_repeats()
    except DganError as e:
        print(f"dgan: error: {cli_wording(str(e))}", file=sys.stderr)
        return 2
    except BrokenPipeError:  # e.g. `dgan predict ... | head`: the reader has what it wanted
        os.dup2(os.open(os.devnull, os.O_WRONLY), sys.stdout.fileno())  # no second error when Python flushes stdout
        return 0
    except (OSError, MemoryError) as e:  # an output that cannot be written, a file that cannot be read
        what = f"{e.strerror}: {e.filename}" if isinstance(e, OSError) and e.strerror and e.filename else repr(e)
        print(f"dgan: error: {what}", file=sys.stderr)
        return 2
    return code


if __name__ == "__main__":
    raise SystemExit(main())
