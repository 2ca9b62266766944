"""The scene files ``dgan predict`` reads: tables of detections (CSV, parquet, Social-GAN text, JSON), maps (an
image with its homography, a vector-map JSON, an Argoverse 2 map), and folders or globs of scenes."""

from __future__ import annotations

import csv
from pathlib import Path
from typing import Any

import numpy as np

import dgan
from dgan.exceptions import InvalidFrameError, InvalidMapError

#: Seconds between the annotations of a Social-GAN layout file (ETH/UCY), whatever its frame numbering.
#: Seconds between the annotations of a Social-GAN layout file (ETH/UCY), whatever its frame numbering.
SOCIAL_GAN_DT_S = 0.4


def read_scene(path: Path) -> tuple[dict[str, Any], float | None]:
    """A scene file as columns, and the seconds per unit of its time column when the format fixes it."""
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
        return dgan.tables.columns(table), None
    if not path.is_file():
        what = "does not exist" if not path.exists() else "is not a regular file"
        raise InvalidFrameError(f"cannot read scene {path}: it {what}")
    try:
        text = path.read_text()
    except (OSError, UnicodeDecodeError, MemoryError) as e:
        raise InvalidFrameError(f"cannot read scene {path}: {e}") from None
    first = text.lstrip().split("\n", 1)[0]
    if "," in first and any(c.isalpha() for c in first):
        rows = list(csv.DictReader(text.splitlines()))
        if not rows:
            raise InvalidFrameError(f"{path} has a header but no rows")
        cols: dict[str, Any] = {k: [r[k] for r in rows] for k in rows[0]}
        for k in list(cols):
            if k in ("class", "agent_id"):
                cols[k] = np.asarray(cols[k], dtype=object)
                continue
            try:
                cols[k] = np.asarray(cols[k], dtype=np.float64)
            except ValueError as e:
                raise InvalidFrameError(f"{path}: column {k!r} is not numeric: {e}") from None
        ids = cols.get("agent_id")
        if ids is not None and all(str(v).lstrip("-").isdigit() for v in ids):
            cols["agent_id"] = ids.astype(np.int64)
        return cols, None
    try:
        data = np.loadtxt(path, ndmin=2)
    except ValueError as e:
        raise InvalidFrameError(f"{path} is neither a CSV with a header nor `frame id x y` rows: {e}") from None
    if data.shape[1] < 4 or data.shape[0] == 0:
        raise InvalidFrameError(f"{path}: expected rows of 4 columns (frame id x y), found shape {data.shape}")
    steps = np.diff(np.unique(data[:, 0]))
    unit = SOCIAL_GAN_DT_S / float(steps.min()) if steps.size else 1.0
    return {"time": data[:, 0], "agent_id": data[:, 1].astype(np.int64), "x": data[:, 2], "y": data[:, 3]}, unit


def read_map(spec: str, pixel_to_world: str | None) -> dgan.RasterMap | dgan.VectorMap:
    """``--map``: a bundled ETH/UCY scene name, an image with ``--pixel-to-world``, or a vector map JSON (dgan's own
    or an Argoverse 2 map archive)."""
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
    try:
        return dgan.VectorMap.from_json(path)
    except InvalidMapError as own:
        from dgan.datasets.hdmaps import av2_map

        try:
            return dgan.VectorMap(av2_map(path))
        except InvalidMapError:
            raise own from None


def scene_files(spec: str) -> list[Path] | None:
    """The scene files ``spec`` names when it is a directory or a glob (sorted), None for one file."""
    import glob

    path = Path(spec)
    if path.is_dir():
        files = sorted(p for p in path.iterdir() if p.is_file() and not p.name.startswith("."))
    elif any(c in spec for c in "*?[") and not path.exists():
        files = sorted(Path(p) for p in glob.glob(spec) if Path(p).is_file())
    else:
        return None
    if not files:
        raise InvalidFrameError(f"no scene files in {spec}")
    return files
