//! Anchor decoding: hierarchical probabilities p(mode) = p(c) · p(k | c) with p(k | c) = softmax(anchor logits / T)
//! and p(c) = softmax(class logits / T_c), trajectories = kinematic prior + anchor + offset taken back to the world
//! frame, modes ranked by probability. T may grow with the agent's speed ([`Calibration`]).

use crate::class::AgentClass;
use crate::error::{DganError, Result};
use crate::limits::on_threads;
use crate::prior::hot_class;
use crate::spec::STATE_FEATURES;
use crate::transform::AgentPose;
use ndarray::{s, Array2, Array3, Array4, ArrayView2, ArrayView3, ArrayView4, ArrayViewMut2, ArrayViewMut4, Axis};

/// Per-class anchor trajectories in the agent-centric frame.
#[derive(Debug, Clone, PartialEq)]
pub struct Anchors {
    classes: Vec<AgentClass>,
    sets: Vec<Array3<f64>>,
}

impl Anchors {
    /// Anchors for each class, in the model's class order; each set is `(K_c, T_f, 2)` metres.
    pub fn new(classes: Vec<AgentClass>, sets: Vec<Array3<f64>>) -> Result<Self> {
        if classes.len() != sets.len() || classes.is_empty() {
            return Err(DganError::Contract(format!("{} anchor sets for {} classes", sets.len(), classes.len())));
        }
        let t_f = sets[0].dim().1;
        for (c, s) in classes.iter().zip(&sets) {
            let (k, t, d) = s.dim();
            if k == 0 || t != t_f || d != 2 {
                return Err(DganError::Contract(format!(
                    "anchors of {c} must have shape (K_c >= 1, T_f = {t_f}, 2), got ({k}, {t}, {d})"
                )));
            }
            if s.iter().any(|v| !v.is_finite()) {
                return Err(DganError::Contract(format!("anchors of {c} hold NaN or infinite values")));
            }
        }
        Ok(Self { classes, sets })
    }

    /// Classes, in the model's order.
    pub fn classes(&self) -> &[AgentClass] {
        &self.classes
    }

    /// The anchor set of each class, `(K_c, T_f, 2)`.
    pub fn sets(&self) -> &[Array3<f64>] {
        &self.sets
    }

    /// K_c for each class.
    pub fn per_class(&self) -> Vec<usize> {
        self.sets.iter().map(|s| s.dim().0).collect()
    }

    /// K = Σ K_c.
    pub fn total(&self) -> usize {
        self.per_class().iter().sum()
    }

    /// T_f.
    pub fn steps(&self) -> usize {
        self.sets[0].dim().1
    }

    /// The index of the class each of the K anchors belongs to.
    pub fn class_of_anchor(&self) -> Vec<usize> {
        self.per_class().iter().enumerate().flat_map(|(c, &k)| std::iter::repeat_n(c, k)).collect()
    }

    /// The K anchors `(K, T_f, 2)` flattened in that order: anchor k's steps at `k · 2 T_f ..`.
    fn flat(&self) -> Vec<f64> {
        self.sets.iter().flat_map(|s| s.iter().copied()).collect()
    }
}

/// The decoded modes of N agents, M modes each, sorted by probability (highest first).
#[derive(Debug, Clone)]
pub struct Decoded {
    /// `(N, M, T_f, 2)` world-frame positions.
    pub trajectories: Array4<f64>,
    /// `(N, M)` p(c) · p(k | c) of each mode.
    pub probabilities: Array2<f64>,
    /// `(N, C)` p(c).
    pub class_probabilities: Array2<f64>,
    /// `(N, M)` index (into the model's classes) of the class whose anchor each mode refines.
    pub mode_classes: Array2<i64>,
    /// `(N, M)` index into the K anchors of each mode.
    pub mode_anchors: Array2<i64>,
}

impl Decoded {
    /// N agents of M modes over T_f steps and C classes, all zero.
    pub fn zeros(n: usize, m: usize, t_f: usize, c: usize) -> Self {
        Self {
            trajectories: Array4::zeros((n, m, t_f, 2)),
            probabilities: Array2::zeros((n, m)),
            class_probabilities: Array2::zeros((n, c)),
            mode_classes: Array2::zeros((n, m)),
            mode_anchors: Array2::zeros((n, m)),
        }
    }

    /// Parts decoded apart as one: part `p`'s row `r` becomes row `rows[p][r]` of `n` (rows absent from every part
    /// stay zero). Every part has the same modes, steps and classes.
    pub fn gather(n: usize, parts: &[(&[usize], Decoded)]) -> Result<Self> {
        let Some((_, first)) = parts.first() else { return Err(DganError::Inference("no part decoded".into())) };
        let (_, m, t_f, _) = first.trajectories.dim();
        let mut out = Self::zeros(n, m, t_f, first.class_probabilities.ncols());
        for (rows, d) in parts {
            if d.trajectories.dim().0 != rows.len() || d.probabilities.ncols() != m {
                return Err(DganError::Inference("a decoded part does not match its rows".into()));
            }
            for (r, &i) in rows.iter().enumerate() {
                if i >= n {
                    return Err(DganError::Inference(format!("row {i} of {n} agents")));
                }
                out.trajectories.slice_mut(s![i, .., .., ..]).assign(&d.trajectories.slice(s![r, .., .., ..]));
                out.probabilities.row_mut(i).assign(&d.probabilities.row(r));
                out.class_probabilities.row_mut(i).assign(&d.class_probabilities.row(r));
                out.mode_classes.row_mut(i).assign(&d.mode_classes.row(r));
                out.mode_anchors.row_mut(i).assign(&d.mode_anchors.row(r));
            }
        }
        Ok(out)
    }
}

/// The softmax of `logits` into `out` (cleared first), without allocating once `out` has room.
fn softmax_into(logits: impl Iterator<Item = f64>, out: &mut Vec<f64>) {
    out.clear();
    out.extend(logits);
    let max = out.iter().copied().fold(f64::NEG_INFINITY, f64::max);
    let mut sum = 0.0;
    for x in out.iter_mut() {
        *x = (*x - max).exp();
        sum += *x;
    }
    out.iter_mut().for_each(|x| *x /= sum);
}

/// The network's outputs for N agents.
#[derive(Debug, Clone, Copy)]
pub struct NetworkOutputs<'a> {
    /// `(N, C)` logits of p(c).
    pub class_logits: ArrayView2<'a, f32>,
    /// `(N, K)` logits of p(k | c), grouped by class.
    pub anchor_logits: ArrayView2<'a, f32>,
    /// `(N, K, T_f, 2)` agent-frame offsets from each anchor.
    pub offsets: ArrayView4<'a, f32>,
}

/// How logits become probabilities: the temperature of the anchor logits, its growth with speed (contract 9) and
/// the temperature of the class logits (contract 9). Agent i's anchor temperature is
/// `temperature · (1 + v_i)^speed_exponent`, v_i the speed of its kinematic prior in metres per second, kept within
/// [[`Calibration::MIN_TEMPERATURE`], [`Calibration::MAX_TEMPERATURE`]].
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Calibration {
    /// The anchor logits' temperature of a standing agent (of every agent when `speed_exponent` is 0).
    pub temperature: f64,
    /// How the anchor temperature grows with speed; 0 = one temperature for every agent.
    pub speed_exponent: f64,
    /// p(c) = softmax(class_logits / class_temperature); 1 = as trained.
    pub class_temperature: f64,
}

impl Calibration {
    /// The smallest temperature an agent gets.
    pub const MIN_TEMPERATURE: f64 = 1e-3;
    /// The largest temperature an agent gets.
    pub const MAX_TEMPERATURE: f64 = 1e3;

    /// One anchor temperature for every agent and class probabilities as trained (contracts 2 to 8).
    pub const fn single(temperature: f64) -> Self {
        Self { temperature, speed_exponent: 0.0, class_temperature: 1.0 }
    }

    /// The anchor temperature of an agent whose prior moves at `speed_mps`.
    pub fn anchor_temperature(&self, speed_mps: f64) -> f64 {
        if self.speed_exponent == 0.0 {
            return self.temperature;
        }
        let t = self.temperature * (1.0 + speed_mps.max(0.0)).powf(self.speed_exponent);
        if t.is_nan() {
            self.temperature
        } else {
            t.clamp(Self::MIN_TEMPERATURE, Self::MAX_TEMPERATURE)
        }
    }

    fn check(&self) -> Result<()> {
        let positive = |v: f64| v.is_finite() && v > 0.0;
        if !(positive(self.temperature) && positive(self.class_temperature) && self.speed_exponent.is_finite()) {
            return Err(DganError::Contract(format!(
                "temperatures must be positive and the speed exponent finite, got {self:?}"
            )));
        }
        Ok(())
    }
}

/// How to turn outputs into modes: the anchors, the kinematic prior `(N, T_f, 2)` they are relative to (agent
/// frame; `None` for none), the calibration and the model's step (the prior's first step over it is the speed a
/// speed-dependent temperature reads).
#[derive(Debug, Clone, Copy)]
pub struct DecodeParams<'a> {
    /// The model's anchors.
    pub anchors: &'a Anchors,
    /// The kinematic prior of each agent, added to every mode.
    pub prior: Option<ArrayView3<'a, f32>>,
    /// The temperatures of the logits.
    pub calibration: Calibration,
    /// The model's time step, seconds.
    pub dt_s: f64,
    /// Contract 14: per class (the model's order), the share s of its residual over the prior that an agent's most
    /// probable mode keeps, `prior + s · (anchor + offset)`, when that class is the agent's most probable one (the
    /// largest class logit; the mode: that class's largest anchor logit, the first of equals). Every other mode, and
    /// every probability, stays as the network gives it. Empty: every class keeps all of it (contracts 1 to 13).
    pub top_scale: &'a [f64],
    /// Contract 15: per agent of the call, whether its history is still ([`still_agents`]); such an agent's most
    /// probable mode is the prior alone (its residual dropped, whatever `top_scale` keeps). Every other mode, and every
    /// probability, stays as the network gives it. Empty: no agent is held (contracts 1 to 14).
    pub still: &'a [bool],
    /// Contract 16: per class (the model's order), a power β: an agent whose most probable class is that one (as for
    /// `top_scale`) has as its most probable mode the mean of all K of its modes (each as decoded, the scaled one
    /// included) weighted by p^β, p their probabilities; 0 keeps the mode as decoded. A still agent keeps its prior.
    /// The mode keeps its probability, and every other mode stays as it is. Empty: no class (contracts 1 to 15).
    pub top_mean: &'a [f64],
}

impl<'a> DecodeParams<'a> {
    /// Decoding by the anchors, prior, calibration and step alone: no top-mode scale, no agent held and no mean top
    /// mode (contracts 1 to 13); a later contract's keys are set over it (`DecodeParams { top_scale, ..new(..) }`).
    pub fn new(anchors: &'a Anchors, prior: Option<ArrayView3<'a, f32>>, calibration: Calibration, dt_s: f64) -> Self {
        Self { anchors, prior, calibration, dt_s, top_scale: &[], still: &[], top_mean: &[] }
    }
}

/// The largest power of contract 16's `top_mean_power` (beyond it the mean is the most probable mode to rounding).
pub const MAX_TOP_MEAN_POWER: f64 = 64.0;

/// The farthest a still history may reach from the last observed position (contract 15's `still_radius_m`), metres.
pub const MAX_STILL_RADIUS_M: f64 = 10.0;

/// Contract 15: which agents' histories are still, from the network inputs `trajectory (N, T_obs, 2)` (agent frame:
/// the last observed position at the origin), `trajectory_mask (N, T_obs)` and `state (N, 7 + C)` (its one-hot class,
/// [`crate::prior`]'s reading of it): every observed step present and each within `radius[class]` metres of the origin
/// (strictly; a radius of 0 holds no agent of that class, nor is an agent without a class held). Empty when `radius`
/// is.
pub fn still_agents(
    trajectory: ArrayView3<'_, f32>,
    mask: ArrayView2<'_, f32>,
    state: ArrayView2<'_, f32>,
    radius: &[f64],
) -> Result<Vec<bool>> {
    if radius.is_empty() {
        return Ok(Vec::new());
    }
    if let Some(bad) = radius.iter().find(|r| !(r.is_finite() && **r >= 0.0)) {
        return Err(DganError::InvalidSpec(format!("still radii must be finite and not negative, got {bad}")));
    }
    let (n, t_obs, two) = trajectory.dim();
    let (c, width) = (radius.len(), STATE_FEATURES.len() + radius.len());
    if two != 2 || mask.dim() != (n, t_obs) || state.dim() != (n, width) {
        return Err(DganError::InvalidSpec(format!(
            "still_agents takes trajectory (N, T_obs, 2), trajectory_mask (N, T_obs) and state (N, {width}) for {c} \
             classes; got {:?}, {:?} and {:?}",
            trajectory.dim(),
            mask.dim(),
            state.dim()
        )));
    }
    Ok((0..n)
        .map(|i| {
            let r = hot_class(state, i, c).map_or(0.0, |k| radius[k]);
            r > 0.0
                && mask.row(i).iter().all(|&v| v > 0.0)
                && trajectory.slice(s![i, .., ..]).outer_iter().all(|p| f64::from(p[0]).hypot(f64::from(p[1])) < r)
        })
        .collect())
}

/// Checks a top-mode scale ([`DecodeParams::top_scale`]) for `classes` classes: empty, or one value in [0, 1] each.
pub fn check_top_scale(top_scale: &[f64], classes: usize) -> Result<()> {
    if top_scale.is_empty() {
        return Ok(());
    }
    if top_scale.len() != classes {
        return Err(DganError::Contract(format!("top_scale has {} values for {classes} classes", top_scale.len())));
    }
    if let Some(bad) = top_scale.iter().find(|s| !(0.0..=1.0).contains(*s)) {
        return Err(DganError::Contract(format!("top_scale values must lie in [0, 1], got {bad}")));
    }
    Ok(())
}

/// Checks a top-mean power ([`DecodeParams::top_mean`]) for `classes` classes: empty, or one value each, 0 (none)
/// or in (0, [`MAX_TOP_MEAN_POWER`]].
pub fn check_top_mean(top_mean: &[f64], classes: usize) -> Result<()> {
    if top_mean.is_empty() {
        return Ok(());
    }
    if top_mean.len() != classes {
        return Err(DganError::Contract(format!("top_mean has {} values for {classes} classes", top_mean.len())));
    }
    if let Some(bad) = top_mean.iter().find(|b| !(0.0..=MAX_TOP_MEAN_POWER).contains(*b)) {
        return Err(DganError::Contract(format!("top_mean powers must lie in [0, {MAX_TOP_MEAN_POWER}], got {bad}")));
    }
    Ok(())
}

/// Contract 16's mean into `out` (one mode's `T_f · 2` residual): every mode's residual over the prior, anchor plus
/// offset (`scaled`'s anchor times its share), weighted by p^`beta` over their sum; each probability is taken over
/// the largest, so that the weights cannot all underflow.
fn mean_residual(p: &[f64], beta: f64, scaled: (usize, f64), anchors: &[f64], offsets: &[f32], out: &mut [f64]) {
    let step = out.len();
    let top = p.iter().copied().fold(0.0, f64::max);
    out.iter_mut().for_each(|v| *v = 0.0);
    let mut total = 0.0;
    // A whole power (every bundled model's) by multiplications: powf is most of the mean's cost.
    let whole = (beta.fract() == 0.0).then_some(beta as i32);
    for (k, &pk) in p.iter().enumerate() {
        let q = whole.map_or_else(|| (pk / top).powf(beta), |b| (pk / top).powi(b));
        total += q;
        let w = q * if k == scaled.0 { scaled.1 } else { 1.0 };
        let (anchor, off) = (&anchors[k * step..(k + 1) * step], &offsets[k * step..(k + 1) * step]);
        for ((v, a), o) in out.iter_mut().zip(anchor).zip(off) {
            *v += w * (a + f64::from(*o));
        }
    }
    out.iter_mut().for_each(|v| *v /= total);
}

/// The first index of the largest value (NaN never larger); 0 for an empty row.
fn first_argmax(v: impl Iterator<Item = f32>) -> usize {
    let mut best = (0, f32::NEG_INFINITY);
    for (i, x) in v.enumerate() {
        if x > best.1 {
            best = (i, x);
        }
    }
    best.0
}

/// Decodes the network's outputs for agents whose agent-centric frames are `poses`, keeping the top `modes`
/// (at most K).
pub fn decode(out: NetworkOutputs<'_>, params: DecodeParams<'_>, poses: &[AgentPose], modes: usize) -> Result<Decoded> {
    decode_on(out, params, poses, modes, 1)
}

/// Agents below which [`decode_on`] stays on the calling thread: a scoped thread costs about as much as decoding a
/// few dozen agents of 60 modes.
pub const PARALLEL_DECODE_FROM: usize = 128;

/// [`decode`] with the agents shared out over up to `threads` threads (scoped, ending with the call) when there are
/// at least [`PARALLEL_DECODE_FROM`]; each agent's result is the same on any number of threads.
pub fn decode_on(
    out: NetworkOutputs<'_>,
    params: DecodeParams<'_>,
    poses: &[AgentPose],
    modes: usize,
    threads: usize,
) -> Result<Decoded> {
    let (n, c, k_total, t_f) =
        (poses.len(), params.anchors.classes().len(), params.anchors.total(), params.anchors.steps());
    check_outputs(&out, &params, n)?;
    let m = modes.clamp(1, k_total);
    let mut decoded = Decoded::zeros(n, m, t_f, c);
    let lanes = if n >= PARALLEL_DECODE_FROM { threads.clamp(1, n) } else { 1 };
    let rows = n.div_ceil(lanes).max(1);
    let d = &mut decoded;
    let parts: Vec<(usize, DecodedMut<'_>)> = d
        .trajectories
        .axis_chunks_iter_mut(Axis(0), rows)
        .zip(d.probabilities.axis_chunks_iter_mut(Axis(0), rows))
        .zip(d.class_probabilities.axis_chunks_iter_mut(Axis(0), rows))
        .zip(d.mode_classes.axis_chunks_iter_mut(Axis(0), rows))
        .zip(d.mode_anchors.axis_chunks_iter_mut(Axis(0), rows))
        .enumerate()
        .map(|(part, ((((trajectories, probabilities), class_probabilities), mode_classes), mode_anchors))| {
            (part * rows, DecodedMut { trajectories, probabilities, class_probabilities, mode_classes, mode_anchors })
        })
        .collect();
    let anchor_flat = params.anchors.flat();
    let work =
        |(first, mut part): (usize, DecodedMut<'_>)| decode_rows(&out, &params, &anchor_flat, poses, first, &mut part);
    let panicked = || Err(DganError::Inference("a decoding thread panicked".into()));
    on_threads(parts, work, panicked).into_iter().collect::<Result<()>>()?;
    Ok(decoded)
}

/// The shapes of the outputs and the prior against N agents and the anchors; the calibration and time step.
fn check_outputs(out: &NetworkOutputs<'_>, params: &DecodeParams<'_>, n: usize) -> Result<()> {
    let NetworkOutputs { class_logits, anchor_logits, offsets } = out;
    let DecodeParams { anchors, prior, calibration, dt_s, top_scale, still, top_mean } = params;
    let (c, k_total, t_f) = (anchors.classes().len(), anchors.total(), anchors.steps());
    check_top_scale(top_scale, c)?;
    check_top_mean(top_mean, c)?;
    let bad = |m: String| Err(DganError::Inference(m));
    if !still.is_empty() && still.len() != n {
        return bad(format!("still has {} agents, expected {n}", still.len()));
    }
    if class_logits.dim() != (n, c) {
        return bad(format!("class_logits has shape {:?}, expected ({n}, {c})", class_logits.dim()));
    }
    if anchor_logits.dim() != (n, k_total) {
        return bad(format!("anchor_logits has shape {:?}, expected ({n}, {k_total})", anchor_logits.dim()));
    }
    if offsets.dim() != (n, k_total, t_f, 2) {
        return bad(format!("offsets has shape {:?}, expected ({n}, {k_total}, {t_f}, 2)", offsets.dim()));
    }
    if let Some(p) = prior {
        if p.dim() != (n, t_f, 2) {
            return bad(format!("the prior has shape {:?}, expected ({n}, {t_f}, 2)", p.dim()));
        }
    }
    calibration.check()?;
    if !(dt_s.is_finite() && *dt_s > 0.0) {
        return Err(DganError::Contract(format!("dt_s must be positive, got {dt_s}")));
    }
    Ok(())
}

/// Rows `first..` of [`Decoded`], as mutable views: one thread's share of [`decode_on`].
struct DecodedMut<'a> {
    trajectories: ArrayViewMut4<'a, f64>,
    probabilities: ArrayViewMut2<'a, f64>,
    class_probabilities: ArrayViewMut2<'a, f64>,
    mode_classes: ArrayViewMut2<'a, i64>,
    mode_anchors: ArrayViewMut2<'a, i64>,
}

/// Decodes agents `first..first + part's rows` (checked shapes) into `part`: the outputs, prior and anchors read as
/// contiguous rows (copied once into that layout if they are not), each agent's rows written in place.
fn decode_rows(
    out: &NetworkOutputs<'_>,
    params: &DecodeParams<'_>,
    anchor_flat: &[f64],
    poses: &[AgentPose],
    first: usize,
    part: &mut DecodedMut<'_>,
) -> Result<()> {
    let DecodeParams { anchors, prior, calibration, dt_s, top_scale, still, top_mean } = *params;
    let (rows, m, t_f, _) = part.trajectories.dim();
    let agents = first..first + rows;
    // Each output's rows of this share, contiguous (copied once into that layout if they are not).
    let class_logits = out.class_logits.slice(s![agents.clone(), ..]);
    let class_logits = class_logits.as_standard_layout();
    let anchor_logits = out.anchor_logits.slice(s![agents.clone(), ..]);
    let anchor_logits = anchor_logits.as_standard_layout();
    let offsets = out.offsets.slice(s![agents.clone(), .., .., ..]);
    let offsets = offsets.as_standard_layout();
    fn contiguous(v: Option<&[f32]>) -> Result<&[f32]> {
        v.ok_or_else(|| DganError::Inference("outputs are not contiguous".into()))
    }
    let offsets = contiguous(offsets.as_slice())?;
    // Over the slices, without an early exit, so that the check vectorises (as ndarray's chained iterators over the
    // views did not: a fifth of decoding's time).
    let finite = |v: &[f32]| !v.iter().fold(false, |bad, x| bad | !x.is_finite());
    if ![contiguous(class_logits.as_slice())?, contiguous(anchor_logits.as_slice())?, offsets].into_iter().all(finite) {
        return Err(DganError::Inference("the model produced NaN or infinite values".into()));
    }
    let k_total = anchors.total();
    let per_class = anchors.per_class();
    let class_of = anchors.class_of_anchor();
    let step = t_f * 2;
    // This share's prior rows, contiguous; zeros without a prior.
    let prior_rows = match prior {
        Some(p) => p.slice_move(s![agents.clone(), .., ..]).iter().copied().collect(),
        None => vec![0f32; rows * step],
    };
    let mut p = Vec::with_capacity(k_total);
    let mut order: Vec<(u64, usize)> = Vec::with_capacity(k_total);
    let (mut pc, mut scratch, mut mean) = (Vec::new(), Vec::new(), vec![0f64; step]);
    for (r, pose) in poses[agents].iter().enumerate() {
        softmax_into(class_logits.row(r).iter().map(|&v| f64::from(v) / calibration.class_temperature), &mut pc);
        let base = &prior_rows[r * step..(r + 1) * step];
        // The prior's first step is its velocity times dt (a constant-velocity rollout; 0 without a prior).
        let speed = f64::from(base[0]).hypot(f64::from(base[1])) / dt_s;
        let temperature = calibration.anchor_temperature(speed);
        p.clear();
        let mut start = 0;
        for (ci, &kc) in per_class.iter().enumerate() {
            softmax_into((start..start + kc).map(|k| f64::from(anchor_logits[[r, k]]) / temperature), &mut scratch);
            p.extend(scratch.iter().map(|v| v * pc[ci]));
            start += kc;
        }
        order.clear();
        // Most probable first, equal probabilities in anchor order (as a stable sort by probability keeps them):
        // the probabilities are finite and not negative, so their bits order as they do, and the complemented bits
        // with the anchor sort as plain integers, without an indirection.
        order.extend(p.iter().map(|v| !v.to_bits()).zip(0..k_total));
        // The keys are distinct (the anchor is part of them), so the m first of a partial selection, sorted, are the
        // m first of the whole sort.
        if m < k_total {
            order.select_nth_unstable(m - 1);
        }
        order[..m].sort_unstable();
        part.class_probabilities.row_mut(r).iter_mut().zip(&pc).for_each(|(o, v)| *o = *v);
        // The agent's most probable class (the largest class logit), which contracts 14 and 16 read.
        let top_class = if top_scale.is_empty() && top_mean.is_empty() {
            0
        } else {
            first_argmax(class_logits.row(r).iter().copied())
        };
        // Contract 14: the anchor whose residual is scaled (none without a scale), and by how much.
        let (scaled, scale) = if top_scale.is_empty() {
            (usize::MAX, 1.0)
        } else {
            let start: usize = per_class[..top_class].iter().sum();
            let block = (start..start + per_class[top_class]).map(|k| anchor_logits[[r, k]]);
            (start + first_argmax(block), top_scale[top_class])
        };
        // Contract 15: a still agent's most probable mode (the first in order) is its prior alone.
        let held = still.get(first + r).copied().unwrap_or(false);
        let off_agent = &offsets[r * k_total * step..(r + 1) * k_total * step];
        // Contract 16: the most probable mode's residual over the prior as the p^β-weighted mean of every mode's.
        let beta = if held || top_mean.is_empty() { 0.0 } else { top_mean[top_class] };
        if beta > 0.0 {
            mean_residual(&p, beta, (scaled, scale), anchor_flat, off_agent, &mut mean);
        }
        let mut traj = part.trajectories.slice_mut(s![r, .., .., ..]);
        let traj = traj.as_slice_mut().ok_or_else(|| DganError::Inference("trajectories are not contiguous".into()))?;
        for (mi, &(key, k)) in order.iter().take(m).enumerate() {
            part.probabilities[[r, mi]] = f64::from_bits(!key);
            part.mode_classes[[r, mi]] = class_of[k] as i64;
            part.mode_anchors[[r, mi]] = k as i64;
            let (anchor, off) = (&anchor_flat[k * step..(k + 1) * step], &off_agent[k * step..(k + 1) * step]);
            let s = if held && mi == 0 {
                0.0
            } else if k == scaled {
                scale
            } else {
                1.0
            };
            let averaged = beta > 0.0 && mi == 0;
            for (t, w_out) in traj[mi * step..(mi + 1) * step].chunks_exact_mut(2).enumerate() {
                let local = if averaged {
                    [f64::from(base[2 * t]) + mean[2 * t], f64::from(base[2 * t + 1]) + mean[2 * t + 1]]
                } else {
                    [
                        f64::from(base[2 * t]) + s * (anchor[2 * t] + f64::from(off[2 * t])),
                        f64::from(base[2 * t + 1]) + s * (anchor[2 * t + 1] + f64::from(off[2 * t + 1])),
                    ]
                };
                let w = pose.to_world(local);
                w_out[0] = w[0];
                w_out[1] = w[1];
            }
        }
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;
    use ndarray::array;

    #[allow(clippy::too_many_arguments)]
    fn run(
        class_logits: &Array2<f32>,
        anchor_logits: &Array2<f32>,
        offsets: &Array4<f32>,
        anchors: &Anchors,
        prior: Option<&Array3<f32>>,
        temperature: f64,
        pose: AgentPose,
        modes: usize,
    ) -> Result<Decoded> {
        let out = NetworkOutputs {
            class_logits: class_logits.view(),
            anchor_logits: anchor_logits.view(),
            offsets: offsets.view(),
        };
        let params = DecodeParams::new(anchors, prior.map(|p| p.view()), Calibration::single(temperature), 0.5);
        decode(out, params, &[pose], modes)
    }

    #[test]
    fn prior_and_temperature() {
        let anchors = Anchors::new(vec![AgentClass::Pedestrian], vec![array![[[1.0, 0.0]], [[2.0, 0.0]]]]).unwrap();
        let pose = AgentPose::new([0.0, 0.0], 0.0);
        let offsets = Array4::<f32>::zeros((1, 2, 1, 2));
        let logits = array![[0.0f32, 2.0f32.ln()]];
        let prior = array![[[0.5f32, -1.0]]];
        let d = run(&array![[0.0f32]], &logits, &offsets, &anchors, Some(&prior), 1.0, pose, 2).unwrap();
        // The prior is added to every mode.
        assert_eq!(d.trajectories[[0, 0, 0, 0]], 2.5);
        assert_eq!(d.trajectories[[0, 0, 0, 1]], -1.0);
        assert!((d.probabilities[[0, 0]] - 2.0 / 3.0).abs() < 1e-9);
        // T = 2 halves the logits: softmax(0, ln 2 / 2) = (1, √2) / (1 + √2).
        let d = run(&array![[0.0f32]], &logits, &offsets, &anchors, Some(&prior), 2.0, pose, 2).unwrap();
        let want = 2f64.sqrt() / (1.0 + 2f64.sqrt());
        assert!((d.probabilities[[0, 0]] - want).abs() < 1e-7, "{}", d.probabilities[[0, 0]]);
        let bad = array![[[0.5f32, -1.0], [0.0, 0.0]]];
        assert!(run(&array![[0.0f32]], &logits, &offsets, &anchors, Some(&bad), 1.0, pose, 2).is_err());
        assert!(run(&array![[0.0f32]], &logits, &offsets, &anchors, None, 0.0, pose, 2).is_err());
    }

    #[test]
    fn speed_dependent_and_class_temperatures() {
        let anchors = Anchors::new(
            vec![AgentClass::Vehicle, AgentClass::Pedestrian],
            vec![array![[[1.0, 0.0]], [[2.0, 0.0]]], array![[[0.0, 1.0]]]],
        )
        .unwrap();
        let offsets = Array4::<f32>::zeros((2, 3, 1, 2));
        let class_logits = array![[2f32.ln(), 0.0], [2f32.ln(), 0.0]];
        let anchor_logits = array![[0.0, 2f32.ln(), 0.0], [0.0, 2f32.ln(), 0.0]];
        // Agent 0 stands, agent 1's prior moves 1.5 m in its first 0.5 s step: 3 m/s.
        let prior = array![[[0.0f32, 0.0]], [[0.9, 1.2]]];
        let out = NetworkOutputs {
            class_logits: class_logits.view(),
            anchor_logits: anchor_logits.view(),
            offsets: offsets.view(),
        };
        let poses = [AgentPose::new([0.0, 0.0], 0.0); 2];
        let calibration = Calibration { temperature: 0.5, speed_exponent: 0.5, class_temperature: 2.0 };
        let params = DecodeParams::new(&anchors, Some(prior.view()), calibration, 0.5);
        let d = decode(out, params, &poses, 3).unwrap();
        // p(c) = softmax(ln 2 / 2, 0) = (√2, 1) / (1 + √2) for both agents.
        let pv = 2f64.sqrt() / (1.0 + 2f64.sqrt());
        for i in 0..2 {
            assert!((d.class_probabilities[[i, 0]] - pv).abs() < 1e-9);
        }
        // Standing: T = 0.5, p(k | vehicle) = softmax(0, 2 ln 2) = (1, 4) / 5.
        assert!((d.probabilities[[0, 0]] - pv * 0.8).abs() < 1e-6, "{}", d.probabilities[[0, 0]]);
        // 3 m/s: T = 0.5 · 4^0.5 = 1, p(k | vehicle) = (1, 2) / 3, second after the pedestrian anchor's 1 - pv.
        assert!((d.probabilities[[1, 0]] - (1.0 - pv)).abs() < 1e-6, "{}", d.probabilities[[1, 0]]);
        assert!((d.probabilities[[1, 1]] - pv * 2.0 / 3.0).abs() < 1e-6, "{}", d.probabilities[[1, 1]]);
        assert_eq!(Calibration::single(1.7).anchor_temperature(100.0), 1.7);
        let extreme = Calibration { temperature: 1.0, speed_exponent: 10.0, class_temperature: 1.0 };
        assert_eq!(extreme.anchor_temperature(1e30), Calibration::MAX_TEMPERATURE);
        for bad in [
            Calibration { class_temperature: 0.0, ..calibration },
            Calibration { speed_exponent: f64::NAN, ..calibration },
        ] {
            assert!(decode(out, DecodeParams { calibration: bad, ..params }, &poses, 3).is_err());
        }
        assert!(decode(out, DecodeParams { dt_s: 0.0, ..params }, &poses, 3).is_err());
    }

    /// Two classes of two one-step anchors each: vehicles (1, 0), (2, 0); pedestrians (0, 1), (0, 3).
    fn vehicle_and_pedestrian() -> Anchors {
        Anchors::new(
            vec![AgentClass::Vehicle, AgentClass::Pedestrian],
            vec![array![[[1.0, 0.0]], [[2.0, 0.0]]], array![[[0.0, 1.0]], [[0.0, 3.0]]]],
        )
        .unwrap()
    }

    /// Decoding at temperature 1 with a prior, no top-mode scale and no agent held.
    fn plain_params<'a>(anchors: &'a Anchors, prior: &'a Array3<f32>) -> DecodeParams<'a> {
        DecodeParams::new(anchors, Some(prior.view()), Calibration::single(1.0), 0.5)
    }

    #[test]
    fn top_scale_shrinks_the_most_probable_class_top_mode_alone() {
        let anchors = vehicle_and_pedestrian();
        // Agent 0's vehicle anchor 1 (its top mode) has the residual (3, 0).
        let mut offsets = Array4::<f32>::zeros((2, 4, 1, 2));
        offsets[[0, 1, 0, 0]] = 1.0;
        // Agent 0: vehicle first, its anchor 1 the larger; agent 1: pedestrian first, its two anchors equal (the
        // first, anchor 2, is the one scaled), and a vehicle anchor whose probability is the highest of all.
        let class_logits = array![[1.0f32, 0.0], [0.0, 0.5]];
        let anchor_logits = array![[0.0f32, 1.0, 0.0, 0.0], [0.0, 9.0, 0.0, 0.0]];
        let prior = array![[[10.0f32, 0.0]], [[0.0, 10.0]]];
        let out = NetworkOutputs {
            class_logits: class_logits.view(),
            anchor_logits: anchor_logits.view(),
            offsets: offsets.view(),
        };
        let poses = [AgentPose::new([0.0, 0.0], 0.0); 2];
        let scale = [0.5, 0.25];
        let base = plain_params(&anchors, &prior);
        let plain = decode(out, base, &poses, 4).unwrap();
        let scaled = decode(out, DecodeParams { top_scale: &scale, ..base }, &poses, 4).unwrap();
        assert_eq!(scaled.probabilities, plain.probabilities);
        assert_eq!(scaled.mode_anchors, plain.mode_anchors);
        let at = |d: &Decoded, i: usize, anchor: i64| {
            let m = d.mode_anchors.row(i).iter().position(|&a| a == anchor).unwrap();
            [d.trajectories[[i, m, 0, 0]], d.trajectories[[i, m, 0, 1]]]
        };
        assert_eq!(at(&plain, 0, 1), [13.0, 0.0]);
        assert_eq!(at(&scaled, 0, 1), [11.5, 0.0], "prior + 0.5 · (2 + 1, 0)");
        assert_eq!(at(&scaled, 1, 2), [0.0, 10.25], "prior + 0.25 · (0, 1): the first of equal logits");
        for (i, k) in [(0, 0), (0, 2), (0, 3), (1, 0), (1, 1), (1, 3)] {
            assert_eq!(at(&scaled, i, k), at(&plain, i, k), "agent {i} anchor {k} is not scaled");
        }
        for bad in [&[0.5][..], &[0.5, 1.5], &[f64::NAN, 1.0]] {
            assert!(decode(out, DecodeParams { top_scale: bad, ..base }, &poses, 4).is_err(), "{bad:?}");
        }
    }

    #[test]
    fn top_mean_makes_the_most_probable_mode_the_weighted_mean_of_every_mode() {
        let anchors = vehicle_and_pedestrian();
        let mut offsets = Array4::<f32>::zeros((3, 4, 1, 2));
        offsets[[0, 1, 0, 1]] = 0.5;
        // Agents 0 and 2 most probably vehicles, agent 1 a pedestrian (whose class has no power).
        let class_logits = array![[1.0f32, 0.0], [0.0, 2.0], [3.0, 0.0]];
        let anchor_logits = array![[0.0f32, 1.0, 0.5, 0.0], [0.0, 0.0, 2.0, 1.0], [2.0, 0.0, 0.0, 1.0]];
        let prior = array![[[1.0f32, 0.0]], [[0.0, 1.0]], [[0.5, 0.5]]];
        let out = NetworkOutputs {
            class_logits: class_logits.view(),
            anchor_logits: anchor_logits.view(),
            offsets: offsets.view(),
        };
        let poses = [AgentPose::new([1.0, 2.0], 0.5); 3];
        let beta = 2.0;
        for scale in [&[][..], &[0.5, 1.0]] {
            let base = DecodeParams { top_scale: scale, ..plain_params(&anchors, &prior) };
            let plain = decode(out, base, &poses, 4).unwrap();
            let mean = DecodeParams { top_mean: &[beta, 0.0], ..base };
            let averaged = decode(out, mean, &poses, 4).unwrap();
            assert_eq!(averaged.probabilities, plain.probabilities);
            assert_eq!(averaged.mode_anchors, plain.mode_anchors);
            assert_eq!(averaged.trajectories.slice(s![.., 1.., .., ..]), plain.trajectories.slice(s![.., 1.., .., ..]));
            assert_eq!(averaged.trajectories.slice(s![1, .., .., ..]), plain.trajectories.slice(s![1, .., .., ..]));
            for i in [0, 2] {
                // The weights sum to 1, so the mean of the modes in the world is the mean in the agent frame.
                let w = plain.probabilities.row(i).mapv(|p| p.powf(beta));
                let want = (0..4).fold([0.0, 0.0], |acc, k| {
                    let x = plain.trajectories[[i, k, 0, 0]];
                    [acc[0] + w[k] * x, acc[1] + w[k] * plain.trajectories[[i, k, 0, 1]]]
                });
                let got = [averaged.trajectories[[i, 0, 0, 0]], averaged.trajectories[[i, 0, 0, 1]]];
                for d in 0..2 {
                    assert!((got[d] - want[d] / w.sum()).abs() < 1e-12, "agent {i}: {got:?} against {want:?}");
                }
            }
            // The mean is over all K modes, however many are kept.
            let one = decode(out, mean, &poses, 1).unwrap();
            assert_eq!(one.trajectories.slice(s![.., 0, .., ..]), averaged.trajectories.slice(s![.., 0, .., ..]));
            // A still agent keeps its prior.
            let held = decode(out, DecodeParams { still: &[true, false, false], ..mean }, &poses, 4).unwrap();
            let prior_world = poses[0].to_world([1.0, 0.0]);
            assert_eq!([held.trajectories[[0, 0, 0, 0]], held.trajectories[[0, 0, 0, 1]]], prior_world);
        }
        for bad in [&[2.0][..], &[2.0, -1.0], &[f64::NAN, 0.0], &[65.0, 0.0]] {
            let params = DecodeParams { top_mean: bad, ..plain_params(&anchors, &prior) };
            assert!(decode(out, params, &poses, 4).is_err(), "{bad:?}");
        }
    }

    #[test]
    fn a_still_agent_keeps_its_most_probable_mode_at_the_prior_alone() {
        let anchors = vehicle_and_pedestrian();
        let offsets = Array4::<f32>::from_elem((2, 4, 1, 2), 0.5);
        let class_logits = array![[1.0f32, 0.0], [0.0, 1.0]];
        let anchor_logits = array![[0.0f32, 1.0, 0.0, 0.0], [0.0, 0.0, 2.0, 0.0]];
        let prior = array![[[0.25f32, 0.0]], [[0.0, 0.5]]];
        let out = NetworkOutputs {
            class_logits: class_logits.view(),
            anchor_logits: anchor_logits.view(),
            offsets: offsets.view(),
        };
        let poses = [AgentPose::new([1.0, 2.0], 0.0); 2];
        let base = DecodeParams { top_scale: &[0.5, 0.5], ..plain_params(&anchors, &prior) };
        let plain = decode(out, base, &poses, 4).unwrap();
        let held = decode(out, DecodeParams { still: &[false, true], ..base }, &poses, 4).unwrap();
        assert_eq!(held.probabilities, plain.probabilities);
        assert_eq!(held.mode_anchors, plain.mode_anchors);
        assert_eq!(held.trajectories.slice(s![0, .., .., ..]), plain.trajectories.slice(s![0, .., .., ..]));
        assert_eq!(plain.mode_anchors[[1, 0]], 2, "agent 1's most probable mode: pedestrian anchor 0");
        assert_eq!([held.trajectories[[1, 0, 0, 0]], held.trajectories[[1, 0, 0, 1]]], [1.0, 2.5], "origin + prior");
        assert_eq!(held.trajectories.slice(s![1, 1.., .., ..]), plain.trajectories.slice(s![1, 1.., .., ..]));
        assert!(decode(out, DecodeParams { still: &[true], ..base }, &poses, 4).is_err(), "one flag for two agents");
    }

    #[test]
    fn still_agents_are_those_whose_every_step_is_observed_and_within_their_class_radius() {
        // Agents 0-1 vehicles, 2-4 pedestrians, 5 without a class: radius 0 (never held) for vehicles, 0.1 m for
        // pedestrians.
        let mut trajectory = Array3::<f32>::zeros((6, 3, 2));
        let mut mask = Array2::<f32>::ones((6, 3));
        let mut state = Array2::<f32>::zeros((6, 9));
        for i in 0..5 {
            state[[i, if i < 2 { 7 } else { 8 }]] = 1.0;
        }
        trajectory[[3, 0, 1]] = 0.1; // at the radius: not within it
        mask[[4, 0]] = 0.0; // a step not observed
        let still = still_agents(trajectory.view(), mask.view(), state.view(), &[0.0, 0.1]).unwrap();
        assert_eq!(still, [false, false, true, false, false, false]);
        assert!(still_agents(trajectory.view(), mask.view(), state.view(), &[]).unwrap().is_empty());
        let err = still_agents(trajectory.view(), mask.view(), state.view(), &[0.1]).unwrap_err();
        assert!(err.to_string().contains("state (N, 8)"), "{err}");
        for bad in [f64::NAN, -0.1, f64::INFINITY] {
            let err = still_agents(trajectory.view(), mask.view(), state.view(), &[0.0, bad]).unwrap_err();
            assert!(err.to_string().contains("finite and not negative"), "{err}");
        }
    }

    #[test]
    fn threads_give_the_single_threaded_result_and_refuse_nan_in_any_share() {
        let anchors = Anchors::new(
            vec![AgentClass::Vehicle, AgentClass::Pedestrian],
            vec![array![[[1.0, 0.0], [2.0, 0.5]], [[2.0, 0.0], [4.0, -1.0]]], array![[[0.0, 1.0], [0.0, 2.0]]]],
        )
        .unwrap();
        let n = PARALLEL_DECODE_FROM + 37;
        let wave = |i: usize, k: usize| ((i * 7 + k * 3) as f32 * 0.37).sin();
        let class_logits = Array2::from_shape_fn((n, 2), |(i, c)| wave(i, c));
        let anchor_logits = Array2::from_shape_fn((n, 3), |(i, k)| 2.0 * wave(i, k + 5));
        let mut offsets = Array4::from_shape_fn((n, 3, 2, 2), |(i, k, t, d)| wave(i + t, k + d) * 0.3);
        let prior = Array3::from_shape_fn((n, 2, 2), |(i, t, d)| (t + 1) as f32 * wave(i, d + 9));
        let poses: Vec<AgentPose> = (0..n).map(|i| AgentPose::new([i as f64, -(i as f64)], i as f64 * 0.1)).collect();
        let calibration = Calibration { temperature: 0.8, speed_exponent: 0.3, class_temperature: 1.5 };
        let params = DecodeParams::new(&anchors, Some(prior.view()), calibration, 0.5);
        let out = NetworkOutputs {
            class_logits: class_logits.view(),
            anchor_logits: anchor_logits.view(),
            offsets: offsets.view(),
        };
        let one = decode_on(out, params, &poses, 2, 1).unwrap();
        for threads in [2, 3, 8] {
            let many = decode_on(out, params, &poses, 2, threads).unwrap();
            assert_eq!(many.trajectories, one.trajectories, "{threads} threads");
            assert_eq!(many.probabilities, one.probabilities);
            assert_eq!(many.class_probabilities, one.class_probabilities);
            assert_eq!(many.mode_classes, one.mode_classes);
            assert_eq!(many.mode_anchors, one.mode_anchors);
        }
        assert!(decode_on(out, params, &poses[..3], 2, 8).is_err(), "outputs of {n} agents for 3 poses");
        // A NaN in the last share's rows refuses the whole call.
        offsets[[n - 1, 2, 1, 0]] = f32::NAN;
        let out = NetworkOutputs {
            class_logits: class_logits.view(),
            anchor_logits: anchor_logits.view(),
            offsets: offsets.view(),
        };
        assert!(matches!(decode_on(out, params, &poses, 2, 4), Err(DganError::Inference(_))));
    }

    #[test]
    fn parts_gather_into_their_rows() {
        let part = |v: f64, n: usize| {
            let mut d = Decoded::zeros(n, 2, 3, 4);
            d.trajectories.fill(v);
            d.probabilities.fill(v);
            d.mode_anchors.fill(v as i64);
            d
        };
        let (a, b) = ([0usize, 2], [1usize]);
        let out = Decoded::gather(3, &[(&a[..], part(1.0, 2)), (&b[..], part(2.0, 1))]).unwrap();
        assert_eq!(out.trajectories.dim(), (3, 2, 3, 2));
        assert_eq!(out.probabilities.column(0).to_vec(), vec![1.0, 2.0, 1.0]);
        assert_eq!(out.mode_anchors.column(1).to_vec(), vec![1, 2, 1]);
        assert_eq!(out.class_probabilities.dim(), (3, 4));
        assert!(Decoded::gather(3, &[]).is_err());
        assert!(Decoded::gather(3, &[(&a[..], part(1.0, 1))]).is_err(), "rows and part disagree");
        assert!(Decoded::gather(1, &[(&a[..], part(1.0, 2))]).is_err(), "a row beyond the agents");
    }

    #[test]
    fn hand_computed_case() {
        // Two classes: vehicle with 2 anchors, pedestrian with 1; T_f = 1.
        let anchors = Anchors::new(
            vec![AgentClass::Vehicle, AgentClass::Pedestrian],
            vec![array![[[1.0, 0.0]], [[2.0, 0.0]]], array![[[0.0, 1.0]]]],
        )
        .unwrap();
        // p(c) = softmax(ln 3, 0) = (0.75, 0.25); p(k | vehicle) = softmax(0, ln 2) = (1/3, 2/3).
        let class_logits = array![[3f32.ln(), 0.0]];
        let anchor_logits = array![[0.0, 2f32.ln(), 5.0]];
        let mut offsets = Array4::<f32>::zeros((1, 3, 1, 2));
        offsets[[0, 1, 0, 1]] = 0.5;
        // Agent at (10, 20) facing +y: local (x, y) → world (10 - y, 20 + x).
        let pose = AgentPose::new([10.0, 20.0], std::f64::consts::FRAC_PI_2);
        let d = run(&class_logits, &anchor_logits, &offsets, &anchors, None, 1.0, pose, 3).unwrap();
        let expect_p = [0.5, 0.25, 0.25];
        for (got, want) in d.probabilities.iter().zip(expect_p) {
            assert!((got - want).abs() < 1e-6, "{got} vs {want}");
        }
        // Mode 0 = vehicle anchor 1 (2, 0) + (0, 0.5) → local (2, 0.5) → world (9.5, 22).
        assert!((d.trajectories[[0, 0, 0, 0]] - 9.5).abs() < 1e-6);
        assert!((d.trajectories[[0, 0, 0, 1]] - 22.0).abs() < 1e-6);
        // Ties keep anchor order: vehicle anchor 0 (local (1, 0) → world (10, 21)), then the pedestrian anchor.
        assert_eq!(d.mode_anchors.row(0).to_vec(), vec![1, 0, 2]);
        assert_eq!(d.mode_classes.row(0).to_vec(), vec![0, 0, 1]);
        assert!((d.trajectories[[0, 1, 0, 1]] - 21.0).abs() < 1e-6);
        assert!((d.trajectories[[0, 2, 0, 0]] - 9.0).abs() < 1e-6);
        assert!((d.class_probabilities[[0, 0]] - 0.75).abs() < 1e-6);
    }

    #[test]
    fn any_number_of_modes_is_the_prefix_of_all_ranked_with_ties_in_anchor_order() {
        // Three classes of 4, 3 and 5 anchors; logits of a few levels, so that many modes tie.
        let sets = [4, 3, 5].map(|k| Array3::from_shape_fn((k, 2, 2), |(a, t, d)| (a + t + d) as f64 * 0.3));
        let anchors = Anchors::new(AgentClass::ALL.to_vec(), sets.to_vec()).unwrap();
        let (n, k) = (5, anchors.total());
        let class_logits = Array2::from_shape_fn((n, 3), |(i, c)| ((i + c) % 2) as f32);
        let anchor_logits = Array2::from_shape_fn((n, k), |(i, a)| ((i * 7 + a * 3) % 3) as f32 * 0.5);
        let offsets = Array4::from_shape_fn((n, k, 2, 2), |(i, a, t, d)| (i + 2 * a + t + d) as f32 * 0.01);
        let poses: Vec<AgentPose> = (0..n).map(|i| AgentPose::new([i as f64, 1.0], 0.3 * i as f64)).collect();
        let out = NetworkOutputs {
            class_logits: class_logits.view(),
            anchor_logits: anchor_logits.view(),
            offsets: offsets.view(),
        };
        let params = DecodeParams::new(&anchors, None, Calibration::single(1.0), 0.4);
        let all = decode(out, params, &poses, k).unwrap();
        for i in 0..n {
            let (p, a) = (all.probabilities.row(i), all.mode_anchors.row(i));
            for m in 1..k {
                assert!(p[m - 1] > p[m] || (p[m - 1] == p[m] && a[m - 1] < a[m]), "agent {i}, modes {m}: {p} {a}");
            }
        }
        for m in 1..=k {
            let some = decode(out, params, &poses, m).unwrap();
            assert_eq!(some.probabilities, all.probabilities.slice(s![.., ..m]));
            assert_eq!(some.mode_anchors, all.mode_anchors.slice(s![.., ..m]));
            assert_eq!(some.trajectories, all.trajectories.slice(s![.., ..m, .., ..]));
        }
        let mut bad = offsets.clone();
        bad[[3, 7, 1, 0]] = f32::INFINITY;
        let out = NetworkOutputs { offsets: bad.view(), ..out };
        assert!(matches!(decode(out, params, &poses, k), Err(DganError::Inference(_))));
    }

    #[test]
    fn top_m_and_bad_outputs() {
        let anchors = Anchors::new(vec![AgentClass::Pedestrian], vec![array![[[1.0, 0.0]], [[2.0, 0.0]]]]).unwrap();
        let pose = AgentPose::new([0.0, 0.0], 0.0);
        let offsets = Array4::<f32>::zeros((1, 2, 1, 2));
        let d = run(&array![[0.0f32]], &array![[0.0f32, 1.0]], &offsets, &anchors, None, 1.0, pose, 1).unwrap();
        assert_eq!(d.trajectories.dim(), (1, 1, 1, 2));
        assert_eq!(d.trajectories[[0, 0, 0, 0]], 2.0);
        let nan = run(&array![[f32::NAN]], &array![[0.0f32, 1.0]], &offsets, &anchors, None, 1.0, pose, 1);
        assert!(matches!(nan, Err(DganError::Inference(_))));
        let shape = run(&array![[0.0f32]], &array![[0.0f32]], &offsets, &anchors, None, 1.0, pose, 1);
        assert!(matches!(shape, Err(DganError::Inference(_))));
    }
}
