//! Anchor decoding: hierarchical probabilities p(mode) = p(c) · p(k | c) with p(k | c) = softmax(anchor logits / T)
//! and p(c) = softmax(class logits / T_c), trajectories = kinematic prior + anchor + offset taken back to the world
//! frame, modes ranked by probability. T may grow with the agent's speed ([`Calibration`]).

use crate::class::AgentClass;
use crate::error::{DganError, Result};
use crate::transform::AgentPose;
use ndarray::{s, Array2, Array3, Array4, ArrayView2, ArrayView3, ArrayView4};

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

    fn anchor(&self, k: usize) -> Option<ndarray::ArrayView2<'_, f64>> {
        let mut k = k;
        for s in &self.sets {
            if k < s.dim().0 {
                return Some(s.index_axis(ndarray::Axis(0), k));
            }
            k -= s.dim().0;
        }
        None
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

fn softmax(logits: impl Iterator<Item = f64>) -> Vec<f64> {
    let v: Vec<f64> = logits.collect();
    let max = v.iter().copied().fold(f64::NEG_INFINITY, f64::max);
    let e: Vec<f64> = v.iter().map(|x| (x - max).exp()).collect();
    let sum: f64 = e.iter().sum();
    e.into_iter().map(|x| x / sum).collect()
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
}

/// Decodes the network's outputs for agents whose agent-centric frames are `poses`, keeping the top `modes`
/// (at most K).
pub fn decode(out: NetworkOutputs<'_>, params: DecodeParams<'_>, poses: &[AgentPose], modes: usize) -> Result<Decoded> {
    let NetworkOutputs { class_logits, anchor_logits, offsets } = out;
    let DecodeParams { anchors, prior, calibration, dt_s } = params;
    let n = poses.len();
    let c = anchors.classes().len();
    let k_total = anchors.total();
    let t_f = anchors.steps();
    let bad = |m: String| Err(DganError::Inference(m));
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
    if !(dt_s.is_finite() && dt_s > 0.0) {
        return Err(DganError::Contract(format!("dt_s must be positive, got {dt_s}")));
    }
    if class_logits.iter().chain(anchor_logits.iter()).chain(offsets.iter()).any(|v| !v.is_finite()) {
        return bad("the model produced NaN or infinite values".into());
    }
    let m = modes.clamp(1, k_total);
    let per_class = anchors.per_class();
    let class_of = anchors.class_of_anchor();
    let mut out = Decoded::zeros(n, m, t_f, c);
    for (i, pose) in poses.iter().enumerate() {
        let pc = softmax(class_logits.row(i).iter().map(|&v| f64::from(v) / calibration.class_temperature));
        // The prior's first step is its velocity times dt (a constant-velocity rollout; 0 without a prior).
        let speed = prior.map_or(0.0, |p| f64::from(p[[i, 0, 0]]).hypot(f64::from(p[[i, 0, 1]])) / dt_s);
        let temperature = calibration.anchor_temperature(speed);
        let mut p = Vec::with_capacity(k_total);
        let mut start = 0;
        for (ci, &kc) in per_class.iter().enumerate() {
            let pk = softmax((start..start + kc).map(|k| f64::from(anchor_logits[[i, k]]) / temperature));
            p.extend(pk.into_iter().map(|v| v * pc[ci]));
            start += kc;
        }
        let mut order: Vec<usize> = (0..k_total).collect();
        // Stable: equal probabilities keep anchor order.
        order.sort_by(|&a, &b| p[b].total_cmp(&p[a]));
        for (ci, v) in pc.iter().enumerate() {
            out.class_probabilities[[i, ci]] = *v;
        }
        for (mi, &k) in order.iter().take(m).enumerate() {
            out.probabilities[[i, mi]] = p[k];
            out.mode_classes[[i, mi]] = class_of[k] as i64;
            out.mode_anchors[[i, mi]] = k as i64;
            let Some(anchor) = anchors.anchor(k) else { continue };
            for t in 0..t_f {
                let base = prior.map_or([0.0, 0.0], |p| [f64::from(p[[i, t, 0]]), f64::from(p[[i, t, 1]])]);
                let local = [
                    base[0] + anchor[[t, 0]] + f64::from(offsets[[i, k, t, 0]]),
                    base[1] + anchor[[t, 1]] + f64::from(offsets[[i, k, t, 1]]),
                ];
                let w = pose.to_world(local);
                out.trajectories[[i, mi, t, 0]] = w[0];
                out.trajectories[[i, mi, t, 1]] = w[1];
            }
        }
    }
    Ok(out)
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
        let params = DecodeParams {
            anchors,
            prior: prior.map(|p| p.view()),
            calibration: Calibration::single(temperature),
            dt_s: 0.5,
        };
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
        let params = DecodeParams { anchors: &anchors, prior: Some(prior.view()), calibration, dt_s: 0.5 };
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
