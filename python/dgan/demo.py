"""``dgan demo``: predict a bundled real scene with a bundled model, print each agent's top modes, and draw them over
the scene image like the paper's Figure 3 (observed path, ground truth, predicted modes coloured by probability)."""

from __future__ import annotations

from pathlib import Path
from typing import Any

import numpy as np

from dgan.exceptions import DganError
from dgan.frame import Frame
from dgan.predictor import Prediction, Predictor
from dgan.scenes import scene_image, scene_map

SCENE_FILE = Path(__file__).parent / "data" / "zara1" / "frames_5430_5620.txt"


def load_scene(t_obs: int, now: float) -> tuple[Frame, dict[int, np.ndarray]]:
    """The bundled zara1 excerpt at frame ``now``, with the future (frame ids step by 10) of every agent."""
    rows = np.loadtxt(SCENE_FILE)
    cols = {"time": rows[:, 0], "agent_id": rows[:, 1].astype(np.int64), "x": rows[:, 2], "y": rows[:, 3]}
    frame = Frame.from_records(cols, t_obs=t_obs, dt=10.0, current_time=now, map=scene_map("zara1"))
    futures = {}
    for pid in frame.ids:
        r = rows[(rows[:, 1] == pid) & (rows[:, 0] > now)]
        futures[int(pid)] = r[np.argsort(r[:, 0]), 2:4]
    return frame, futures


def draw(frame: Frame, pred: Prediction, futures: dict[int, np.ndarray], out: Path, title: str) -> Path:
    try:
        import matplotlib

        matplotlib.use("Agg")
        import matplotlib.pyplot as plt
    except ImportError as e:
        raise DganError("the demo's picture needs matplotlib: pip install matplotlib") from e
    img = scene_image("zara1")
    if img is None:
        raise DganError("the zara1 scene image is not bundled")
    image, h = img

    def px(p: np.ndarray) -> Any:
        q = np.c_[p, np.ones(len(p))] @ h.T
        return q[:, :2] / q[:, 2:]

    hgt, wid = image.shape[:2]
    fig, ax = plt.subplots(figsize=(wid / 60 + 1.5, hgt / 60), dpi=100)
    ax.imshow(image)
    ax.set_xlim(0, wid)
    ax.set_ylim(hgt, 0)
    cmap = plt.get_cmap("cool")
    modes = pred.trajectories.shape[1]
    for i, pid in enumerate(frame.ids):
        obs = px(frame.positions[i][frame.mask[i]])
        ax.plot(obs[:, 0], obs[:, 1], "--", color="yellow", lw=1.6)
        for m in reversed(range(modes)):
            pr = pred.probabilities[i, m]
            tr = px(np.vstack([frame.positions[i][frame.mask[i]][-1:], pred.trajectories[i, m]]))
            ax.plot(tr[:, 0], tr[:, 1], "-", color=cmap(min(1.0, pr / 0.5)), lw=1.0 + 3 * pr, alpha=0.9)
        fut = futures.get(int(pid))
        if fut is not None and len(fut):
            gt = px(np.vstack([frame.positions[i][frame.mask[i]][-1:], fut]))
            ax.plot(gt[:, 0], gt[:, 1], "-", color="red", lw=1.8)
        ax.plot(*obs[-1], "o", color="white", ms=4, mec="black")
    sm = plt.cm.ScalarMappable(cmap=cmap, norm=matplotlib.colors.Normalize(0, 0.5))
    fig.colorbar(sm, ax=ax, fraction=0.03, pad=0.01, label="mode probability (≥ 0.5 saturates)")
    ax.plot([], [], "--", color="yellow", label="observed (3.2 s)")
    ax.plot([], [], "-", color="red", label="ground truth")
    ax.plot([], [], "-", color=cmap(0.9), label="predicted modes")
    ax.legend(loc="lower left")
    ax.set_title(title)
    ax.set_axis_off()
    fig.tight_layout()
    out.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(out)
    plt.close(fig)
    return out


def run(model: str = "zara1", now: float = 5500.0, modes: int = 3, out: Path = Path("dgan_demo.png")) -> int:
    predictor = Predictor(model, modes=modes)
    frame, futures = load_scene(predictor.spec.t_obs, now)
    pred = predictor.predict(frame)
    card = predictor.contract.get("name", model)
    print(f"model {card}: {len(frame)} pedestrians of zara1 at frame {int(now)}, {len(pred.edges)} attention edges")
    print("agent   top modes: probability -> position in 4.8 s (world metres)        actual")
    for i, pid in enumerate(pred.agent_ids):
        end = pred.trajectories[i, :, -1]
        ends = "  ".join(
            f"{pred.probabilities[i, m]:.2f} -> ({end[m, 0]:5.2f}, {end[m, 1]:5.2f})" for m in range(len(end))
        )
        fut = futures.get(int(pid))
        actual = (
            f"({fut[-1, 0]:5.2f}, {fut[-1, 1]:5.2f})" if fut is not None and len(fut) == 12 else "   (left the scene)"
        )
        print(f"{pid:>5}   {ends}   {actual}")
    path = draw(frame, pred, futures, out, f"DGAN ({card}) on zara1, frame {int(now)}: top {modes} modes")
    print(f"wrote {path}")
    return 0
