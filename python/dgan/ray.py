"""Scenes on many processes with Ray Data: :class:`Predict`, one :class:`~dgan.Predictor` per actor.

A dataset of many scenes is one long table of detections with a scene column (``scene_id``, ``agent_id``,
``time``, ``x``, ``y`` and any optional column :meth:`dgan.Frame.from_records` reads). Group it by scene, so that
each call sees whole scenes, and map the groups with :class:`Predict` on a pool of actors::

    import ray, dgan.ray
    ds = ray.data.read_parquet("detections/")             # scene_id, agent_id, time, x, y, ...
    out = ds.groupby("scene_id").map_groups(
        dgan.ray.Predict, fn_constructor_kwargs={"model": "hdmap", "modes": 3},
        concurrency=2, batch_format="pyarrow",
    )
    out.write_parquet("predictions/")                      # scene_id + Prediction.to_records() columns

``map_batches`` works as well when every batch holds whole scenes (one scene per block, ``batch_size=None``). Each
scene is predicted at its latest time (or ``current_time``), as ``dgan predict`` does. Needs ``pip install
'dgan[ray]'``; this module imports neither Ray nor pyarrow itself.
"""

from __future__ import annotations

from typing import Any

import numpy as np
import numpy.typing as npt

from dgan.exceptions import InvalidFrameError
from dgan.frame import Frame
from dgan.predictor import Predictor
from dgan.tables import columns

__all__ = ["Predict", "predict_scenes"]


def predict_scenes(
    predictor: Predictor,
    table: Any,
    *,
    scene_column: str = "scene_id",
    modes: int | None = None,
    unknown_classes: str = "error",
    **records: Any,
) -> dict[str, npt.NDArray[Any]]:
    """Every scene of a long table predicted: the prediction long tables of :meth:`Prediction.to_records`, one
    after the other in the order the scenes first appear, with the scene column first. ``records`` are options of
    :meth:`Frame.from_records` (``time_unit``, ``current_time``, ``upsample``, column names ...)."""
    cols = columns(table)
    if scene_column not in cols:
        raise InvalidFrameError(f"the table has no scene column {scene_column!r}; it has {list(cols)}")
    scenes = cols[scene_column]
    order = list(dict.fromkeys(scenes.tolist()))
    parts: list[dict[str, npt.NDArray[Any]]] = []
    for scene in order:
        rows = scenes == scene
        frame = Frame.from_records({k: v[rows] for k, v in cols.items()}, spec=predictor, **records)
        out = predictor.predict(frame, modes=modes, unknown_classes=unknown_classes).to_records()
        n = len(out["x"])
        parts.append({scene_column: np.repeat(scenes[rows][:1], n), **out})
    if not parts:
        return {scene_column: scenes[:0]}
    return {k: np.concatenate([p[k] for p in parts]) for k in parts[0]}


class Predict:
    """A callable class for Ray Data (``map_groups`` by scene, or ``map_batches`` of whole scenes): loads its
    :class:`~dgan.Predictor` once per actor and turns each batch of detections into prediction rows
    (:func:`predict_scenes`).

    Args:
        model: a bundled model's name, an ``.onnx`` path, or a :class:`~dgan.Predictor` (it pickles as its file and
            options, so each actor loads its own).
        modes, unknown_classes: as :meth:`Predictor.predict`.
        scene_column: the column naming each row's scene.
        threads: ONNX Runtime threads per actor (1: one core per actor).
        records: options of :meth:`Frame.from_records` (``time_unit``, ``current_time``, ``upsample`` ...).
    """

    def __init__(
        self,
        model: str | Predictor = "hdmap",
        *,
        modes: int | None = None,
        unknown_classes: str = "error",
        scene_column: str = "scene_id",
        threads: int = 1,
        **records: Any,
    ) -> None:
        self.predictor = model if isinstance(model, Predictor) else Predictor(model, threads=threads, sessions=1)
        self.options = {"scene_column": scene_column, "modes": modes, "unknown_classes": unknown_classes, **records}

    def __call__(self, batch: Any) -> dict[str, npt.NDArray[Any]]:
        return predict_scenes(self.predictor, batch, **self.options)
