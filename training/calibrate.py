"""Calibration of the mode probabilities, fitted on a validation split. The event is the best mode (the mode closest
to the ground truth by ADE, which the reliability diagram of :mod:`training.evaluate` counts).

``train.calibration = "temperature"`` (contract 2): one temperature T of the anchor logits, p(k | c) =
softmax(logits / T). Two proper scores are minimised over a grid of T: the best mode's negative log-likelihood and
the Brier score of the best-mode indicator (which weighs the probable modes more); of the two temperatures, the one
whose validation reliability is closer in the bins the must-show checks (p ≥ 0.3, at least 30 modes:
:func:`training.metrics.worst_gap`) is kept.

``"speed_class"`` (contract 9): T_i = T · (1 + v_i)^b for an agent whose prior moves at v_i m/s, and p(c) =
softmax(class logits / T_c); T, b and T_c fitted together by the Brier score (Nelder-Mead from the best of a few
starting class temperatures, since the score has more than one minimum). Fast agents' top modes are rarely the best
of K and standing agents' often; a model whose class is an input has p(c) ≈ 1 although its best mode is often
another class's anchor. The engine applies either in decoding (:class:`training.losses.Calibration`).

``"per_class"``: one temperature per class's block of anchors, each fitted as ``"temperature"`` is on the targets of
that class (the class is an input, so p(c) is all but one-hot), folded into the network as a scale of each anchor's
logit (``DGAN.set_anchor_logit_scale``, the checkpoint's ``anchor_logit_scale``), contract temperature 1. ``"entropy"``:
T_i = exp(a + b · H_i), H_i the entropy of the agent's anchor distribution at T = 1
(:func:`training.modules.dgan.entropy_tempered`), a and b fitted by the Brier score, folded in the same way (the
checkpoint's ``anchor_entropy_temperature``), contract temperature 1: a distilled student's reliability is S-shaped
(spread distributions' top modes overconfident, peaked ones' underconfident), which one temperature cannot mend.
``"entropy_class"``: these (a, b) and contract 9's T_c fitted together (T_c lends other classes' anchors probability,
which a multi-class best of K uses). The last three are folded into the network (a consensus's first member).
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass, replace
from pathlib import Path
from typing import Any, NamedTuple

import numpy as np
import torch

import dgan
from training.config import Config, validation_data
from training.data.arrays import Windows
from training.losses import Calibration, mode_probabilities
from training.metrics import worst_gap
from training.modules.dgan import DGAN, entropy_tempered

#: ``train.calibration``: what is fitted (:func:`fit_calibration`).
CALIBRATIONS = ("temperature", "speed_class", "per_class", "entropy", "entropy_class")
#: The kinds folded into the network's anchor logits (a consensus's: its first member's), as a model card names them.
_ENTROPY = "a temperature set by each agent's anchor entropy"
FOLDED = {"per_class": "one temperature per class", "entropy": _ENTROPY}
FOLDED["entropy_class"] = "a class temperature and " + _ENTROPY
#: The class temperatures ``"speed_class"``'s search starts from (log-spaced, 1/e to e³).
CLASS_TEMPERATURE_STARTS = np.exp(np.linspace(-1.0, 3.0, 9))
#: The temperatures tried, log-spaced.
GRID = np.exp(np.linspace(np.log(0.05), np.log(20.0), 121))


class BestModes(NamedTuple):
    """Per validation target: class logits ``(N, C)``, anchor logits ``(N, K)``, the index of its best mode (smallest
    ADE) and the speed of its kinematic prior (m/s)."""

    class_logits: torch.Tensor
    anchor_logits: torch.Tensor
    best: torch.Tensor
    speed: torch.Tensor

    def probabilities(self, class_of: torch.Tensor, cal: Calibration) -> torch.Tensor:
        """``(N, K)`` the mode probabilities under ``cal``, as the engine decodes them."""
        t: float | torch.Tensor = cal.temperature
        if cal.speed_exponent != 0.0:
            t = cal.at_speed(self.speed).to(self.anchor_logits.dtype)
        return mode_probabilities(self.class_logits, self.anchor_logits, class_of, t, cal.class_temperature)

    @staticmethod
    def joined(parts: Sequence[BestModes]) -> BestModes:
        """Several splits' targets as one."""
        return BestModes(*(torch.cat(x) for x in zip(*parts, strict=True)))


@torch.no_grad()
def best_mode_logits(
    model: torch.nn.Module, w: Windows, spec: dgan.InputSpec, anchors: torch.Tensor, batch: int = 64
) -> BestModes:
    """For every target of ``w``: class logits, anchor logits, the index of its best mode (smallest ADE) and the
    speed of its prior."""
    from training.data.batches import forward_inputs, prepared_batch, windows_with_targets

    model.eval()
    cls, anc, best, speed = [], [], [], []
    keep = windows_with_targets(w)
    for start in range(0, len(keep), batch):
        b = prepared_batch(w, keep[start : start + batch], spec)
        cl, al, off = model(*forward_inputs(b))
        t = b["target"]
        modes = anchors.unsqueeze(0) + off[t] + b["prior"][t].unsqueeze(1)
        ade = torch.linalg.norm(modes - b["future"][t].unsqueeze(1), dim=-1).mean(-1)
        cls.append(cl[t])
        anc.append(al[t])
        best.append(ade.argmin(dim=1))
        speed.append(torch.linalg.norm(b["prior"][t][:, 0].double(), dim=-1) / spec.dt_s)
    return BestModes(torch.cat(cls), torch.cat(anc), torch.cat(best), torch.cat(speed))


def best_mode_log_loss(p: torch.Tensor, best: torch.Tensor) -> float:
    """Mean −log p(best mode) of mode probabilities ``p (N, K)``."""
    return float(-torch.log(p[torch.arange(len(best)), best].clamp_min(1e-12)).mean())


def best_mode_brier(p: torch.Tensor, best: torch.Tensor) -> float:
    """Mean Brier score Σ_k (p_k − [k is the best mode])² of mode probabilities ``p (N, K)``."""
    hit = torch.zeros_like(p)
    hit[torch.arange(len(best)), best] = 1.0
    return float(((p - hit) ** 2).sum(dim=1).mean())


def best_mode_reliability(p: torch.Tensor, best: torch.Tensor) -> dict[str, Any]:
    """The reliability bins (``training.evaluate.calibration``) of mode probabilities ``p (N, K)`` against the event
    'this mode is the best'."""
    from training.evaluate import calibration

    hit = torch.zeros_like(p, dtype=torch.bool)
    hit[torch.arange(len(best)), best] = True
    return calibration(p.double().numpy().ravel(), hit.numpy().ravel())


def reliability_gap(p: torch.Tensor, best: torch.Tensor) -> float:
    """The worst |frequency − probability| of a checked reliability bin (``training.metrics.worst_gap``); infinite
    when no bin qualifies, so that a temperature cannot pass by leaving no mode at p ≥ 0.3."""
    gap, at = worst_gap(best_mode_reliability(p, best))
    return gap if at == at else float("inf")


@dataclass(frozen=True)
class TemperatureFit:
    """The kept temperature, the score it minimised (``"nll"`` or ``"brier"``), the validation best-mode NLL at
    T = 1 and at it, the worst checked reliability gap on validation at T = 1 and at it, the number of targets it
    was fitted on and of validation splits they came from (``folds`` > 1: cross-fitted)."""

    temperature: float
    objective: str
    nll_before: float
    nll_after: float
    gap_before: float
    gap_after: float
    targets: int = 0
    folds: int = 1
    speed_exponent: float = 0.0
    class_temperature: float = 1.0
    #: ``"per_class"``: each anchor's logit scale, 1 / its class's temperature (None for the other kinds).
    anchor_logit_scale: tuple[float, ...] | None = None
    #: ``"entropy"``: (a, b) of T_i = exp(a + b · H_i) (None for the other kinds).
    entropy_temperature: tuple[float, float] | None = None

    def checkpoint_keys(self) -> dict[str, Any]:
        """What a checkpoint stores of this fit: the engine's calibration at full precision and :meth:`folded_keys`."""
        return {**self.calibration.keys(complete=True), **self.folded_keys()}

    def folded_keys(self) -> dict[str, Any]:
        """The terms folded into the network, None where this kind has none (a refit of another kind clears them)."""
        return {
            "anchor_logit_scale": None if self.anchor_logit_scale is None else list(self.anchor_logit_scale),
            "anchor_entropy_temperature": None if self.entropy_temperature is None else list(self.entropy_temperature),
        }

    @property
    def calibration(self) -> Calibration:
        """What the engine decodes with."""
        return Calibration(self.temperature, self.speed_exponent, self.class_temperature)

    def __str__(self) -> str:
        where = "validation" if self.folds == 1 else f"{self.folds} validation folds"
        extra = ""
        if self.anchor_logit_scale is not None:
            per = sorted({round(1.0 / x, 3) for x in self.anchor_logit_scale})
            extra = f", per class's anchors {per} folded into the network"
        if self.entropy_temperature is not None:
            a, b = self.entropy_temperature
            extra = f", exp({a:.3f} + {b:.3f} H) by each agent's anchor entropy H, folded into the network"
        extra += f" x (1 + v)^{self.speed_exponent:.3f}" if self.speed_exponent else ""
        extra += f", class temperature {self.class_temperature:.3f}" if self.class_temperature != 1.0 else ""
        return (
            f"temperature {self.temperature:.3f}{extra} (by {self.objective}; {self.targets} targets of {where}): "
            f"best-mode NLL {self.nll_before:.4f} -> {self.nll_after:.4f}, worst reliability gap "
            f"{self.gap_before:.3f} -> {self.gap_after:.3f}"
        )


def fit_temperature(
    model: torch.nn.Module,
    w: Windows,
    spec: dgan.InputSpec,
    anchors: torch.Tensor,
    class_of: torch.Tensor,
    kind: str = "temperature",
) -> TemperatureFit:
    """:func:`fit_calibration` of the model's predictions on ``w``."""
    return fit_calibration(kind, best_mode_logits(model, w, spec, anchors), class_of)


def check_calibration(kind: str) -> None:
    """Raises a ValueError naming the choices unless ``kind`` is one of :data:`CALIBRATIONS`."""
    if kind not in CALIBRATIONS:
        raise ValueError(f"train.calibration must be one of {', '.join(CALIBRATIONS)}, got {kind!r}")


def fit_calibration(kind: str, modes: BestModes, class_of: torch.Tensor) -> TemperatureFit:
    """The ``train.calibration`` named ``kind`` fitted on ``modes`` (:func:`check_calibration`)."""
    check_calibration(kind)
    single = choose_temperature(modes.class_logits, modes.anchor_logits, modes.best, class_of)
    if kind == "per_class":
        return fit_per_class(modes, class_of, single)
    if kind in ("entropy", "entropy_class"):
        return fit_entropy(modes, class_of, single, with_class=kind == "entropy_class")
    return single if kind == "temperature" else fit_speed_class(modes, class_of, single)


#: ``"per_class"``: a class with fewer validation targets keeps the single temperature.
MIN_CLASS_TARGETS = 30


def fit_per_class(modes: BestModes, class_of: torch.Tensor, single: TemperatureFit) -> TemperatureFit:
    """``"per_class"``: for each class, :func:`choose_temperature` on the targets of that class (the argmax of their
    class logits: the class is an input), ``single``'s where it has fewer than :data:`MIN_CLASS_TARGETS`; returned
    as each anchor's logit scale 1 / T of its class, with a temperature of 1."""
    klass = modes.class_logits.argmax(dim=1)
    temps = []
    for c in range(modes.class_logits.shape[1]):
        m = klass == c
        if int(m.sum()) < MIN_CLASS_TARGETS:
            temps.append(single.temperature)
            continue
        temps.append(
            choose_temperature(modes.class_logits[m], modes.anchor_logits[m], modes.best[m], class_of).temperature
        )
    scale = 1.0 / torch.tensor(temps, dtype=torch.float64)[class_of]
    p = mode_probabilities(modes.class_logits, modes.anchor_logits * scale.to(modes.anchor_logits.dtype), class_of)
    return folded_fit(single, "per class", p, modes.best, anchor_logit_scale=tuple(float(x) for x in scale))


def folded_fit(
    single: TemperatureFit, objective: str, p: torch.Tensor, best: torch.Tensor, **folded: Any
) -> TemperatureFit:
    """A kind folded into the network (:data:`FOLDED`): ``single`` with a contract temperature of 1, the scores of
    the folded probabilities ``p`` against the best modes ``best``, and the folded terms ``folded``."""
    return replace(
        single,
        temperature=1.0,
        objective=objective,
        nll_after=best_mode_log_loss(p, best),
        gap_after=reliability_gap(p, best),
        **folded,
    )


def choose_temperature(
    cl: torch.Tensor, al: torch.Tensor, best: torch.Tensor, class_of: torch.Tensor
) -> TemperatureFit:
    """The temperature of smallest best-mode NLL and the one of smallest Brier score, given class logits
    ``cl (N, C)``, anchor logits ``al (N, K)``, the best modes ``best (N,)`` and each anchor's class
    ``class_of (K,)``; keeps the one whose worst checked reliability gap is smaller (the NLL's on a tie)."""
    nll, brier = [], []
    for t in GRID:
        p = mode_probabilities(cl, al, class_of, float(t))
        nll.append(best_mode_log_loss(p, best))
        brier.append(best_mode_brier(p, best))
    candidates = {"nll": int(np.argmin(nll)), "brier": int(np.argmin(brier))}
    gaps = {
        k: reliability_gap(mode_probabilities(cl, al, class_of, float(GRID[i])), best) for k, i in candidates.items()
    }
    objective = "brier" if gaps["brier"] < gaps["nll"] else "nll"
    i = candidates[objective]
    at_one = mode_probabilities(cl, al, class_of, 1.0)
    return TemperatureFit(
        float(GRID[i]),
        objective,
        best_mode_log_loss(at_one, best),
        nll[i],
        reliability_gap(at_one, best),
        gaps[objective],
        len(best),
    )


def fit_speed_class(modes: BestModes, class_of: torch.Tensor, single: TemperatureFit) -> TemperatureFit:
    """``"speed_class"``: log T, b and log T_c minimising the best mode's Brier score on ``modes``, searched
    (Nelder-Mead) from the start of smallest score among ``single``'s temperature with b = 0 and each of
    :data:`CLASS_TEMPERATURE_STARTS`. A model of one class keeps T_c = 1 (its class probability is 1 whatever T_c:
    nothing to fit), and only T and b are searched."""
    from scipy.optimize import minimize

    one_class = modes.class_logits.shape[1] == 1

    def calibration(x: np.ndarray) -> Calibration:
        log_t, b, *log_tc = (float(v) for v in np.clip(x, -6.9, 6.9))
        return Calibration(float(np.exp(log_t)), b, float(np.exp(log_tc[0])) if log_tc else 1.0)

    def score(x: np.ndarray) -> float:
        return best_mode_brier(modes.probabilities(class_of, calibration(x)), modes.best)

    starts = [np.array([np.log(single.temperature), 0.0, np.log(tc)]) for tc in CLASS_TEMPERATURE_STARTS]
    x0 = starts[0][:2] if one_class else min(starts, key=score)
    found = calibration(minimize(score, x0, method="Nelder-Mead", options={"xatol": 1e-3, "fatol": 1e-6}).x)
    p = modes.probabilities(class_of, found)
    return replace(
        single,
        temperature=found.temperature,
        speed_exponent=found.speed_exponent,
        class_temperature=found.class_temperature,
        objective="brier (speed)" if one_class else "brier (speed, class)",
        nll_after=best_mode_log_loss(p, modes.best),
        gap_after=reliability_gap(p, modes.best),
    )


def fit_entropy(modes: BestModes, class_of: torch.Tensor, single: TemperatureFit, with_class: bool) -> TemperatureFit:
    """``"entropy"``: (a, b) of T_i = exp(a + b · H_i) minimising the best mode's Brier score on ``modes`` (Nelder-Mead
    from ``single``'s temperature, b = 0), contract temperature 1; ``with_class`` (``"entropy_class"``) searches log T_c
    too, from the best of :data:`CLASS_TEMPERATURE_STARTS` (a model of one class keeps T_c = 1)."""
    from scipy.optimize import minimize

    classes = modes.class_logits.shape[1]
    with_class &= classes > 1

    def terms(x: np.ndarray) -> tuple[float, float, float]:
        a, b, *log_tc = (float(v) for v in np.clip(x, -6.9, 6.9))
        return a, b, float(np.exp(log_tc[0])) if log_tc else 1.0

    def probabilities(x: np.ndarray) -> torch.Tensor:
        a, b, tc = terms(x)
        anchor_logits = entropy_tempered(modes.anchor_logits, classes, a, b)
        return mode_probabilities(modes.class_logits, anchor_logits, class_of, 1.0, tc)

    def score(x: np.ndarray) -> float:
        return best_mode_brier(probabilities(x), modes.best)

    x0 = np.array([np.log(single.temperature), 0.0])
    options: dict[str, Any] = {"xatol": 1e-4, "fatol": 1e-8}
    if with_class:  # a simplex of 0.5 a side: scipy's default steps a zero coordinate (b) by 0.00025 only
        x0 = min((np.array([*x0, np.log(tc)]) for tc in CLASS_TEMPERATURE_STARTS), key=score)
        options["initial_simplex"] = np.vstack([x0, x0 + 0.5 * np.eye(3)])
    x = np.clip(minimize(score, x0, method="Nelder-Mead", options=options).x, -6.9, 6.9)
    a, b, tc = terms(x)
    fit = folded_fit(single, "brier (entropy)", probabilities(x), modes.best, entropy_temperature=(a, b))
    return replace(fit, class_temperature=tc, objective="brier (entropy, class)") if with_class else fit


def calibration_config(cfg: Config) -> Config:
    """The configuration whose validation split the temperature is fitted on: ``cfg`` itself
    (``train.calibration_split = "all"``), or ``cfg`` without its ``data.extra_sources`` ("own": the configuration's
    own dataset's validation windows alone; :func:`training.config.validation_data`). Raises a ValueError naming the
    choices for any other value."""
    data = validation_data(cfg.data, cfg.train.calibration_split, "train.calibration_split")
    return cfg if data is cfg.data else replace(cfg, data=data)


def validation_logits(
    path: Path, data_root: Path | None = None, progress: bool = False
) -> tuple[BestModes, torch.Tensor, str]:
    """:func:`best_mode_logits` of the checkpoint at ``path`` on its configuration's validation split (under
    ``data_root`` if given; the windows :func:`calibration_config` names, and of a per-class run only its class's
    targets, as the trainer counts them), the class of each of its anchors, and its ``train.calibration``."""
    from training.data.splits import only_target_class, split_windows, target_class_index
    from training.export import load_checkpoint

    model, spec, anchors, class_of, cfg, _ = load_checkpoint(path)
    # Fitted on the network's own logits, not an earlier fit's folded ones (a consensus's are its first member's).
    first = model if isinstance(model, DGAN) else model.members[0]
    assert isinstance(first, DGAN)
    first.set_anchor_logit_scale(None)
    first.set_entropy_temperature(None)
    if data_root is not None:
        cfg = replace(cfg, data=replace(cfg.data, root=str(data_root)))
    val = split_windows(calibration_config(cfg), spec, "val", progress)
    only_target_class(val, target_class_index(cfg.data.target_class, spec))  # a per-class run's class alone
    modes = best_mode_logits(model, val, spec, torch.from_numpy(anchors).float())
    return modes, torch.from_numpy(class_of).long(), cfg.train.calibration


def calibrate_checkpoint(
    path: Path, data_root: Path | None = None, progress: bool = False, folds: Sequence[Path] = ()
) -> TemperatureFit:
    """Fits and stores the calibration (``train.calibration``) of the checkpoint at ``path`` (a run's, or an ensemble's,
    whose first member keeps the folded terms) on its configuration's validation split (under ``data_root`` if given).

    ``folds``: checkpoints of the same configuration trained with other validation splits (cross-fitting,
    ``data.val_recordings``); their predictions on their own validation splits join the fit, which then sees every
    fold's validation data instead of one split's."""
    from training.checkpoint import save_atomic

    modes, class_of, kind = validation_logits(path, data_root, progress)
    parts = [modes]
    for fold in folds:
        fold_modes, fold_class_of, _ = validation_logits(fold, data_root, progress)
        if not torch.equal(fold_class_of, class_of):
            raise ValueError(f"{fold}: its anchors' classes differ from {path}'s; folds must share a configuration")
        parts.append(fold_modes)
    found = replace(fit_calibration(kind, BestModes.joined(parts), class_of), folds=len(parts))
    ckpt = torch.load(path, weights_only=False)
    ckpt.update(found.calibration.keys(complete=True))
    (ckpt["members"][0] if "members" in ckpt else ckpt).update(found.folded_keys())
    save_atomic(ckpt, path)
    return found
