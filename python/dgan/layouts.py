"""The headerless text layouts of public trajectory datasets that ``dgan predict`` and ``dgan evaluate`` read
(:func:`dgan.scenefiles.read_scene`): one agent at one time per row, fields split by white space. A file's layout is
told by how many fields its rows have and whether the last is a label; any other file is refused, never read as its
first four columns.

>>> from dgan.layouts import LAYOUTS
>>> [(layout.name, " ".join(layout.fields)) for layout in LAYOUTS][-1]
('apolloscape', 'frame id type x y z length width height heading')

Positions are metres, or image pixels times ``metres_per_pixel`` (Stanford Drone), as its model was trained; a Stanford
Drone annotation marked lost (outside the view) is left out.
"""

from __future__ import annotations

import os
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Final

import numpy as np
import numpy.typing as npt

from dgan.exceptions import InvalidFrameError
from dgan.scenes import APOLLO_TYPES, SDD_LABEL_CLASS

#: Seconds between the annotations of a Social-GAN layout file (ETH/UCY), whatever its frame numbering.
SOCIAL_GAN_DT_S = 0.4

Rows = npt.NDArray[np.str_]
Numbers = npt.NDArray[np.float64]
#: A layout's columns for :meth:`dgan.Frame.from_records`, and which rows are observations of an agent in view.
Read = tuple[dict[str, Any], npt.NDArray[np.bool_]]


@dataclass(frozen=True)
class Layout:
    """One headerless layout: its fields as the source names them, and how its rows become the columns
    :meth:`dgan.Frame.from_records` reads."""

    name: str
    source: str
    fields: tuple[str, ...]
    #: Whether the last field is a text label (the other fields are numbers).
    labelled: bool
    #: Whether positions are image pixels (read with ``metres_per_pixel``), not metres.
    pixels: bool
    #: Seconds per unit of the time field; None: the Social-GAN rule (0.4 s over the smallest step between frames).
    seconds_per_unit: float | None
    #: Its rows' numbers (every field but a label), their last fields as text (the labels), the scale and the path.
    read: Callable[[Numbers, Rows, float, Path], Read]

    def describe(self) -> str:
        unit = "metres" if not self.pixels else "pixels"
        return f"{self.name} ({' '.join(self.fields)}; {self.source}, {unit})"


def _numbers(rows: Rows, path: Path, layout: str) -> Numbers:
    try:
        return rows.astype(np.float64)
    except ValueError as e:
        raise InvalidFrameError(f"{path}: a field of the {layout} layout is not a number: {e}") from None


def _all(rows: Numbers) -> npt.NDArray[np.bool_]:
    return np.ones(len(rows), dtype=bool)


def _social_gan(rows: Numbers, _labels: Rows, _scale: float, _path: Path) -> Read:
    return {"time": rows[:, 0], "agent_id": rows[:, 1], "x": rows[:, 2], "y": rows[:, 3]}, _all(rows)


def _sdd_steps(rows: Numbers, labels: Rows, scale: float, _path: Path) -> Read:
    cols = {"time": rows[:, 0], "agent_id": rows[:, 1], "x": rows[:, 2] * scale, "y": rows[:, 3] * scale}
    return cols | {"class": _sdd_classes(labels)}, _all(rows)


def _sdd_annotations(rows: Numbers, labels: Rows, scale: float, _path: Path) -> Read:
    centre = (rows[:, 1:3] + rows[:, 3:5]) / 2 * scale
    cols = {"time": rows[:, 5], "agent_id": rows[:, 0], "x": centre[:, 0], "y": centre[:, 1]}
    return cols | {"class": _sdd_classes(labels)}, rows[:, 6] == 0  # lost: the agent is outside the view


def _apolloscape(rows: Numbers, _labels: Rows, _scale: float, path: Path) -> Read:
    cols = {"time": rows[:, 0], "agent_id": rows[:, 1], "x": rows[:, 3], "y": rows[:, 4]}
    sizes = {"length": rows[:, 6], "width": rows[:, 7], "heading": rows[:, 9]}
    return cols | sizes | {"class": _apollo_classes(rows[:, 2], path)}, _all(rows)


def _sdd_classes(labels: Rows) -> npt.NDArray[np.object_]:
    """Stanford Drone's labels (quoted in a video's annotations) as dgan's classes; others as they are."""
    return np.array([SDD_LABEL_CLASS.get(s, s) for s in np.char.strip(labels, '"')], dtype=object)


#: The layouts :func:`read` tells apart, by their rows' field counts and labels.
LAYOUTS: Final = (
    Layout(
        "social-gan", "ETH/UCY as Social-GAN releases it", ("frame", "id", "x", "y"), False, False, None, _social_gan
    ),
    Layout(
        "sdd-steps",
        "Stanford Drone at every 10th video frame, 1/3 s",
        ("step", "id", "x", "y", "label"),
        True,
        True,
        1 / 3,
        _sdd_steps,
    ),
    Layout(
        "sdd-annotations",
        "a Stanford Drone video's annotations.txt, 30 frames a second",
        ("track_id", "xmin", "ymin", "xmax", "ymax", "frame", "lost", "occluded", "generated", "label"),
        True,
        True,
        1 / 30,
        _sdd_annotations,
    ),
    Layout(
        "apolloscape",
        "ApolloScape trajectory, 2 Hz",
        ("frame", "id", "type", "x", "y", "z", "length", "width", "height", "heading"),
        False,
        False,
        0.5,
        _apolloscape,
    ),
)


def by_name(name: str) -> Layout:
    """The layout called ``name``."""
    return next(lay for lay in LAYOUTS if lay.name == name)


def layout_of(first_row: str) -> Layout | None:
    """The layout whose rows look like ``first_row`` (its field count, and whether the last field is a number)."""
    fields = first_row.split()
    if not fields:
        return None
    labelled = not is_number(fields[-1])
    return next((lay for lay in LAYOUTS if len(lay.fields) == len(fields) and lay.labelled == labelled), None)


def is_number(field: str) -> bool:
    """Whether a text field reads as a number."""
    try:
        float(field)
    except ValueError:
        return False
    return True


def read(
    path: str | os.PathLike[str], metres_per_pixel: float | None = None, text: str | None = None
) -> tuple[dict[str, Any], float, Layout]:
    """A headerless scene file as columns for :meth:`dgan.Frame.from_records` (``class`` in dgan's classes where the
    layout has labels or types), the seconds per unit of its time column (its ``time_unit``), and its layout. Pixel
    layouts need ``metres_per_pixel``. ``text``: the file's text, if already read.

    >>> import dgan
    >>> from dgan.demo import APOLLO_FILE                   # frames 10..25 of an ApolloScape recording
    >>> cols, time_unit, layout = read(APOLLO_FILE)
    >>> layout.name, time_unit, sorted(cols)
    ('apolloscape', 0.5, ['agent_id', 'class', 'heading', 'length', 'time', 'width', 'x', 'y'])
    >>> frame = dgan.Frame.from_records(cols, t_obs=6, dt=0.5, time_unit=time_unit)
    """
    if not isinstance(path, (str, os.PathLike)):
        raise InvalidFrameError(f"a scene file's path must be a str or a path, got {type(path).__name__}")
    path = Path(path)
    if text is None:
        try:
            text = path.read_text(encoding="utf-8-sig")
        except (OSError, UnicodeDecodeError, MemoryError) as e:
            raise InvalidFrameError(f"cannot read scene {path}: {e}") from None
    first = next((line for line in text.splitlines() if line.strip()), "")
    layout = layout_of(first)
    if layout is None:
        known = "; ".join(lay.describe() for lay in LAYOUTS)
        raise InvalidFrameError(
            f"{path} is neither a CSV with a header nor a known headerless layout: its first row has "
            f"{len(first.split())} fields ({first.strip()[:60]!r}). Known layouts: {known}"
        )
    if layout.pixels and metres_per_pixel is None:
        raise InvalidFrameError(
            f"{path} is in the {layout.describe()} layout, in image pixels: give --metres-per-pixel S (Python: "
            "metres_per_pixel=S; each Stanford Drone video's S is in its estimated_scales.yaml; hyang video0: "
            "0.034749693)"
        )
    scale = 1.0 if metres_per_pixel is None else _scale(metres_per_pixel)
    rows = _rows(path, text, layout)
    numbers = _numbers(rows[:, : len(layout.fields) - layout.labelled], path, layout.name)
    cols, seen = layout.read(numbers, rows[:, -1], scale, path)
    cols["agent_id"] = _ids(cols["agent_id"], path)
    return {k: v[seen] for k, v in cols.items()}, _seconds_per_unit(layout, cols["time"]), layout


def _rows(path: Path, text: str, layout: Layout) -> Rows:
    lines = [line.split() for line in text.splitlines() if line.strip()]
    if bad := next((i for i, f in enumerate(lines) if len(f) != len(layout.fields)), None):
        raise InvalidFrameError(
            f"{path}: row {bad + 1} has {len(lines[bad])} fields where the {layout.name} layout has "
            f"{len(layout.fields)}"
        )
    return np.asarray(lines, dtype=str)


def _scale(metres_per_pixel: float) -> float:
    number = isinstance(metres_per_pixel, (int, float)) and not isinstance(metres_per_pixel, bool)
    if not (number and 0 < metres_per_pixel < float("inf")):
        raise InvalidFrameError(f"metres per pixel must be a positive number, got {metres_per_pixel!r:.40}")
    return float(metres_per_pixel)


def _ids(ids: npt.NDArray[np.float64], path: Path) -> npt.NDArray[np.int64]:
    if not (np.isfinite(ids).all() and (ids == np.round(ids)).all()):
        raise InvalidFrameError(f"{path}: agent ids must be whole numbers")
    return ids.astype(np.int64)


def _apollo_classes(types: npt.NDArray[np.float64], path: Path) -> npt.NDArray[np.object_]:
    if bad := sorted(set(types.tolist()) - set(APOLLO_TYPES)):
        raise InvalidFrameError(f"{path}: ApolloScape object types are 1..5, found {bad[:5]}")
    return np.array([APOLLO_TYPES[int(t)][1] for t in types], dtype=object)


def _seconds_per_unit(layout: Layout, times: npt.NDArray[np.float64]) -> float:
    if layout.seconds_per_unit is not None:
        return layout.seconds_per_unit
    steps = np.diff(np.unique(times))
    return SOCIAL_GAN_DT_S / float(steps.min()) if steps.size and steps.min() > 0 else 1.0
