"""What ``dgan predict`` writes: a prediction as JSON (``--json``), and the long table of modes of one or several
predictions as CSV, parquet or JSON lines (``--out``), written atomically."""

from __future__ import annotations

import csv
import io
import json
from collections.abc import Sequence
from pathlib import Path
from typing import Any

import dgan
from dgan._times import iso_text
from dgan.exceptions import InvalidFrameError


def prediction_json(pred: dgan.Prediction, frame: dgan.Frame, model: str, now: float | str) -> dict[str, Any]:
    return {
        "model": model,
        "current_time": now,
        "dt_s": pred.dt_s,
        "times_s": pred.times_s.tolist(),
        "classes": list(pred.classes),
        "agents": [
            {
                "id": pred.agent_ids[i].item() if hasattr(pred.agent_ids[i], "item") else pred.agent_ids[i],
                "class": frame.classes[i],
                "class_probabilities": dict(zip(pred.classes, pred.class_probabilities[i].tolist(), strict=True)),
                "modes": [
                    {
                        "probability": float(pred.probabilities[i, m]),
                        "class": pred.classes[pred.mode_classes[i, m]],
                        "trajectory": pred.trajectories[i, m].tolist(),
                    }
                    for m in range(pred.trajectories.shape[1])
                ],
            }
            for i in range(len(pred))
        ],
    }


def write_table(pred: dgan.Prediction, out: Path, scene: str | None = None) -> None:
    """``--out``: the long table of :meth:`Prediction.to_records` as CSV, parquet or JSON lines, by extension; with
    ``scene``, a first column ``scene`` holding it. Written beside ``out`` and renamed onto it (a failed write leaves
    ``out`` as it was)."""
    write_records({} if scene is None else {"scene": [scene]}, [pred], out)


def write_records(extra: dict[str, list[str]], preds: Sequence[dgan.Prediction], out: Path) -> None:
    """The predictions' long tables one after the other (at least one), each led by the columns of ``extra`` (one
    value per prediction, repeated on its rows)."""
    from dgan.prediction import write_atomically

    if _format(out) == ".parquet":
        import pyarrow as pa
        import pyarrow.parquet as pq

        tables = []
        for i, pr in enumerate(preds):
            t = pr.to_arrow()
            for j, (k, v) in enumerate(extra.items()):
                t = t.add_column(j, k, pa.array([v[i]] * t.num_rows, type=pa.string()))
            tables.append(t)
        try:
            table = pa.concat_tables(tables)
        except pa.ArrowInvalid as e:
            raise dgan.exceptions.OutputError(f"the scenes' tables do not join (ids of other types?): {e}") from None
        write_atomically(out, lambda f: pq.write_table(table, f))
        return
    names = list(extra) + list(preds[0].to_records())
    rows: list[tuple[Any, ...]] = []
    for i, pr in enumerate(preds):
        cols = {k: _listed(v) for k, v in pr.to_records().items()}
        cols.update({k: [v[i]] * len(cols["x"]) for k, v in extra.items()})
        rows.extend(zip(*(cols[k] for k in names), strict=True))
    _write_rows(out, names, rows)


def _write_rows(out: Path, names: list[str], rows: list[tuple[Any, ...]]) -> None:
    """Rows under a header as CSV, or as JSON lines, by ``out``'s extension, atomically."""
    from dgan.prediction import write_atomically

    def write(f: Any) -> None:
        if _format(out) == ".csv":
            text = io.StringIO()
            w = csv.writer(text)
            w.writerow(names)
            w.writerows(rows)
            f.write(text.getvalue().encode())
        else:
            f.write("".join(json.dumps(dict(zip(names, r, strict=True))) + "\n" for r in rows).encode())

    write_atomically(out, write)


def write_columns(columns: dict[str, Any], out: Path) -> None:
    """Columns of equal length (``dgan evaluate --out``) as CSV, parquet or JSON lines, by extension, atomically."""
    from dgan.prediction import write_atomically

    if _format(out) == ".parquet":
        import pyarrow as pa
        import pyarrow.parquet as pq

        table = pa.table({k: list(v) if v.dtype == object else v for k, v in columns.items()})
        write_atomically(out, lambda f: pq.write_table(table, f))
        return
    names = list(columns)
    _write_rows(out, names, list(zip(*(_listed(columns[k]) for k in names), strict=True)))


def _format(out: Path) -> str:
    """``--out``'s format by its extension: ``.csv``, ``.parquet``, or JSON lines (``.jsonl``, ``.ndjson``)."""
    suffix = out.suffix.lower()
    if suffix not in (".csv", ".parquet", ".jsonl", ".ndjson"):
        raise InvalidFrameError(f"--out must end in .csv, .parquet or .jsonl, got {out.name}")
    return suffix


def _listed(column: Any) -> list[Any]:
    """A column's values for CSV or JSON: instants in ISO 8601 (milliseconds), everything else as numpy lists it."""
    if column.dtype.kind == "M":
        return [str(t) for t in iso_text(column)]
    return list(column.tolist())
