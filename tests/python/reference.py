"""An independent numpy implementation of preprocessing and decoding, written from the contract's text
(``docs/model-contract.md``), to check the engine against."""

from __future__ import annotations

from typing import Any

import numpy as np
import numpy.typing as npt

from dgan import contract

MIN_MOVING_SPEED = 0.2
#: The classes' codes and default sizes are the engine's (the contract's text names them; dgan.contract holds them).
CLASS_CODES = {c: i for i, c in enumerate(contract.CLASSES)}
DEFAULT_LENGTH = {c: size[0] for c, size in contract.CLASS_SIZES_M.items()}
DEFAULT_WIDTH = {c: size[1] for c, size in contract.CLASS_SIZES_M.items()}

Arr = npt.NDArray[Any]


def rot(theta: float) -> Arr:
    c, s = np.cos(theta), np.sin(theta)
    return np.array([[c, -s], [s, c]])


def wrap(a: float) -> float:
    return float((a + np.pi) % (2 * np.pi) - np.pi)


def agent_state(p: Arr, m: Arr, dt: float) -> tuple[Arr, Arr, float, float, float]:
    """Last position, velocity, acceleration, heading and yaw rate of one agent (no given heading/velocity)."""
    idx = np.flatnonzero(m)
    last = idx[-1]
    v = np.zeros(2)
    acc = yaw = 0.0
    if idx.size >= 2:
        v = (p[last] - p[idx[-2]]) / ((last - idx[-2]) * dt)
    if idx.size >= 3:
        v0 = (p[idx[-2]] - p[idx[-3]]) / ((idx[-2] - idx[-3]) * dt)
        span = (last - idx[-3]) * 0.5 * dt
        acc = (np.linalg.norm(v) - np.linalg.norm(v0)) / span
        if np.linalg.norm(v) >= MIN_MOVING_SPEED and np.linalg.norm(v0) >= MIN_MOVING_SPEED:
            yaw = wrap(np.arctan2(v[1], v[0]) - np.arctan2(v0[1], v0[0])) / span
    disp = p[last] - p[idx[0]]
    if np.linalg.norm(v) >= MIN_MOVING_SPEED:
        heading = float(np.arctan2(v[1], v[0]))
    elif np.linalg.norm(disp) >= MIN_MOVING_SPEED * dt * idx.size:
        heading = float(np.arctan2(disp[1], disp[0]))
    else:
        heading = 0.0
    return p[last], v, acc, wrap(heading), yaw


def denoise(positions: Arr, mask: Arr, gate_m: float) -> Arr:
    """Contract 10: each agent with at least 4 valid steps whose positions lie off their least-squares parabola in
    time by ``gate_m`` or more (root mean square of the distances) gets the parabola's points."""
    out = positions.astype(np.float64).copy()
    for i in range(len(positions)):
        t = np.flatnonzero(mask[i])
        if t.size < 4:
            continue
        coef = np.polyfit(t.astype(np.float64), positions[i, t], 2)
        fitted = np.stack([np.polyval(coef[:, c], t) for c in range(2)], axis=1)
        if np.sqrt(np.mean(np.sum((positions[i, t] - fitted) ** 2, axis=1))) >= gate_m:
            out[i, t] = fitted
    return out


def preprocess(positions: Arr, mask: Arr, classes: list[str], spec: dict[str, Any]) -> dict[str, Arr]:
    n, t_obs, _ = positions.shape
    if spec.get("denoise_gate_m", 0.0) > 0:
        positions = denoise(positions, mask, spec["denoise_gate_m"])
    dt, horizon, lam = spec["dt_s"], spec["t_f"] * spec["dt_s"], spec["attention_lambda"]
    model_classes = list(spec["classes"])
    states = [agent_state(positions[i], mask[i], dt) for i in range(n)]
    origin = np.array([s[0] for s in states]).reshape(n, 2)
    vel = np.array([s[1] for s in states]).reshape(n, 2)
    heading = np.array([s[3] for s in states])
    lengths = np.array([DEFAULT_LENGTH[c] for c in classes])
    widths = np.array([DEFAULT_WIDTH[c] for c in classes])
    traj = np.zeros((n, t_obs, 2))
    state = np.zeros((n, contract.state_width(model_classes)))
    for i in range(n):
        r_inv = rot(-heading[i])
        traj[i] = ((positions[i] - origin[i]) @ r_inv.T) * mask[i][:, None]
        speed = np.linalg.norm(vel[i])
        v_local = r_inv @ vel[i]
        mc, ms = (v_local / speed) if speed > 0 else (1.0, 0.0)
        state[i, :7] = [speed, states[i][2], states[i][4], mc, ms, lengths[i], widths[i]]
        state[i, 7 + model_classes.index(classes[i])] = 1.0
    radius = np.linalg.norm(vel, axis=1) * horizon + lam * lengths
    dist = np.linalg.norm(origin[:, None] - origin[None], axis=2)
    adjacent = dist <= radius[:, None] + radius[None, :]
    receivers, senders = np.nonzero(adjacent)  # row-major: sorted by receiver, then sender; includes i == i
    feats = []
    for i, j in zip(receivers.tolist(), senders.tolist(), strict=True):
        r_inv = rot(-heading[i])
        d = r_inv @ (origin[j] - origin[i])
        dv = r_inv @ (vel[j] - vel[i])
        dh = wrap(heading[j] - heading[i])
        feats.append([d[0], d[1], dv[0], dv[1], np.cos(dh), np.sin(dh)])
    upper = np.argwhere(np.triu(adjacent, k=1))
    return {
        "trajectory": traj,
        "trajectory_mask": mask.astype(np.float64),
        "state": state,
        "edge_index": np.stack([receivers, senders], axis=1),
        "edge_features": np.array(feats).reshape(-1, 6),
        "origin": origin,
        "heading": heading,
        "edges": upper,
    }


def softmax(x: Arr) -> Arr:
    e = np.exp(x - x.max())
    out: Arr = e / e.sum()
    return out


def decode(outputs: dict[str, Arr], contract: dict[str, Any], origin: Arr, heading: Arr) -> dict[str, Arr]:
    classes = list(contract["classes"])
    anchors = np.concatenate([np.asarray(contract["anchors"][c], dtype=np.float64) for c in classes])
    sizes = [len(contract["anchors"][c]) for c in classes]
    n = origin.shape[0]
    trajs, probs = [], []
    for i in range(n):
        pc = softmax(outputs["class_logits"][i])
        logits = np.split(outputs["anchor_logits"][i], np.cumsum(sizes)[:-1])
        p = np.concatenate([pc[c] * softmax(lg) for c, lg in enumerate(logits)])
        order = np.argsort(-p, kind="stable")
        local = anchors + outputs["offsets"][i]
        world = local @ rot(heading[i]).T + origin[i]
        trajs.append(world[order])
        probs.append(p[order])
    return {"trajectories": np.array(trajs), "probabilities": np.array(probs)}
