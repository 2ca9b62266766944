"""The window cache: each :class:`~training.data.recording.Located` window set's windows, saved under the cache
directory by content and built from its recordings (through the reader the registry handed down) only when absent.

The key holds the spec, the source files' names and sizes, the stride, the builder's version (the target rule, the
tracker noise) and the engine's raster and preprocessing versions (``dgan.contract.CACHE_KEY``), so a change to any of
them builds the windows anew. This module alone reads and writes the cache's files.
"""

from __future__ import annotations

import hashlib
import json
from collections.abc import Sequence
from pathlib import Path

import numpy as np

import dgan
from dgan.contract import CACHE_KEY
from training.data.arrays import Windows
from training.data.recording import Located
from training.data.windows import build_windows
from training.modules.scene import SCENE_TRAIN_PX


def cache_path(found: Located, spec: dgan.InputSpec, cache_dir: Path, scene_px: int = 0) -> Path:
    """Where ``found``'s windows for ``spec`` are cached: a stem naming the set and a key of its content."""
    part, info = found.part, found.info
    if part.pedestrians:
        stem, version = f"pedestrians_{part.dataset}", "pedestrians-v1"
    else:
        stem = f"{part.dataset}{'_' + part.fold if part.fold else ''}_{part.split}"
        # v8: every fully observed agent is a target (hdmap dropped those moving under 1 m before).
        version = f"v8-move{info.min_move_m:g}"
        if part.noise != (0.0, 0.0):
            version += f"-noise{part.noise[0]:g}-drop{part.noise[1]:g}"
        if part.hold > 0:
            version += f"-hold{part.hold:g}" + ("-future" if part.hold_future else "")
        if part.speed != 1.0:
            version += f"-speed{part.speed:g}"
    if scene_px > 0 and spec.map is not None and spec.map.scene is not None:
        version += f"-scene{scene_px}"
    files_key = [(f.name, f.stat().st_size) for f in found.files]
    content = json.dumps([spec.to_json(), files_key, part.stride, version, CACHE_KEY])
    return cache_dir / f"{stem}_{hashlib.sha256(content.encode()).hexdigest()[:16]}.npz"


def read_windows(path: Path) -> Windows:
    """Windows saved by :func:`cached`."""
    with np.load(path, allow_pickle=False) as z:
        d = {k: z[k] for k in z.files}
    d["files"] = [str(f) for f in d["files"]]
    d.setdefault("map", None)
    d.setdefault("map_absent", None)
    d.setdefault("scene", None)
    d.setdefault("scene_grid", None)
    return Windows(**d)


def cached(
    found: Sequence[Located], spec: dgan.InputSpec, cache_dir: Path, progress: bool = True, scene_px: int = 0
) -> list[Windows]:
    """The windows of each set of ``found``, in order: read from ``cache_dir`` when cached, else built by
    :func:`~training.data.windows.build_windows` from the set's recordings and saved (a scene model's with rasters of
    ``scene_px``, ``data.map_scene_px``)."""
    scene_px = scene_px or SCENE_TRAIN_PX
    out = []
    for f in found:
        path = cache_path(f, spec, cache_dir, scene_px)
        if path.is_file():
            out.append(read_windows(path))
            continue
        w = build_windows(
            f.read(), f.info, spec, f.part.stride, progress, f.part.noise, f.part.hold, scene_px, f.part.hold_future
        )
        cache_dir.mkdir(parents=True, exist_ok=True)
        arrays = {k: v for k, v in vars(w).items() if isinstance(v, np.ndarray)}
        np.savez(path, files=np.array(w.files), **arrays)  # type: ignore[arg-type]
        out.append(w)
    return out
