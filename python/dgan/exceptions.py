"""The exceptions of dgan. Each subclasses :class:`DganError` and the matching built-in, so ``except ValueError``
keeps working for callers who do not know dgan's own classes.

The native engine maps each of its error kinds to exactly one of these classes.
"""

from __future__ import annotations

__all__ = [
    "ColumnWarning",
    "ContractError",
    "DatasetWarning",
    "DganError",
    "HeadingWarning",
    "InferenceError",
    "InvalidFrameError",
    "InvalidMapError",
    "InvalidSpecError",
    "MapRequiredError",
    "MapWarning",
    "ModelLoadError",
    "ModelNotFoundError",
    "NoTargetError",
    "OutputError",
    "RuntimeLibraryError",
    "TimeUnitWarning",
    "UnitWarning",
    "UnknownClassError",
]


class DganError(Exception):
    """Base class of every dgan error."""


class InvalidFrameError(DganError, ValueError):
    """A frame's arrays are inconsistent or hold invalid values (NaN, wrong shapes, no valid step)."""


class MapRequiredError(InvalidFrameError):
    """A model whose map branch needs a map was given a frame without one. Pass the map in the frame
    (``map=dgan.VectorMap(...)``, ``dgan.RasterMap(...)`` or ``dgan.scene_map(name)``), or use a model trained with
    optional maps (``spec.map.optional``), which serves frames without a map."""


class TimeBaseError(InvalidFrameError):
    """The frame's time base differs from the model's, or the data cannot be resampled to it (too sparse,
    unordered times)."""


class NoTargetError(InvalidFrameError):
    """A table with nothing to score (:func:`dgan.evaluate`): no agent seen over the model's window and horizon."""


class SceneTooLargeError(InvalidFrameError, MemoryError):
    """A scene whose attention graph or input tensors exceed the predictor's limits (``max_edges``,
    ``max_input_bytes``), refused before the memory is allocated."""


class UnknownClassError(DganError, ValueError):
    """A class name or code that dgan or the model does not know."""


class InvalidMapError(DganError, ValueError):
    """A raster or vector map that cannot be used."""


class InvalidSpecError(DganError, ValueError):
    """An input specification or option that cannot be satisfied."""


class ModelNotFoundError(DganError, FileNotFoundError):
    """The model file does not exist."""


class ModelLoadError(DganError, ValueError):
    """The model file exists but is not a readable ONNX model (corrupt, truncated)."""


class ContractError(DganError, ValueError):
    """The model loads but breaks the dgan model contract (inputs, outputs or metadata)."""


class RuntimeLibraryError(DganError, OSError):
    """The ONNX Runtime shared library cannot be found or loaded."""


class InferenceError(DganError, RuntimeError):
    """ONNX Runtime failed while running a loaded model."""


class OutputError(DganError, ValueError):
    """A prediction that an output format cannot hold: ids of mixed types, or integers past 64 bits, in an Arrow
    table or parquet file (pandas and numpy hold them)."""


class ColumnWarning(UserWarning):
    """A table has no column of a name :meth:`~dgan.Frame.from_records` reads but one close to it (``Class`` for
    ``class``): it is not read; pass its name (``cls_column="Class"``) to read it."""


class DatasetWarning(UserWarning):
    """A scenario file read by :mod:`dgan.datasets` holds something its reader leaves out or replaces: map element
    types that are not drawn (named with their counts), agents whose box has no size (their class default is used)."""


class TimeUnitWarning(UserWarning):
    """No agent of a frame built from a table has two observed steps: the time column is most likely in another
    unit than ``time_unit`` says (milliseconds read as seconds), and every prediction would start from a single
    position."""


class MapWarning(UserWarning):
    """A raster map that is not the kind of map the model read in training: most of its pixels are not colours of
    the semantic mask (:data:`dgan.scenes.MASK_PALETTE`) that the ETH/UCY models take (a photo, say). Such a map
    makes their predictions worse than no map at all (docs/models.md). Issued once per :class:`~dgan.Predictor`."""


class HeadingWarning(UserWarning):
    """A frame's measured headings do not follow its agents' motion (median disagreement over 45° among the agents
    moving at 1 m/s or more), for a model that takes measured headings: most likely another convention (degrees,
    compass bearings, the rear of the box). Every agent-centric frame is then turned by that much. Pass headings in
    radians, counter-clockwise from the world x axis, along the direction of travel; or pass none (the engine then
    takes the direction of motion). Issued once per :class:`~dgan.Predictor`."""


class UnitWarning(UserWarning):
    """A frame's agents move implausibly fast for their class (the median over at least three moving agents of a
    class beyond 6 m/s for pedestrians, 35 for cyclists, 70 for vehicles, taking the positions as metres and the
    steps as the model's): the positions are most likely in pixels or centimetres, or the times in another unit than
    ``time_unit`` says. Every model takes metres; a scene in pixels needs its homography first. Issued once per
    :class:`~dgan.Predictor`."""
