"""The training side: typed config, loss, the engine–PyTorch parity of exported models, and DDP on two CPU
processes (gloo). Needs torch (``pip install -e ".[train]"``; ``./dev test`` installs it) and the shared data."""

from __future__ import annotations

import csv
import os
import subprocess
import sys
from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest
import torch
from conftest import shared_data

import dgan
from dgan.contract import KEPT_INPUTS
from training.build import build_model, input_spec
from training.config import Config
from training.data.batches import INPUTS, forward_inputs
from training.export import export_model, load_checkpoint
from training.losses import (
    Calibration,
    DecodingKeys,
    anchor_pool,
    class_weights,
    closest_anchor,
    decode_torch,
    dgan_loss,
)
from training.modules.consensus import ConsensusEnsemble
from training.modules.dgan import DGAN

ROOT = Path(__file__).resolve().parents[3]
CHECKPOINTS = ROOT / "training" / "checkpoints"
CONFIG = ROOT / "training" / "configs" / "ethucy_zara1.toml"


def data_root() -> Path:
    return shared_data("eth_ucy")


def test_config_is_typed() -> None:
    cfg = Config.load(CONFIG, {"train.epochs": 3, "model.use_gat": False})
    assert cfg.train.epochs == 3
    assert not cfg.model.use_gat
    assert cfg.data.scene == "zara1"
    with pytest.raises(ValueError, match="unknown keys"):
        Config.load(CONFIG, {"train.epoch": 3})
    with pytest.raises(ValueError, match="must be int"):
        Config.load(CONFIG, {"train.epochs": "three"})
    with pytest.raises(ValueError, match="unknown config section"):
        Config.from_dict({"optimizer": {}})


def test_the_crops_can_leave_the_agents_boxes_out() -> None:
    """``data.map_draw_agents = false``: the spec's crops without the agents' boxes (the engine draws none)."""
    with_boxes = input_spec(Config.load(CONFIG))
    without = input_spec(Config.load(CONFIG, {"data.map_draw_agents": False}))
    assert with_boxes.map is not None
    assert without.map is not None
    assert with_boxes.map.draw_agents
    assert not without.map.draw_agents
    frame = dgan.demo.scene_for(with_boxes).frame
    a, b = dgan.preprocess(frame, with_boxes)["map"], dgan.preprocess(frame, without)["map"]

    # The boxes are blue (0, 0, 1): without them fewer pixels are pure blue, and nothing else differs in kind.
    def blue(m: np.ndarray) -> int:
        return int(((m[:, 2] == 1.0) & (m[:, 0] == 0.0) & (m[:, 1] == 0.0)).sum())

    assert blue(a) > blue(b)


def test_the_map_cnn_keeps_zero_one_or_two_residual_blocks() -> None:
    cfg = Config.load(ROOT / "training" / "configs" / "hdmap.toml")
    spec = input_spec(cfg)
    sizes = {}
    for blocks in (0, 1, 2):
        model = build_model(replace(cfg, model=replace(cfg.model, map_res_blocks=blocks)), spec, 30)
        sizes[blocks] = sum(p.numel() for p in model.parameters())
    assert sizes[0] < sizes[1] < sizes[2]
    with pytest.raises(ValueError, match="map_res_blocks must be 0, 1 or 2"):
        build_model(replace(cfg, model=replace(cfg.model, map_res_blocks=3)), spec, 30)


def test_loss_picks_the_closest_anchor_of_the_class() -> None:
    anchors = torch.tensor([[[1.0, 0.0]], [[2.0, 0.0]], [[0.0, 5.0]]])
    class_of = torch.tensor([0, 0, 1])
    future = torch.tensor([[[0.0, 4.0]], [[0.0, 4.0]]])
    # Agent 0 is class 0: anchors 0 and 1 only (anchor 2 is closer but belongs to class 1).
    k = closest_anchor(future, anchors, anchor_pool("own_class", class_of, torch.tensor([0, 1])))
    assert k.tolist() == [0, 2]
    zeros = torch.zeros(2, 3, 1, 2)
    loss, parts = dgan_loss(
        torch.zeros(2, 2), torch.zeros(2, 3), zeros, future, torch.tensor([0, 1]), anchors, class_of, 1.0
    )
    # −log(½ · ½) for agent 0, −log(½ · 1) for agent 1; errors √17 and 1.
    assert parts["cls"] == pytest.approx((np.log(4) + np.log(2)) / 2, rel=1e-6)
    assert parts["reg"] == pytest.approx((np.sqrt(17) + 1) / 2, rel=1e-6)
    assert float(loss) == pytest.approx(parts["cls"] + parts["reg"], rel=1e-6)
    _, prob = decode_torch(torch.zeros(2, 2), torch.zeros(2, 3), zeros, anchors, class_of)
    assert prob.sum(dim=1).tolist() == pytest.approx([1.0, 1.0])
    # Class balance: weights 1 and 3 make agent 1's loss count three times.
    weighted, _ = dgan_loss(
        torch.zeros(2, 2),
        torch.zeros(2, 3),
        zeros,
        future,
        torch.tensor([0, 1]),
        anchors,
        class_of,
        1.0,
        weights=torch.tensor([1.0, 3.0]),
    )
    each = [np.log(4) + np.sqrt(17), np.log(2) + 1.0]
    assert float(weighted) == pytest.approx((each[0] + 3 * each[1]) / 4, rel=1e-6)


def test_the_classifier_can_be_taught_the_best_decoded_mode() -> None:
    anchors = torch.tensor([[[1.0, 0.0]], [[2.0, 0.0]], [[0.0, 5.0]]])
    class_of = torch.tensor([0, 0, 1])
    future = torch.tensor([[[0.0, 4.0]]])
    # Anchor 0 is the closest of class 0, but anchor 1's offset brings its mode onto the future.
    offsets = torch.tensor([[[[0.0, 0.0]], [[-2.0, 4.0]], [[0.0, 0.0]]]])
    anchor_logits = torch.tensor([[0.0, float(np.log(3.0)), 0.0]])  # p(k | class 0) = 1/4, 3/4
    args = (torch.zeros(1, 2), anchor_logits, offsets, future, torch.tensor([0]), anchors, class_of, 1.0)
    _, paper = dgan_loss(*args)
    _, best = dgan_loss(*args, cls_target="best_mode")
    assert paper["cls"] == pytest.approx(np.log(2) + np.log(4), rel=1e-6)  # −log(½ · ¼): anchor 0
    assert best["cls"] == pytest.approx(np.log(2) + np.log(4 / 3), rel=1e-6)  # −log(½ · ¾): mode 1
    assert best["reg"] == paper["reg"] == pytest.approx(np.sqrt(17), rel=1e-6)  # the regression follows anchor 0
    with pytest.raises(ValueError, match="cls_target"):
        dgan_loss(*args, cls_target="nearest")


def test_the_anchors_can_be_drawn_from_every_class() -> None:
    anchors = torch.tensor([[[1.0, 0.0]], [[2.0, 0.0]], [[0.0, 5.0]]])
    class_of = torch.tensor([0, 0, 1])
    future = torch.tensor([[[0.0, 4.0]]])  # a class-0 agent whose future is nearest class 1's anchor
    pool = anchor_pool("all_classes", class_of, torch.tensor([0]))
    assert closest_anchor(future, anchors, pool).tolist() == [2]
    class_logits = torch.tensor([[float(np.log(3.0)), 0.0]])  # p(c) = 3/4, 1/4
    args = (class_logits, torch.zeros(1, 3), torch.zeros(1, 3, 1, 2), future, torch.tensor([0]), anchors, class_of)
    _, own = dgan_loss(*args, 1.0)
    _, every = dgan_loss(*args, 1.0, pool="all_classes")
    assert own["cls"] == pytest.approx(np.log(4 / 3) + np.log(2), rel=1e-6)  # −log(¾ · ½): anchor 0 of class 0
    assert every["cls"] == pytest.approx(np.log(4), rel=1e-6)  # −log(¼ · 1): anchor 2, the only one of class 1
    assert every["reg"] == pytest.approx(1.0, rel=1e-6)  # the regression follows anchor 2
    with pytest.raises(ValueError, match="anchor_pool"):
        dgan_loss(*args, 1.0, pool="mine")


def test_class_weights_balance_the_classes() -> None:
    classes = torch.tensor([0] * 70 + [1] * 20 + [2] * 10)
    assert class_weights(classes, 3, 0.0).tolist() == [1.0, 1.0, 1.0]
    w = class_weights(classes, 3, 1.0)
    # Every class carries the same total weight, and the mean weight of a target is 1.
    totals = [float(w[c]) * int((classes == c).sum()) for c in range(3)]
    assert totals == pytest.approx([totals[0]] * 3, rel=1e-5)
    assert float(w[classes].mean()) == pytest.approx(1.0, rel=1e-6)
    # A class without targets weighs nothing.
    assert class_weights(torch.tensor([0, 0, 2]), 3, 1.0)[1] == 0.0


def real_frames(spec: dgan.InputSpec) -> list[dgan.Frame]:
    """Two real frames of the bundled demo scene that matches the spec's time base (ETH/UCY, SDD, ApolloScape,
    Waymo)."""
    from dgan.demo import scene_for

    first = scene_for(spec)
    return [first.frame, scene_for(spec, first.default_now + first.time_step).frame]


def assert_parity(
    model: torch.nn.Module,
    spec: dgan.InputSpec,
    anchors: np.ndarray,
    class_of: np.ndarray,
    onnx_path: Path,
    temperature: float | Calibration = 1.0,
) -> None:
    """The engine's predictions equal PyTorch's (model, kinematic prior, decoding at ``temperature``, a single one
    or a contract-9 calibration) on real frames, and, for a model whose map is optional, on the same frames without
    their map."""
    cal = temperature if isinstance(temperature, Calibration) else Calibration(temperature)
    predictor = dgan.Predictor(onnx_path)
    # Contracts 14 to 16: top-mode scale (a consensus applies its own in its forward), still radius, mean top mode.
    keys = DecodingKeys.of(predictor.contract, spec.classes, isinstance(model, ConsensusEnsemble))
    frames = real_frames(spec)
    if spec.map is not None and spec.map.optional:
        frames += [frame.without_map() for frame in frames]
    for frame in frames:
        x = kept_inputs(model, spec, dgan.preprocess(frame, spec))
        with torch.no_grad():
            if "map_patches" in x:  # named: the kept readings follow contract 12's grids in forward's order
                named = {k: torch.from_numpy(x[k]) for k in (*INPUTS, *KEPT_INPUTS) if k in x}
                cl, al, off = model(**named)[:3]
            else:
                cl, al, off = model(
                    *forward_inputs({k: torch.from_numpy(np.ascontiguousarray(v)) for k, v in x.items()})
                )
            prior = torch.from_numpy(x["prior"])
            a, c = torch.from_numpy(anchors), torch.from_numpy(class_of).long()
            t = cal.anchor_temperatures(prior, spec.dt_s)
            traj, prob = decode_torch(
                cl, al, off, a, c, prior, t, cal.class_temperature, keys.still(x), keys.top_scale, keys.top_mean
            )
        n, k = traj.shape[:2]
        flat = traj.numpy().astype(np.float64).reshape(n, -1, 2)
        world = dgan.to_world_frame(flat, x["origin"], x["heading"]).reshape(n, k, -1, 2)
        got = predictor.predict(frame)
        np.testing.assert_allclose(got.probabilities, prob.numpy(), atol=1e-4)
        np.testing.assert_allclose(got.trajectories, tied_order(world, prob.numpy(), got.trajectories), atol=1e-4)


def kept_inputs(model: torch.nn.Module, spec: dgan.InputSpec, x: dict[str, np.ndarray]) -> dict[str, np.ndarray]:
    """``x`` (``dgan.preprocess``'s) as the network gets it: of a model that keeps its map features (contract 13), its
    tiles' features computed by ``model`` and each agent's reading of them (``dgan.read_kept``), no tile left."""
    if "map_rows" not in x:
        return x
    assert spec.map is not None
    assert spec.map.scene is not None
    assert isinstance(model, DGAN | ConsensusEnsemble)
    with torch.no_grad():
        rows = model.tile_rows(torch.from_numpy(x["map"])).numpy()
    grid = spec.map.scene_grid
    assert grid is not None
    patches = dgan.read_kept(np.concatenate([x["map_rows"], rows]), x["map_index"], x["map_weight"], grid)
    return x | {"map": x["map"][:0], "map_patches": patches}


def tied_order(expected: np.ndarray, prob: np.ndarray, got: np.ndarray, tie: float = 1e-6) -> np.ndarray:
    """``expected (N, K, T, 2)`` with modes of equal probability (within ``tie``) reordered as close to ``got`` as
    they can be: two sorts of the same probabilities may order a tie either way."""
    out = expected.copy()
    for i in range(len(prob)):
        for k in range(prob.shape[1]):
            tied = np.flatnonzero(np.abs(prob[i] - prob[i, k]) <= tie)
            if len(tied) > 1:
                errors = np.abs(expected[i, tied] - got[i, k]).max(axis=(1, 2))
                out[i, k] = expected[i, tied[int(np.argmin(errors))]]
    return out


@pytest.mark.slow
@pytest.mark.parametrize("name", sorted(p.stem for p in CHECKPOINTS.glob("*.pt")))
def test_bundled_models_match_pytorch(name: str) -> None:
    model, spec, anchors, class_of, _, calibration = load_checkpoint(CHECKPOINTS / f"{name}.pt")
    assert_parity(model, spec, anchors, class_of, dgan.models.path(name), calibration)


def test_every_bundled_model_has_a_checkpoint() -> None:
    assert set(dgan.models.list()) <= {p.stem for p in CHECKPOINTS.glob("*.pt")}


#: Contract 13: the map features kept with the map, in tiles of 64 px.
KEPT = {"data.map_draw_agents": False, "data.map_scene_tile_px": 64}


def randomised_batch_norm(model: DGAN) -> DGAN:
    """``model`` with random BatchNorm running statistics (fresh ones are 0 and 1, which would hide their export)."""
    for m in model.modules():
        if isinstance(m, torch.nn.BatchNorm2d):
            assert m.running_mean is not None
            assert m.running_var is not None
            m.running_mean.uniform_(-0.5, 0.5)
            m.running_var.uniform_(0.5, 2.0)
    return model


@pytest.mark.parametrize(
    ("config", "variant"),
    [
        ("ethucy_zara1", {}),
        ("ethucy_zara1", {"model.use_map": False}),
        ("ethucy_zara1", {"model.use_gat": False}),
        ("sdd", {}),
        ("apolloscape", {}),
        ("hdmap", {}),
        ("hdmap", {"train.map_dropout": 0.0}),
        ("hdmap", {"model.map_res_blocks": 1}),
        ("hdmap", {"model.map_res_blocks": 0}),
        ("hdmap", {"model.neighbor_groups": True}),
        ("apolloscape", {"model.neighbor_groups": True}),
        ("ethucy_zara1", {"data.prior": "none", "train.map_dropout": 0.0}),
        ("ethucy_zara1", {"model.map_mode": "scene", "data.map_scene_px": 64}),
        ("ethucy_zara1", {"model.map_mode": "scene", "data.map_scene_px": 64, "train.map_dropout": 0.0}),
        ("ethucy_zara1", {"model.map_mode": "scene", "data.map_scene_px": 64, **KEPT}),
    ],
)
@pytest.mark.slow
def test_fresh_exports_match_pytorch(config: str, variant: dict[str, object], tmp_path: Path) -> None:
    torch.manual_seed(1)
    cfg = Config.load(ROOT / "training" / "configs" / f"{config}.toml", variant)
    spec = input_spec(cfg)
    k_c = 4
    k = k_c * len(spec.classes)
    class_of = np.repeat(np.arange(len(spec.classes)), k_c)
    anchors = np.cumsum(np.random.default_rng(0).normal(0.4, 0.2, (k, spec.t_f, 2)), axis=1).astype(np.float32)
    model = randomised_batch_norm(build_model(cfg, spec, k).eval())
    # Contract 9's speed-dependent and class temperatures where the model has a prior for the speed.
    cal = Calibration(1.7, 0.6, 2.5) if cfg.data.prior != "none" else Calibration(1.7)
    path = export_model(model, spec, anchors, class_of, tmp_path / "m.onnx", "fresh", temperature=cal)
    predictor = dgan.Predictor(path)
    assert predictor.classes == spec.classes
    assert predictor.contract["contract_version"] == dgan._dgan.CONTRACT_VERSION
    # the rasteriser and features it was exported with: an engine with others refuses it
    assert predictor.contract["raster_version"] == dgan.contract.RASTER_VERSION
    assert predictor.contract["preprocess_version"] == dgan.contract.PREPROCESS_VERSION
    assert predictor.spec.graph == "padded"
    assert predictor.contract["temperature"] == pytest.approx(1.7)
    assert predictor.contract.get("temperature_speed_exponent", 0.0) == pytest.approx(cal.speed_exponent)
    assert predictor.contract.get("class_temperature", 1.0) == pytest.approx(cal.class_temperature)
    assert_parity(model, spec, anchors, class_of, path, temperature=cal)
    if cfg.data.prior == "none":  # the speed is the prior's: a model without one cannot declare the exponent
        with pytest.raises(dgan.exceptions.ContractError, match="declares none"):
            export_model(model, spec, anchors, class_of, tmp_path / "n.onnx", "x", temperature=Calibration(1.7, 0.6))


@pytest.mark.slow
def test_ddp_on_two_cpu_processes_and_resume(tmp_path: Path) -> None:
    from training.data.splits import training_splits

    root = data_root()
    cfg = Config.load(CONFIG)
    # Build the cache once, before two processes read it.
    training_splits(replace(cfg, data=replace(cfg.data, root=str(root))), input_spec(cfg), progress=False)
    out = tmp_path / "run"
    common = [
        "-m",
        "training.train",
        "--config",
        str(CONFIG),
        "--out",
        str(out),
        "--no-export",
        "--set",
        f"data.root={root}",
        "--set",
        "train.max_train_windows=24",
        "--set",
        "train.batch_windows=4",
        "--set",
        "train.select=val_ade",
    ]
    env = {**os.environ, "PYTHONPATH": str(ROOT)}
    torchrun = [sys.executable, "-m", "torch.distributed.run", "--standalone", "--nproc_per_node", "2"]

    def run(*extra: str) -> str:
        done = subprocess.run(
            [*torchrun, *common, "--set", "train.epochs=2", *extra],
            cwd=ROOT,
            env=env,
            capture_output=True,
            text=True,
            timeout=600,
        )
        assert done.returncode == 0, done.stdout[-3000:] + done.stderr[-3000:]
        return done.stdout

    assert "2 process(es)" in run("--stop-after", "1")  # interrupted after epoch 1
    run("--resume")
    rows = list(csv.DictReader((out / "log.csv").open()))
    assert [r["epoch"] for r in rows] == ["1", "2"]
    assert np.isfinite(float(rows[-1]["val_min_ade20"]))
    # best.pt holds the epoch of the lowest validation top-1 ADE (train.select = "val_ade").
    kept = torch.load(out / "best.pt", weights_only=False)
    assert kept["epoch"] + 1 == int(min(rows, key=lambda r: float(r["val_ade"]))["epoch"])


def test_a_checkpoint_save_stopped_midway_keeps_the_previous_one(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    from training import checkpoint

    path = tmp_path / "last.pt"
    checkpoint.save_atomic({"epoch": 3}, path)
    assert torch.load(path)["epoch"] == 3
    assert [p.name for p in tmp_path.iterdir()] == ["last.pt"]

    def killed(state: object, f: Path) -> None:  # the job's time limit strikes inside torch.save
        Path(f).write_bytes(b"\x80\x02half a pick")
        raise KeyboardInterrupt

    monkeypatch.setattr(torch, "save", killed)
    with pytest.raises(KeyboardInterrupt):
        checkpoint.save_atomic({"epoch": 4}, path)
    assert torch.load(path)["epoch"] == 3  # --resume still loads epoch 3


def test_concatenated_windows_batch_as_their_parts() -> None:
    from training.data.arrays import concat_windows
    from training.data.recording import WindowSet
    from training.data.splits import window_set

    root = data_root()
    cfg = Config.load(CONFIG)
    spec = input_spec(cfg)
    cache = Path(cfg.data.cache_dir).expanduser()
    val = window_set(WindowSet("ethucy", "val", fold="zara1"), root, spec, cache)
    both = concat_windows([val, val])
    assert both.num_windows == 2 * val.num_windows
    assert both.files == val.files * 2
    n = val.num_windows
    for w in (0, n - 1):
        a, b = val.batch([w]), both.batch([n + w])
        assert a.keys() == b.keys()
        for k in a:
            np.testing.assert_array_equal(a[k], b[k], err_msg=k)
    np.testing.assert_array_equal(both.window_file[n:], val.window_file + len(val.files))
    with pytest.raises(ValueError, match="with and without map"):
        concat_windows([val, replace(val, map=None)])


@pytest.mark.slow
def test_anchors_can_leave_the_extra_windows_out() -> None:
    from training.anchors import anchor_windows, fit_anchors
    from training.data.arrays import concat_windows
    from training.data.recording import WindowSet
    from training.data.splits import window_set

    root = data_root()
    cfg = Config.load(CONFIG, {"train.anchors_per_class": 4})
    spec = input_spec(cfg)
    cache = Path(cfg.data.cache_dir).expanduser()
    parts = [window_set(WindowSet("ethucy", "val", fold=f), root, spec, cache) for f in ("zara1", "eth")]
    both = concat_windows(parts)
    own = replace(cfg, data=replace(cfg.data, extra_in_anchors=False))
    assert anchor_windows(own, parts, both) is parts[0]
    assert anchor_windows(cfg, parts, both) is both
    alone, _ = fit_anchors(own, anchor_windows(own, parts, both), spec, 1)
    mixed, _ = fit_anchors(cfg, anchor_windows(cfg, parts, both), spec, 1)
    np.testing.assert_array_equal(alone, fit_anchors(cfg, parts[0], spec, 1)[0])
    assert not np.allclose(alone, mixed)


def test_an_anchor_can_be_held_at_the_prior() -> None:
    from training.anchors import kmeans_anchors

    rng = np.random.default_rng(0)
    futures = np.concatenate([rng.normal(0.0, 0.05, (200, 5, 2)), rng.normal(1.0, 0.1, (200, 5, 2))])
    futures = np.concatenate([futures, rng.normal(-2.0, 0.1, (100, 5, 2))])
    held = kmeans_anchors(futures, 4, zero=True)
    assert held.shape == (4, 5, 2)
    assert np.count_nonzero(np.abs(held).sum(axis=(1, 2)) == 0.0) == 1  # exactly one anchor is the prior itself
    ends = sorted(held[:, -1, 0].round(1).tolist())
    assert ends[0] == pytest.approx(-2.0, abs=0.1)
    assert ends[-1] == pytest.approx(1.0, abs=0.1)  # the others still find the clusters around it
    assert not (np.abs(kmeans_anchors(futures, 4)).sum(axis=(1, 2)) == 0.0).any()


def test_bad_training_inputs_are_clear_errors(tmp_path: Path) -> None:
    from training.anchors import kmeans_anchors
    from training.data.datasets import recordings
    from training.data.ethucy import split_files

    with pytest.raises(FileNotFoundError, match=r"set data\.root"):
        split_files(tmp_path, "zara1", "train")
    for dataset in ("sdd", "apolloscape"):
        with pytest.raises(FileNotFoundError, match=r"set data\.root"):
            recordings(dataset, tmp_path, "test")
    with pytest.raises(ValueError, match="unknown dataset"):
        recordings("kitti", tmp_path, "test")
    with pytest.raises(ValueError, match=r"unknown data\.dataset"):
        input_spec(Config.load(CONFIG, {"data.dataset": "kitti"}))
    with pytest.raises(ValueError, match="3 futures cannot make 20 anchors"):
        kmeans_anchors(np.zeros((3, 12, 2)), 20)
    from training.data.splits import split_windows

    sdd = Config.load(ROOT / "training" / "configs" / "sdd.toml", {"data.extra_pedestrians": "sdd"})
    with pytest.raises(ValueError, match="for the ETH/UCY models"):
        split_windows(replace(sdd, data=replace(sdd.data, root=str(data_root()))), input_spec(sdd), "train", False)
    sdd_val = Config.load(ROOT / "training" / "configs" / "sdd.toml", {"data.val_recordings": "9050,9055"})
    with pytest.raises(ValueError, match="val_recordings is for ApolloScape"):
        split_windows(
            replace(sdd_val, data=replace(sdd_val.data, root=str(data_root()))), input_spec(sdd_val), "val", False
        )


def _teacher_batch(cfg: Config, k_c: int) -> tuple[dgan.InputSpec, dict[str, torch.Tensor], torch.Tensor, torch.Tensor]:
    """The bundled apolloscape scene as a batch whose every agent is a target (its future 0.3 m off the prior), and
    ``k_c`` random anchors per class with the class of each."""
    from dgan.demo import scene_for
    from training.data.batches import to_tensors

    spec = input_spec(cfg)
    frame = scene_for(spec).frame
    x = dgan.preprocess(frame, spec)
    b = to_tensors({k: x[k] for k in (*INPUTS, "prior") if k in x})
    b["target"] = torch.ones(len(frame), dtype=torch.bool)
    b["class_index"] = torch.tensor([spec.classes.index(c) for c in frame.classes])
    b["future"] = b["prior"] + 0.3
    torch.manual_seed(0)
    anchors = torch.randn(k_c * len(spec.classes), spec.t_f, 2)
    return spec, b, anchors, torch.arange(len(spec.classes)).repeat_interleave(k_c)


def test_a_teacher_s_most_probable_mode_is_a_second_target_of_the_loss() -> None:
    from training.losses import dgan_loss
    from training.step import Teacher, forward_loss

    cfg = Config.load(ROOT / "training" / "configs" / "apolloscape.toml", {"train.distill_weight": 2.5})
    spec, b, anchors, class_of = _teacher_batch(cfg, 4)
    n = len(b["target"])
    with pytest.raises(ValueError, match="takes other inputs"):
        Teacher.load(str(ROOT / "training" / "checkpoints" / "hdmap.pt"), spec)
    teacher = Teacher.load(str(ROOT / "training" / "checkpoints" / "apolloscape.pt"), spec)
    student = build_model(cfg, spec, len(anchors)).eval()
    top = teacher.top_residual(b)
    assert top.shape == (n, spec.t_f, 2)
    assert torch.isfinite(top).all()
    alone, _, outs = forward_loss(student, b, anchors, class_of, cfg)
    taught, _, _ = forward_loss(student, b, anchors, class_of, cfg, teacher=teacher)
    tr = cfg.train
    classes = b["class_index"]
    second, second_parts = dgan_loss(
        *outs, top, classes, anchors, class_of, tr.alpha, tr.beta, None, tr.cls_target, tr.anchor_pool
    )
    torch.testing.assert_close(taught, alone + 2.5 * second)
    # train.distill_classifier false: the teacher's mode teaches the offsets only, its classification term left out.
    assert second_parts["cls"] > 0
    offsets_only = replace(cfg, train=replace(cfg.train, distill_classifier=False))
    taught_offsets, _, _ = forward_loss(student, b, anchors, class_of, offsets_only, teacher=teacher)
    torch.testing.assert_close(taught_offsets, alone + 2.5 * (second - second_parts["cls"]))
    no_cls, no_cls_parts = dgan_loss(
        *outs, top, classes, anchors, class_of, tr.alpha, tr.beta, None, tr.cls_target, tr.anchor_pool, False
    )
    torch.testing.assert_close(no_cls, second - second_parts["cls"])
    assert no_cls_parts == second_parts


def test_a_teacher_with_another_prior_teaches_residuals_from_the_student_s() -> None:
    from training.data.batches import batch_prior
    from training.step import Teacher

    cfg = Config.load(ROOT / "training" / "configs" / "apolloscape.toml")
    spec, b, _, _ = _teacher_batch(cfg, 4)
    same = Teacher.load(str(ROOT / "training" / "checkpoints" / "apolloscape.pt"), spec)
    assert not same.own_prior
    # A student with the adaptive prior: the teacher runs on the same tensors, its modes carried onto that prior.
    adaptive = replace(spec, prior=replace(spec.prior, fit="adaptive", window_s=2.0))
    b2 = dict(b, prior=torch.from_numpy(batch_prior(b, adaptive)))
    assert not torch.allclose(b2["prior"], b["prior"])
    other = Teacher.load(str(ROOT / "training" / "checkpoints" / "apolloscape.pt"), adaptive)
    assert other.own_prior
    mine, p = same.modes(b)
    carried, p2 = other.modes(b2)
    torch.testing.assert_close(p2, p)  # the same network, the same calibration at its own prior's speeds
    torch.testing.assert_close(carried + b2["prior"].unsqueeze(1), mine + b["prior"].unsqueeze(1))


def test_a_teacher_can_leave_the_noisy_copies_to_the_data() -> None:
    from training.losses import dgan_loss
    from training.step import Teacher, forward_loss

    cfg = Config.load(ROOT / "training" / "configs" / "apolloscape.toml", {"train.distill_noisy": False})
    spec, b, anchors, class_of = _teacher_batch(cfg, 4)
    n = len(b["target"])
    teacher = Teacher.load(str(ROOT / "training" / "checkpoints" / "apolloscape.pt"), spec)
    student = build_model(cfg, spec, len(anchors)).eval()
    alone, _, outs = forward_loss(student, b, anchors, class_of, cfg)
    # Every agent of a noisy copy: the data's loss alone.
    noisy = dict(b, noisy=torch.ones(n, dtype=torch.bool))
    torch.testing.assert_close(forward_loss(student, noisy, anchors, class_of, cfg, teacher=teacher)[0], alone)
    # Half of them: the teacher's term over the clean half, times its share of the targets.
    half = torch.arange(n) % 2 == 0
    taught, _, _ = forward_loss(student, dict(b, noisy=half), anchors, class_of, cfg, teacher=teacher)
    keep = ~half
    tr = cfg.train
    top = teacher.top_residual(b)[keep]
    cl, al, off = (o[keep] for o in outs)
    second, _ = dgan_loss(
        cl,
        al,
        off,
        top,
        b["class_index"][keep],
        anchors,
        class_of,
        tr.alpha,
        tr.beta,
        None,
        tr.cls_target,
        tr.anchor_pool,
    )
    torch.testing.assert_close(taught, alone + float(keep.float().mean()) * second)
    # With the soft term, a batch of noisy copies alone reports it as 0 (the epoch's totals add it up) and adds none.
    soft = replace(cfg, train=replace(cfg.train, distill_soft=0.7))
    soft_loss, soft_parts, _ = forward_loss(student, noisy, anchors, class_of, soft, teacher=teacher)
    torch.testing.assert_close(soft_loss, alone)
    assert soft_parts["soft"] == 0.0
    # train.distill_noisy true (the default): the flag changes nothing.
    every = replace(cfg, train=replace(cfg.train, distill_noisy=True))
    with_flag = forward_loss(student, dict(b, noisy=half), anchors, class_of, every, teacher=teacher)[0]
    torch.testing.assert_close(with_flag, forward_loss(student, b, anchors, class_of, every, teacher=teacher)[0])


def test_a_teacher_s_mode_distribution_is_a_soft_target_of_the_classifier(tmp_path: Path) -> None:
    from training.data.batches import forward_inputs
    from training.losses import soft_class_loss
    from training.step import Teacher, forward_loss
    from training.train import main

    cfg = Config.load(ROOT / "training" / "configs" / "apolloscape.toml", {"train.distill_soft": 0.7})
    spec, b, anchors, class_of = _teacher_batch(cfg, 5)
    n = len(b["target"])
    teacher = Teacher.load(str(ROOT / "training" / "checkpoints" / "apolloscape.pt"), spec)
    top, soft = teacher.mode_targets(b, anchors, class_of, "own_class")
    torch.testing.assert_close(top, teacher.top_residual(b))
    # A distribution over the student's anchors, only on the agent's class's ...
    assert soft.shape == (n, len(anchors))
    torch.testing.assert_close(soft.sum(1), torch.ones(n, dtype=soft.dtype))
    assert (soft[class_of.unsqueeze(0) != b["class_index"].unsqueeze(1)] == 0).all()
    # ... where each teacher mode's probability sits at the anchor closest to that mode.
    with torch.no_grad():
        cl, al, off = teacher.model(*forward_inputs(b))
        cal = teacher.calibration
        t = cal.anchor_temperatures(b["prior"], spec.dt_s)
        modes, p = decode_torch(cl, al, off, teacher.anchors, teacher.class_of, None, t, cal.class_temperature)
    for i in range(n):
        pool = (class_of == b["class_index"][i]).repeat(modes.shape[1], 1)
        nearest = closest_anchor(modes[i], anchors, pool)
        want = torch.zeros(len(anchors), dtype=p.dtype).index_add_(0, nearest, p[i])
        torch.testing.assert_close(soft[i], want / want.sum(), atol=1e-6, rtol=0)
    # A one-hot target is the paper's classification term for that anchor.
    student = build_model(cfg, spec, len(anchors)).eval()
    _, _, outs = forward_loss(student, b, anchors, class_of, cfg)
    k_star = closest_anchor(b["future"] - b["prior"], anchors, class_of.unsqueeze(0) == b["class_index"].unsqueeze(1))
    hot = torch.nn.functional.one_hot(k_star, len(anchors)).float()
    _, parts = dgan_loss(*outs, b["future"] - b["prior"], b["class_index"], anchors, class_of, 1.0)
    assert float(soft_class_loss(outs[0], outs[1], class_of, hot).mean().detach()) == pytest.approx(
        parts["cls"], rel=1e-5
    )
    # The term joins the loss with its weight, beside the top mode's.
    hard = replace(cfg, train=replace(cfg.train, distill_soft=0.0))
    taught_hard, _, _ = forward_loss(student, b, anchors, class_of, hard, teacher=teacher)
    taught, parts, _ = forward_loss(student, b, anchors, class_of, cfg, teacher=teacher)
    torch.testing.assert_close(taught, taught_hard + 0.7 * soft_class_loss(outs[0], outs[1], class_of, soft).mean())
    assert parts["soft"] > 0
    # It needs a teacher, and a weight of at least 0.
    config = str(ROOT / "training" / "configs" / "apolloscape.toml")
    for bad in (["--set", "train.distill_soft=0.5"], ["--set", "train.distill_soft=-1", "--set", "train.distill=x"]):
        with pytest.raises(ValueError, match=r"train\.distill_soft must be >= 0 and needs train\.distill"):
            main(["--config", config, "--out", str(tmp_path), *bad])


def test_a_teacher_runs_on_the_student_s_crops_whichever_way_its_own_were_drawn() -> None:
    from training.step import Teacher

    # The kept teacher is the earlier recipe's network (before every source): its prior was the parabola's.
    cfg = Config.load(ROOT / "training" / "configs" / "hdmap.toml", {"data.prior_fit": "quadratic"})
    spec = input_spec(cfg)
    assert spec.map is not None
    assert spec.map.render == "tiles"
    # The kept teacher was trained on crops drawn per agent; it takes the tiled crops (the same tensors) ...
    Teacher.load(str(ROOT / "training" / "checkpoints" / "teachers" / "hdmap.pt"), spec)
    # ... but not crops it must share: an optional map is another input (map_present).
    other = replace(spec, map=replace(spec.map, optional=not spec.map.optional))
    with pytest.raises(ValueError, match="takes other inputs"):
        Teacher.load(str(ROOT / "training" / "checkpoints" / "teachers" / "hdmap.pt"), other)


def test_a_teacher_with_crops_of_another_geometry_runs_on_its_own() -> None:
    """A student with a cheaper map encoder (coarser crops of the same field of view, issue 26) learns from a teacher
    that runs on crops drawn to its own geometry (``teacher_map``), exactly as on a batch of its own."""
    from training.data.arrays import Windows
    from training.step import Teacher

    cfg = Config.load(CONFIG, {"data.map_height_px": 16, "data.map_width_px": 15, "data.map_resolution_m": 1.0})
    cfg = replace(cfg, data=replace(cfg.data, map_agent_row=12))
    spec, b, _, _ = _teacher_batch(cfg, 2)
    teacher = Teacher.load(str(CHECKPOINTS / "teachers" / "zara1.pt"), spec)
    assert teacher.own_map
    assert spec.map is not None
    assert teacher.spec.map is not None
    assert (teacher.spec.map.height_px, spec.map.height_px) == (32, 16)
    own = teacher.crop_spec(spec)
    assert own.map == replace(spec.map, height_px=32, width_px=31, resolution_m=0.5, agent_row=24, agent_col=15)
    with pytest.raises(ValueError, match="teacher_map"):
        teacher.top_residual(b)
    frame = dgan.demo.scene_for(spec).frame
    theirs = torch.from_numpy(dgan.preprocess(frame, own)["map"])
    # The same teacher given a batch of its own geometry's crops, as a student of its own geometry would give it:
    same = Teacher.load(str(CHECKPOINTS / "teachers" / "zara1.pt"), own)
    assert not same.own_map
    expected = same.top_residual({**b, "map": theirs})
    torch.testing.assert_close(teacher.top_residual({**b, "teacher_map": theirs}), expected, rtol=0, atol=0)
    # The training windows carry the teacher's crops beside the student's, batched and mirrored alike.
    n = len(frame)
    raw = {k: np.asarray(v) for k, v in b.items()}
    w = Windows(
        raw["trajectory"], raw["trajectory_mask"], raw["state"], raw["edge_index"], raw["edge_features"],
        np.round(raw["map"] * 255).astype(np.uint8), raw["future"], raw["target"], raw["class_index"],
        np.zeros((n, 2)), np.zeros(n), np.array([0, n]), np.array([0, len(raw["edge_index"])]), np.zeros(1, int),
        np.zeros(1, int), ["scene"], teacher_map=np.round(theirs.numpy() * 255).astype(np.uint8),
    )  # fmt: skip
    plain, flipped = w.batch([0]), w.batch([0], flip=np.array([True]))
    assert plain["teacher_map"].shape == (n, 3, 32, 31)
    np.testing.assert_array_equal(flipped["teacher_map"], plain["teacher_map"][..., ::-1])
    np.testing.assert_array_equal(flipped["map"], plain["map"][..., ::-1])
    # Crops without the agents' boxes are another geometry too: the teacher draws its own with them.
    boxless = replace(input_spec(Config.load(CONFIG)), map=replace(own.map, draw_agents=False))
    assert Teacher.load(str(CHECKPOINTS / "teachers" / "zara1.pt"), boxless).own_map
