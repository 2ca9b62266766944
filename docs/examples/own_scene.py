"""A user's own scene, end to end: an Argoverse 2 scenario (10 Hz, string track ids, a vector map; a source the
bundled models never trained on) read with polars, predicted by the bundled ``hdmap`` model (5 Hz: the table is
resampled), written as a parquet table, drawn with ``dgan.plot`` and streamed tick by tick through ``dgan.Tracker``
into a rerun recording.

    python docs/examples/own_scene.py [SCENARIO_FOLDER] [--out docs/images]

Needs ``pip install 'dgan[plot,rerun,arrow]' polars``; the default scenario is the first one under
``$DGAN_DATA_ROOT/argoverse2/motion_forecasting`` (``../shared/data`` beside the clone). Argoverse 2 is licensed
CC BY-NC-SA 4.0: non-commercial use only.
"""

from __future__ import annotations

import argparse
import os
from pathlib import Path

import numpy as np
import polars as pl

import dgan
from dgan.datasets.hdmaps import AV2_SCENARIO_CLASSES as AV2_CLASSES  # object types -> dgan classes
from dgan.datasets.hdmaps import av2_map

NOW_S = 4.9  # the end of Argoverse 2's 5 s of history; the 6 s after it are the truth


def main() -> None:
    root = Path(os.environ.get("DGAN_DATA_ROOT", Path(__file__).resolve().parents[3] / "shared" / "data"))
    parser = argparse.ArgumentParser()
    parser.add_argument("scenario", nargs="?", default=None)
    parser.add_argument("--out", default="docs/images")
    args = parser.parse_args()
    folder = Path(args.scenario) if args.scenario else sorted((root / "argoverse2" / "motion_forecasting").iterdir())[0]
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)

    tracks = (
        pl.read_parquet(next(folder.glob("scenario_*.parquet")))
        .filter(pl.col("object_type").is_in(list(AV2_CLASSES)))
        .select(
            agent_id="track_id",
            time=pl.col("timestep") * 0.1,
            x="position_x",
            y="position_y",
            heading="heading",
            vx="velocity_x",
            vy="velocity_y",
            **{"class": pl.col("object_type").replace_strict(AV2_CLASSES)},
        )
    )
    scene_map = dgan.VectorMap(av2_map(next(folder.glob("log_map_archive_*.json"))))
    predictor = dgan.Predictor("hdmap", modes=3)

    # One frame at 4.9 s from the whole table (polars in, resampled from 10 Hz to the model's 5 Hz).
    history = tracks.filter(pl.col("time") <= NOW_S + 1e-9)
    frame = dgan.Frame.from_records(history, spec=predictor, current_time=NOW_S, map=scene_map)
    prediction = predictor.predict(frame)
    prediction.to_parquet(out / "own_scene_prediction.parquet")

    # The truth for the plot, and the agents near the focal area (within 40 m of the frame's mean position).
    future = tracks.filter(pl.col("time") > NOW_S + 1e-9)
    truth = {
        a: np.c_[g["x"].to_numpy(), g["y"].to_numpy()][1::2]  # every second 10 Hz step: the model's 0.2 s grid
        for (a,), g in future.sort("time").group_by("agent_id")
    }
    centre = np.nanmean(frame.positions[:, -1], axis=0)
    near = np.flatnonzero(np.linalg.norm(frame.positions[:, -1] - centre, axis=1) < 40)
    sub = dgan.Frame(
        frame.positions[near],
        mask=frame.mask[near],
        classes=[frame.classes[i] for i in near],
        ids=frame.agent_ids[near],
        map=scene_map,
        dt=frame.dt,
    )
    sub_prediction = predictor.predict(sub)  # the near agents alone: fewer neighbours, a slightly other answer
    fig = dgan.plot(
        sub,
        sub_prediction,
        ground_truth=truth,
        title=f"hdmap on Argoverse 2 {folder.name[:8]} (never trained on): 3 modes, 3 s",
    )
    fig.savefig(out / "own_scene.png", dpi=90)
    print(f"{len(frame)} agents at {NOW_S} s; drew {len(sub)} near the centre -> {out / 'own_scene.png'}")

    # The same scenario streamed tick by tick at 10 Hz through the tracker, logged to rerun.
    import rerun as rr
    import rerun.blueprint as rrb

    rec = rr.RecordingStream("dgan-own-scene")
    rec.save(out / "own_scene.rrd", default_blueprint=rrb.Spatial2DView(origin="/dgan", name="dgan (world metres)"))
    tracker = dgan.Tracker(predictor, map=scene_map)
    for (t,), tick in history.sort("time").group_by("time", maintain_order=True):
        tracker.update(
            float(t),
            ids=tick["agent_id"].to_list(),
            positions=np.c_[tick["x"].to_numpy(), tick["y"].to_numpy()],
            classes=tick["class"].to_list(),
            headings=tick["heading"].to_numpy(),
            velocities=np.c_[tick["vx"].to_numpy(), tick["vy"].to_numpy()],
        )
        if round(float(t) * 10) % 2 == 1:  # predict at the model's 5 Hz
            streamed = tracker.frame()
            dgan.viz.log_rerun(streamed, predictor.predict(streamed), recording=rec, time_s=float(t))
    rec.flush()
    last = tracker.predict()
    order = {a: i for i, a in enumerate(last.agent_ids.tolist())}  # the tracker orders agents by first appearance
    rows = [order[a] for a in prediction.agent_ids.tolist()]
    same = np.allclose(last.trajectories[rows], prediction.trajectories, atol=1e-6)
    print(f"tracker at {tracker.now:.1f} s equals the one-shot frame: {same}; recording -> {out / 'own_scene.rrd'}")


if __name__ == "__main__":
    main()
