"""ApolloScape trajectory (2 Hz; class, length, width, heading), split by recording; no map."""

from __future__ import annotations

import re
from pathlib import Path

import numpy as np

from training.data.recording import Recording

#: ApolloScape recordings held out for testing and validation; the other recordings train.
APOLLO_TEST = (9048, 9056, 9058, 9061)


APOLLO_VAL = (9049, 9060)


def apollo_recording_id(path: Path) -> int:
    m = re.fullmatch(r"result_(\d+)_\d+_frame", path.stem)
    if m is None:
        raise ValueError(f"not an ApolloScape trajectory file name: {path.name}")
    return int(m.group(1))


def apollo_val_recordings(fold: str) -> tuple[int, ...]:
    """The ApolloScape recordings of the validation split: ``fold`` (comma-separated recording numbers, never a test
    recording) or, if empty, :data:`APOLLO_VAL`."""
    if not fold:
        return APOLLO_VAL
    try:
        ids = tuple(int(x) for x in fold.split(","))
    except ValueError:
        raise ValueError(f"data.val_recordings must be comma-separated recording numbers, got {fold!r}") from None
    if clash := sorted(set(ids) & set(APOLLO_TEST)):
        raise ValueError(f"data.val_recordings {clash} are test recordings (training.data.datasets.APOLLO_TEST)")
    return ids


def apollo_files(root: Path, split: str, fold: str = "") -> list[Path]:
    """The files of a split; ``fold`` names the validation recordings (:func:`apollo_val_recordings`)."""
    folder = root / "apolloscape_trajectory" / "prediction_train"
    files = sorted(folder.glob("result_*_frame.txt"))
    if not files:
        raise FileNotFoundError(f"no ApolloScape files in {folder}; set data.root to the folder holding it")
    val = apollo_val_recordings(fold)
    if missing := sorted(set(val) - {apollo_recording_id(p) for p in files}):
        raise ValueError(f"no ApolloScape recording {missing} in {folder}")
    held = {"test": APOLLO_TEST, "val": val}
    if split == "train":
        return [p for p in files if apollo_recording_id(p) not in APOLLO_TEST + val]
    return [p for p in files if apollo_recording_id(p) in held[split]]


def apollo_recording(path: Path) -> Recording:
    rows = np.loadtxt(path, ndmin=2)
    types = rows[:, 2].astype(np.int64)
    if not np.isin(types, [1, 2, 3, 4, 5]).all():
        raise ValueError(f"{path.name}: object types must be 1..5, found {sorted(set(types.tolist()))}")
    return Recording.sorted(
        name=path.stem,
        step=rows[:, 0].astype(np.int64),
        agent=rows[:, 1].astype(np.int64),
        xy=rows[:, 3:5].astype(np.float64),
        label=types - 1,
        heading=rows[:, 9].astype(np.float64),
        length=rows[:, 6].astype(np.float64),
        width=rows[:, 7].astype(np.float64),
    )
