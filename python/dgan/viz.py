"""Pictures of predictions: :func:`plot` draws a frame, its predicted modes and optionally the map and the truth, in
world metres (needs matplotlib: ``pip install dgan[plot]``).

The map is drawn as the engine rasterises it for the network (the same colours, the same geometry): a north-up
crop around the agents, so a raster map and a vector map look alike and what you see is what the model sees.
"""

from __future__ import annotations

import numbers
from collections.abc import Mapping
from typing import Any

import numpy as np
import numpy.typing as npt

from dgan._values import checked_array, checked_real, shown
from dgan.exceptions import DganError, InvalidFrameError, InvalidMapError, InvalidSpecError
from dgan.frame import Frame
from dgan.maps import RasterMap, VectorMap
from dgan.prediction import Prediction

#: Colour of each class in the pictures.
CLASS_COLOURS = {"vehicle": "deepskyblue", "cyclist": "limegreen", "pedestrian": "orange"}
#: Mode probability at which the colour scale saturates.
SATURATION = 0.5
#: The colour map of the mode probabilities.
MODE_COLOURS = "viridis"

Arr = npt.NDArray[Any]


def _pyplot() -> Any:
    try:
        import matplotlib.pyplot as plt
    except ImportError as e:
        raise DganError("dgan.plot needs matplotlib: pip install 'dgan[plot]'") from e
    return plt


def render_map(
    scene_map: RasterMap | VectorMap, centre: npt.ArrayLike, extent_m: float, pixels: int = 800
) -> tuple[Arr, tuple[float, float, float, float]]:
    """The map north-up, ``extent_m`` a side around ``centre``, as the engine rasterises it: an ``(H, W, 3)`` uint8
    image and its ``(left, right, bottom, top)`` extent in world metres (for ``imshow(extent=...)``)."""
    from dgan.spec import InputSpec, MapSpec, preprocess

    if not (np.isfinite(extent_m) and extent_m > 0):
        raise InvalidMapError(f"extent_m must be a positive number of metres, got {extent_m}")
    side = int(np.clip(pixels, 16, 2048))
    res = extent_m / side
    c = np.asarray(centre, dtype=np.float64)
    spec = InputSpec(dt_s=1.0, t_obs=2, t_f=1, map=MapSpec(side, side, res, side // 2, side // 2, draw_agents=False))
    # A virtual agent at the centre heading north: its crop is the picture.
    view = Frame(np.array([[c - [0.0, 0.1], c]]), headings=[np.pi / 2], map=scene_map)
    crop = preprocess(view, spec)["map"][0]
    image: Arr = (np.moveaxis(crop, 0, -1) * 255).round().clip(0, 255).astype(np.uint8)
    a = side // 2
    # Pixel (row, col) centre ↔ world (cx + (col − a)·res, cy + (a − row)·res).
    extent = (
        c[0] + (-0.5 - a) * res,
        c[0] + (side - 0.5 - a) * res,
        c[1] + (a - side + 0.5) * res,
        c[1] + (a + 0.5) * res,
    )
    return image, extent


def _bounds(point_sets: list[Arr], margin_m: float) -> tuple[Arr, Arr]:
    """The corners ``(lo, hi)`` of the box around every point of ``point_sets``, widened by ``margin_m``."""
    points = [p for p in point_sets if len(p)]
    every = np.vstack(points) if points else np.zeros((1, 2))
    return every.min(axis=0) - margin_m, every.max(axis=0) + margin_m


def _map_under(scene_map: RasterMap | VectorMap, lo: Arr, hi: Arr) -> tuple[Arr, tuple[float, float, float, float]]:
    """:func:`render_map` of the square around the box ``(lo, hi)``."""
    return render_map(scene_map, (lo + hi) / 2, float(max(hi - lo)))


def _to_pixels(points: Arr, h: Arr | None) -> Arr:
    """``(P, 2)`` world points through the homography ``h`` (unchanged without one)."""
    if h is None:
        return points
    q = np.c_[points, np.ones(len(points))] @ h.T
    out: Arr = q[:, :2] / q[:, 2:]
    return out


def _box(centre: Arr, yaw: float, length: float, width: float) -> Arr:
    """The four corners of a ``length`` × ``width`` box at ``centre`` heading ``yaw`` (world frame)."""
    c, s = np.cos(yaw), np.sin(yaw)
    half = np.array([[1, 1], [1, -1], [-1, -1], [-1, 1]]) * [length / 2, width / 2]
    out: Arr = centre + half @ np.array([[c, s], [-s, c]])
    return out


def _truths(
    frame: Frame, ground_truth: Mapping[Any, npt.ArrayLike] | npt.ArrayLike | None, t_f: int
) -> list[Arr | None]:
    """Each row's true future up to ``t_f`` steps, from an ``(N, T, 2)`` array or an id → ``(T, 2)`` mapping."""
    n = len(frame)
    truth: list[Arr | None] = [None] * n
    if ground_truth is None:
        return truth
    if isinstance(ground_truth, Mapping):
        for i, a in enumerate(frame.agent_ids.tolist()):
            if a in ground_truth:
                future = checked_array(f"ground_truth[{a!r}]", ground_truth[a], np.float64, required=True)
                truth[i] = future.reshape(-1, 2)[:t_f]
        return truth
    gt = checked_array("ground_truth", ground_truth, np.float64)
    if gt.ndim != 3 or gt.shape[0] != n or gt.shape[2] != 2:
        raise InvalidFrameError(f"ground_truth must have shape (N={n}, T, 2), got {gt.shape}")
    return [gt[i, :t_f] for i in range(n)]


def _check_options(ax: Any, margin_m: Any, in_pixels: Any, headings: Any) -> None:
    """Refuses what :func:`plot` cannot draw with, naming the option."""
    margin = checked_real("margin_m", margin_m, InvalidSpecError)
    if not (np.isfinite(margin) and margin >= 0):
        raise InvalidSpecError(f"margin_m must be a finite, non-negative number of metres, got {margin_m!r}")
    if not isinstance(in_pixels, (bool, np.bool_)):
        raise InvalidSpecError(f"in_pixels must be True or False, got {shown(in_pixels)}")
    if headings is not None and not isinstance(headings, Mapping):
        raise InvalidSpecError(f"headings must map agent ids to headings in radians, got {shown(headings)}")
    if ax is not None and not (hasattr(ax, "figure") and hasattr(ax, "imshow")):
        raise InvalidSpecError(f"ax must be a matplotlib Axes or None, got {shown(ax)}")


def _new_axes(plt: Any, picture: Arr | None, lo: Arr, hi: Arr) -> Any:
    """Axes sized to the picture (11 inches on its longer side) or to the scene's aspect (8 inches high or 12 wide at
    most), with room for the colour bar."""
    if picture is not None:
        rows, cols = picture.shape[:2]
        size = (cols / max(rows, cols) * 11 + 1.6, rows / max(rows, cols) * 11)
    else:
        aspect = float(np.clip((hi[0] - lo[0]) / (hi[1] - lo[1]), 0.3, 3.0))
        w, ht = (12.0, 12.0 / aspect) if aspect > 1.4 else (8.0 * aspect, 8.0)
        size = (max(w, 4.0) + 1.6, max(ht, 3.0))
    _, ax = plt.subplots(figsize=size, dpi=100, layout="constrained")
    return ax


def _draw_agent(
    ax: Any,
    cmap: Any,
    h: Arr | None,
    cls: str,
    hist: Arr,
    modes: list[Arr],
    probabilities: Arr,
    truth: Arr | None,
    box: tuple[float, float, float] | None,
) -> None:
    """One agent: its observed path dashed in its class's colour, a dot (or its ``(yaw, length, width)`` box) at the
    last observed step, its modes coloured and thickened by probability (most probable on top), its truth in red."""
    from matplotlib.patches import Polygon

    colour = CLASS_COLOURS.get(cls, "white")
    obs = _to_pixels(hist, h)
    ax.plot(obs[:, 0], obs[:, 1], "--", color=colour, lw=1.6, zorder=3)
    if box is not None:
        corners = _to_pixels(_box(hist[-1], *box), h)
        ax.add_patch(Polygon(corners, closed=True, fc=colour, ec="white", lw=0.6, alpha=0.8))
    else:
        ax.plot(*obs[-1], "o", color=colour, ms=5, mec="black", zorder=5)
    for path, pr in reversed(list(zip(modes, probabilities.tolist(), strict=True))):
        tr = _to_pixels(path, h)
        ax.plot(tr[:, 0], tr[:, 1], "-", color=cmap(min(1.0, pr / SATURATION)), lw=0.8 + 3 * pr, zorder=4)
    if truth is not None:
        t = truth[np.isfinite(truth).all(axis=1)]
        if len(t):
            g = _to_pixels(np.vstack([hist[-1:], t]), h)
            ax.plot(g[:, 0], g[:, 1], "-", color="red", lw=1.6, zorder=4)


def plot(
    frame: Frame,
    prediction: Prediction,
    map: RasterMap | VectorMap | None = None,
    ground_truth: Mapping[Any, npt.ArrayLike] | npt.ArrayLike | None = None,
    *,
    modes: int | None = None,
    ax: Any = None,
    title: str | None = None,
    margin_m: float = 5.0,
    in_pixels: bool = False,
    headings: Mapping[Any, float] | None = None,
) -> Any:
    """A matplotlib figure of a prediction, axes in world metres (or in the pixels of a raster map's image).

    Args:
        frame: the frame that was predicted (its observed paths are drawn dashed, coloured by class).
        prediction: ``Predictor.predict(frame)``; modes are drawn most probable on top, coloured and thickened by
            probability.
        map: drawn underneath as the engine rasterises it (the frame's own map if None; none if neither).
        ground_truth: the true futures, ``(N, T, 2)`` in frame row order (NaN where unknown) or a mapping from
            agent id to a ``(T, 2)`` array; drawn in red up to the predicted horizon.
        modes: the modes drawn per agent (all that the prediction holds if None).
        ax: a matplotlib Axes to draw on (a new figure if None).
        title: the axes' title.
        margin_m: metres of margin around the drawn paths.
        in_pixels: draw the map (a :class:`RasterMap`: a camera view, a drone video's frame) as its own image, with
            every path taken into its pixels by the map's world → pixel homography, instead of north-up in metres.
        headings: agent id → heading (rad, world frame) at the last observed step: the agent is drawn as its
            ``length`` × ``width`` box instead of a dot.

    Returns:
        The matplotlib Figure.

    Raises:
        InvalidFrameError: the prediction does not belong to the frame (other agents, other count).
        InvalidMapError: ``in_pixels`` without a raster map to draw.
        DganError: matplotlib is not installed.
    """
    plt = _pyplot()
    from matplotlib.colors import Normalize

    if not isinstance(frame, Frame) or not isinstance(prediction, Prediction):
        raise InvalidFrameError("plot takes a dgan.Frame and its dgan.Prediction")
    _check_options(ax, margin_m, in_pixels, headings)
    scene_map = frame.map if map is None else map
    picture, h = None, None
    if in_pixels:
        if not isinstance(scene_map, RasterMap):
            kind = type(scene_map).__name__
            raise InvalidMapError(f"in_pixels draws a RasterMap in its own pixels; the map is {kind}")
        picture, h = scene_map.image, scene_map.world_to_pixel
    n, m, t_f = len(frame), _drawn_modes(frame, prediction, modes), prediction.trajectories.shape[2]
    truth = _truths(frame, ground_truth, t_f)
    pts = [frame.positions[i][frame.mask[i]] for i in range(n)]
    drawn = [*pts, *prediction.trajectories[:, :m].reshape(-1, t_f, 2)]
    drawn += [t[np.isfinite(t).all(axis=1)] for t in truth if t is not None]
    lo, hi = _bounds(drawn, margin_m)
    if ax is None:
        ax = _new_axes(plt, picture, lo, hi)
    fig = ax.figure
    if picture is not None:
        ax.imshow(picture, zorder=0)
    elif scene_map is not None:
        rendered, extent = _map_under(scene_map, lo, hi)
        ax.imshow(rendered, extent=extent, origin="upper", interpolation="nearest", zorder=0)
    else:
        ax.set_facecolor("0.96")
    cmap = plt.get_cmap(MODE_COLOURS)
    ids = frame.agent_ids.tolist()
    for i in range(n):
        yaw = None if headings is None else headings.get(ids[i])
        box = None if yaw is None or not len(pts[i]) else (float(yaw), float(frame.lengths[i]), float(frame.widths[i]))
        paths = [np.vstack([pts[i][-1:], prediction.trajectories[i, k]]) for k in range(m)]
        _draw_agent(ax, cmap, h, frame.classes[i], pts[i], paths, prediction.probabilities[i, :m], truth[i], box)
    _frame_axes(ax, picture, lo, hi)
    sm = plt.cm.ScalarMappable(cmap=cmap, norm=Normalize(0, SATURATION))
    fig.colorbar(sm, ax=ax, fraction=0.035, pad=0.01, label=f"mode probability (≥ {SATURATION:g} saturates)")
    _legend(ax, cmap, sorted(set(frame.classes)), any(t is not None for t in truth), t_f * prediction.dt_s)
    if title is not None:
        ax.set_title(title)
    return fig


def _drawn_modes(frame: Frame, prediction: Prediction, modes: int | None) -> int:
    """How many modes of each agent are drawn, once the prediction is checked to be of the frame."""
    n = len(frame)
    if len(prediction) != n or not np.array_equal(np.asarray(prediction.agent_ids), np.asarray(frame.agent_ids)):
        raise InvalidFrameError(f"the prediction ({len(prediction)} agents) is not of this frame ({n} agents)")
    m_all = int(prediction.trajectories.shape[1])
    if modes is not None and (isinstance(modes, bool) or not isinstance(modes, numbers.Integral) or modes < 1):
        raise InvalidSpecError(f"modes must be a whole number of at least 1 (or None for all), got {modes!r}")
    return m_all if modes is None else min(int(modes), m_all)


def _frame_axes(ax: Any, picture: npt.NDArray[np.uint8] | None, lo: Any, hi: Any) -> None:
    """The axes' limits: a picture's own pixels (no axes drawn), or the world metres between ``lo`` and ``hi``."""
    if picture is not None:
        ax.set_xlim(-0.5, picture.shape[1] - 0.5)
        ax.set_ylim(picture.shape[0] - 0.5, -0.5)
        ax.set_axis_off()
        return
    ax.set_xlim(lo[0], hi[0])
    ax.set_ylim(lo[1], hi[1])
    ax.set_aspect("equal")
    ax.set_xlabel("x (m)")
    ax.set_ylabel("y (m)")


def _legend(ax: Any, cmap: Any, classes: list[str], truth: bool, horizon_s: float) -> None:
    """One legend entry per observed class, the ground truth (if drawn) and the predicted modes."""
    for cls in classes:
        ax.plot([], [], "--", color=CLASS_COLOURS.get(cls, "white"), label=f"observed {cls}")
    if truth:
        ax.plot([], [], "-", color="red", label="ground truth")
    ax.plot([], [], "-", color=cmap(0.9), label=f"predicted modes ({horizon_s:g} s)")
    ax.legend(loc="best", fontsize=8)


_RGB = {"vehicle": (0, 191, 255), "cyclist": (50, 205, 50), "pedestrian": (255, 165, 0)}


def log_rerun(
    frame: Frame,
    prediction: Prediction,
    *,
    recording: Any = None,
    time_s: float | None = None,
    ground_truth: Mapping[Any, npt.ArrayLike] | None = None,
    map: RasterMap | VectorMap | None = None,
    entity: str = "dgan",
) -> None:
    """Logs a frame and its prediction to a rerun recording (``pip install 'dgan[rerun]'``), in world metres: each
    agent's observed path (``{entity}/observed``), its current position labelled by id, the modes
    (``{entity}/modes``, labelled with their probability), the truth if given and the map (rendered as the engine
    sees it) underneath. Call it at every tick with ``time_s`` to get a timeline (``time``).

    Args:
        recording: a ``rerun.RecordingStream`` (the global one if None); ``recording.save(path)`` writes an
            ``.rrd`` file that ``rerun path.rrd`` opens.
        time_s: the frame's current time in seconds, set on the ``time`` timeline.

    Raises:
        DganError: rerun is not installed. InvalidFrameError: the prediction is not of this frame.
    """
    try:
        import rerun as rr
    except ImportError as e:
        raise DganError("logging to rerun needs rerun-sdk: pip install 'dgan[rerun]'") from e
    if not isinstance(frame, Frame) or not isinstance(prediction, Prediction):
        raise InvalidFrameError("log_rerun takes a dgan.Frame and its dgan.Prediction")
    if len(prediction) != len(frame):
        raise InvalidFrameError(f"the prediction ({len(prediction)} agents) is not of this frame ({len(frame)})")
    rec = recording if recording is not None else rr.get_global_data_recording()
    if rec is None:
        raise DganError("no rerun recording: pass recording=rerun.RecordingStream(...) or call rerun.init first")
    if time_s is not None:
        rec.set_time("time", duration=float(time_s))
    n = len(frame)
    ids = [str(a) for a in frame.agent_ids.tolist()]
    colours = [_RGB.get(c, (255, 255, 255)) for c in frame.classes]
    hist = [frame.positions[i][frame.mask[i]] for i in range(n)]
    rec.log(f"{entity}/observed", rr.LineStrips2D(hist, colors=colours, radii=0.05))
    now = np.array([h[-1] for h in hist]) if n else np.zeros((0, 2))
    rec.log(f"{entity}/agents", rr.Points2D(now, colors=colours, labels=ids, radii=0.2))
    strips, strip_colours, labels = [], [], []
    m = prediction.trajectories.shape[1]
    for i in range(n):
        for k in range(m):
            p = float(prediction.probabilities[i, k])
            strips.append(np.vstack([hist[i][-1:], prediction.trajectories[i, k]]))
            level = round(min(1.0, p / SATURATION) * 255)
            strip_colours.append((level, 64, 255 - level))
            labels.append(f"{ids[i]} p={p:.2f}")
    rec.log(f"{entity}/modes", rr.LineStrips2D(strips, colors=strip_colours, labels=labels, radii=0.04))
    if ground_truth is not None:
        truth = [
            np.vstack([hist[i][-1:], np.asarray(ground_truth[a], dtype=np.float64).reshape(-1, 2)])
            for i, a in enumerate(frame.agent_ids.tolist())
            if a in ground_truth
        ]
        rec.log(f"{entity}/ground_truth", rr.LineStrips2D(truth, colors=(255, 0, 0), radii=0.05))
    scene_map = frame.map if map is None else map
    if scene_map is not None and n:
        lo, hi = _bounds([*hist, prediction.trajectories.reshape(-1, 2)], 5.0)
        image, (left, right, _bottom, top) = _map_under(scene_map, lo, hi)
        res = (right - left) / image.shape[1]
        # Pixel (u, v) → world (left + u·res, top − v·res); the image sits under the agents.
        rec.log(
            f"{entity}/map",
            rr.Transform3D(translation=[left, top, 0.0], mat3x3=[[res, 0, 0], [0, -res, 0], [0, 0, 1]]),
            rr.Image(image, draw_order=-10.0),
        )
