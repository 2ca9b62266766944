"""Other names for dgan's classes: the labels detectors, trackers and datasets give their objects (``car``,
``person``, ``bicycle``, ``TYPE_VEHICLE`` ...), read as ``vehicle``, ``cyclist`` or ``pedestrian`` when asked
(``class_names=`` of :meth:`dgan.Frame.from_records` and :class:`dgan.Tracker`, ``dgan predict --common-classes``).

Nothing is renamed unless asked: which of a source's labels are which class is the user's to say (a motorcycle may
be a vehicle in one dataset and a cyclist's in another, so it is not in the table).
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from typing import Any, Final

import numpy as np
import numpy.typing as npt

from dgan._values import ClassLike, shown, typename
from dgan.contract import CLASSES
from dgan.exceptions import InvalidFrameError, InvalidSpecError, UnknownClassError

_VEHICLES = (
    "car",
    "truck",
    "bus",
    "van",
    "trailer",
    "vehicle",
    "regular_vehicle",
    "large_vehicle",
    "type_vehicle",
    "construction_vehicle",
    "emergency_vehicle",
    "pickup",
    "suv",
    "taxi",
    "lorry",
)
_CYCLISTS = ("bicycle", "bike", "cyclist", "bicyclist", "type_cyclist", "motorcyclist", "rider", "riderless_bicycle")
_PEDESTRIANS = ("person", "people", "pedestrian", "ped", "walker", "type_pedestrian", "adult", "child", "human")

#: Common labels (compared without case, around spaces) and the dgan class each is read as, for ``class_names=``.
COMMON_CLASS_NAMES: Final[Mapping[str, str]] = {
    **dict.fromkeys(_VEHICLES, "vehicle"),
    **dict.fromkeys(_CYCLISTS, "cyclist"),
    **dict.fromkeys(_PEDESTRIANS, "pedestrian"),
}


def _key(label: Any) -> Any:
    return label.strip().lower() if isinstance(label, str) else label


def relabelled(labels: Sequence[Any], class_names: Mapping[Any, ClassLike] | None) -> list[Any]:
    """``labels`` with each one ``class_names`` names (without case, for strings) read as the class it gives; other
    labels as they are.

    Raises:
        InvalidSpecError: ``class_names`` is not a mapping.
        UnknownClassError: a label left that is no dgan class but a common name of one (the error says to pass
            ``class_names=dgan.COMMON_CLASS_NAMES``).
    """
    if class_names is None:
        _refuse_common(labels)
        return list(labels)
    if not isinstance(class_names, Mapping):
        raise InvalidSpecError(f"class_names must map labels to dgan classes, got {shown(class_names)}")
    table = {_key(k): v for k, v in class_names.items()}
    out = [table.get(_key(label), label) for label in labels]
    _refuse_common(out)
    return out


def _refuse_common(labels: Sequence[Any]) -> None:
    for label in dict.fromkeys(labels):
        key = _key(label)
        if isinstance(key, str) and key not in CLASSES and key in COMMON_CLASS_NAMES:
            raise UnknownClassError(
                f"{label!r} is no dgan class (known: {', '.join(CLASSES)}); class_names=dgan.COMMON_CLASS_NAMES reads "
                f"it as {COMMON_CLASS_NAMES[key]!r} (or map your labels yourself: class_names={{'{label}': ...}})"
            )


def classes_of(
    classes: Sequence[ClassLike] | npt.ArrayLike | None, n: int, class_names: Mapping[Any, ClassLike] | None
) -> list[Any]:
    """One class per agent of a frame built from arrays, its labels read through ``class_names``: what
    :class:`dgan.Frame` gives the engine (which refuses the names and codes it does not know)."""
    if classes is None:
        return ["pedestrian"] * n
    if isinstance(classes, (str, bytes)) or not hasattr(classes, "__iter__"):
        raise InvalidFrameError(f"classes must be a sequence with one class per agent, got {typename(classes)}")
    given = np.asarray(classes).tolist() if isinstance(classes, np.ndarray) else list(classes)  # type: ignore[arg-type]
    out = relabelled(given, class_names)
    for c in out:
        if isinstance(c, bool) or not isinstance(c, (str, int)):
            raise UnknownClassError(f"a class must be a name {CLASSES} or a code 0, 1, 2; got {c!r}")
    return out
