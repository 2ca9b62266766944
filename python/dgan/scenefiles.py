"""The scene files ``dgan predict`` reads: tables of detections (CSV, parquet, Social-GAN text and the other headerless
layouts of :mod:`dgan.layouts`), driving scenarios with their vector maps (ScenarioNet, GPUDrive, Argoverse 2), maps
(an image with its homography, a vector-map JSON, an Argoverse 2 map), and folders or globs of scenes."""

from __future__ import annotations

import csv
import os
import re
from collections.abc import Collection, Sequence
from pathlib import Path
from typing import Any, Final, NamedTuple

import numpy as np
import numpy.typing as npt

import dgan
from dgan import datasets, layouts
from dgan.datasets import is_scenario
from dgan.exceptions import InvalidFrameError, InvalidMapError

#: What may separate the fields of a scene table with a header.
DELIMITERS = ",;\t|"


#: The columns that make a table an INTERACTION track file (:func:`dgan.datasets.lanelet2.read_interaction`).
INTERACTION_COLUMNS: Final = frozenset({"track_id", "frame_id", "timestamp_ms", "agent_type", "x", "y"})
#: How a scenario's ``source`` is named in notes.
SCENARIO_SOURCES: Final = {"nuscenes": "nuScenes", "waymo": "Waymo", "argoverse2": "Argoverse 2"}


class SceneFile(NamedTuple):
    """A scene file read by :func:`read_scene`."""

    #: Its rows as columns for :meth:`dgan.Frame.from_records`.
    columns: dict[str, Any]
    #: The seconds per unit of its time column where the format fixes it (None: a table's, the caller's to say).
    time_unit: float | None
    #: The name of its headerless layout (:mod:`dgan.layouts`) or ``"<source> scenario"``; None for a table.
    layout: str | None
    #: How it was read, for a note (None for a table or a Social-GAN file).
    description: str | None = None
    #: A scenario's own vector map.
    map: dgan.VectorMap | None = None


def read_scenario_file(path: Path) -> SceneFile:
    """A driving scenario (:func:`dgan.datasets.is_scenario`) as a scene file: every valid state of every agent (time
    in seconds from its first step; :meth:`dgan.datasets.scenario.Scenario.records`) and its vector map."""
    scenario = datasets.read(path)
    source = SCENARIO_SOURCES.get(scenario.source, scenario.source)
    what = f"a scenario of {source} ({1 / scenario.dt_s:g} Hz tracks of {len(scenario.ids)} agents, its vector map)"
    return SceneFile(scenario.records(), 1.0, f"{scenario.source} scenario", what, scenario.map)


def read_scene(
    path: Path, text_columns: Collection[str] = ("class",), metres_per_pixel: float | None = None
) -> SceneFile:
    """A scene file (:class:`SceneFile`): a table, a headerless layout (:mod:`dgan.layouts`) or a driving scenario
    with its map (:func:`is_scenario`). In a table with a header, ``text_columns`` are kept as text, other columns of
    numbers (empty fields NaN) become numbers, and any other column stays text (ids that are names, times in ISO
    8601). A headerless file in pixels needs ``metres_per_pixel``."""
    if is_scenario(path):
        return read_scenario_file(path)
    if path.suffix in (".parquet", ".feather", ".arrow") and path.is_file():
        try:
            import pyarrow.feather as feather
            import pyarrow.parquet as pq
        except ImportError:
            raise InvalidFrameError(f"reading {path.suffix} files needs pyarrow: pip install pyarrow") from None
        try:
            table = pq.read_table(path) if path.suffix == ".parquet" else feather.read_table(path)
        except (OSError, ValueError) as e:
            raise InvalidFrameError(f"cannot read {path}: {e}") from None
        return SceneFile(dgan.tables.columns(table), None, None)
    if not path.is_file():
        what = "does not exist" if not path.exists() else "is not a regular file"
        raise InvalidFrameError(f"cannot read scene {path}: it {what}")
    try:
        text = path.read_text(encoding="utf-8-sig")  # a byte-order mark (a spreadsheet's CSV) is no column name
    except (OSError, UnicodeDecodeError, MemoryError) as e:
        raise InvalidFrameError(f"cannot read scene {path}: {e}") from None
    first = text.lstrip().split("\n", 1)[0]
    if not _is_header(first):
        cols, unit, layout = layouts.read(path, metres_per_pixel, text)
        return SceneFile(cols, unit, layout.name, None if layout.name == "social-gan" else layout.describe())
    if {f.strip() for f in first.split(",")} >= INTERACTION_COLUMNS:
        from dgan.datasets.lanelet2 import interaction_companion

        scenario = datasets.read(path, "interaction")
        other = interaction_companion(path)
        joined = "" if other is None else f", with {other.name} beside it"
        what = f"INTERACTION tracks (10 Hz, {len(scenario.ids)} agents{joined}; its Lanelet2 map with --map MAP.osm)"
        return SceneFile(scenario.records(), 1.0, "interaction", what)
    return SceneFile(_header_table(path, text, first, text_columns), None, None)


def _is_header(line: str) -> bool:
    """Whether a file's first line is a header: fields split by one of :data:`DELIMITERS`, one of them no number."""
    return any(d in line and any(not layouts.is_number(f) for f in line.split(d)) for d in DELIMITERS)


def _header_table(path: Path, text: str, header: str, text_columns: Collection[str]) -> dict[str, Any]:
    """A delimited table with a header (comma, semicolon, tab or bar, whichever the header uses) as columns."""
    try:
        dialect = csv.Sniffer().sniff(header, delimiters=DELIMITERS)
    except csv.Error:
        raise InvalidFrameError(
            f"{path}: cannot tell which of {DELIMITERS!r} separates the header {header!r}"
        ) from None
    rows = [r for r in csv.reader(text.splitlines(), delimiter=dialect.delimiter) if any(f.strip() for f in r)]
    if len(rows) < 2:
        raise InvalidFrameError(f"{path} has a header but no rows")
    names = [n.strip() for n in rows[0]]
    if len(set(names)) != len(names):
        raise InvalidFrameError(f"{path}: the header names a column twice: {names}")
    if bad := next((i for i, r in enumerate(rows) if len(r) != len(names)), None):
        raise InvalidFrameError(f"{path}: row {bad} has {len(rows[bad])} fields where the header has {len(names)}")
    cols: dict[str, Any] = {}
    for k, values in zip(names, zip(*rows[1:], strict=True), strict=True):
        text_values = np.asarray([v.strip() for v in values], dtype=object)
        cols[k] = text_values if k in text_columns else _numbers_or_text(text_values)
    return cols


def _numbers_or_text(values: npt.NDArray[Any]) -> npt.NDArray[Any]:
    """A column of text fields as numbers when every field is one (empty fields NaN): whole numbers as int64 (ids),
    others as float64; else the text as it is."""
    try:
        numbers = np.asarray([float(v) if v else np.nan for v in values], dtype=np.float64)
    except ValueError:
        return values
    if all(v.lstrip("-").isdigit() for v in values):
        return numbers.astype(np.int64)
    return numbers


def read_map(spec: str, pixel_to_world: str | None) -> dgan.RasterMap | dgan.VectorMap:
    """``--map``: a bundled ETH/UCY scene name, an image with ``--pixel-to-world``, a vector map JSON (dgan's own
    or an Argoverse 2 map archive), or a Lanelet2 ``.osm`` map (INTERACTION's, from the origin (0, 0))."""
    if spec in dgan.scenes.ETH_UCY_SCENES:
        return dgan.scene_map(spec)
    path = Path(spec)
    if not path.is_file():
        raise InvalidMapError(
            f"--map {spec!r} is neither a bundled scene ({', '.join(dgan.scenes.ETH_UCY_SCENES)}) nor a file"
        )
    if path.suffix.lower() in (".png", ".jpg", ".jpeg"):
        if pixel_to_world is None:
            raise InvalidMapError("an image map needs --pixel-to-world H.txt (its 3×3 pixel → world homography)")
        try:
            homography = np.loadtxt(pixel_to_world, ndmin=2)
        except (OSError, ValueError) as e:
            raise InvalidMapError(f"cannot read --pixel-to-world {pixel_to_world}: {e}") from None
        return dgan.RasterMap.from_pixel_to_world(path, homography)
    if path.suffix.lower() == ".osm":
        from dgan.datasets.lanelet2 import lanelet2_map

        return lanelet2_map(path)  # INTERACTION's origin (0, 0), projected as Lanelet2's UtmProjector does
    try:
        return dgan.VectorMap.from_json(path)
    except InvalidMapError as own:
        from dgan.datasets.hdmaps import av2_map

        try:
            return dgan.VectorMap(av2_map(path))
        except InvalidMapError:
            raise own from None


def scene_files(spec: str) -> list[Path] | None:
    """The scene files ``spec`` names when it is a directory or a glob (sorted), None for one file or scenario. A
    directory's or a glob's Argoverse 2 scenario folders are scenes too."""
    import glob

    path = Path(spec)
    if path.is_dir() and is_scenario(path):
        return None
    if path.is_dir():
        files = sorted(p for p in path.iterdir() if (p.is_file() or is_scenario(p)) and not p.name.startswith("."))
    elif any(c in spec for c in "*?[") and not path.exists():
        files = sorted(Path(p) for p in glob.glob(spec) if Path(p).is_file() or is_scenario(Path(p)))
    else:
        return None
    if not files:
        raise InvalidFrameError(f"no scene files in {spec}")
    return _without_companions(files)


def _without_companions(files: list[Path]) -> list[Path]:
    """``files`` less each INTERACTION ``pedestrian_tracks_*.csv`` whose recording's ``vehicle_tracks_*.csv`` is
    among them: reading the one reads the other too (:func:`dgan.datasets.lanelet2.read_interaction`), so each
    recording is one scene, once."""
    from dgan.datasets.lanelet2 import interaction_companion

    listed = set(files)
    return [f for f in files if not (f.name.startswith("pedestrian_tracks_") and interaction_companion(f) in listed)]


def scene_names(files: Sequence[Path]) -> list[str]:
    """What the ``scene`` column calls each file: its name, or where two files share a name (every video's
    ``annotations.txt``), its path from the folder that holds them all (``quad/video0/annotations.txt``)."""
    if len({f.name for f in files}) == len(files):
        return [f.name for f in files]
    top = Path(os.path.commonpath([f.parent.absolute() for f in files]))
    return [f.absolute().relative_to(top).as_posix() for f in files]


#: ``--column ARG=NAME``: each ARG and the argument of :meth:`dgan.Frame.from_records` that names that column.
COLUMN_ARGUMENTS: Final = {
    "agent_id": "agent_id",
    "time": "time",
    "x": "x",
    "y": "y",
    "class": "cls_column",
    "heading": "heading",
    "length": "length",
    "width": "width",
    "velocity": "velocity",
}


def column_names(options: Sequence[str] | None) -> dict[str, Any]:
    """``--column ARG=NAME`` options (``velocity=VX,VY``) as keyword arguments of :meth:`dgan.Frame.from_records`."""
    out: dict[str, Any] = {}
    for option in options or ():
        arg, _, name = (part.strip() for part in option.partition("="))
        vx, vy = (part.strip() for part in name.partition(",")[::2])
        if arg not in COLUMN_ARGUMENTS or not name or (arg == "velocity" and not (vx and vy)):
            raise InvalidFrameError(
                f"--column takes ARG=NAME with ARG one of {', '.join(COLUMN_ARGUMENTS)} (velocity=VX,VY), "
                f"got {option!r}"
            )
        out[COLUMN_ARGUMENTS[arg]] = (vx, vy) if arg == "velocity" else name
    return out


def cli_wording(text: str) -> str:
    """A message of :meth:`dgan.Frame.from_records` that names its arguments (``agent_id='track_id'``,
    ``time_unit=``) in the options that ``dgan predict`` takes (``--column agent_id=track_id``, ``--time-unit``);
    every error the command line prints passes through it."""
    by_argument = {v: k for k, v in COLUMN_ARGUMENTS.items()}
    text = text.replace("unknown_classes='ignore'", "--unknown-classes ignore")
    text = text.replace('(duplicates="first", "last" or "mean" in Python)', "(--duplicates first, last or mean)")
    text = re.sub(
        r"\b(\w+)='([^']*)'",
        lambda m: f"--column {by_argument[m[1]]}={m[2]}" if m[1] in by_argument else m[0],
        text,
    )
    text = text.replace("class_names=dgan.COMMON_CLASS_NAMES", "--common-classes")
    text = re.sub(r"class_names=\{'([^']*)': \.\.\.\}", r"--class-name \1=CLASS", text)
    text = text.replace("upsample=True in Python", "--upsample")
    return text.replace("time_unit=", "--time-unit")


def class_names(options: Sequence[str] | None, common: bool) -> dict[str, str] | None:
    """``--class-name LABEL=CLASS`` options over :data:`dgan.COMMON_CLASS_NAMES` with ``--common-classes``."""
    names: dict[str, str] = dict(dgan.COMMON_CLASS_NAMES) if common else {}
    for option in options or ():
        label, _, name = (part.strip() for part in option.partition("="))
        if not label or not name:
            raise InvalidFrameError(
                f"--class-name takes LABEL=CLASS (CLASS one of {', '.join(dgan.CLASSES)}), got {option!r}"
            )
        names[label] = name
    return names or None


def time_value(text: str | None) -> float | str | None:
    """``--time``: a number in the file's time unit, or an instant (ISO 8601) as given."""
    if text is None:
        return None
    try:
        return float(text)
    except ValueError:
        return text
