"""What a network expects of its inputs (:class:`InputSpec`, :class:`MapSpec`) and :func:`preprocess`, the exact
tensors it receives. Training uses :func:`preprocess` so that training and inference run one implementation."""

from __future__ import annotations

import json
import math
from collections.abc import Mapping, Sequence
from dataclasses import asdict, dataclass, field
from functools import cached_property
from typing import Any

import numpy as np
import numpy.typing as npt

from dgan import _dgan
from dgan.contract import CLASSES, state_width
from dgan.exceptions import InvalidFrameError, InvalidSpecError
from dgan.frame import Frame


def _class_names(value: Any, key: str) -> tuple[str, ...]:
    """``value`` (a spec's ``key``) as a tuple of class names; a bare string or a non-sequence is refused."""
    if isinstance(value, str) or not hasattr(value, "__iter__"):
        raise InvalidSpecError(f"{key} must be a sequence of class names, got {value!r}")
    return tuple(value)


@dataclass(frozen=True)
class SceneSpec:
    """How a scene model's map CNN reads the map (contract 12): once per group of agents whose crops meet, over a
    square north-up raster of the scene at the crops' resolution (:func:`scene_raster`), at least ``min_px`` pixels a
    side and larger where a group's crops reach farther; each agent reads the network's features at the centres of
    its crop's ``stride × stride`` blocks (:func:`crop_grid`).

    Contract 13, ``tile_px`` > 0: the map CNN's features are kept with the map instead (``dgan_core::kept``): on a
    grid fixed in the world, in tiles of ``tile_px`` pixels, each computed once per map and predictor from a raster of
    the tile and ``halo_px`` more pixels each side (the map alone: ``draw_agents`` must be false), ``channels`` wide;
    every later call on that map reads them."""

    min_px: int = 128
    stride: int = 4
    tile_px: int = 0
    halo_px: int = 0
    channels: int = 0


@dataclass(frozen=True)
class MapSpec:
    """The agent-centric, heading-aligned map crop: ``height_px × width_px`` at ``resolution_m`` metres per pixel,
    the agent at the centre of pixel ``(agent_row, agent_col)``, its heading pointing up."""

    height_px: int = 64
    width_px: int = 64
    resolution_m: float = 0.5
    agent_row: int = 48
    agent_col: int = 32
    draw_agents: bool = True
    #: The model also serves frames without a map (contract 2): it takes a ``map_present`` input, and a frame
    #: without a map gets blank crops flagged absent. A model whose map is not optional refuses such frames
    #: (:class:`dgan.exceptions.MapRequiredError`).
    optional: bool = False
    #: How a vector map becomes the crops (contract 7): ``"agent"`` draws each agent's crop from the map's
    #: elements; ``"tiles"`` draws the map once into north-up tiles at half the crop's pixel size, kept with the
    #: :class:`dgan.VectorMap` for every later call, and resamples each crop from them (a raster map is always
    #: resampled per crop).
    render: str = "agent"
    #: Contract 11: the classes whose agents read the map, when the network reads it for them alone (e.g.
    #: ``("cyclist", "pedestrian")``); the other agents' crops are left blank instead of drawn. Empty: every agent's.
    classes: Sequence[str] = ()
    #: Contract 12: the map CNN reads rasters of the scene, one per group of agents, instead of a crop per agent (the
    #: crop's geometry then says where each agent reads them); None, a crop per agent.
    scene: SceneSpec | None = None

    def __post_init__(self) -> None:
        object.__setattr__(self, "classes", _class_names(self.classes, "map.classes"))
        if isinstance(self.scene, Mapping):
            object.__setattr__(self, "scene", SceneSpec(**self.scene))
        if self.scene is not None and not isinstance(self.scene, SceneSpec):
            raise InvalidSpecError(f"map.scene must be a dgan.SceneSpec, got {self.scene!r}")

    @property
    def scene_grid(self) -> tuple[int, int] | None:
        """The blocks of each agent's crop a scene model reads, ``(rows, columns)``: ``ceil(height_px / stride)``,
        ``ceil(width_px / stride)`` (``dgan_core::spec::MapSpec::scene_grid``); None for a crop model."""
        if self.scene is None:
            return None
        return -(-self.height_px // self.scene.stride), -(-self.width_px // self.scene.stride)


@dataclass(frozen=True)
class ClassPrior:
    """One class's own velocity estimate in a :class:`PriorSpec` (contract 8): its ``window_s``, ``fit`` and
    ``standing_mps``, with the meanings they have there."""

    window_s: float = 0.0
    fit: str = "endpoints"
    standing_mps: float = 0.0


@dataclass(frozen=True)
class PriorSpec:
    """The kinematic prior the network's outputs are relative to (``docs/model-contract.md``).

    ``kind`` is ``"none"`` (anchors are absolute, every contract-1 model) or ``"constant_velocity"`` (along the
    direction of motion). ``window_s`` = 0 takes the traffic state's velocity; > 0 a velocity estimated from the last
    ``window_s`` seconds of the observed positions: by ``fit`` ``"endpoints"`` (the first and last valid positions
    of the window), ``"least_squares"`` (a line through every valid position against its time, robust to tracker
    noise and dropped steps), ``"quadratic"`` (a parabola's slope at the current step: as robust, without the
    line's lag behind an accelerating agent) or ``"adaptive"`` (contract 8: a line through as many of the most recent
    positions as the track's own noise calls for, from the last two steps of a clean track to the whole window of a
    noisy one). An agent whose estimated speed is below ``standing_mps`` (m/s; 0
    never) stands: its prior stays at its last position. ``by_class`` (contract 8) gives the agents of a class
    their own estimate, e.g. ``{"pedestrian": ClassPrior(2.0, "least_squares", 0.3)}``; the other classes keep
    the model-wide one.
    """

    kind: str = "none"
    window_s: float = 0.0
    fit: str = "endpoints"
    standing_mps: float = 0.0
    by_class: Mapping[str, ClassPrior] = field(default_factory=dict)

    def __post_init__(self) -> None:
        if not isinstance(self.by_class, Mapping):
            raise InvalidSpecError(f"prior.by_class must map class names to ClassPrior, got {self.by_class!r}")
        own = {}
        for name, c in self.by_class.items():
            own[name] = ClassPrior(**c) if isinstance(c, Mapping) else c
            if not isinstance(own[name], ClassPrior):
                raise InvalidSpecError(f"prior.by_class[{name!r}] must be a ClassPrior, got {c!r}")
        object.__setattr__(self, "by_class", own)

    def to_dict(self) -> dict[str, Any]:
        """The prior as the model contract writes it (``by_class`` left out when empty)."""
        d: dict[str, Any] = {"kind": self.kind, "window_s": self.window_s, "fit": self.fit}
        d["standing_mps"] = self.standing_mps
        if self.by_class:
            d["by_class"] = {name: asdict(c) for name, c in self.by_class.items()}
        return d


@dataclass(frozen=True)
class InputSpec:
    """Time base, classes, attention-zone λ and map crop of a model (the input half of the model contract)."""

    dt_s: float
    t_obs: int
    t_f: int
    classes: Sequence[str] = CLASSES
    attention_lambda: float = 0.5
    map: MapSpec | None = field(default=None)
    prior: PriorSpec = field(default_factory=PriorSpec)
    #: How the attention graph reaches the network: ``"edge_list"`` (``edge_index``, ``edge_features``; contracts 1
    #: and 2) or ``"padded"`` (``neighbor_index``, ``neighbor_mask``, ``neighbor_features``; contract 3).
    graph: str = "edge_list"
    #: Where each agent's heading (the orientation of its agent-centric frame) comes from (contract 5):
    #: ``"measured"``, the frame's headings where given, else the direction of motion (contracts 1–4);
    #: ``"motion_when_moving"``, the direction of motion for agents moving at least 1 m/s and the measured heading
    #: only for slower ones; ``"motion"``, measured headings ignored.
    heading: str = "measured"
    #: Contract 10: tracker noise taken out of the histories before any input is built, as
    #: :meth:`dgan.Frame.denoised` does with this gate (metres); 0, the histories as given.
    denoise_gate_m: float = 0.0

    def __post_init__(self) -> None:
        object.__setattr__(self, "classes", _class_names(self.classes, "classes"))
        numbers = {"dt_s": self.dt_s, "attention_lambda": self.attention_lambda, "denoise_gate_m": self.denoise_gate_m}
        if self.map is not None:
            numbers["map.resolution_m"] = self.map.resolution_m
        numbers["prior.window_s"] = self.prior.window_s
        numbers["prior.standing_mps"] = self.prior.standing_mps
        for name, c in self.prior.by_class.items():
            numbers[f"prior.by_class.{name}.window_s"] = c.window_s
            numbers[f"prior.by_class.{name}.standing_mps"] = c.standing_mps
        for key, value in numbers.items():
            if isinstance(value, float) and not math.isfinite(value):
                raise InvalidSpecError(f"invalid specification: {key} must be a finite number, got {value}")
        _dgan.validate_spec(self.to_json())

    def to_json(self) -> str:
        """The specification as the model contract writes it: JSON, computed once (the specification is frozen), so
        that :func:`preprocess` and the other functions that pass it to the engine on every call do not build it
        again (30-50 µs each time, as much as preprocessing a few agents)."""
        return self._json

    @cached_property
    def _json(self) -> str:
        d = asdict(self)
        d["classes"] = list(self.classes)
        d["prior"] = self.prior.to_dict()
        if d["denoise_gate_m"] == 0:  # as the contract writes it: contracts 1-9 have no gate
            del d["denoise_gate_m"]
        if d["map"] is not None and not d["map"]["classes"]:  # contracts 1-10 draw every agent's crop
            del d["map"]["classes"]
        if d["map"] is not None and d["map"]["scene"] is None:  # contracts 1-11 take a crop per agent
            del d["map"]["scene"]
        elif d["map"] is not None and not d["map"]["scene"]["tile_px"]:  # contract 12 reads rasters per call
            for key in ("tile_px", "halo_px", "channels"):
                del d["map"]["scene"][key]
        return json.dumps(d)

    @classmethod
    def from_dict(cls, d: dict[str, Any]) -> InputSpec:
        m = d.get("map")
        return cls(
            dt_s=float(d["dt_s"]),
            t_obs=int(d["t_obs"]),
            t_f=int(d["t_f"]),
            classes=tuple(d["classes"]),
            attention_lambda=float(d["attention_lambda"]),
            map=None if m is None else MapSpec(**m),
            prior=PriorSpec(**d.get("prior", {})),
            graph=str(d.get("graph", "edge_list")),
            heading=str(d.get("heading", "measured")),
            denoise_gate_m=float(d.get("denoise_gate_m", 0.0)),
        )

    @property
    def state_dim(self) -> int:
        """Width of the traffic-state vector: 7 features and a one-hot class."""
        return state_width(self.classes)


def preprocess(frame: Frame, spec: InputSpec, threads: int | None = None) -> dict[str, npt.NDArray[Any]]:
    """The network inputs of ``frame`` (see ``docs/model-contract.md``) plus its geometry.

    Returns ``trajectory (N, T_obs, 2)``, ``trajectory_mask (N, T_obs)``, ``state (N, 7 + C)``,
    ``edge_index (E, 2)``, ``edge_features (E, 6)`` (and for the padded layout ``neighbor_index (N, D)``,
    ``neighbor_mask (N, D)``, ``neighbor_features (N, D, 6)``), ``map (N, 3, H, W)`` for map models,
    ``map_present (N,)`` for models whose map is optional (a scene model's ``map`` is the frame's rasters
    ``(G, 3, S, S)``, with ``map_grid (G, M, gh, gw, 2)`` and ``map_slot (N,)``), the kinematic
    ``prior (N, T_f, 2)`` in each agent's frame, and ``origin (N, 2)``, ``heading (N,)`` (each agent's frame),
    ``speed (N,)``, ``radius (N,)`` and undirected ``edges``. The map crops are drawn on at most ``threads``
    threads (default: every core; a ``Predictor`` draws them on its own ``threads``); the tensors are the same
    whatever the threads.
    """
    if not isinstance(frame, Frame):
        raise InvalidFrameError(
            f"preprocess takes a dgan.Frame, got {'None' if frame is None else type(frame).__name__}"
        )
    if threads is not None and (isinstance(threads, bool) or not isinstance(threads, int) or not 1 <= threads < 2**31):
        raise InvalidSpecError(f"threads must be a positive int or None, got {threads!r}")
    out: dict[str, npt.NDArray[Any]] = _dgan.preprocess(frame._frame, _spec_json(spec), threads)
    return out


def _spec_json(spec: Any) -> str:
    if not isinstance(spec, InputSpec):
        raise InvalidSpecError(f"spec must be a dgan.InputSpec (a Predictor's .spec), got {type(spec).__name__}")
    return spec.to_json()


def kinematic_prior(
    trajectory: npt.ArrayLike, trajectory_mask: npt.ArrayLike, state: npt.ArrayLike, spec: InputSpec
) -> npt.NDArray[np.float32]:
    """The engine's kinematic prior ``(N, T_f, 2)`` (agent frame) from the network inputs ``trajectory``,
    ``trajectory_mask`` and ``state``; training fits its anchors and offsets to the residual from it."""
    t, m, s = (np.ascontiguousarray(a, dtype=np.float32) for a in (trajectory, trajectory_mask, state))
    return _dgan.kinematic_prior(t, m, s, _spec_json(spec))


def still_agents(
    trajectory: npt.ArrayLike, trajectory_mask: npt.ArrayLike, state: npt.ArrayLike, radius: Sequence[float]
) -> npt.NDArray[np.bool_]:
    """Which agents of the network inputs ``trajectory``, ``trajectory_mask`` and ``state`` have a still history
    (contract 15): every observed step present and each within ``radius[c]`` metres of the last observed position, c
    the agent's class in the model's order (0: never held). The engine holds such an agent's most probable mode at its
    prior when the model declares ``still_radius_m``. Shapes that disagree (``state`` must be as wide as
    ``dgan.contract.state_width`` gives for one radius per class) or a radius that is negative or not finite raise
    :class:`dgan.exceptions.InvalidSpecError`."""
    t, m, s = (np.ascontiguousarray(a, dtype=np.float32) for a in (trajectory, trajectory_mask, state))
    return _dgan.still_agents(t, m, s, [float(r) for r in radius])


def to_agent_frame(
    points_world: npt.ArrayLike, origins: npt.ArrayLike, headings: npt.ArrayLike
) -> npt.NDArray[np.float64]:
    """World points ``(N, T, 2)`` in each agent's frame (``origins (N, 2)``, ``headings (N,)``)."""
    return _dgan.to_agent_frame(*(np.ascontiguousarray(a, dtype=np.float64) for a in (points_world, origins, headings)))


def to_world_frame(
    points_local: npt.ArrayLike, origins: npt.ArrayLike, headings: npt.ArrayLike
) -> npt.NDArray[np.float64]:
    """Agent-frame points ``(N, T, 2)`` back in the world frame."""
    return _dgan.to_world_frame(*(np.ascontiguousarray(a, dtype=np.float64) for a in (points_local, origins, headings)))


def attention_graph(
    centres: npt.ArrayLike, radii: npt.ArrayLike, *, brute_force: bool = False
) -> npt.NDArray[np.int64]:
    """Undirected edges ``(E, 2)``, ``i < j``, between circles that intersect (touching counts)."""
    c = np.ascontiguousarray(centres, dtype=np.float64)
    r = np.ascontiguousarray(radii, dtype=np.float64)
    return _dgan.attention_graph(c, r, brute_force)


def scene_raster(
    frame: Frame, spec: InputSpec, size_px: int, origin: npt.ArrayLike, heading: float
) -> npt.NDArray[np.float32]:
    """The square scene raster ``(3, size_px, size_px)`` (values in [0, 1]) of ``frame``'s map at the resolution of
    ``spec``'s map crops, centred on ``origin`` (world metres) with image-up along ``heading`` (radians; π/2 puts
    north up), the agents drawn as the crops draw them, each once: what a map CNN shared by every agent reads
    (issue 26). Each agent's crop lies in it at :func:`crop_grid`."""
    if not isinstance(frame, Frame):
        raise InvalidFrameError(f"scene_raster takes a dgan.Frame, got {type(frame).__name__}")
    o = np.asarray(origin, dtype=np.float64).reshape(-1)
    if o.shape != (2,):
        raise InvalidFrameError(f"origin must be two numbers, got shape {np.shape(origin)}")
    out: npt.NDArray[np.float32] = _dgan.scene_raster(
        frame._frame, _spec_json(spec), _count(size_px, "size_px"), (float(o[0]), float(o[1])), float(heading)
    )
    return out


def crop_grid(
    origins: npt.ArrayLike,
    headings: npt.ArrayLike,
    spec: InputSpec,
    stride: int,
    size_px: int,
    scene_origin: npt.ArrayLike,
    scene_heading: float,
) -> npt.NDArray[np.float32]:
    """Where each agent's map crop (``origins (N, 2)``, ``headings (N,)``: its frame, as :func:`preprocess` returns
    them) lies in the :func:`scene_raster` of ``size_px`` placed at ``scene_origin``, ``scene_heading``:
    ``(N, ceil(H / stride), ceil(W / stride), 2)``, for each ``stride × stride`` block of the crop the ``(x, y)`` of
    its centre in ``torch.nn.functional.grid_sample``'s coordinates (``align_corners=False``; −1 and 1 at the raster's
    outer edges)."""
    o = np.asarray(scene_origin, dtype=np.float64).reshape(-1)
    if o.shape != (2,):
        raise InvalidFrameError(f"scene_origin must be two numbers, got shape {np.shape(scene_origin)}")
    oo, hh = (np.ascontiguousarray(a, dtype=np.float64) for a in (origins, headings))
    out: npt.NDArray[np.float32] = _dgan.crop_grid(
        oo,
        hh,
        _spec_json(spec),
        _count(stride, "stride"),
        _count(size_px, "size_px"),
        (float(o[0]), float(o[1])),
        float(scene_heading),
    )
    return out


def _count(v: Any, name: str) -> int:
    if isinstance(v, bool) or not isinstance(v, int | np.integer) or v < 1:
        raise InvalidSpecError(f"{name} must be a positive int, got {v!r}")
    return int(v)


def read_kept(
    rows: npt.ArrayLike, index: npt.ArrayLike, weight: npt.ArrayLike, grid: tuple[int, int]
) -> npt.NDArray[np.float32]:
    """Each agent's reading ``(N, C, gh, gw)`` of a kept-features model's map (contract 13, the input
    ``map_patches``): for every crop block centre the weighted sum of its four rows (``index``, ``weight``
    ``(N, gh · gw · 4)``, as :func:`preprocess` gives them as ``map_index`` and ``map_weight``) of ``rows`` ``(R, C)``:
    ``map_rows`` followed by the network's ``map_features`` of the tiles in ``map`` (what the engine does between its
    two runs of such a model; ``dgan_core::kept``)."""
    r = np.ascontiguousarray(rows, dtype=np.float32)
    i = np.ascontiguousarray(index, dtype=np.int64)
    w = np.ascontiguousarray(weight, dtype=np.float32)
    if r.ndim != 2 or i.ndim != 2 or w.ndim != 2:
        raise InvalidSpecError(f"rows, index and weight must be 2-D, got {r.shape}, {i.shape}, {w.shape}")
    out: npt.NDArray[np.float32] = _dgan.read_kept(r, i, w, (int(grid[0]), int(grid[1])))
    return out
