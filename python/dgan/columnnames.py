"""The columns of a long table that :meth:`dgan.Frame.from_records` reads, by name: the keywords that name them,
the names trackers give them instead (for the hint of a missing column), and the check of a table's columns."""

from __future__ import annotations

import difflib
import warnings
from dataclasses import dataclass
from typing import Any, Final

from dgan._values import checked_text
from dgan.exceptions import ColumnWarning, InvalidFrameError
from dgan.tables import Columns


@dataclass(frozen=True)
class Names:
    """The table's column names :meth:`~dgan.Frame.from_records` reads, by what they hold, and the argument that
    names each."""

    agent_id: str = "agent_id"
    time: str = "time"
    x: str = "x"
    y: str = "y"
    cls: str = "class"
    heading: str = "heading"
    length: str = "length"
    width: str = "width"
    vx: str = "vx"
    vy: str = "vy"

    def required(self) -> dict[str, str]:
        return {"agent_id": self.agent_id, "time": self.time, "x": self.x, "y": self.y}

    def optional(self) -> list[tuple[str, str]]:
        """(argument, column) of each optional column; both velocity columns are named by ``velocity``."""
        return [
            ("cls_column", self.cls),
            ("heading", self.heading),
            ("length", self.length),
            ("width", self.width),
            ("velocity", self.vx),
            ("velocity", self.vy),
        ]


#: The keywords of :meth:`~dgan.Frame.from_records` that name its columns (``velocity``: the (vx, vy) pair).
NAME_ARGUMENTS: Final = ("agent_id", "time", "x", "y", "cls_column", "heading", "length", "width", "velocity")


def names_of(
    agent_id: str, time: str, x: str, y: str, cls_column: str, heading: str, length: str, width: str, velocity: Any
) -> Names:
    """The :class:`Names` of :meth:`~dgan.Frame.from_records`' column keywords, each checked."""
    if not (isinstance(velocity, (tuple, list)) and len(velocity) == 2):
        raise InvalidFrameError(f"velocity must be a pair of column names (vx, vy), got {velocity!r:.60}")
    single = (agent_id, time, x, y, cls_column, heading, length, width)
    return Names(
        *(checked_text(arg, c) for arg, c in zip(NAME_ARGUMENTS[:-1], single, strict=True)),
        *(checked_text("velocity", c) for c in velocity),
    )


#: Other names trackers and datasets give the columns :meth:`~dgan.Frame.from_records` reads (compared without case,
#: ``_`` or ``-``), so that a table holding one of them is told which argument reads it.
SYNONYMS: Final = {
    "agent_id": ("trackid", "track", "objectid", "obj", "objid", "id", "agent", "pedid", "uid", "instanceid"),
    "time": ("timestamp", "t", "frame", "frameid", "ts", "times", "timestamps", "timestampns", "sec", "seconds"),
    "x": ("posx", "positionx", "centerx", "xm", "px", "utmx", "east", "easting"),
    "y": ("posy", "positiony", "centery", "ym", "py", "utmy", "north", "northing"),
    "class": ("type", "category", "label", "objecttype", "agenttype", "objectclass", "classname", "cls"),
    "heading": ("yaw", "theta", "orientation", "angle", "headingrad"),
    "length": ("len", "l", "dimx", "sizex"),
    "width": ("w", "dimy", "sizey"),
    "vx": ("velocityx", "velx", "speedx"),
    "vy": ("velocityy", "vely", "speedy"),
}


def _key(name: str) -> str:
    return name.lower().replace("_", "").replace("-", "").replace(" ", "")


def _close(name: str, candidates: list[str], cutoff: float = 0.8) -> str | None:
    """The candidate that is ``name`` but for case, one of its :data:`SYNONYMS`, or the one closest to it (difflib
    ratio ≥ ``cutoff``)."""
    for c in candidates:
        if c.lower() == name.lower():
            return c
    synonyms = SYNONYMS.get(name, ())
    for c in candidates:
        if _key(c) in synonyms:
            return c
    best = difflib.get_close_matches(name, candidates, n=1, cutoff=cutoff)
    return best[0] if best else None


def check_columns(cols: Columns, names: Names) -> None:
    """Refuses a missing required column (naming a close match) and warns (:class:`ColumnWarning`) of an optional
    column that is absent while one close to it is there, unread."""
    for arg, name in names.required().items():
        if name not in cols:
            close = _close(name, list(cols), cutoff=0.6)
            hint = f"; did you mean {close!r} ({arg}={close!r})?" if close else ""
            if close and arg == "time" and _key(close).startswith("frame"):
                hint = hint[:-2] + ", with time_unit= the seconds per frame)?"
            raise InvalidFrameError(f"records lack the column {name!r}; they have {list(cols)}{hint}")
    known = set(names.required().values()) | {name for _, name in names.optional()}
    unread = [c for c in cols if c not in known]
    for arg, name in names.optional():
        close = None if name in cols else _close(name, unread)
        if close is not None:
            warnings.warn(
                f"the table has no column {name!r} but has {close!r}, which is not read; pass "
                f"{arg}={close!r} to read it" + (" (as a (vx, vy) pair)" if arg == "velocity" else ""),
                ColumnWarning,
                stacklevel=5,
            )
