"""The research-style pipeline: what a researcher would run instead of the engine (issue 26).

Preprocessing written in numpy from the model contract's text (`docs/model-contract.md`), vectorised the way numpy
code usually is (over agents, pixels and edges; a Python loop only over the agents' map crops of a vector map), the
training code's network in eager PyTorch on its edge-list inputs, and decoding in numpy:

- traffic state (velocity, acceleration, yaw rate, heading by the model's ``heading`` rule), agent-centric
  trajectories and the one-hot state;
- the attention-zone graph by its O(N²) definition (‖p_i − p_j‖ ≤ r_i + r_j), as an edge list with its features;
- the kinematic prior (``endpoints``, ``least_squares``, ``quadratic`` or ``adaptive`` fit over its window, standing
  agents at 0);
- the map crops: a raster map resampled bilinearly through its homography; a vector map drawn per agent by a crossing
  test for regions and the distance to each segment for lines (no anti-aliasing, unlike the engine); the agents as
  blue boxes (pixel centres inside the box);
- decoding: p(c) · p(k | c) with the temperatures (contract 9's speed-dependent one too), modes sorted, taken back to
  the world.

It is checked against the engine in ``tests/python/benches/test_research.py`` (the same tensors to float32
rounding, the crops of a raster map to a grey level, those of a vector map up to the anti-aliased edges). This is a
benchmark's comparison pipeline, not an API: the engine is the one implementation the package serves.
"""

from __future__ import annotations

import dataclasses
from collections.abc import Callable
from pathlib import Path
from typing import Any

import numpy as np
import numpy.typing as npt

import dgan
from dgan import contract

Arr = npt.NDArray[Any]
#: Speeds below this have no direction of motion (the contract's 0.2 m/s).
MIN_MOVING_SPEED = 0.2
#: The ``motion_when_moving`` heading rule's speed (1 m/s).
MOTION_HEADING_SPEED = 1.0
#: Dashed lane lines: 3 m painted, 6 m blank.
DASH_M = (3.0, 6.0)
ROOT = Path(__file__).resolve().parents[1]
AGENT_COLOUR = np.array(contract.AGENT_COLOUR, dtype=np.uint8)


def wrap(a: Arr) -> Arr:
    w = np.mod(a, 2 * np.pi)
    return np.where(w > np.pi, w - 2 * np.pi, w)


def kth_last(mask: Arr, k: int) -> Arr:
    """``(N,)`` index of each agent's k-th last observed step, -1 where it has fewer."""
    hit = np.cumsum(mask[:, ::-1], axis=1) >= k
    return np.where(hit.any(axis=1), mask.shape[1] - 1 - np.argmax(hit, axis=1), -1)


def to_local(points: Arr, origin: Arr, heading: Arr) -> Arr:
    """World points ``(N, ..., 2)`` in each agent's frame (origin ``(N, 2)``, heading ``(N,)``)."""
    shape = (len(origin),) + (1,) * (points.ndim - 2)
    c, s = np.cos(heading).reshape(shape), np.sin(heading).reshape(shape)
    d = points - origin.reshape((*shape, 2))
    return np.stack([c * d[..., 0] + s * d[..., 1], -s * d[..., 0] + c * d[..., 1]], axis=-1)


def to_world(points: Arr, origin: Arr, heading: Arr) -> Arr:
    shape = (len(origin),) + (1,) * (points.ndim - 2)
    c, s = np.cos(heading).reshape(shape), np.sin(heading).reshape(shape)
    x, y = points[..., 0], points[..., 1]
    return np.stack([c * x - s * y, s * x + c * y], axis=-1) + origin.reshape((*shape, 2))


def traffic_states(frame: dgan.Frame, dt: float, heading_rule: str) -> dict[str, Arr]:
    """Position, velocity, speed, acceleration, yaw rate and heading of every agent at its last observed step."""
    pos, mask = np.nan_to_num(frame.positions), frame.mask
    n = len(pos)
    rows = np.arange(n)
    l1, l2, l3 = kth_last(mask, 1), kth_last(mask, 2), kth_last(mask, 3)
    count = mask.sum(axis=1)

    def at(idx: Arr) -> Arr:
        return pos[rows, np.maximum(idx, 0)]

    with np.errstate(divide="ignore", invalid="ignore"):
        v_hist = np.where((count >= 2)[:, None], (at(l1) - at(l2)) / ((l1 - l2) * dt)[:, None], 0.0)
        v_prev = np.where((count >= 3)[:, None], (at(l2) - at(l3)) / ((l2 - l3) * dt)[:, None], 0.0)
        given = frame.velocities
        known = np.asarray(np.isfinite(given).all(axis=1))
        velocity = np.where(known[:, None], given, v_hist)
        speed = np.hypot(velocity[:, 0], velocity[:, 1])
        s1, s0 = np.hypot(v_hist[:, 0], v_hist[:, 1]), np.hypot(v_prev[:, 0], v_prev[:, 1])
        span = (l1 - l3) * 0.5 * dt
        three = count >= 3
        acceleration = np.where(three, (s1 - s0) / span, 0.0)
        turning = three & (s1 >= MIN_MOVING_SPEED) & (s0 >= MIN_MOVING_SPEED)
        turn = wrap(np.arctan2(v_hist[:, 1], v_hist[:, 0]) - np.arctan2(v_prev[:, 1], v_prev[:, 0]))
        yaw_rate = np.where(turning, turn / span, 0.0)
    last = at(l1)
    disp = last - at(np.argmax(mask, axis=1))
    motion = np.where(
        speed >= MIN_MOVING_SPEED,
        np.arctan2(velocity[:, 1], velocity[:, 0]),
        np.where(
            np.hypot(disp[:, 0], disp[:, 1]) >= MIN_MOVING_SPEED * dt * count, np.arctan2(disp[:, 1], disp[:, 0]), 0
        ),
    )
    given_h = frame.headings
    if heading_rule == "measured":
        heading = np.where(np.isfinite(given_h), given_h, motion)
    elif heading_rule == "motion_when_moving":
        heading = np.where(np.isfinite(given_h) & (speed < MOTION_HEADING_SPEED), given_h, motion)
    else:
        heading = motion
    return {
        "position": last,
        "velocity": velocity,
        "speed": speed,
        "acceleration": acceleration,
        "yaw_rate": yaw_rate,
        "heading": wrap(heading),
        "length": frame.lengths,
        "width": frame.widths,
    }


def window_velocity(traj: Arr, mask: Arr, steps: int, dt: float, fit: str) -> tuple[Arr, Arr]:
    """Each agent's velocity over its last ``steps`` steps by ``fit``, and where it has one."""
    n, t_obs, _ = traj.shape
    last = kth_last(mask, 1)
    t = np.arange(t_obs)[None, :]
    if fit == "endpoints":
        before = mask & (t >= (last - steps)[:, None]) & (t < last[:, None])
        first = np.argmax(before, axis=1)
        rows = np.arange(n)
        with np.errstate(divide="ignore", invalid="ignore"):
            v = (traj[rows, last] - traj[rows, first]) / ((last - first) * dt)[:, None]
        return v, before.any(axis=1) & (last >= 0)
    w = (mask & (t >= (last - steps)[:, None]) & (t <= last[:, None])).astype(np.float64)
    k = w.sum(axis=1)
    tau = (t - last[:, None]).astype(np.float64)
    if fit == "adaptive":
        w = adaptive_window(w, tau, traj)
    line = slope(w, tau, traj, 1)
    if fit == "quadratic":
        quad = slope(w, tau, traj, 2)
        line = np.where((k >= 3)[:, None], quad, line)
    return line / dt, k >= 2


def adaptive_window(w: Arr, tau: Arr, traj: Arr) -> Arr:
    """The weights of the most recent m valid steps of each agent's window ``w``, m (at least 2) of least expected
    squared velocity error: the noise's 2 var / sum (t - mean)^2 plus the lag's |a|^2 (last - mean)^2, the noise
    variance and the acceleration a from the least-squares parabola through the whole window (a's sampling variance
    taken off |a|^2); the last two steps where the window holds fewer than four (the engine's ``adaptive_span``)."""
    n = w.sum(axis=1)
    powers = np.stack([tau**j for j in range(3)], axis=-1)  # (N, T, 3)
    normal = np.einsum("nt,nti,ntj->nij", w, powers, powers) + np.eye(3) * 1e-12
    coef = np.linalg.solve(normal, np.einsum("nt,nti,ntc->nic", w, powers, traj))  # (N, 3, 2)
    rss = np.einsum("nt,ntc->n", w, (traj - np.einsum("nti,nic->ntc", powers, coef)) ** 2)
    sigma2 = rss / (2.0 * np.maximum(n - 3, 1))
    inv_cc = np.linalg.inv(normal)[:, 2, 2]
    acc2 = np.maximum(4.0 * ((coef[:, 2] ** 2).sum(axis=1) - 2.0 * sigma2 * inv_cc), 0.0)
    from_end = np.cumsum(w[:, ::-1], axis=1)[:, ::-1]  # valid steps at or after each step
    cost = np.full((len(w), w.shape[1] + 1), np.inf)
    for m in range(2, w.shape[1] + 1):
        wm = w * (from_end <= m)
        k = wm.sum(axis=1)
        mean_t = (wm * tau).sum(axis=1) / np.maximum(k, 1)
        sxx = (wm * (tau - mean_t[:, None]) ** 2).sum(axis=1)
        with np.errstate(divide="ignore", invalid="ignore"):
            cost[:, m] = np.where(k == m, 2.0 * sigma2 / sxx + acc2 * mean_t**2, np.inf)
    span = np.where(n >= 4, np.argmin(cost, axis=1), 2)
    out: Arr = w * (from_end <= span[:, None])
    return out


def slope(w: Arr, tau: Arr, traj: Arr, degree: int) -> Arr:
    """The slope at τ = 0 of each agent's weighted least-squares polynomial of ``degree`` in τ (both coordinates)."""
    powers = np.stack([tau**j for j in range(degree + 1)], axis=-1)  # (N, T, d + 1)
    normal = np.einsum("nt,nti,ntj->nij", w, powers, powers)
    rhs = np.einsum("nt,nti,ntc->nic", w, powers, traj)
    normal = normal + np.eye(degree + 1) * 1e-12  # agents without enough steps: any finite answer, masked above
    out: Arr = np.linalg.solve(normal, rhs)[:, 1]
    return out


def prior_rollout(traj: Arr, mask: Arr, state: Arr, spec: dgan.InputSpec) -> Arr:
    """``(N, T_f, 2)`` the kinematic prior in each agent's frame."""
    n = len(traj)
    prior = spec.prior
    if prior.kind == "none":
        return np.zeros((n, spec.t_f, 2))
    v = state[:, :1] * state[:, 3:5]
    steps = max(1, round(prior.window_s / spec.dt_s)) if prior.window_s > 0 else 0
    if steps:
        fitted, ok = window_velocity(traj, mask, steps, spec.dt_s, prior.fit)
        v = np.where(ok[:, None], fitted, v)
    if prior.standing_mps > 0:
        if steps:
            line, ok = window_velocity(traj, mask, steps, spec.dt_s, "least_squares")
            judged = np.where(ok[:, None], line, v) if prior.fit != "least_squares" else v
        else:
            judged = v
        still = np.hypot(judged[:, 0], judged[:, 1]) < prior.standing_mps
        v = np.where(still[:, None], 0.0, v)
    v = np.where(np.isfinite(v).all(axis=1)[:, None], v, 0.0)
    times = np.arange(1, spec.t_f + 1) * spec.dt_s
    out: Arr = v[:, None, :] * times[None, :, None]
    return out


def pixel_world(states: dict[str, Arr], m: Any) -> Arr:
    """``(N, H, W, 2)`` world position of every pixel centre of every agent's crop."""
    rows, cols = np.meshgrid(np.arange(m.height_px), np.arange(m.width_px), indexing="ij")
    local = np.stack([(m.agent_row - rows) * m.resolution_m, (m.agent_col - cols) * m.resolution_m], axis=-1)
    n = len(states["position"])
    return to_world(np.broadcast_to(local, (n, *local.shape)), states["position"], states["heading"])


def round_u8(x: Arr) -> Arr:
    """Round half away from zero into [0, 255], as an 8-bit image is written."""
    return np.clip(np.floor(np.nan_to_num(x) + 0.5), 0, 255).astype(np.uint8)


def raster_crops(raster: dgan.RasterMap, world: Arr) -> Arr:
    """Bilinear resampling of the image through its homography; black outside it."""
    image, h = raster.image, np.asarray(raster.world_to_pixel)
    assert image is not None
    ih, iw, _ = image.shape
    x, y = world[..., 0], world[..., 1]
    z = h[2, 0] * x + h[2, 1] * y + h[2, 2]
    with np.errstate(divide="ignore", invalid="ignore"):
        u = (h[0, 0] * x + h[0, 1] * y + h[0, 2]) / z
        v = (h[1, 0] * x + h[1, 1] * y + h[1, 2]) / z
    inside = (u > -1) & (v > -1) & (u < iw) & (v < ih) & np.isfinite(u) & np.isfinite(v)
    u, v = np.where(inside, u, 0.0), np.where(inside, v, 0.0)
    c0, r0 = np.floor(u).astype(np.int64), np.floor(v).astype(np.int64)
    fu, fv = (u - c0).astype(np.float32), (v - r0).astype(np.float32)
    out = np.zeros((*u.shape, 3), dtype=np.float32)
    for dr, wr in ((0, 1 - fv), (1, fv)):
        for dc, wc in ((0, 1 - fu), (1, fu)):
            r, c = r0 + dr, c0 + dc
            ok = (r >= 0) & (r < ih) & (c >= 0) & (c < iw)
            tap = image[np.clip(r, 0, ih - 1), np.clip(c, 0, iw - 1)].astype(np.float32)
            out += np.where(ok, wr * wc, 0)[..., None] * tap
    return np.where(inside[..., None], round_u8(out), 0).astype(np.uint8)


def dashes(px: Arr, on: float, period: float, size: tuple[int, int]) -> list[Arr]:
    """The painted stretches of a polyline ``(V, 2)`` (pixels), dashed from its first vertex, that can reach a crop
    of ``size`` (height, width)."""
    arc = np.concatenate([[0.0], np.cumsum(np.hypot(*np.diff(px, axis=0).T))])
    start = np.arange(0.0, arc[-1], period)
    end = np.minimum(start + on, arc[-1])
    a = np.stack([np.interp(start, arc, px[:, 0]), np.interp(start, arc, px[:, 1])], axis=1)
    b = np.stack([np.interp(end, arc, px[:, 0]), np.interp(end, arc, px[:, 1])], axis=1)
    # A dash is at most `on` pixels long: one whose start is farther than that from the crop cannot reach it.
    h, w = size
    near = (a[:, 0] > -on - 2) & (a[:, 0] < w + on + 2) & (a[:, 1] > -on - 2) & (a[:, 1] < h + on + 2)
    first, last = np.searchsorted(arc, start, side="right"), np.searchsorted(arc, end, side="left")
    return [np.concatenate([a[k : k + 1], px[first[k] : last[k]], b[k : k + 1]]) for k in np.flatnonzero(near)]


class Elements:
    """A vector map's elements in the contract's drawing order, their points in one array and their bounding boxes
    (made once per frame, as research code caches its map)."""

    def __init__(self, elements: list[tuple[str, Arr]]) -> None:
        order = {k.name: i for i, k in enumerate(contract.MAP_KINDS)}
        ranked = sorted(elements, key=lambda e: order[e[0]])
        self.kinds = [contract.MAP_KINDS[order[name]] for name, _ in ranked]
        self.points = np.concatenate([p for _, p in ranked]) if ranked else np.zeros((0, 2))
        self.ends = np.cumsum([0] + [len(p) for _, p in ranked])
        self.lo = np.array([p.min(axis=0) for _, p in ranked]).reshape(-1, 2)
        self.hi = np.array([p.max(axis=0) for _, p in ranked]).reshape(-1, 2)


def vector_crop(els: Elements, origin: Arr, heading: float, m: Any) -> Arr:
    """One agent's crop ``(H, W, 3)`` of a vector map, drawn with Pillow as research code does (each kind in the
    contract's drawing order, regions filled, lines of their width, dashed lines cut into their dashes; no
    anti-aliasing)."""
    from PIL import Image, ImageDraw

    reach = np.hypot(m.height_px, m.width_px) * m.resolution_m + 2.0
    near = np.flatnonzero(~((els.lo > origin + reach).any(axis=1) | (els.hi < origin - reach).any(axis=1)))
    img = Image.new("RGB", (m.width_px, m.height_px))
    if len(near) == 0:
        return np.asarray(img)
    idx = np.concatenate([np.arange(els.ends[k], els.ends[k + 1]) for k in near])
    local = to_local(els.points[idx][None], origin[None], np.array([heading]))[0]
    # Pillow's integer coordinates are pixel centres; the contract's are pixel corners.
    px = np.stack([m.agent_col - local[:, 1] / m.resolution_m, m.agent_row - local[:, 0] / m.resolution_m], 1)
    draw = ImageDraw.Draw(img)
    at = 0
    for k in near:
        kind, count = els.kinds[k], els.ends[k + 1] - els.ends[k]
        part, at = px[at : at + count], at + count
        colour = kind.colour
        if kind.polygon or kind.width_m is None:
            draw.polygon(part.ravel().tolist(), fill=colour)
            continue
        width = max(1, round(kind.width_m / m.resolution_m))
        pieces = [part]
        if kind.name == "lane_line_dashed":
            pieces = dashes(part, DASH_M[0] / m.resolution_m, sum(DASH_M) / m.resolution_m, (m.height_px, m.width_px))
        for piece in pieces:
            draw.line(piece.ravel().tolist(), fill=colour, width=width)
    return np.asarray(img)


def draw_boxes(crops: Arr, states: dict[str, Arr], m: Any, owners: tuple[Arr, Arr] | None = None) -> None:
    """Every agent as a blue box over every crop it reaches: the pixels whose centres lie inside it (no
    anti-aliasing), each box tested only over the pixels around it. The crops are the agents' own, or those placed
    by ``owners`` (positions, headings: a scene raster's)."""
    pos, heading, res = states["position"], states["heading"], m.resolution_m
    at, facing = owners if owners is not None else (pos, heading)
    half_l, half_w = states["length"] / 2, states["width"] / 2
    span = int(np.ceil(np.hypot(half_l, half_w).max(initial=0.0) / res)) + 1
    reach = np.hypot(m.height_px, m.width_px) * res + 2 * span * res
    dist = np.hypot(*(at[:, None, :] - pos[None]).transpose(2, 0, 1))
    i, j = np.nonzero(dist <= reach)
    centre = to_local(pos[j][:, None, :], at[i], facing[i])[:, 0]  # agent j in crop i's frame
    offsets = np.arange(-span, span + 1)
    rows = np.rint(m.agent_row - centre[:, 0] / res).astype(np.int64)[:, None, None] + offsets[None, :, None]
    cols = np.rint(m.agent_col - centre[:, 1] / res).astype(np.int64)[:, None, None] + offsets[None, None, :]
    rows, cols = np.broadcast_arrays(rows, cols)
    local = np.stack([(m.agent_row - rows) * res, (m.agent_col - cols) * res], axis=-1)  # crop i's pixel centres
    seen = to_local(to_world(local, at[i], facing[i]), pos[j], heading[j])
    hit = (np.abs(seen[..., 0]) <= half_l[j][:, None, None]) & (np.abs(seen[..., 1]) <= half_w[j][:, None, None])
    hit &= (rows >= 0) & (rows < m.height_px) & (cols >= 0) & (cols < m.width_px)
    crops[np.broadcast_to(i[:, None, None], hit.shape)[hit], rows[hit], cols[hit]] = AGENT_COLOUR


def map_crops(frame: dgan.Frame, states: dict[str, Arr], m: Any) -> Arr:
    """``(N, 3, H, W)`` float32 crops in [0, 1]; those of classes not in ``m.classes`` (contract 11) all zeros."""
    readers = np.isin(np.asarray(frame.classes), m.classes) if m.classes else np.ones(len(frame), dtype=bool)
    if isinstance(frame.map, dgan.RasterMap):
        crops = raster_crops(frame.map, pixel_world(states, m))
    else:
        els = Elements(frame.map.elements() if frame.map is not None else [])
        pos, heading = states["position"], states["heading"]
        crops = np.zeros((len(pos), m.height_px, m.width_px, 3), dtype=np.uint8)
        for i in np.flatnonzero(readers):
            crops[i] = vector_crop(els, pos[i], heading[i], m)
    if m.draw_agents:
        draw_boxes(crops, states, m)
    crops[~readers] = 0
    out: Arr = (crops.astype(np.float32) / 255.0).transpose(0, 3, 1, 2)
    return np.ascontiguousarray(out)


def groups_of(boxes: Arr) -> Arr:
    """Each box's group ``(N,)``: boxes that intersect (touching counts), through any chain of them, share one; groups
    numbered in the order of their lowest index."""
    lo, hi = boxes[:, :2], boxes[:, 2:]
    meet = ((lo[:, None] <= hi[None]) & (lo[None] <= hi[:, None])).all(axis=-1)
    label = np.arange(len(boxes))
    while True:
        new = np.where(meet, label[None, :], len(boxes)).min(axis=1)
        if (new == label).all():
            break
        label = new
    out: Arr = np.unique(label, return_inverse=True)[1]
    return out


def layout(boxes: Arr, group: Arr, res: float, min_px: int) -> tuple[Arr, int]:
    """Each group's raster centre (the middle of its box of crop corners) and the rasters' one side (the least multiple
    of 32 at or above ``min_px`` and every group box's side in pixels + 2); one centre at 0 without agents."""
    if not len(boxes):
        return np.zeros((1, 2)), min(-(-min_px // 32) * 32, 2048)
    count = int(group.max()) + 1
    lo = np.array([boxes[group == g, :2].min(axis=0) for g in range(count)])
    hi = np.array([boxes[group == g, 2:].max(axis=0) for g in range(count)])
    need = max([min_px, *(int(np.ceil(v / res)) + 2 for v in (hi - lo).max(axis=1))])
    return (lo + hi) / 2, min(-(-need // 32) * 32, 2048)


def scene_inputs(frame: dgan.Frame, states: dict[str, Arr], m: Any) -> tuple[Arr, Arr, Arr]:
    """A scene model's rasters ``(G, 3, S, S)``, grids ``(G, M, gh, gw, 2)`` and slots ``(N,)`` (contract 12): one
    north-up raster per group of agents whose crops meet, centred on the group's box of crop corners, S the least
    multiple of 32 at or above ``min_px`` and every group box's side in pixels + 2; one raster of the whole frame
    where that holds no more pixels."""
    pos, heading, res, n = states["position"], states["heading"], m.resolution_m, len(states["position"])
    edges = np.array([[0, 0], [0, m.width_px], [m.height_px, 0], [m.height_px, m.width_px]], dtype=np.float64)
    corners = np.stack([(m.agent_row + 0.5 - edges[:, 0]) * res, (m.agent_col + 0.5 - edges[:, 1]) * res], axis=1)
    world = to_world(np.broadcast_to(corners, (n, 4, 2)), pos, heading)
    boxes = np.concatenate([world.min(axis=1), world.max(axis=1)], axis=1)
    group = groups_of(boxes) if n else np.zeros(0, np.int64)
    centre, side = layout(boxes, group, res, m.scene.min_px)
    whole = layout(boxes, np.zeros(n, np.int64), res, m.scene.min_px)
    if len(centre) > 1 and whole[1] ** 2 <= len(centre) * side**2:  # one raster where it holds fewer pixels
        group, (centre, side) = np.zeros(n, np.int64), whole
    count = len(centre)
    north = np.full(count, np.pi / 2)
    scene = dataclasses.replace(m, height_px=side, width_px=side, agent_row=side // 2, agent_col=side // 2)
    raster = np.zeros((count, side, side, 3), dtype=np.uint8)
    if isinstance(frame.map, dgan.RasterMap):
        raster = raster_crops(frame.map, pixel_world({"position": centre, "heading": north}, scene))
    elif frame.map is not None:
        els = Elements(frame.map.elements())
        raster = np.stack([vector_crop(els, c, np.pi / 2, scene) for c in centre])
    if m.draw_agents and frame.map is not None:
        draw_boxes(raster, states, scene, owners=(centre, north))
    # Each crop block's centre (rows from the top, columns centred on the agent's) in its group's raster.
    gh, gw = block_grid(m)
    w = block_centres(states, m) - centre[group][:, None]
    u, v = side // 2 + 0.5 + w[..., 0] / res, side // 2 + 0.5 - w[..., 1] / res
    cells = np.stack([2 * u / side - 1, 2 * v / side - 1], axis=-1).reshape(n, gh, gw, 2)
    place = np.array([np.sum(group[:i] == group[i]) for i in range(n)], dtype=np.int64)
    most = int(np.bincount(group).max()) if n else 0
    grid = np.zeros((count, most, gh, gw, 2), dtype=np.float32)
    grid[group, place] = cells
    out: Arr = (raster.astype(np.float32) / 255.0).transpose(0, 3, 1, 2)
    return np.ascontiguousarray(out), grid, (group * most + place).astype(np.int64)


def block_grid(m: Any) -> tuple[int, int]:
    """The ``stride × stride`` blocks of a scene model's crop, ``(rows, columns)``, the last ones partial."""
    return -(-m.height_px // m.scene.stride), -(-m.width_px // m.scene.stride)


def block_centres(states: dict[str, Arr], m: Any) -> Arr:
    """``(N, B, 2)`` the world positions of the centres of each agent's crop's ``stride × stride`` blocks, row-major
    (rows from the crop's top, columns laid out symmetrically about the agent's)."""
    pos, heading, res, k = states["position"], states["heading"], m.resolution_m, m.scene.stride
    gh, gw = block_grid(m)
    rows = np.arange(gh) * k + k / 2
    cols = m.agent_col + 0.5 + (np.arange(gw) - (gw - 1) / 2) * k
    local = np.stack(np.meshgrid((m.agent_row + 0.5 - rows) * res, (m.agent_col + 0.5 - cols) * res, indexing="ij"), -1)
    return to_world(np.broadcast_to(local.reshape(-1, 2), (len(pos), gh * gw, 2)), pos, heading)


def kept_inputs(frame: dgan.Frame, states: dict[str, Arr], m: Any) -> dict[str, Arr]:
    """A kept-features model's inputs (contract 13) with every tile computed: the rasters ``(T, 3, P, P)`` of the
    tiles the agents read (north up on the world's grid of pixels, global pixel ``(k, l)`` at ``(k r, -l r)``, each
    with its halo), no kept rows, and each agent's four rows and bilinear weights per block centre."""
    sc, res = m.scene, m.resolution_m
    t, side, n = sc.tile_px // sc.stride, sc.tile_px + 2 * sc.halo_px, len(states["position"])
    w = block_centres(states, m)
    u, v = (w[..., 0] / res + 0.5) / sc.stride - 0.5, (-w[..., 1] / res + 0.5) / sc.stride - 0.5
    u0, v0 = np.floor(u), np.floor(v)
    du, dv = u - u0, v - v0
    cu = (u0[..., None] + [0, 1, 0, 1]).astype(np.int64).reshape(n, -1)
    cv = (v0[..., None] + [0, 0, 1, 1]).astype(np.int64).reshape(n, -1)
    weight = np.stack([(1 - du) * (1 - dv), du * (1 - dv), (1 - du) * dv, du * dv], -1).reshape(n, -1)
    rows = np.zeros((0, sc.channels), np.float32)
    if frame.map is None:  # one blank block, read with zero weights
        out = {"map": np.zeros((0, 3, side, side), np.float32), "map_rows": np.zeros((t * t, sc.channels), np.float32)}
        return out | {"map_index": np.zeros_like(cu), "map_weight": np.zeros_like(weight, dtype=np.float32)}
    tiles = np.stack([cu // t, cv // t], -1).reshape(-1, 2)
    unique, first, block = np.unique(tiles, axis=0, return_index=True, return_inverse=True)
    order = np.argsort(first, kind="stable")  # tiles in order of first use
    rank = np.empty_like(order)
    rank[order] = np.arange(len(order))
    index = rank[block.reshape(-1)].reshape(n, -1) * t * t + (cv % t) * t + cu % t
    centre = (unique[order] * sc.tile_px - sc.halo_px + side // 2) * res * np.array([1.0, -1.0])
    north = np.full(len(centre), np.pi / 2)
    tile = dataclasses.replace(m, height_px=side, width_px=side, agent_row=side // 2, agent_col=side // 2)
    if isinstance(frame.map, dgan.RasterMap):
        raster = raster_crops(frame.map, pixel_world({"position": centre, "heading": north}, tile))
    else:
        els = Elements(frame.map.elements())
        raster = np.stack([vector_crop(els, c, np.pi / 2, tile) for c in centre])
    maps = np.ascontiguousarray((raster.astype(np.float32) / 255.0).transpose(0, 3, 1, 2))
    return {"map": maps, "map_rows": rows, "map_index": index, "map_weight": weight.astype(np.float32)}


def read_rows(table: Arr, x: dict[str, Arr], m: Any) -> Arr:
    """``(N, C, gh, gw)``: each agent's bilinear reading of a kept-features model's rows (contract 13), the weighted
    sum of the four rows ``map_index`` names per block centre (weights ``map_weight``)."""
    n, k = x["map_index"].shape
    gh, gw = block_grid(m)
    picked = table[x["map_index"]] * x["map_weight"][..., None]  # (N, B · 4, C)
    out: Arr = picked.reshape(n, k // 4, 4, -1).sum(axis=2).transpose(0, 2, 1).reshape(n, -1, gh, gw)
    return np.ascontiguousarray(out, dtype=np.float32)


def preprocess(frame: dgan.Frame, spec: dgan.InputSpec) -> dict[str, Arr]:
    """The network's edge-list inputs, the prior and the agents' frames, from ``frame`` (numpy, from the contract)."""
    s = traffic_states(frame, spec.dt_s, spec.heading)
    origin, heading, mask = s["position"], s["heading"], frame.mask
    n = len(origin)
    traj = np.where(mask[..., None], to_local(np.nan_to_num(frame.positions), origin, heading), 0.0)
    v_local = to_local(s["velocity"][:, None, :], np.zeros_like(origin), heading)[:, 0]
    with np.errstate(divide="ignore", invalid="ignore"):
        motion = np.where((s["speed"] > 0)[:, None], v_local / s["speed"][:, None], [1.0, 0.0])
    classes = list(spec.classes)
    onehot = np.zeros((n, len(classes)))
    onehot[np.arange(n), [classes.index(c) for c in frame.classes]] = 1.0
    cols = [s["speed"], s["acceleration"], s["yaw_rate"], motion[:, 0], motion[:, 1], s["length"], s["width"]]
    state = np.concatenate([np.stack(cols, axis=1), onehot], axis=1)
    radius = s["speed"] * spec.t_f * spec.dt_s + spec.attention_lambda * s["length"]
    dist = np.hypot(*(origin[:, None, :] - origin[None]).transpose(2, 0, 1))
    receivers, senders = np.nonzero(dist <= radius[:, None] + radius[None, :])
    d = to_local(origin[senders][:, None, :], origin[receivers], heading[receivers])[:, 0]
    dv = to_local(
        (s["velocity"][senders] - s["velocity"][receivers])[:, None, :], np.zeros((len(d), 2)), heading[receivers]
    )[:, 0]
    dh = wrap(heading[senders] - heading[receivers])
    x: dict[str, Arr] = {
        "trajectory": traj.astype(np.float32),
        "trajectory_mask": mask.astype(np.float32),
        "state": state.astype(np.float32),
        "edge_index": np.stack([receivers, senders], axis=1).astype(np.int64),
        "edge_features": np.column_stack([d, dv, np.cos(dh), np.sin(dh)]).astype(np.float32),
        "origin": origin,
        "heading": heading,
    }
    x["prior"] = prior_rollout(x["trajectory"].astype(np.float64), mask, x["state"], spec).astype(np.float32)
    if spec.map is not None and spec.map.scene is not None and spec.map.scene.tile_px:
        x |= kept_inputs(frame, s, spec.map)
        if spec.map.optional:
            x["map_present"] = np.full(n, float(frame.map is not None), dtype=np.float32)
    elif spec.map is not None and spec.map.scene is not None:
        x["map"], x["map_grid"], x["map_slot"] = scene_inputs(frame, s, spec.map)
        if spec.map.optional:
            x["map_present"] = np.full(n, float(frame.map is not None), dtype=np.float32)
    elif spec.map is not None:
        if frame.map is not None:
            x["map"] = map_crops(frame, s, spec.map)
        else:
            x["map"] = np.zeros((n, 3, spec.map.height_px, spec.map.width_px), dtype=np.float32)
        if spec.map.optional:
            x["map_present"] = np.full(n, float(frame.map is not None), dtype=np.float32)
    return x


def softmax(x: Arr) -> Arr:
    e = np.exp(x - x.max(axis=-1, keepdims=True))
    out: Arr = e / e.sum(axis=-1, keepdims=True)
    return out


def decode(
    outputs: tuple[Arr, Arr, Arr], x: dict[str, Arr], contract_: dict[str, Any], scaled: bool = False
) -> tuple[Arr, Arr]:
    """World trajectories ``(N, K, T_f, 2)`` and probabilities ``(N, K)`` of every mode, most probable first;
    ``scaled``: the network's outputs already carry contract 14's top-mode scale (a consensus of one in training)."""
    class_logits, anchor_logits, offsets = (np.asarray(o, dtype=np.float64) for o in outputs)
    classes = list(contract_["classes"])
    anchors = np.concatenate([np.asarray(contract_["anchors"][c], dtype=np.float64) for c in classes])
    class_of = np.concatenate([np.full(len(contract_["anchors"][c]), k) for k, c in enumerate(classes)])
    p_class = softmax(class_logits / float(contract_.get("class_temperature", 1.0)))
    # Contract 9: the anchor temperature grows with the speed of the prior, whose first step is velocity · dt.
    speed = np.linalg.norm(x["prior"][:, 0].astype(np.float64), axis=1) / float(contract_["dt_s"])
    exponent = float(contract_.get("temperature_speed_exponent", 0.0))
    t = np.clip(float(contract_.get("temperature", 1.0)) * (1.0 + speed) ** exponent, 1e-3, 1e3)[:, None]
    p = np.zeros_like(anchor_logits)
    for k in range(len(classes)):
        block = class_of == k
        p[:, block] = p_class[:, k : k + 1] * softmax(anchor_logits[:, block] / t)
    order = np.argsort(-p, axis=1, kind="stable")
    rows = np.arange(len(p))[:, None]
    residual = anchors[None] + offsets
    # Contracts 14 and 16 read the most probable class; 14 scales its top anchor's residual.
    top_class = class_logits.argmax(axis=1)

    def per_class(key: str, neutral: float) -> Arr:
        return np.array([float(contract_.get(key, {}).get(c, neutral)) for c in classes])

    block = np.where(class_of[None] == top_class[:, None], anchor_logits, -np.inf)
    scale = np.ones(len(classes)) if scaled else per_class("top_scale", 1.0)
    residual[rows[:, 0], block.argmax(axis=1)] *= scale[top_class][:, None, None]
    local = (x["prior"][:, None].astype(np.float64) + residual)[rows, order]
    p = p[rows, order]
    # Contract 16: the most probable mode as the p^β-weighted mean of every mode.
    beta = per_class("top_mean_power", 0.0)[top_class]
    w = (p / p[:, :1]) ** beta[:, None]
    mean = np.einsum("nk,nktd->ntd", w / w.sum(axis=1, keepdims=True), local)
    local[:, 0] = np.where((beta > 0)[:, None, None], mean, local[:, 0])
    # Contract 15: a still history (every step present, each within its class's radius) keeps its prior.
    radius = per_class("still_radius_m", 0.0)[x["state"][:, -len(classes) :].argmax(axis=1)]
    near = np.hypot(x["trajectory"][..., 0], x["trajectory"][..., 1]) < radius[:, None]
    still = (radius > 0) & (x["trajectory_mask"] > 0).all(axis=1) & near.all(axis=1)
    local[still, 0] = x["prior"][still]
    return to_world(local, x["origin"], x["heading"]), p


def pipeline(name: str) -> Callable[[dgan.Frame], tuple[Arr, Arr]] | None:
    """``frame → (trajectories, probabilities)``: numpy preprocessing, the bundled checkpoint's network in eager
    PyTorch on one thread, numpy decoding; None without torch."""
    try:
        import torch

        from training.export import load_checkpoint
        from training.modules.consensus import ConsensusEnsemble
        from training.modules.dgan import DGAN
    except ImportError:
        return None
    torch.set_num_threads(1)
    predictor = dgan.Predictor(name, sessions=1)
    spec, contract_ = predictor.spec, predictor._contract
    model = load_checkpoint(ROOT / "training" / "checkpoints" / f"{name}.pt")[0]
    inputs = [k for k in contract.EDGE_LIST_INPUTS if k != "map" or spec.map is not None]
    inputs = [k for k in inputs if k != "map_present" or (spec.map is not None and spec.map.optional)]
    scene = spec.map.scene if spec.map is not None else None
    inputs = [k for k in inputs if k not in contract.SCENE_GRID_INPUTS or (scene and not scene.tile_px)]
    kept = scene is not None and scene.tile_px > 0
    inputs += list(contract.KEPT_INPUTS) if kept else []

    def run(frame: dgan.Frame) -> tuple[Arr, Arr]:
        x = preprocess(frame, spec)
        with torch.no_grad():
            if kept:  # the tiles' features, then each agent's reading of them (contract 13)
                assert isinstance(model, DGAN | ConsensusEnsemble)
                rows = model.tile_rows(torch.from_numpy(x["map"])).numpy()
                x["map_patches"] = read_rows(np.concatenate([x["map_rows"], rows]), x, spec.map)
                x["map"] = x["map"][:0]
            out = model(**{k: torch.from_numpy(x[k]) for k in inputs})
        scaled = isinstance(model, ConsensusEnsemble)  # its forward applies its own top-mode scale
        return decode((out[0].numpy(), out[1].numpy(), out[2].numpy()), x, contract_, scaled)

    return run
