"""training.calibrate: the two proper scores, the reliability gap that chooses between their temperatures, the
choice itself on best modes drawn at a known temperature, the speed-dependent and class temperatures of contract 9
and the entropy temperature (alone and with a class temperature) given back from best modes drawn with them, a
temperature cross-fitted over validation folds, and the validation windows it is fitted on
(train.calibration_split)."""

from __future__ import annotations

import math
from dataclasses import asdict
from pathlib import Path

import numpy as np
import pytest
import torch
from conftest import shared_data

from training.build import build_model, input_spec
from training.calibrate import (
    BestModes,
    best_mode_brier,
    calibrate_checkpoint,
    calibration_config,
    check_calibration,
    choose_temperature,
    fit_calibration,
    reliability_gap,
    validation_logits,
)
from training.config import Config
from training.losses import Calibration
from training.modules.dgan import entropy_tempered

ROOT = Path(__file__).resolve().parents[3]


def test_the_brier_score_of_the_best_mode_indicator() -> None:
    p = torch.tensor([[1.0, 0.0], [0.5, 0.5], [0.2, 0.8]])
    best = torch.tensor([0, 1, 0])
    # 0; 0.25 + 0.25; 0.64 + 0.64
    assert best_mode_brier(p, best) == pytest.approx((0.0 + 0.5 + 1.28) / 3)


def test_the_reliability_gap_of_the_checked_bins() -> None:
    # 40 modes at p = 0.75 that are the best 30 times: frequency 0.75, no gap; then 20 of 40: gap 0.25.
    p = torch.tensor([[0.75, 0.25]] * 40)
    assert reliability_gap(p, torch.tensor([0] * 30 + [1] * 10)) == pytest.approx(0.0, abs=1e-9)
    assert reliability_gap(p, torch.tensor([0] * 20 + [1] * 20)) == pytest.approx(0.25)
    # Fewer than 30 modes at p >= 0.3 in every bin: no bin is checked, and the gap counts as infinite, so that a
    # temperature cannot pass by leaving no probable mode.
    assert math.isinf(reliability_gap(torch.tensor([[0.75, 0.25]] * 10), torch.zeros(10, dtype=torch.long)))


def test_best_modes_drawn_at_a_temperature_give_it_back() -> None:
    g = torch.Generator().manual_seed(0)
    n, k, true_t = 20000, 6, 2.0
    cl = torch.zeros(n, 1)
    al = 3.0 * torch.randn(n, k, generator=g)
    best = torch.multinomial(torch.softmax(al / true_t, dim=1), 1, generator=g).squeeze(1)
    fit = choose_temperature(cl, al, best, torch.zeros(k, dtype=torch.long))
    assert fit.objective in ("nll", "brier")
    assert fit.temperature == pytest.approx(true_t, rel=0.1)
    assert fit.nll_after < fit.nll_before  # the logits at T = 1 are overconfident
    assert fit.gap_after < 0.05 < fit.gap_before
    assert "temperature" in str(fit)


def test_speed_and_class_temperatures_drawn_are_given_back() -> None:
    # Two classes of three anchors; the best mode drawn from p(c) at T_c = 3 and p(k | c) at 0.5 · (1 + v)^0.8.
    g = torch.Generator().manual_seed(1)
    n, true = 40000, Calibration(0.5, 0.8, 3.0)
    class_of = torch.tensor([0, 0, 0, 1, 1, 1])
    cl = torch.stack([torch.full((n,), 4.0), torch.zeros(n)], dim=1) + torch.randn(n, 2, generator=g)
    al = 2.0 * torch.randn(n, 6, generator=g)
    speed = 10.0 * torch.rand(n, generator=g, dtype=torch.float64)
    drawn = BestModes(cl, al, torch.zeros(n, dtype=torch.long), speed)
    best = torch.multinomial(drawn.probabilities(class_of, true), 1, generator=g).squeeze(1)
    modes = drawn._replace(best=best)
    fit = fit_calibration("speed_class", modes, class_of)
    assert fit.objective == "brier (speed, class)"
    assert (fit.temperature, fit.speed_exponent, fit.class_temperature) == pytest.approx((0.5, 0.8, 3.0), rel=0.15)
    single = fit_calibration("temperature", modes, class_of)
    assert (single.speed_exponent, single.class_temperature) == (0.0, 1.0)
    # One temperature cannot be right for slow and fast agents at once.
    assert fit.gap_after < 0.03 < single.gap_after
    assert "class temperature" in str(fit)
    with pytest.raises(ValueError, match=r"train\.calibration must be one of temperature, speed_class, per_class"):
        check_calibration("platt")


def test_a_one_class_model_keeps_a_class_temperature_of_one() -> None:
    # Its class probability is 1 whatever T_c: only T and b are fitted (the search had wandered to T_c = 0.001 or 992).
    g = torch.Generator().manual_seed(2)
    n, true = 20000, Calibration(0.7, 0.6)
    class_of = torch.zeros(5, dtype=torch.long)
    al = 2.0 * torch.randn(n, 5, generator=g)
    speed = 5.0 * torch.rand(n, generator=g, dtype=torch.float64)
    drawn = BestModes(torch.zeros(n, 1), al, torch.zeros(n, dtype=torch.long), speed)
    modes = drawn._replace(best=torch.multinomial(drawn.probabilities(class_of, true), 1, generator=g).squeeze(1))
    fit = fit_calibration("speed_class", modes, class_of)
    assert fit.objective == "brier (speed)"
    assert fit.class_temperature == 1.0
    assert (fit.temperature, fit.speed_exponent) == pytest.approx((0.7, 0.6), rel=0.15)
    assert set(fit.calibration.keys(complete=False)) == {"temperature", "temperature_speed_exponent"}


def test_per_class_temperatures_drawn_are_given_back_and_fold_into_the_logits() -> None:
    # Two classes (an input: p(c) all but one-hot), each agent's best mode drawn at its class's temperature.
    g = torch.Generator().manual_seed(3)
    n, temps = 40000, (0.6, 2.5)
    class_of = torch.tensor([0, 0, 0, 1, 1, 1])
    klass = (torch.rand(n, generator=g) < 0.5).long()
    cl = 8.0 * torch.nn.functional.one_hot(klass, 2).float()
    al = 2.0 * torch.randn(n, 6, generator=g)
    t = torch.tensor(temps)[class_of]  # (K,)
    p = torch.softmax(cl, dim=1)[:, class_of] * torch.cat(
        [torch.softmax(al[:, :3] / t[:3], dim=1), torch.softmax(al[:, 3:] / t[3:], dim=1)], dim=1
    )
    modes = BestModes(cl, al, torch.multinomial(p, 1, generator=g).squeeze(1), torch.zeros(n, dtype=torch.float64))
    fit = fit_calibration("per_class", modes, class_of)
    assert fit.objective == "per class"
    assert fit.temperature == 1.0
    assert fit.anchor_logit_scale is not None
    assert [1.0 / x for x in fit.anchor_logit_scale] == pytest.approx([0.6] * 3 + [2.5] * 3, rel=0.1)
    single = fit_calibration("temperature", modes, class_of)
    assert fit.gap_after < 0.03 < single.gap_after  # one temperature cannot be right for both classes
    assert "folded into the network" in str(fit)


def test_an_entropy_temperature_drawn_is_given_back_and_one_temperature_cannot_match_it() -> None:
    # Best modes drawn at T_i = exp(a + b H_i): spread distributions flattened, peaked ones sharpened (b > 0).
    g = torch.Generator().manual_seed(5)
    n, a, b = 60000, -0.6, 0.5
    class_of = torch.zeros(6, dtype=torch.long)
    al = torch.randn(n, 6, generator=g) * (0.3 + 3.0 * torch.rand(n, 1, generator=g))
    p = torch.softmax(entropy_tempered(al, 1, a, b), dim=1)
    modes = BestModes(torch.zeros(n, 1), al, torch.multinomial(p, 1, generator=g).squeeze(1), torch.zeros(n))
    fit = fit_calibration("entropy", modes, class_of)
    assert fit.objective == "brier (entropy)"
    assert fit.temperature == 1.0
    assert fit.entropy_temperature is not None
    assert fit.entropy_temperature == pytest.approx((a, b), abs=0.08)
    single = fit_calibration("temperature", modes, class_of)
    assert fit.gap_after < 0.03 < single.gap_after
    assert "anchor entropy" in str(fit)
    keys = fit.checkpoint_keys()
    assert keys["anchor_entropy_temperature"] == list(fit.entropy_temperature)
    assert keys["anchor_logit_scale"] is None  # a refit of this kind clears a per-class one
    assert single.checkpoint_keys()["anchor_entropy_temperature"] is None


def test_an_entropy_and_class_temperature_drawn_are_given_back_with_the_class_in_the_contract() -> None:
    # Two classes of three anchors, the class an input (p(c) confident at T_c = 1): best modes drawn at T_c = 3 and
    # T_i = exp(a + b H_i) of each class's block. "entropy" alone cannot lend the other class's anchors probability.
    g = torch.Generator().manual_seed(6)
    n, a, b, tc = 60000, -0.4, 0.4, 3.0
    class_of = torch.tensor([0, 0, 0, 1, 1, 1])
    klass = (torch.rand(n, generator=g) < 0.5).long()
    cl = 4.0 * torch.nn.functional.one_hot(klass, 2).float() + torch.randn(n, 2, generator=g)
    al = torch.randn(n, 6, generator=g) * (0.3 + 3.0 * torch.rand(n, 1, generator=g))
    p = torch.softmax(cl / tc, dim=1)[:, class_of] * entropy_probabilities(al, a, b)
    modes = BestModes(cl, al, torch.multinomial(p, 1, generator=g).squeeze(1), torch.zeros(n))
    fit = fit_calibration("entropy_class", modes, class_of)
    assert fit.objective == "brier (entropy, class)"
    assert (fit.temperature, fit.speed_exponent) == (1.0, 0.0)
    assert fit.entropy_temperature == pytest.approx((a, b), abs=0.1)
    assert fit.class_temperature == pytest.approx(tc, rel=0.15)
    assert fit.checkpoint_keys()["class_temperature"] == pytest.approx(fit.class_temperature)
    entropy = fit_calibration("entropy", modes, class_of)
    assert entropy.class_temperature == 1.0
    assert fit.gap_after < 0.03 < entropy.gap_after
    assert "class temperature" in str(fit)
    assert "anchor entropy" in str(fit)
    # A model of one class has no class temperature to fit.
    one = fit_calibration("entropy_class", modes._replace(class_logits=torch.zeros(n, 1)), torch.zeros(6).long())
    assert one.class_temperature == 1.0
    assert one.objective == "brier (entropy)"


def entropy_probabilities(al: torch.Tensor, a: float, b: float) -> torch.Tensor:
    """p(k | c) of two classes' blocks of three anchors, each at its entropy temperature."""
    t = entropy_tempered(al, 2, a, b)
    return torch.cat([torch.softmax(t[:, :3], dim=1), torch.softmax(t[:, 3:], dim=1)], dim=1)


def test_entropy_tempered_works_per_class_block() -> None:
    # Two classes' blocks: each divided by exp(a + b H) of its own softmax.
    al = torch.tensor([[0.0, 0.0, 5.0, 0.0], [1.0, -1.0, 2.0, 2.0]])
    out = entropy_tempered(al, 2, 0.1, 0.7)
    for block in (slice(0, 2), slice(2, 4)):
        q = torch.softmax(al[:, block], dim=1)
        h = -(q * q.log()).sum(dim=1, keepdim=True)
        torch.testing.assert_close(out[:, block], al[:, block] / torch.exp(0.1 + 0.7 * h))


def _apollo_checkpoint(path: Path, val_recordings: str, kc: int, seed: int, target_class: str = "") -> Path:
    """An untrained ApolloScape network with random anchors, saved as a checkpoint whose validation split is
    ``val_recordings`` (the default split if empty), a per-class run's for ``target_class``."""
    torch.manual_seed(seed)
    overrides = {
        "data.val_recordings": val_recordings,
        "data.root": str(shared_data("apolloscape_trajectory")),
        "data.target_class": target_class,
    }
    cfg = Config.load(ROOT / "training" / "configs" / "apolloscape.toml", overrides)
    spec = input_spec(cfg)
    k = kc * len(spec.classes)
    anchors = np.cumsum(np.random.default_rng(seed).normal(0.5, 0.3, (k, spec.t_f, 2)), axis=1)
    ckpt = {
        "model": build_model(cfg, spec, k).eval().state_dict(),
        "anchors": anchors.astype(np.float32),
        "class_of": np.repeat(np.arange(len(spec.classes)), kc),
        "config": asdict(cfg),
        "epoch": 0,
    }
    torch.save(ckpt, path)
    return path


def _apollo_runs(tmp_path: Path, seeds: tuple[int, ...]) -> list[Path]:
    """Untrained ApolloScape networks with random anchors (``test_calibrate``'s) saved as training runs."""
    runs = []
    for seed in seeds:
        run = tmp_path / f"apollo{seed}"
        run.mkdir()
        _apollo_checkpoint(run / "best.pt", "", 3, seed)
        runs.append(run)
    return runs


@pytest.mark.slow
def test_a_cross_fitted_temperature_pools_every_folds_validation_split(tmp_path: Path) -> None:
    main = _apollo_checkpoint(tmp_path / "main.pt", "", 4, 0)
    fold = _apollo_checkpoint(tmp_path / "fold.pt", "9053,9059", 4, 1)
    own = len(validation_logits(main)[0].best)
    other = len(validation_logits(fold)[0].best)
    assert own > 0
    assert other > 0
    alone = calibrate_checkpoint(main)
    assert (alone.targets, alone.folds) == (own, 1)
    pooled = calibrate_checkpoint(main, folds=[fold])
    assert (pooled.targets, pooled.folds) == (own + other, 2)
    assert "2 validation folds" in str(pooled)
    ckpt = torch.load(main, weights_only=False)
    assert ckpt["temperature"] == pooled.temperature
    # A fold of another anchor layout is another configuration: refused, and the checkpoint keeps its temperature.
    odd = _apollo_checkpoint(tmp_path / "odd.pt", "9053,9059", 3, 2)
    with pytest.raises(ValueError, match="folds must share a configuration"):
        calibrate_checkpoint(main, folds=[odd])
    assert torch.load(main, weights_only=False)["temperature"] == pooled.temperature


@pytest.mark.slow
def test_a_per_class_runs_temperature_is_fitted_on_its_class_alone(tmp_path: Path) -> None:
    from training.data.splits import split_windows

    every = validation_logits(_apollo_checkpoint(tmp_path / "all.pt", "", 2, 0))[0]
    cyclists = validation_logits(_apollo_checkpoint(tmp_path / "cyc.pt", "", 2, 0, "cyclist"))[0]
    cfg = Config.load(
        ROOT / "training" / "configs" / "apolloscape.toml", {"data.root": str(shared_data("apolloscape_trajectory"))}
    )
    spec = input_spec(cfg)
    val = split_windows(cfg, spec, "val", False)
    want = int((val.target & (val.class_index == list(spec.classes).index("cyclist"))).sum())
    assert len(every.best) == val.num_targets
    assert 0 < len(cyclists.best) == want < len(every.best)


def test_the_calibration_split_names_the_validation_windows_of_the_fit() -> None:
    joint = Config.from_dict(
        {"name": "hdmap", "data": {"dataset": "hdmap", "extra_sources": "ethucy_5hz:3,sdd_5hz:20"}, "train": {}}
    )
    # "all" (the default): every validation window of the configuration, the extra sources' too.
    assert calibration_config(joint) is joint
    # "own": the configuration's own dataset's alone; everything else as configured.
    own = calibration_config(Config.from_dict({**asdict(joint), "train": {"calibration_split": "own"}}))
    assert own.data.extra_sources == ""
    assert (own.data.dataset, own.train.calibration_split) == ("hdmap", "own")
    assert own.data.augment_noise == joint.data.augment_noise
    with pytest.raises(ValueError, match=r"train\.calibration_split must be 'all' or 'own', got 'every'"):
        calibration_config(Config.from_dict({"train": {"calibration_split": "every"}}))


@pytest.mark.slow
def test_a_consensus_folds_its_calibration_into_its_first_member(tmp_path: Path) -> None:
    """A folded kind (``"entropy"``) fitted for a consensus goes into its first member, whose anchor logits the
    consensus keeps: the other members and every top mode stay as they were, the contract's temperature is 1, and the
    exported file decodes as PyTorch does."""
    from test_training import assert_parity

    from training.checkpoint import update_checkpoint
    from training.ensemble import ensemble_checkpoint
    from training.export import export_model, load_checkpoint

    path = ensemble_checkpoint(_apollo_runs(tmp_path, (0, 1)), tmp_path / "consensus.pt")
    ckpt = torch.load(path, weights_only=False)
    for holder in [ckpt, *ckpt["members"]]:
        if "config" in holder:
            holder["config"]["train"]["calibration"] = "entropy"
    update_checkpoint(path, members=ckpt["members"])
    found = calibrate_checkpoint(path)
    assert found.entropy_temperature is not None
    kept = torch.load(path, weights_only=False)
    assert kept["members"][0]["anchor_entropy_temperature"] == list(found.entropy_temperature)
    assert kept["members"][1].get("anchor_entropy_temperature") is None
    assert kept.get("anchor_entropy_temperature") is None
    assert kept["temperature"] == 1.0
    model, spec, anchors, class_of, _, cal = load_checkpoint(path)
    path_onnx = export_model(model, spec, anchors, class_of, tmp_path / "m.onnx", "entropy consensus", temperature=cal)
    assert_parity(model, spec, anchors, class_of, path_onnx, cal)
    assert calibrate_checkpoint(path).entropy_temperature == found.entropy_temperature  # fitted on its own logits
