"""``dgan demo``: predict a bundled real scene with a bundled model, print each agent's top modes, and draw them like
the paper's Figure 3 (observed path, ground truth, predicted modes coloured by probability).

The scene follows the model's time base: ETH/UCY models (0.4 s) get zara1, ``sdd`` (1/3 s) a Stanford Drone excerpt
over its reference image, ``apolloscape`` (0.5 s) an ApolloScape excerpt drawn in world metres with each agent's
measured box, ``hdmap`` (0.2 s) a Waymo Open Motion scenario over its vector map as the engine rasterises it, plus a
second picture of one agent's map crop as the engine draws it for the network. Classes are told apart by colour.
"""

from __future__ import annotations

import warnings
from collections.abc import Sequence
from dataclasses import dataclass, replace
from pathlib import Path
from typing import Any

import numpy as np
import numpy.typing as npt

from dgan.exceptions import DatasetWarning, DganError
from dgan.frame import Frame
from dgan.maps import RasterMap
from dgan.prediction import Prediction
from dgan.predictor import Predictor
from dgan.scenes import APOLLO_TYPES, SDD_LABEL_CLASS, scene_image, scene_map, sdd_raster_map
from dgan.spec import InputSpec

DATA = Path(__file__).parent / "data"
SCENE_FILE = DATA / "zara1" / "frames_5430_5620.txt"
SDD_FILE = DATA / "sdd" / "hyang_0" / "frames_824_853.txt"
SDD_IMAGE = DATA / "sdd" / "hyang_0" / "reference.jpg"
#: Metres per pixel of SDD hyang video0 (``estimated_scales.yaml``).
SDD_SCALE = 0.034749693
APOLLO_FILE = DATA / "apolloscape" / "result_9048_1_frames_10_25.txt"
WAYMO_FILE = DATA / "waymo" / "tfrecord-00005-of-00150_2bd577a009790706.json.gz"
#: ETH/UCY frame numbers are video frames at 25 fps; the annotations come every 10 frames (0.4 s).
ZARA1_SECONDS_PER_FRAME = 0.04
#: The Waymo scene's 10 Hz steps per model step (the hdmap model runs at 5 Hz).
WAYMO_EVERY = 2

Arr = npt.NDArray[Any]


@dataclass
class DemoScene:
    """A bundled excerpt at one time: the frame, every agent's future (world metres), what to draw on."""

    name: str
    frame: Frame
    futures: dict[int, Arr]
    labels: dict[int, str]
    image: Arr | None  # (H, W, 3) background, or None to draw in world metres
    world_to_pixel: Arr | None
    default_now: float
    headings: dict[int, float] | None = None  # measured headings at t_obs, for the boxes
    time_step: float = 1.0  # time between steps in the file's unit


def _futures(times: Arr, ids: Arr, xy: Arr, frame: Frame, now: float, t_f: int) -> dict[int, Arr]:
    """Each agent's true positions after ``now``, at most ``t_f`` steps (the predicted horizon; the file's rows are
    at the model's rate)."""
    out = {}
    for pid in frame.ids:
        sel = (ids == pid) & (times > now)
        out[int(pid)] = xy[sel][np.argsort(times[sel])][:t_f]
    return out


def zara1_scene(t_obs: int, t_f: int, now: float | None) -> DemoScene:
    """The bundled zara1 excerpt (frame ids step by 10; ``now`` in 5500..5510)."""
    now = 5500.0 if now is None else now
    rows = np.loadtxt(SCENE_FILE)
    ids = rows[:, 1].astype(np.int64)
    cols = {"time": rows[:, 0], "agent_id": ids, "x": rows[:, 2], "y": rows[:, 3]}
    frame = Frame.from_records(
        cols, t_obs=t_obs, dt=0.4, time_unit=ZARA1_SECONDS_PER_FRAME, current_time=now, map=scene_map("zara1")
    )
    img = scene_image("zara1")
    if img is None:
        raise DganError("the zara1 scene image is not bundled")
    labels = {int(i): "pedestrian" for i in frame.ids}
    futures = _futures(rows[:, 0], ids, rows[:, 2:4], frame, now, t_f)
    return DemoScene("zara1", frame, futures, labels, *img, 5500.0, time_step=10.0)


def sdd_scene(t_obs: int, t_f: int, now: float | None) -> DemoScene:
    """The bundled Stanford Drone excerpt (hyang video0, test split, steps 824..853; ``now`` in 831..841)."""
    now = 841.0 if now is None else now
    raw = np.loadtxt(SDD_FILE, dtype=str)
    times, ids = raw[:, 0].astype(float), raw[:, 1].astype(float).astype(np.int64)
    xy = raw[:, 2:4].astype(float) * SDD_SCALE
    cols = {
        "time": times,
        "agent_id": ids,
        "x": xy[:, 0],
        "y": xy[:, 1],
        "class": np.array([SDD_LABEL_CLASS[s] for s in raw[:, 4]], dtype=object),
    }
    smap = sdd_raster_map(SDD_IMAGE, SDD_SCALE)
    frame = Frame.from_records(cols, t_obs=t_obs, dt=1 / 3, time_unit=1 / 3, current_time=now, map=smap)
    labels = {int(i): str(raw[ids == i, 4][-1]) for i in frame.ids}
    image = RasterMap.from_file(SDD_IMAGE, np.eye(3)).image
    w2p = np.diag([1 / SDD_SCALE, 1 / SDD_SCALE, 1.0])
    futures = _futures(times, ids, xy, frame, now, t_f)
    return DemoScene("Stanford Drone hyang video0", frame, futures, labels, image, w2p, 841.0)


def apollo_scene(t_obs: int, t_f: int, now: float | None) -> DemoScene:
    """The bundled ApolloScape excerpt (recording 9048 file 1, frames 10..25; ``now`` in 15..19)."""
    now = 17.0 if now is None else now
    rows = np.loadtxt(APOLLO_FILE)
    ids = rows[:, 1].astype(np.int64)
    types = rows[:, 2].astype(int)
    cols = {
        "time": rows[:, 0],
        "agent_id": ids,
        "x": rows[:, 3],
        "y": rows[:, 4],
        "class": np.array([APOLLO_TYPES[t][1] for t in types], dtype=object),
        "length": rows[:, 6],
        "width": rows[:, 7],
        "heading": rows[:, 9],
    }
    frame = Frame.from_records(cols, t_obs=t_obs, dt=0.5, time_unit=0.5, current_time=now)
    labels = {int(i): APOLLO_TYPES[int(types[ids == i][-1])][0] for i in frame.ids}
    futures = _futures(rows[:, 0], ids, rows[:, 3:5], frame, now, t_f)
    at_now = rows[:, 0] == now
    headings = {int(i): float(hd) for i, hd in zip(ids[at_now], rows[at_now, 9], strict=True)}
    return DemoScene("ApolloScape recording 9048", frame, futures, labels, None, None, 17.0, headings)


def waymo_scene(
    t_obs: int, t_f: int, now: float | None, extent_m: float = 110.0, resolution_m: float = 0.2
) -> DemoScene:
    """The bundled Waymo scenario (10 Hz steps 0..90, sampled every second step; ``now`` in 18..60), over the
    engine's north-up rendering of its vector map."""
    from dgan.datasets.hdmaps import bird_eye, read_waymo_json

    step = 40 if now is None else int(now)
    with warnings.catch_warnings():  # the bundled scene's driveways are known and not drawn
        warnings.simplefilter("ignore", DatasetWarning)
        sc = read_waymo_json(WAYMO_FILE)
    span = WAYMO_EVERY * (t_obs - 1)
    if not span <= step <= sc.num_steps - 1 - WAYMO_EVERY:
        raise DganError(f"the Waymo demo scene needs --time in {span}..{sc.num_steps - 1 - WAYMO_EVERY}, got {step}")
    frame = sc.frame(step, t_obs, every=WAYMO_EVERY)
    rows = np.flatnonzero(sc.valid[:, step])
    moving = np.nanmax(np.linalg.norm(sc.positions[rows] - sc.positions[rows, step][:, None], axis=-1), axis=1) > 1
    c = np.nanmean(sc.positions[rows[moving] if moving.any() else rows, step], axis=0)  # centred on the movers
    image = bird_eye(sc, step, c, extent_m, resolution_m)
    half = image.shape[0] // 2
    # Pixel centres at integers: u = col + (x - cx) / res, v = row - (y - cy) / res (north up).
    w2p = np.array(
        [
            [1 / resolution_m, 0, half - c[0] / resolution_m],
            [0, -1 / resolution_m, half + c[1] / resolution_m],
            [0, 0, 1],
        ]
    )
    fut = np.arange(step + WAYMO_EVERY, sc.num_steps, WAYMO_EVERY)[:t_f]
    futures = {int(sc.ids[r]): sc.positions[r, fut][sc.valid[r, fut]] for r in rows}
    labels = {int(sc.ids[r]): sc.labels[r] for r in rows}
    headings = {int(sc.ids[r]): float(sc.heading[r, step]) for r in rows}
    return DemoScene(f"Waymo Open Motion {sc.name}", frame, futures, labels, image, w2p, 40.0, headings, WAYMO_EVERY)


def scene_for(spec: InputSpec, now: float | None = None) -> DemoScene:
    """The bundled scene that matches a model's time base, at step ``now`` (the scene's default if None)."""
    if abs(spec.dt_s - 0.4) < 1e-6:
        return zara1_scene(spec.t_obs, spec.t_f, now)
    if abs(spec.dt_s - 1 / 3) < 1e-6:
        return sdd_scene(spec.t_obs, spec.t_f, now)
    if abs(spec.dt_s - 0.5) < 1e-6:
        return apollo_scene(spec.t_obs, spec.t_f, now)
    if abs(spec.dt_s - 0.2) < 1e-6:
        return waymo_scene(spec.t_obs, spec.t_f, now)
    raise DganError(
        f"no bundled demo scene has steps of {spec.dt_s} s (ETH/UCY 0.4 s, SDD 1/3 s, ApolloScape 0.5 s, Waymo 0.2 s)"
    )


def draw(scene: DemoScene, pred: Prediction, out: Path, title: str) -> Path:
    """The scene's picture (``dgan.plot`` over its image, else its map) with the observed paths, the true futures and
    the predicted modes, written to ``out``."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    from dgan.viz import plot

    picture = None
    if scene.image is not None and scene.world_to_pixel is not None:
        picture = RasterMap(scene.image, scene.world_to_pixel)
    fig = plot(
        scene.frame,
        pred,
        map=picture,
        ground_truth=scene.futures,
        title=title,
        in_pixels=picture is not None,
        headings=scene.headings,
    )
    out.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(out)
    plt.close(fig)
    return out


def crop_agent(scene: DemoScene, readers: Sequence[str] = ()) -> int:
    """The row of the agent whose crop the demo shows: the one that travels farthest over its observed path and its
    future, among the classes that read the map (``readers``, a model's ``map.classes``; empty: every class)."""
    frame = scene.frame
    best, row = -1.0, 0
    for i, pid in enumerate(frame.ids):
        fut = scene.futures.get(int(pid))
        if fut is None or not len(fut) or (readers and frame.classes[i] not in readers):
            continue
        hist = frame.positions[i][frame.mask[i]]
        score = float(np.linalg.norm(fut[-1] - hist[-1]) + np.linalg.norm(hist[-1] - hist[0]))
        if score > best:
            best, row = score, i
    return row


def draw_crop(scene: DemoScene, predictor: Predictor, pred: Prediction, out: Path) -> Path:
    """One agent's map crop exactly as the network receives it (``dgan.preprocess``), with its observed path, its
    ground truth and the predicted modes drawn over it in the crop's pixels."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    from dgan.spec import preprocess, to_agent_frame
    from dgan.viz import MODE_COLOURS, SATURATION

    m = predictor.spec.map
    assert m is not None
    # A scene model (contract 12) reads its raster over the ground of this crop.
    spec = replace(predictor.spec, map=replace(m, scene=None))
    x = preprocess(scene.frame, spec)
    i = crop_agent(scene, m.classes)
    pid = int(scene.frame.ids[i])
    origin, heading = x["origin"][i : i + 1], x["heading"][i : i + 1]

    def px(world: Arr) -> Arr:
        local = to_agent_frame(world[None], origin, heading)[0]
        out: Arr = np.c_[m.agent_col - local[:, 1] / m.resolution_m, m.agent_row - local[:, 0] / m.resolution_m]
        return out

    fig, ax = plt.subplots(figsize=(6.4, 6.4 * m.height_px / m.width_px + 0.6), dpi=100)
    ax.imshow(np.moveaxis(x["map"][i], 0, -1), interpolation="nearest")
    hist = scene.frame.positions[i][scene.frame.mask[i]]
    h = px(hist)
    ax.plot(h[:, 0], h[:, 1], "--", color="orange", lw=2, label="observed")
    cmap = plt.get_cmap(MODE_COLOURS)
    for k in reversed(range(pred.trajectories.shape[1])):
        tr = px(np.vstack([hist[-1:], pred.trajectories[i, k]]))
        pr = pred.probabilities[i, k]
        ax.plot(tr[:, 0], tr[:, 1], "-", color=cmap(min(1.0, pr / SATURATION)), lw=1 + 3 * pr)
    fut = scene.futures.get(pid)
    if fut is not None and len(fut):
        g = px(np.vstack([hist[-1:], fut]))
        ax.plot(g[:, 0], g[:, 1], "-", color="red", lw=1.8, label="ground truth")
    ax.plot([], [], "-", color=cmap(0.9), label="predicted modes")
    ax.set_xlim(-0.5, m.width_px - 0.5)
    ax.set_ylim(m.height_px - 0.5, -0.5)
    ax.legend(loc="lower left", fontsize=8)
    ax.set_title(
        f"{scene.labels.get(pid, scene.frame.classes[i])} {pid}: its {m.height_px}×{m.width_px} px crop at "
        f"{m.resolution_m:g} m/px, heading up",
        fontsize=10,
    )
    fig.tight_layout()
    fig.savefig(out)
    plt.close(fig)
    return out


def run(model: str = "zara1", now: float | None = None, modes: int = 3, out: Path = Path("dgan_demo.png")) -> int:
    predictor = Predictor(model, modes=modes)
    scene = scene_for(predictor.spec, now)
    frame = scene.frame
    t = scene.default_now if now is None else now
    pred = predictor.predict(frame)
    card = predictor.contract.get("name", model)
    horizon = predictor.spec.t_f * predictor.spec.dt_s
    print(f"model {card}: {len(frame)} agents of {scene.name} at step {t:g}, {len(pred.edges)} attention edges")
    print(f"agent  label          top modes: probability -> position in {horizon:.1f} s (world metres)      true")
    for i, pid in enumerate(pred.agent_ids):
        end = pred.trajectories[i, :, -1]
        ends = "  ".join(
            f"{pred.probabilities[i, m]:.2f} -> ({end[m, 0]:6.2f}, {end[m, 1]:6.2f})" for m in range(len(end))
        )
        fut = scene.futures.get(int(pid))
        seen = 0 if fut is None else len(fut)
        if seen == predictor.spec.t_f and fut is not None:
            actual = f"({fut[-1, 0]:6.2f}, {fut[-1, 1]:6.2f})"
        elif seen and fut is not None:  # the excerpt or the track ends before the horizon
            actual = f"({fut[-1, 0]:6.2f}, {fut[-1, 1]:6.2f}) last seen {seen * predictor.spec.dt_s:.1f} s ahead"
        else:
            actual = "   (not seen after now)"
        print(f"{pid:>5}  {scene.labels[int(pid)]:<13}  {ends}   {actual}")
    try:
        import matplotlib  # noqa: F401
    except ImportError:
        print("(no picture: the demo draws with matplotlib; pip install 'dgan[plot]')")
        return 0
    path = draw(scene, pred, out, f"DGAN ({card}) on {scene.name}, step {t:g}: top {modes} modes")
    print(f"wrote {path}")
    if predictor.spec.map is not None:
        crop = draw_crop(scene, predictor, pred, out.with_name(f"{out.stem}_crop{out.suffix}"))
        print(f"wrote {crop} (one agent's map crop as the engine draws it for the network)")
    return 0
