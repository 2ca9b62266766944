""":class:`Predictor`, a DGAN model in ONNX Runtime, and its :class:`Prediction`."""

from __future__ import annotations

import json
import numbers
import os
import warnings
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
import numpy.typing as npt

from dgan import _dgan
from dgan._runtime import onnxruntime_library as onnxruntime_library_path
from dgan.exceptions import (
    HeadingWarning,
    InvalidFrameError,
    InvalidSpecError,
    ModelNotFoundError,
    OutputError,
    UnknownClassError,
)
from dgan.frame import Frame, typename
from dgan.spec import InputSpec


@dataclass(frozen=True)
class Prediction:
    """Every agent's modes, most probable first. Positions are world metres.

    Attributes:
        agent_ids: ``(N,)`` the frame's ids as given (integers, or strings in an object array), in row order.
        trajectories: ``(N, M, T_f, 2)`` future positions of each mode.
        probabilities: ``(N, M)`` p(c) · p(k | c) of each mode.
        class_probabilities: ``(N, C)`` p(c), columns in ``classes`` order.
        mode_classes: ``(N, M)`` index into ``classes`` of each mode's anchor class.
        edges: ``(E, 2)`` undirected attention-zone edges between frame rows ``i < j``.
        classes: the model's class names.
        dt_s: seconds between predicted steps (the model's time base); step ``s`` is ``(s + 1) · dt_s`` after now.
    """

    agent_ids: npt.NDArray[Any]
    trajectories: npt.NDArray[np.float64]
    probabilities: npt.NDArray[np.float64]
    class_probabilities: npt.NDArray[np.float64]
    mode_classes: npt.NDArray[np.int64]
    edges: npt.NDArray[np.int64]
    classes: tuple[str, ...]
    dt_s: float = float("nan")

    def __len__(self) -> int:
        return int(self.agent_ids.shape[0])

    @property
    def times_s(self) -> npt.NDArray[np.float64]:
        """``(T_f,)`` seconds after the current time of each predicted step."""
        return np.round(np.arange(1, self.trajectories.shape[2] + 1) * self.dt_s, 9)

    def to_records(self) -> dict[str, npt.NDArray[Any]]:
        """The prediction as a long table of numpy columns, one row per agent, mode and step: ``agent_id``,
        ``mode`` (0 = most probable), ``probability``, ``class`` (the mode's anchor class), ``class_probability``,
        ``step`` (1..T_f), ``time_offset_s``, ``x``, ``y`` (world metres)."""
        from dgan.io import prediction_columns

        return prediction_columns(self)

    def to_pandas(self) -> Any:
        """:meth:`to_records` as a pandas DataFrame (needs pandas)."""
        import pandas as pd

        return pd.DataFrame(self.to_records())

    def to_arrow(self) -> Any:
        """:meth:`to_records` as a pyarrow Table (needs pyarrow); its schema metadata holds ``dt_s`` and the
        classes.

        Raises:
            OutputError: ids an Arrow column cannot hold (integers mixed with strings, integers past 64 bits).
        """
        import pyarrow as pa

        cols = self.to_records()
        arrays = {k: pa.array(v.tolist() if v.dtype == object else v) for k, v in cols.items() if k != "agent_id"}
        table = pa.table({"agent_id": _arrow_ids(cols["agent_id"]), **arrays})
        meta = {b"dgan.dt_s": str(self.dt_s).encode(), b"dgan.classes": ",".join(self.classes).encode()}
        return table.replace_schema_metadata(meta)

    def to_parquet(self, path: str | os.PathLike[str]) -> None:
        """Writes :meth:`to_arrow` to a parquet file (needs pyarrow). The file is written beside ``path`` and then
        renamed onto it, so a failed write leaves ``path`` as it was (a path that is not a regular file, such as a
        device or a pipe, is written in place and never removed).

        Raises:
            OutputError: as :meth:`to_arrow`. OSError: the file cannot be written.
        """
        import pyarrow.parquet as pq

        write_atomically(path, lambda f: pq.write_table(self.to_arrow(), f))

    @property
    def most_likely(self) -> npt.NDArray[np.float64]:
        """``(N, T_f, 2)`` the top-1 mode of each agent."""
        return self.trajectories[:, 0]


class Predictor:
    """A DGAN model: an ONNX file that follows the model contract, served by the Rust engine.

    Args:
        model: path of the ``.onnx`` file, or the name of a bundled model (:func:`dgan.models.list`).
        modes: how many modes :meth:`predict` returns by default (all K = Σ K_c if None).
        threads: threads ONNX Runtime may use inside one operator.
        sessions: ONNX Runtime sessions of the model: threads sharing this predictor run concurrently, up to this
            many at a time (default: 2, or 1 on a one-core machine).
        onnxruntime_library: absolute path of ``libonnxruntime``; found in the ``onnxruntime`` wheel if None.
        execution_provider: where ONNX Runtime runs the network: ``"cpu"``, ``"cuda"`` or ``"cuda:N"`` (needs an
            ONNX Runtime library built with CUDA, e.g. ``onnxruntime-gpu``'s; see
            :func:`available_execution_providers`). A provider the library lacks raises at load, never falls back.
        max_edges: the most attention-zone edges one frame may have (a denser scene raises
            :class:`~dgan.exceptions.SceneTooLargeError` before the network runs).
        max_input_bytes: the most bytes of network inputs one frame may need (the map crops dominate).

    Raises:
        ModelNotFoundError, ModelLoadError, ContractError, RuntimeLibraryError: at load, never later.
    """

    def __init__(
        self,
        model: str | os.PathLike[str],
        *,
        modes: int | None = None,
        threads: int = 1,
        sessions: int | None = None,
        onnxruntime_library: str | os.PathLike[str] | None = None,
        execution_provider: str = "cpu",
        max_edges: int = 200_000,
        max_input_bytes: int = 2 << 30,
    ) -> None:
        if model is None or not isinstance(model, (str, os.PathLike)):
            raise ModelNotFoundError(f"model must be a path or a bundled model's name, got {typename(model)}")
        lib = Path(onnxruntime_library) if onnxruntime_library is not None else onnxruntime_library_path()
        cores = os.cpu_count() or 1
        if isinstance(threads, bool) or not isinstance(threads, int) or not 1 <= threads <= cores:
            raise InvalidSpecError(f"threads must be an integer in 1..={cores} (this machine's cores), got {threads!r}")
        if sessions is None:
            sessions = min(2, cores)
        if isinstance(sessions, bool) or not isinstance(sessions, int) or not 1 <= sessions <= 64:
            raise InvalidSpecError(f"sessions must be an integer in 1..=64, got {sessions!r}")
        if not isinstance(execution_provider, str):
            raise InvalidSpecError(
                f"execution_provider must be a string such as 'cpu' or 'cuda', got {execution_provider!r}"
            )
        for key, value in (("max_edges", max_edges), ("max_input_bytes", max_input_bytes)):
            if isinstance(value, bool) or not isinstance(value, int) or not 1 <= value <= 2**62:
                raise InvalidSpecError(f"{key} must be a positive integer, got {value!r}")
        # What pickling rebuilds the predictor from: a bundled model by name (found in the receiver's own dgan),
        # a file by its absolute path.
        bundled = isinstance(model, str) and _resolve(model) != Path(model)
        self._options: dict[str, Any] = {
            "model": model if bundled else os.path.abspath(os.fspath(model)),
            "modes": modes,
            "threads": threads,
            "sessions": sessions,
            "onnxruntime_library": None if onnxruntime_library is None else os.fspath(lib),
            "execution_provider": execution_provider,
            "max_edges": max_edges,
            "max_input_bytes": max_input_bytes,
        }
        self._predictor = _dgan.Predictor(
            os.fspath(_resolve(model)),
            os.fspath(lib),
            threads,
            sessions,
            execution_provider,
            (max_edges, max_input_bytes),
        )
        self._contract: dict[str, Any] = json.loads(self._predictor.contract_json)
        self._spec = InputSpec.from_dict(self._contract)
        self._modes = self._check_modes(modes)
        self._heading_warned = False

    def _check_modes(self, modes: int | None) -> int:
        k = self.num_modes
        if modes is None:
            return k
        if isinstance(modes, bool) or not isinstance(modes, numbers.Integral):
            raise InvalidSpecError(f"modes must be a whole number in 1..={k}, got {modes!r} ({type(modes).__name__})")
        if not 1 <= modes <= k:
            raise InvalidSpecError(f"modes must be in 1..={k} (the model's anchors), got {modes}")
        return int(modes)

    @property
    def num_modes(self) -> int:
        """K = Σ K_c, the most modes :meth:`predict` can return."""
        k: int = self._predictor.num_modes
        return k

    @property
    def sessions(self) -> int:
        """ONNX Runtime sessions serving concurrent calls from several threads."""
        n: int = self._predictor.sessions
        return n

    @property
    def spec(self) -> InputSpec:
        """The model's input specification."""
        return self._spec

    @property
    def contract(self) -> dict[str, Any]:
        """The full model contract from the model's metadata."""
        return self._contract

    @property
    def classes(self) -> tuple[str, ...]:
        """The model's classes, in the order of its class probabilities."""
        return tuple(self._spec.classes)

    @property
    def anchors(self) -> dict[str, npt.NDArray[np.float64]]:
        """Anchors per class, ``(K_c, T_f, 2)`` in the agent-centric frame."""
        return {c: np.asarray(self._contract["anchors"][c], dtype=np.float64) for c in self.classes}

    @property
    def path(self) -> Path:
        return Path(self._predictor.path)

    def predict(self, frame: Frame, *, modes: int | None = None, unknown_classes: str = "error") -> Prediction:
        """Predicts every agent of ``frame``. Releases the GIL while the engine runs.

        An empty frame gives an empty prediction.

        Args:
            unknown_classes: what to do with agents of a class the model does not know (a vehicle for a pedestrian
                model): ``"error"`` refuses the frame; ``"ignore"`` predicts the agents of the model's classes, with
                their ids in the prediction, and leaves the others out of the scene (neither predicted nor anyone's
                neighbour: the model has never seen them).

        Raises:
            InvalidFrameError: the frame does not fit the model (e.g. a different T_obs).
            UnknownClassError: a class the model does not know (with ``unknown_classes="error"``).
            InferenceError: ONNX Runtime failed.
        """
        m = self._modes if modes is None else self._check_modes(modes)
        frame = self._known(frame, unknown_classes)
        try:
            out = self._predictor.predict(_native(frame), m)
        except UnknownClassError as e:
            raise UnknownClassError(f"{e}; unknown_classes='ignore' predicts only the agents of its classes") from None
        self._check_headings(frame)
        return self._prediction(out, frame)

    def _known(self, frame: Frame, unknown_classes: str) -> Frame:
        """``frame``, or with ``unknown_classes="ignore"`` its agents of the model's classes."""
        if unknown_classes not in ("error", "ignore"):
            raise InvalidSpecError(f"unknown_classes must be 'error' or 'ignore', got {unknown_classes!r}")
        if unknown_classes == "error" or not isinstance(frame, Frame):
            return frame
        keep = np.fromiter((c in self.classes for c in frame.classes), dtype=bool, count=len(frame))
        return frame if keep.all() else frame.select(keep)

    def _check_headings(self, frame: Frame) -> None:
        """Warns once (:class:`~dgan.exceptions.HeadingWarning`) if ``frame``'s measured headings, which this model
        takes as they are, disagree with its agents' motion."""
        if self._heading_warned or self._spec.heading != "measured":
            return
        check = _dgan.check_headings(frame._frame, self._spec.dt_s)
        if check is None:
            return
        moving, median_deg, beyond_two_pi, disagrees = check
        if disagrees:
            self._heading_warned = True
            why = "some exceed 2π, so they may be degrees; " if beyond_two_pi else ""
            warnings.warn(
                f"the frame's headings disagree with its agents' direction of motion by {median_deg:.0f}° (median "
                f"over {moving} agents moving at ≥ 1 m/s); {why}{self.path.name} turns each agent's frame by its "
                "heading. Pass headings in radians, counter-clockwise from the world x axis along the direction of "
                "travel, or none (the engine then takes the direction of motion). Warned once per Predictor.",
                HeadingWarning,
                stacklevel=3,
            )

    def _prediction(self, out: dict[str, Any], frame: Frame) -> Prediction:
        out["agent_ids"] = frame.agent_ids
        return Prediction(classes=self.classes, dt_s=self._spec.dt_s, **out)

    def predict_batch(
        self, frames: Sequence[Frame], *, modes: int | None = None, unknown_classes: str = "error"
    ) -> list[Prediction]:
        """Predicts several frames: each preprocessed in parallel, consecutive frames' graphs joined (disjoint) into
        network calls of up to 256 agents (``dgan_core::runtime::BATCH_AGENTS_PER_CALL``) and ``max_input_bytes``
        of inputs. Equal to :meth:`predict`
        on each frame, up to float rounding; 0.96–1.54× the throughput of a loop of :meth:`predict` for 64 real
        frames of the bundled models. Releases the GIL while the engine runs.

        ``unknown_classes`` as :meth:`predict`.

        Raises:
            InvalidFrameError, UnknownClassError, MapRequiredError, SceneTooLargeError: as :meth:`predict`, for any
                frame; the message names the first bad frame by its index ("frame 2 of the batch: ...").
        """
        m = self._modes if modes is None else self._check_modes(modes)
        if isinstance(frames, Frame) or not isinstance(frames, Sequence):
            raise InvalidFrameError(f"predict_batch takes a sequence of dgan.Frame, got {typename(frames)}")
        frames = [self._known(f, unknown_classes) for f in frames]
        outs = self._predictor.predict_batch([_native(f, f"frame {i} of the batch") for i, f in enumerate(frames)], m)
        for f in frames:
            self._check_headings(f)
        return [self._prediction(o, f) for o, f in zip(outs, frames, strict=True)]

    def __reduce__(self) -> tuple[Any, ...]:
        """Pickles as its model and options (for multiprocessing, Ray, Dask, Spark): the receiver loads the model
        again, from its own bundled copy for a bundled name, from the same path otherwise."""
        return (_unpickle_predictor, (self._options,))

    def __repr__(self) -> str:
        return f"Predictor({str(self.path)!r}, classes={self.classes}, modes={self._modes})"


def _unpickle_predictor(options: dict[str, Any]) -> Predictor:
    opts = dict(options)
    return Predictor(opts.pop("model"), **opts)


def _arrow_ids(ids: npt.NDArray[Any]) -> Any:
    """The agent-id column of an Arrow table: one type, or :class:`OutputError`."""
    import pyarrow as pa

    if ids.dtype != object:
        return pa.array(ids)
    values = ids.tolist()
    if all(isinstance(v, str) for v in values):
        return pa.array(values, type=pa.string())
    if all(isinstance(v, numbers.Integral) and not isinstance(v, bool) for v in values):
        ints = [int(v) for v in values]
        if all(-(2**63) <= v < 2**63 for v in ints):
            return pa.array(ints, type=pa.int64())
        if all(0 <= v < 2**64 for v in ints):
            return pa.array(ints, type=pa.uint64())
        raise OutputError("agent ids past 64 bits cannot be an Arrow column; give them as strings")
    kinds = sorted({type(v).__name__ for v in values})
    raise OutputError(
        f"agent ids mix {' and '.join(kinds)}; an Arrow or parquet column holds one type: give the frame ids of one "
        "type (e.g. strings), or use to_records() / to_pandas(), which keep them as given"
    )


def write_atomically(path: str | os.PathLike[str], write: Any) -> None:
    """Calls ``write(file)`` on a temporary file beside ``path``, then renames it onto ``path``: a failure leaves
    ``path`` as it was. A path that exists and is not a regular file (a device, a pipe) is opened and written in
    place, and never removed."""
    target = Path(path)
    if target.exists() and not target.is_file():
        with open(target, "wb") as f:
            write(f)
        return
    tmp = target.with_name(f".{target.name}.{os.getpid()}.tmp")
    try:
        with open(tmp, "wb") as f:
            write(f)
        os.replace(tmp, target)
    except OSError as e:
        tmp.unlink(missing_ok=True)
        raise OSError(e.errno, f"cannot write {target}: {e.strerror or e}", os.fspath(target)) from None
    except BaseException:
        tmp.unlink(missing_ok=True)
        raise


def _native(frame: Any, what: str = "") -> _dgan.Frame:
    if not isinstance(frame, Frame):
        raise InvalidFrameError(f"{what}{': ' if what else ''}expected a dgan.Frame, got {typename(frame)}")
    return frame._frame


def _resolve(model: str | os.PathLike[str]) -> Path:
    """A model file as given, or a bundled model's file when ``model`` is a bundled name that is not a file here (a
    folder named like a bundled model, ``./sdd`` say, does not shadow it)."""
    p = Path(model)
    if isinstance(model, str) and not p.is_file() and p.suffix == "" and "/" not in model and os.sep not in model:
        from dgan import models

        return models.path(model)  # a bundled name, or ModelNotFoundError listing them
    return p


def available_execution_providers(onnxruntime_library: str | os.PathLike[str] | None = None) -> list[str]:
    """The execution providers the ONNX Runtime library offers (``"cpu"``, and ``"cuda"`` with a CUDA build)."""
    lib = Path(onnxruntime_library) if onnxruntime_library is not None else onnxruntime_library_path()
    return list(_dgan.available_execution_providers(os.fspath(lib)))
