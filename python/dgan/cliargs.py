"""The arguments of ``dgan predict`` and ``dgan evaluate`` (what :mod:`dgan.cli` runs with them): the model and
scene, how a scene table is read (its columns, times, classes, repeated and sparse rows), its map, and the output."""

from __future__ import annotations

import argparse
from typing import Any

from dgan.frame import DENOISE_GATE_M
from dgan.records import DUPLICATES
from dgan.scenefiles import time_value


def predict_arguments(sub: Any) -> argparse.ArgumentParser:
    """``dgan predict``'s sub-parser with its arguments."""
    pred = sub.add_parser(
        "predict", help="predict the agents of a scene file at one time (or of every file of a directory or glob)"
    )
    pred.add_argument("model")
    pred.add_argument(
        "scene",
        help="Social-GAN txt (frame id x y; Stanford Drone's and ApolloScape's layouts too: dgan.layouts), CSV "
        "(or ; tab | separated) with agent_id,time,x,y[,...] (other names: --column), parquet/feather, or a "
        "driving scenario with its vector map (ScenarioNet .pkl[.gz] or .json[.gz], GPUDrive .json[.gz], an "
        "Argoverse 2 scenario or sensor-log folder, an INTERACTION track file; times in seconds from its first "
        "step; pickles run code: only files you trust); a "
        "directory or a quoted glob of them predicts each (at its last time, or --time) into one --out table with a "
        "scene column",
    )
    table_options(pred)
    pred.add_argument(
        "--time",
        type=time_value,
        default=None,
        help="current time t_obs in the file's unit, or an ISO 8601 instant where its times are (default: the last)",
    )
    pred.add_argument(
        "--every",
        action="store_true",
        help="predict at every time of the scene (of each scene), into one --out table with a time column",
    )
    map_options(pred)
    pred.add_argument("--modes", type=int, default=3, help="modes per agent (default 3)")
    pred.add_argument(
        "--provider", default="cpu", help="ONNX Runtime execution provider: cpu (default), cuda or cuda:N"
    )
    pred.add_argument(
        "--unknown-classes",
        choices=("error", "ignore"),
        default="error",
        help="agents of classes the model does not know: refuse (default) or leave them out",
    )
    pred.add_argument(
        "--denoise",
        type=float,
        nargs="?",
        const=DENOISE_GATE_M,
        default=None,
        metavar="GATE_M",
        help="smooth tracks whose positions lie GATE_M metres (RMS) or more off their least-squares parabola, for a "
        f"noisy tracker's data (Frame.denoised; {DENOISE_GATE_M} m if no value is given); a model that declares "
        "denoise_gate_m (dgan info) does this itself",
    )
    pred.add_argument("--json", action="store_true", help="print JSON (times, classes, probabilities) to stdout")
    pred.add_argument("--out", default=None, help="write the long table of modes: .csv, .parquet or .jsonl")
    return pred  # type: ignore[no-any-return]


def map_options(pred: Any) -> None:
    """A scene's map: ``--map`` and an image's homography."""
    pred.add_argument(
        "--map",
        default=None,
        help="a bundled scene (eth hotel univ zara1 zara2), an image (for the ETH/UCY models a semantic mask in "
        "dgan.scenes.MASK_PALETTE, not a photo), a vector map JSON, or a Lanelet2 .osm map (INTERACTION's); a "
        "driving scenario's own map serves unless --map names another",
    )
    pred.add_argument("--pixel-to-world", default=None, help="the 3×3 homography file of an image --map")
    pred.add_argument(
        "--no-map", action="store_true", help="predict without a map, a scenario's own too (a model's map optional)"
    )


def evaluate_arguments(sub: Any) -> argparse.ArgumentParser:
    """``dgan evaluate``'s sub-parser with its arguments."""
    ev = sub.add_parser(
        "evaluate",
        help="score a model on a scene file's tracks beside constant velocity: every agent seen over the model's "
        "window and horizon, at every time",
    )
    ev.add_argument("model")
    ev.add_argument("scene", help="a scene file as dgan predict reads it; a directory or a quoted glob pools them")
    table_options(ev)
    map_options(ev)
    ev.add_argument("--modes", type=int, default=None, help="K of best-of-K (default 20, or the model's if fewer)")
    ev.add_argument("--stride", type=int, default=1, help="score every STRIDE-th time (default 1: every time)")
    ev.add_argument(
        "--standing-m",
        type=float,
        default=1.0,
        help="an agent that moved less than this from its first observed to its last true position is standing "
        "(the table's unit; default 1)",
    )
    ev.add_argument(
        "--min-targets",
        type=int,
        default=1,
        help="leave out times with fewer targets (2: the Social-GAN protocol of the ETH/UCY results)",
    )
    ev.add_argument(
        "--unknown-classes",
        choices=("error", "ignore"),
        default="error",
        help="agents of classes the model does not know: refuse (default) or leave them out",
    )
    ev.add_argument("--json", action="store_true", help="print the table's rows as JSON to stdout")
    ev.add_argument("--out", default=None, help="write every target's errors: .csv, .parquet or .jsonl")
    ev.add_argument("--plot", default=None, metavar="PNG", help="draw top-1 beside constant velocity (dgan[plot])")
    ev.add_argument("--plot-horizon", default=None, metavar="PNG", help="draw the mean error at each predicted step")
    return ev  # type: ignore[no-any-return]


def table_options(pred: Any) -> None:
    """How a scene table is read: its columns, time unit, classes and repeated or sparse rows."""
    pred.add_argument(
        "--column",
        action="append",
        metavar="ARG=NAME",
        help="read the column NAME as ARG: agent_id, time, x, y, class, heading, length, width or velocity=VX,VY "
        "(repeatable; e.g. --column agent_id=track_id --column time=timestamp)",
    )
    pred.add_argument(
        "--time-unit",
        type=float,
        default=None,
        help="seconds per unit of the file's time column (default: 1 for tables; Social-GAN files 0.4 s a step, "
        "the other headerless layouts their own)",
    )
    pred.add_argument(
        "--metres-per-pixel",
        type=float,
        default=None,
        help="the scale of a headerless Stanford Drone file's pixels (its video's estimated_scales.yaml)",
    )
    pred.add_argument(
        "--duplicates",
        choices=DUPLICATES,
        default="error",
        help="several rows of one agent at one time: refuse (default), keep the first or last, or their mean",
    )
    pred.add_argument(
        "--upsample", action="store_true", help="interpolate data up to 2.5x sparser than the model's step"
    )
    pred.add_argument(
        "--class-name",
        action="append",
        metavar="LABEL=CLASS",
        help="read LABEL of the class column as CLASS (vehicle, cyclist or pedestrian); repeatable",
    )
    pred.add_argument(
        "--common-classes",
        action="store_true",
        help="read common labels of the class column (car, truck, person, bicycle, TYPE_VEHICLE ...) as dgan's "
        "classes (dgan.COMMON_CLASS_NAMES)",
    )
