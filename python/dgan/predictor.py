""":class:`Predictor`, a DGAN model in ONNX Runtime, and its :class:`Prediction`."""

from __future__ import annotations

import json
import numbers
import os
import warnings
import weakref
from collections.abc import Sequence
from pathlib import Path
from typing import Any

import numpy as np
import numpy.typing as npt

from dgan import _dgan
from dgan._runtime import onnxruntime_library as onnxruntime_library_path
from dgan._values import typename
from dgan.exceptions import (
    HeadingWarning,
    InvalidFrameError,
    InvalidSpecError,
    MapWarning,
    ModelNotFoundError,
    UnitWarning,
    UnknownClassError,
)
from dgan.frame import Frame
from dgan.maps import RasterMap
from dgan.prediction import Prediction
from dgan.scenes import MIN_PALETTE_SHARE, palette_share, reads_masks
from dgan.spec import InputSpec


class Predictor:
    """A DGAN model: an ONNX file that follows the model contract, served by the Rust engine.

    Args:
        model: path of the ``.onnx`` file, or the name of a bundled model (:func:`dgan.models.list`).
        modes: how many modes :meth:`predict` returns by default (all K = Σ K_c if None).
        threads: cores one call may use: the threads that draw the map crops (and preprocess the frames of
            :meth:`predict_batch`) and run the network. With 2 or more, a frame whose attention graph falls into
            components that share out evenly runs as one single-threaded network call per thread, concurrently
            (:attr:`lanes`), any other frame on ``threads`` intra-op threads (a frame under 16 agents on one), and
            :meth:`predict_batch` runs its network calls concurrently; each agent's result is the one a single call
            gives. The default, 1, keeps each call on its own thread, so that predictors sharing a machine do not
            compete; ``os.cpu_count()`` gives one call the lowest latency.
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
        if onnxruntime_library is not None and not isinstance(onnxruntime_library, (str, os.PathLike)):
            what = typename(onnxruntime_library)
            raise InvalidSpecError(f"onnxruntime_library must be the path of libonnxruntime.so or None, got {what}")
        lib = Path(onnxruntime_library) if onnxruntime_library is not None else onnxruntime_library_path()
        if sessions is None:
            sessions = min(2, os.cpu_count() or 1)
        # What the engine can be handed; it checks the ranges (threads within the cores, up to 64 sessions) and the
        # execution provider's name itself, once.
        for key, value in (("threads", threads), ("sessions", sessions)):
            _positive_int(key, value, 2**31)
        for key, value in (("max_edges", max_edges), ("max_input_bytes", max_input_bytes)):
            _positive_int(key, value, 2**62)
        if not isinstance(execution_provider, str):
            raise InvalidSpecError(
                f"execution_provider must be a string such as 'cpu' or 'cuda', got {execution_provider!r}"
            )
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
        self._speed_warned = False
        self._reads_mask = reads_masks(self._contract)
        self._maps_checked: weakref.WeakSet[RasterMap] = weakref.WeakSet()  # by reference: ids are reused

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
    def lanes(self) -> int:
        """Single-threaded sessions (one per thread, with ``threads`` ≥ 2 on the CPU, else 0) on which the parts of
        a split frame and :meth:`predict_batch`'s network calls run concurrently."""
        n: int = self._predictor.lanes
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

    @property
    def last_timings(self) -> dict[str, float] | None:
        """Where the latest :meth:`predict` call's time went, in milliseconds (None before the first; with several
        threads predicting at once, the call that finished last; :meth:`predict_batch` is not timed).

        ``preprocess``: the tensors other than the map crops, on the calling thread. ``crops``: the map crops, on up
        to ``threads`` threads (zero without a map). ``network``: the ONNX Runtime call, copies to and from a GPU
        included. ``decode``: world-frame modes, on up to ``threads`` threads. ``parts``: a frame split across lanes
        draws, runs and decodes each part on its own thread, so those three are this one figure there (zero
        otherwise). ``total``: the engine's whole call (the Python wrapping of the result is outside it).
        """
        timings = self._predictor.last_timings
        return None if timings is None else dict(timings)

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
        self._check_map(frame)
        try:
            native = self._predictor.predict(_native(frame), m, self._checks_headings, not self._speed_warned)
        except UnknownClassError as e:
            raise UnknownClassError(f"{e}; unknown_classes='ignore' predicts only the agents of its classes") from None
        self._warn_headings(native.headings)
        self._warn_speeds(native.speeds)
        return Prediction.from_native(native, frame.agent_ids, self.classes, self._spec.dt_s, frame._table_time)

    def _known(self, frame: Frame, unknown_classes: str) -> Frame:
        """``frame``, or with ``unknown_classes="ignore"`` its agents of the model's classes."""
        if unknown_classes not in ("error", "ignore"):
            raise InvalidSpecError(f"unknown_classes must be 'error' or 'ignore', got {unknown_classes!r}")
        if unknown_classes == "error" or not isinstance(frame, Frame):
            return frame
        keep = self._known_rows(frame)
        return frame if keep.all() else frame.select(keep)

    def _known_rows(self, frame: Frame) -> npt.NDArray[np.bool_]:
        """``(N,)`` which agents of ``frame`` are of this model's classes."""
        return np.fromiter((c in self.classes for c in frame.classes), dtype=bool, count=len(frame))

    def _check_map(self, frame: Frame) -> None:
        """Warns once (:class:`~dgan.exceptions.MapWarning`) if this model reads the ETH/UCY semantic masks and the
        frame's raster map is no such mask (each map looked at once: about 1.4 ms for a 576 × 720 image)."""
        raster = getattr(frame, "map", None)
        if not self._reads_mask or not isinstance(raster, RasterMap) or raster in self._maps_checked:
            return
        self._maps_checked.add(raster)
        share = palette_share(raster.image)
        if share < MIN_PALETTE_SHARE:
            self._reads_mask = False  # warned: not again
            warnings.warn(
                f"{self.path.name} reads its map as a semantic mask coloured in dgan.scenes.MASK_PALETTE (as "
                f"dgan.scene_map gives; dgan.scenes.colourise_mask colours one), but {share:.0%} of this map's pixels "
                "are its colours: a photo? Such a map makes the predictions worse than none; give a mask, or "
                "frame.without_map(). Warned once per Predictor.",
                MapWarning,
                stacklevel=3,
            )

    @property
    def _checks_headings(self) -> bool:
        """Whether the engine should check the frame's headings within the call: this model takes measured headings
        as they are and has not warned yet (:meth:`_warn_headings`)."""
        return not self._heading_warned and self._spec.heading == "measured"

    def _warn_headings(self, check: tuple[int, float, float, bool, bool, bool] | None) -> None:
        """Warns once (:class:`~dgan.exceptions.HeadingWarning`) if the frame's measured headings, which this model
        takes as they are, disagree with its agents' motion (the engine checks them within ``predict``)."""
        if check is None or self._heading_warned:
            return
        moving, median_deg, largest, beyond_two_pi, by_motion, disagrees = check
        if disagrees:
            self._heading_warned = True
            if by_motion:
                why = "some exceed 2π, so they may be degrees; " if beyond_two_pi else ""
                what = (
                    f"the frame's headings disagree with its agents' direction of motion by {median_deg:.0f}° "
                    f"(median over {moving} agents moving at ≥ 1 m/s); {why}"
                )
            else:
                what = (
                    f"the frame's headings reach {largest:.4g}, beyond radians unwrapped by three turns (6π), and "
                    f"too few agents move at ≥ 1 m/s ({moving}) to check them against the motion: degrees? "
                )
            warnings.warn(
                f"{what}{self.path.name} turns each agent's frame by its heading. Pass headings in radians, "
                "counter-clockwise from the world x axis along the direction of travel, or none (the engine then "
                "takes the direction of motion). Warned once per Predictor.",
                HeadingWarning,
                stacklevel=3,
            )

    def _warn_speeds(self, check: tuple[str, int, float, float, bool] | None) -> None:
        """Warns once (:class:`~dgan.exceptions.UnitWarning`) if a class's moving agents are implausibly fast in
        metres (the engine checks their speeds within ``predict``)."""
        if check is None or self._speed_warned or not check[4]:
            return
        self._speed_warned = True
        cls, moving, median, bound, _ = check
        warnings.warn(
            f"the frame's {moving} moving {cls} agents go at a median {median:.3g} units a second, taking its "
            f"positions as metres: beyond the {bound:g} m/s that {cls} agents reach. The positions are most likely "
            "in pixels or centimetres, or the times in another unit than time_unit says; "
            f"{self.path.name} takes metres (a scene in pixels needs its homography first). Warned once per "
            "Predictor.",
            UnitWarning,
            stacklevel=3,
        )

    def predict_batch(
        self, frames: Sequence[Frame], *, modes: int | None = None, unknown_classes: str = "error"
    ) -> list[Prediction]:
        """Predicts several frames: each preprocessed in parallel, consecutive frames' graphs joined (disjoint) into
        network calls of up to 256 agents (``dgan_core::runtime::BATCH_AGENTS_PER_CALL``) and ``max_input_bytes``
        of inputs; with ``threads`` ≥ 2 the calls run concurrently, one per thread (:attr:`lanes`). Equal to
        :meth:`predict` on each frame, up to float rounding. For 64 real frames of the bundled models: about a loop
        of :meth:`predict`'s throughput on one thread, and 1.8–2.3× it with ``threads=2`` on two cores
        (docs/speed.md). Releases the GIL while the engine runs.

        ``unknown_classes`` as :meth:`predict`.

        Raises:
            InvalidFrameError, UnknownClassError, MapRequiredError, SceneTooLargeError: as :meth:`predict`, for any
                frame; the message names the first bad frame by its index ("frame 2 of the batch: ...").
        """
        m = self._modes if modes is None else self._check_modes(modes)
        if isinstance(frames, Frame) or not isinstance(frames, Sequence):
            raise InvalidFrameError(f"predict_batch takes a sequence of dgan.Frame, got {typename(frames)}")
        frames = [self._known(f, unknown_classes) for f in frames]
        for f in frames:
            self._check_map(f)
        natives = [_native(f, f"frame {i} of the batch") for i, f in enumerate(frames)]
        try:
            outs = self._predictor.predict_batch(natives, m, self._checks_headings, not self._speed_warned)
        except UnknownClassError as e:
            raise UnknownClassError(f"{e}; unknown_classes='ignore' predicts only the agents of its classes") from None
        for o in outs:
            self._warn_headings(o.headings)
            self._warn_speeds(o.speeds)
        dt_s = self._spec.dt_s
        return [
            Prediction.from_native(o, f.agent_ids, self.classes, dt_s, f._table_time)
            for o, f in zip(outs, frames, strict=True)
        ]

    def __reduce__(self) -> tuple[Any, ...]:
        """Pickles as its model and options (for multiprocessing, Ray, Dask, Spark): the receiver loads the model
        again, from its own bundled copy for a bundled name, from the same path otherwise."""
        return (_unpickle_predictor, (self._options,))

    def __repr__(self) -> str:
        return f"Predictor({str(self.path)!r}, classes={self.classes}, modes={self._modes})"


def _positive_int(name: str, value: Any, most: int) -> None:
    """Refuses what cannot cross to the engine as a count: not an integer, a bool, below 1 or beyond ``most``."""
    if isinstance(value, bool) or not isinstance(value, int) or not 1 <= value <= most:
        raise InvalidSpecError(f"{name} must be a positive integer, got {value!r}")


def _unpickle_predictor(options: dict[str, Any]) -> Predictor:
    opts = dict(options)
    return Predictor(opts.pop("model"), **opts)


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
