"""Type stubs of the native module ``dgan._dgan`` (checked against the module by ``mypy.stubtest``)."""

import os
from collections.abc import Sequence
from typing import Any, final

import numpy as np
import numpy.typing as npt

__all__ = [
    "CONTRACT",
    "CONTRACT_VERSION",
    "DUPLICATES",
    "SPARSE_SLACK",
    "UPSAMPLE_LIMIT",
    "Frame",
    "Prediction",
    "Predictor",
    "RasterMap",
    "Tracker",
    "VectorMap",
    "__version__",
    "attention_graph",
    "available_execution_providers",
    "crop_grid",
    "frames_from_rows",
    "init_onnxruntime",
    "kinematic_prior",
    "preprocess",
    "read_kept",
    "sample_track",
    "scene_raster",
    "seal_model",
    "still_agents",
    "to_agent_frame",
    "to_world_frame",
    "validate_spec",
]

__version__: str
#: The model contract version the exporter writes (``dgan_core::contract::CONTRACT_VERSION``).
CONTRACT_VERSION: int
#: What the engine owns about the model contract (``dgan-py/src/constants.rs``): ``version``,
#: ``supported_versions``, ``raster_version``, ``preprocess_version``, ``metadata_key``, ``classes`` (by code),
#: ``class_sizes_m`` (default length, width), ``map_kinds`` (in drawing order: ``name``, ``polygon``, ``colour``,
#: ``width_m``), ``agent_colour``, ``state_features``, ``edge_features``, ``state_mirrored``, ``edge_mirrored`` (the
#: columns that change sign when a scene is mirrored y → −y), ``inputs`` (by graph layout: ``edge_list``,
#: ``padded``; ``kept``, a padded model whose features are kept with the map; in the contract's order), ``outputs``,
#: ``kept_output``. Read it through :mod:`dgan.contract`.
CONTRACT: dict[str, Any]
#: The choices of ``frames_from_rows``' ``duplicates`` (``dgan_core::Duplicates::ALL``).
DUPLICATES: list[str]
#: Data at most this many times sparser than the grid are upsampled (``dgan_core::history::UPSAMPLE_LIMIT``).
UPSAMPLE_LIMIT: float
#: Relative slack of the spacing checks (``dgan_core::history::SPARSE_SLACK``).
SPARSE_SLACK: float

@final
class Frame:
    def __new__(
        cls,
        positions: npt.NDArray[np.float64],
        mask: npt.NDArray[np.bool_] | None,
        classes: list[Any],
        ids: npt.NDArray[np.int64] | None,
        headings: npt.NDArray[np.float64] | None,
        velocities: npt.NDArray[np.float64] | None,
        lengths: npt.NDArray[np.float64] | None,
        widths: npt.NDArray[np.float64] | None,
        map: RasterMap | VectorMap | None,
        dt: float | None = None,
    ) -> Frame: ...
    def __len__(self) -> int: ...
    def without_map(self) -> Frame: ...
    def denoised(self, gate_m: float) -> tuple[Frame, int]: ...
    def with_map(self, map: RasterMap | VectorMap) -> Frame: ...
    @property
    def dt(self) -> float | None: ...
    @property
    def positions(self) -> npt.NDArray[np.float64]: ...
    @property
    def mask(self) -> npt.NDArray[np.bool_]: ...
    @property
    def ids(self) -> npt.NDArray[np.int64]: ...
    @property
    def classes(self) -> list[str]: ...
    @property
    def lengths(self) -> npt.NDArray[np.float64]: ...
    @property
    def widths(self) -> npt.NDArray[np.float64]: ...
    @property
    def headings(self) -> npt.NDArray[np.float64]: ...
    @property
    def velocities(self) -> npt.NDArray[np.float64]: ...
    @property
    def has_map(self) -> bool: ...

@final
class RasterMap:
    def __new__(cls, image: npt.NDArray[np.uint8], world_to_pixel: npt.NDArray[np.float64]) -> RasterMap: ...
    @staticmethod
    def from_file(path: str | os.PathLike[str], world_to_pixel: npt.NDArray[np.float64]) -> RasterMap: ...
    @property
    def image(self) -> npt.NDArray[np.uint8] | None: ...
    @property
    def world_to_pixel(self) -> npt.NDArray[np.float64] | None: ...
    @property
    def features_kept(self) -> int: ...

@final
class VectorMap:
    def __new__(cls, elements: list[tuple[str, npt.NDArray[np.float64]]]) -> VectorMap: ...
    def __len__(self) -> int: ...
    def elements(self) -> list[tuple[str, npt.NDArray[np.float64]]]: ...
    @property
    def tiles_kept(self) -> int: ...
    @property
    def features_kept(self) -> int: ...

@final
class Prediction:
    @property
    def agent_ids(self) -> npt.NDArray[np.int64]: ...
    @property
    def trajectories(self) -> npt.NDArray[np.float64]: ...
    @property
    def probabilities(self) -> npt.NDArray[np.float64]: ...
    @property
    def class_probabilities(self) -> npt.NDArray[np.float64]: ...
    @property
    def mode_classes(self) -> npt.NDArray[np.int64]: ...
    @property
    def edges(self) -> npt.NDArray[np.int64]: ...
    @property
    def headings(self) -> tuple[int, float, float, bool, bool, bool] | None: ...
    @property
    def speeds(self) -> tuple[str, int, float, float, bool] | None: ...

@final
class Predictor:
    def __new__(
        cls,
        path: str | os.PathLike[str],
        onnxruntime_library: str | os.PathLike[str] | None,
        intra_threads: int = 1,
        sessions: int = 1,
        execution_provider: str = "cpu",
        limits: tuple[int, int] | None = None,
    ) -> Predictor: ...
    @property
    def contract_json(self) -> str: ...
    @property
    def num_modes(self) -> int: ...
    @property
    def sessions(self) -> int: ...
    @property
    def lanes(self) -> int: ...
    @property
    def path(self) -> str: ...
    @property
    def last_timings(self) -> list[tuple[str, float]] | None: ...
    def predict(
        self, frame: Frame, modes: int, check_headings: bool = False, check_speeds: bool = False
    ) -> Prediction: ...
    def predict_batch(
        self, frames: list[Frame], modes: int, check_headings: bool = False, check_speeds: bool = False
    ) -> list[Prediction]: ...

@final
class Tracker:
    def __new__(cls, t_obs: int, dt: float, max_gap: float | None, default_class: str | int) -> Tracker: ...
    def update(self, time: float, columns: dict[str, Any]) -> None: ...
    def frame(self) -> Frame: ...
    @property
    def now(self) -> float | None: ...
    def __len__(self) -> int: ...
    def ids(self) -> npt.NDArray[np.int64]: ...
    def state(self) -> dict[str, Any]: ...
    @staticmethod
    def restore(
        t_obs: int, dt: float, max_gap: float | None, default_class: str | int, state: dict[str, Any]
    ) -> Tracker: ...

def frames_from_rows(
    columns: dict[str, Any],
    nows: Sequence[float],
    t_obs: int,
    dt: float,
    max_gap: float | None,
    default_class: str | int,
    duplicates: str = "error",
    upsample: bool = False,
    t_f: int = 0,
) -> list[tuple[Frame, float | None, bool, npt.NDArray[np.float64] | None, npt.NDArray[np.bool_] | None]]: ...
def sample_track(
    times: npt.NDArray[np.float64],
    xy: npt.NDArray[np.float64],
    at: npt.NDArray[np.float64],
    dt: float,
    max_gap: float | None = None,
) -> npt.NDArray[np.float64]: ...
def preprocess(frame: Frame, spec_json: str, threads: int | None = None) -> dict[str, Any]: ...
def validate_spec(json: str) -> str: ...
def kinematic_prior(
    trajectory: npt.NDArray[np.float32],
    trajectory_mask: npt.NDArray[np.float32],
    state: npt.NDArray[np.float32],
    spec_json: str,
) -> npt.NDArray[np.float32]: ...
def still_agents(
    trajectory: npt.NDArray[np.float32],
    trajectory_mask: npt.NDArray[np.float32],
    state: npt.NDArray[np.float32],
    radius: list[float],
) -> npt.NDArray[np.bool_]: ...
def to_agent_frame(
    points_world: npt.NDArray[np.float64], origins: npt.NDArray[np.float64], headings: npt.NDArray[np.float64]
) -> npt.NDArray[np.float64]: ...
def to_world_frame(
    points_local: npt.NDArray[np.float64], origins: npt.NDArray[np.float64], headings: npt.NDArray[np.float64]
) -> npt.NDArray[np.float64]: ...
def attention_graph(
    centres: npt.NDArray[np.float64], radii: npt.NDArray[np.float64], brute_force: bool = False
) -> npt.NDArray[np.int64]: ...
def scene_raster(
    frame: Frame, spec_json: str, size_px: int, origin: tuple[float, float], heading: float
) -> npt.NDArray[np.float32]: ...
def crop_grid(
    origins: npt.NDArray[np.float64],
    headings: npt.NDArray[np.float64],
    spec_json: str,
    stride: int,
    size_px: int,
    scene_origin: tuple[float, float],
    scene_heading: float,
) -> npt.NDArray[np.float32]: ...
def read_kept(
    rows: npt.NDArray[np.float32],
    index: npt.NDArray[np.int64],
    weight: npt.NDArray[np.float32],
    grid: tuple[int, int],
) -> npt.NDArray[np.float32]: ...
def seal_model(path: str | os.PathLike[str]) -> str: ...
def available_execution_providers(onnxruntime_library: str | os.PathLike[str] | None) -> list[str]: ...
def init_onnxruntime(path: str | os.PathLike[str] | None) -> str: ...
