//! The kinematic prior: a physical rollout of each agent's motion that the network refines.
//!
//! A model whose contract declares a prior predicts its anchors and offsets *relative to this rollout*: mode k's
//! agent-frame trajectory is `prior + anchor_k + offset_k`, so a network with nothing to add falls back to physics
//! rather than to a k-means anchor. The rollout is computed here from the network's own input tensors
//! (`trajectory`, `trajectory_mask`, `state`), once, and training calls this same function through the bindings.

use crate::class::AgentClass;
use crate::error::{DganError, Result};
use ndarray::{Array3, ArrayView2, ArrayView3};
use serde::{Deserialize, Serialize};

/// Which physical rollout the network's outputs are relative to.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum PriorKind {
    /// No prior: anchors and offsets are absolute agent-frame positions (every contract-1 model).
    #[default]
    None,
    /// Constant velocity along the direction of motion.
    ConstantVelocity,
}

impl PriorKind {
    /// The name used in the metadata.
    pub fn name(self) -> &'static str {
        match self {
            Self::None => "none",
            Self::ConstantVelocity => "constant_velocity",
        }
    }
}

/// How the velocity of a windowed prior is estimated from the observed positions in its window.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum VelocityFit {
    /// The displacement between the window's first and last valid positions over their time apart (contracts 2-5).
    #[default]
    Endpoints,
    /// The slope of a least-squares line through every valid position of the window against its time: robust to
    /// position noise, jittered and dropped steps, since every observation counts and the gaps are timed.
    LeastSquares,
    /// The derivative at the last valid step of a least-squares parabola through the window's valid positions (a
    /// Savitzky-Golay-style fit): averages noise like `LeastSquares` without its lag behind an accelerating agent.
    /// Needs three valid steps; with two it is the least-squares line.
    Quadratic,
    /// The least-squares line through the most recent valid positions of the window whose expected error at the
    /// last step is smallest (contract 8): the track's position noise σ² (the residuals of the window's
    /// least-squares parabola) against the lag of a longer line behind the parabola's acceleration. A clean track
    /// gets the last two steps, a noisy one the whole window. Needs four valid steps; with fewer, the last two.
    Adaptive,
}

impl VelocityFit {
    /// The name used in the metadata.
    pub fn name(self) -> &'static str {
        match self {
            Self::Endpoints => "endpoints",
            Self::LeastSquares => "least_squares",
            Self::Quadratic => "quadratic",
            Self::Adaptive => "adaptive",
        }
    }
}

/// The prior a model declares: its kind and, for constant velocity, how the velocity is estimated.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize, Default)]
pub struct PriorSpec {
    /// The rollout.
    #[serde(default)]
    pub kind: PriorKind,
    /// 0: the traffic state's velocity (given, else the last two valid steps). > 0: a velocity estimated from the
    /// last `window_s` seconds of the observed positions (`max(1, round(window_s / dt))` steps), which is less noisy.
    #[serde(default)]
    pub window_s: f64,
    /// How a windowed velocity is estimated (`window_s > 0`): endpoints (the default) or a least-squares line.
    #[serde(default)]
    pub fit: VelocityFit,
    /// An agent whose speed is below this many metres per second is standing: its prior stays at its last position.
    /// The speed is that of the least-squares line over the window (`window_s > 0`, whatever `fit` gives the
    /// velocity), else the estimated velocity's. 0 (the default) never clamps.
    #[serde(default)]
    pub standing_mps: f64,
    /// Per-class velocity estimates (contract 8) in place of `window_s`, `fit` and `standing_mps` for the agents
    /// of those classes; every other class keeps the model-wide ones.
    #[serde(default, skip_serializing_if = "ByClass::is_empty")]
    pub by_class: ByClass,
}

/// One class's velocity estimate: its window, fit and standing threshold, as in [`PriorSpec`].
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct ClassPrior {
    /// As [`PriorSpec::window_s`].
    #[serde(default)]
    pub window_s: f64,
    /// As [`PriorSpec::fit`].
    #[serde(default)]
    pub fit: VelocityFit,
    /// As [`PriorSpec::standing_mps`].
    #[serde(default)]
    pub standing_mps: f64,
}

/// The classes whose agents take their own velocity estimate (none by default); in the metadata an object keyed by
/// class name, e.g. `{"pedestrian": {"window_s": 2.0, "fit": "least_squares", "standing_mps": 0.3}}`.
#[derive(Debug, Clone, Copy, PartialEq, Default, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct ByClass {
    /// Vehicles' estimate.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub vehicle: Option<ClassPrior>,
    /// Cyclists' estimate.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub cyclist: Option<ClassPrior>,
    /// Pedestrians' estimate.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub pedestrian: Option<ClassPrior>,
}

impl ByClass {
    /// No class with its own estimate.
    pub const NONE: Self = Self { vehicle: None, cyclist: None, pedestrian: None };

    /// Whether no class has its own estimate.
    pub fn is_empty(&self) -> bool {
        *self == Self::NONE
    }

    /// The estimate of `class`, if it has its own.
    pub fn get(&self, class: AgentClass) -> Option<ClassPrior> {
        match class {
            AgentClass::Vehicle => self.vehicle,
            AgentClass::Cyclist => self.cyclist,
            AgentClass::Pedestrian => self.pedestrian,
        }
    }

    /// The classes with their own estimate, in canonical order.
    pub fn iter(&self) -> impl Iterator<Item = (AgentClass, ClassPrior)> + '_ {
        AgentClass::ALL.into_iter().filter_map(|c| self.get(c).map(|p| (c, p)))
    }
}

impl PriorSpec {
    /// No prior.
    pub const NONE: Self = Self {
        kind: PriorKind::None,
        window_s: 0.0,
        fit: VelocityFit::Endpoints,
        standing_mps: 0.0,
        by_class: ByClass::NONE,
    };

    /// Constant velocity with the given velocity window and the other settings at their defaults.
    pub fn constant_velocity(window_s: f64) -> Self {
        Self { kind: PriorKind::ConstantVelocity, window_s, ..Self::NONE }
    }

    /// The prior of an agent of `class`: its class's own estimate where it has one, else this one.
    pub fn for_class(&self, class: Option<AgentClass>) -> Self {
        match class.and_then(|c| self.by_class.get(c)) {
            Some(c) => Self {
                kind: self.kind,
                window_s: c.window_s,
                fit: c.fit,
                standing_mps: c.standing_mps,
                by_class: ByClass::NONE,
            },
            None => Self { by_class: ByClass::NONE, ..*self },
        }
    }

    /// Checks the velocity window and the standing threshold, the model-wide ones and each class's.
    pub fn validate(&self) -> Result<()> {
        Self::check_estimate("prior", self.window_s, self.fit, self.standing_mps)?;
        for (class, c) in self.by_class.iter() {
            Self::check_estimate(&format!("prior.by_class.{class}"), c.window_s, c.fit, c.standing_mps)?;
        }
        if self.kind == PriorKind::None
            && (self.window_s != 0.0 || self.standing_mps != 0.0 || !self.by_class.is_empty())
        {
            return Err(DganError::InvalidSpec(
                "prior.window_s, prior.standing_mps and prior.by_class need a prior (prior.kind \"constant_velocity\")"
                    .into(),
            ));
        }
        Ok(())
    }

    fn check_estimate(key: &str, window_s: f64, fit: VelocityFit, standing_mps: f64) -> Result<()> {
        if !(window_s.is_finite() && (0.0..=60.0).contains(&window_s)) {
            return Err(DganError::InvalidSpec(format!(
                "{key}.window_s must be between 0 and 60 seconds, got {window_s}"
            )));
        }
        if !(standing_mps.is_finite() && (0.0..=5.0).contains(&standing_mps)) {
            return Err(DganError::InvalidSpec(format!(
                "{key}.standing_mps must be between 0 and 5 metres per second, got {standing_mps}"
            )));
        }
        if fit != VelocityFit::Endpoints && window_s == 0.0 {
            return Err(DganError::InvalidSpec(format!(
                "{key}.fit {:?} needs a velocity window ({key}.window_s > 0)",
                fit.name()
            )));
        }
        Ok(())
    }

    /// The estimated velocity `[vx, vy]` (m/s, the trajectory's frame) of one agent from its observed positions
    /// `traj (T_obs, 2)` and validity `mask (T_obs)`; `None` where the window holds fewer than two valid steps.
    fn window_velocity(&self, traj: ArrayView2<'_, f32>, mask: &[bool], steps: usize, dt_s: f64) -> Option<[f64; 2]> {
        let last = (0..mask.len()).rev().find(|&t| mask[t])?;
        let from = last.saturating_sub(steps);
        let p = |t: usize, c: usize| f64::from(traj[[t, c]]);
        match self.fit {
            VelocityFit::Endpoints => {
                let first = (from..last).find(|&t| mask[t])?;
                let span = (last - first) as f64 * dt_s;
                Some([(p(last, 0) - p(first, 0)) / span, (p(last, 1) - p(first, 1)) / span])
            }
            VelocityFit::LeastSquares | VelocityFit::Quadratic | VelocityFit::Adaptive => {
                let valid: Vec<usize> = (from..=last).filter(|&t| mask[t]).collect();
                if valid.len() < 2 {
                    return None;
                }
                if self.fit == VelocityFit::Quadratic && valid.len() >= 3 {
                    return Some(quadratic_slope(&valid, last, p).map(|b| b / dt_s));
                }
                let used = match self.fit {
                    VelocityFit::Adaptive => &valid[valid.len() - adaptive_span(&valid, last, p)..],
                    _ => &valid[..],
                };
                let (slope, _, _) = line_fit(used, p);
                Some(slope.map(|b| b / dt_s))
            }
        }
    }

    /// The rollout of every agent, `(N, T_f, 2)` metres in each agent's frame, from the network inputs
    /// `trajectory (N, T_obs, 2)`, `trajectory_mask (N, T_obs)` and `state (N, S)` (columns as in
    /// `crate::spec::STATE_FEATURES`, then the one-hot class in the order of `classes`, the model's). Zero for
    /// [`PriorKind::None`].
    pub fn rollout(
        &self,
        trajectory: ArrayView3<'_, f32>,
        trajectory_mask: ArrayView2<'_, f32>,
        state: ArrayView2<'_, f32>,
        dt_s: f64,
        t_f: usize,
        classes: &[AgentClass],
    ) -> Result<Array3<f32>> {
        self.validate()?;
        let (n, t_obs, d) = trajectory.dim();
        if d != 2 || trajectory_mask.dim() != (n, t_obs) || state.nrows() != n || state.ncols() < 5 {
            return Err(DganError::InvalidSpec(format!(
                "prior inputs must be trajectory (N, T_obs, 2), trajectory_mask (N, T_obs) and state (N, >= 5); got \
                 {:?}, {:?} and {:?}",
                trajectory.dim(),
                trajectory_mask.dim(),
                state.dim()
            )));
        }
        if !(dt_s.is_finite() && dt_s > 0.0) {
            return Err(DganError::InvalidSpec(format!("dt_s must be positive, got {dt_s}")));
        }
        let mut out = Array3::<f32>::zeros((n, t_f, 2));
        if self.kind == PriorKind::None {
            return Ok(out);
        }
        // The one-hot class is the last `classes.len()` columns of the state, after its 5 kinematic and 2 size ones.
        if !self.by_class.is_empty() && state.ncols() < 7 + classes.len() {
            return Err(DganError::InvalidSpec(format!(
                "a prior with per-class estimates needs the one-hot class in state: {} columns, expected {}",
                state.ncols(),
                7 + classes.len()
            )));
        }
        // Each agent's class: the hot column of its one-hot (none if no column is set).
        let class_of = |i: usize| {
            if self.by_class.is_empty() {
                return None;
            }
            hot_class(state, i, classes.len()).map(|j| classes[j])
        };
        let mut mask = vec![false; t_obs];
        for i in 0..n {
            let own = self.for_class(class_of(i));
            let window = (own.window_s > 0.0).then(|| ((own.window_s / dt_s).round() as usize).max(1));
            let from_state = [
                f64::from(state[[i, 0]]) * f64::from(state[[i, 3]]),
                f64::from(state[[i, 0]]) * f64::from(state[[i, 4]]),
            ];
            for (t, m) in mask.iter_mut().enumerate() {
                *m = trajectory_mask[[i, t]] > 0.5;
            }
            let traj = trajectory.index_axis(ndarray::Axis(0), i);
            let mut v = window.and_then(|k| own.window_velocity(traj, &mask, k, dt_s)).unwrap_or(from_state);
            // Standing is judged on the least-squares line over the window, the estimate least moved by noise,
            // whichever fit gives the velocity.
            let speed = match (own.standing_mps > 0.0, window) {
                (false, _) => [f64::INFINITY, 0.0],
                (true, Some(k)) if own.fit != VelocityFit::LeastSquares => {
                    let line = Self { fit: VelocityFit::LeastSquares, ..own };
                    line.window_velocity(traj, &mask, k, dt_s).unwrap_or(v)
                }
                (true, _) => v, // the velocity is the line's already, or there is no window
            };
            if !(v[0].is_finite() && v[1].is_finite()) || speed[0].hypot(speed[1]) < own.standing_mps {
                v = [0.0, 0.0];
            }
            for t in 0..t_f {
                let s = (t + 1) as f64 * dt_s;
                out[[i, t, 0]] = (v[0] * s) as f32;
                out[[i, t, 1]] = (v[1] * s) as f32;
            }
        }
        Ok(out)
    }
}

/// The least-squares line through the positions `p(t, c)` at the steps `valid` (at least two distinct): its slope
/// per step (both coordinates), the mean step and Σ (t - mean)².
fn line_fit(valid: &[usize], p: impl Fn(usize, usize) -> f64) -> ([f64; 2], f64, f64) {
    let n = valid.len() as f64;
    let mean_t = valid.iter().map(|&t| t as f64).sum::<f64>() / n;
    let mean = |c: usize| valid.iter().map(|&t| p(t, c)).sum::<f64>() / n;
    let (mx, my) = (mean(0), mean(1));
    let (mut sxx, mut sx, mut sy) = (0.0, 0.0, 0.0);
    for &t in valid {
        let dt = t as f64 - mean_t;
        sxx += dt * dt;
        sx += dt * (p(t, 0) - mx);
        sy += dt * (p(t, 1) - my);
    }
    ([sx / sxx, sy / sxx], mean_t, sxx)
}

/// How many of the most recent `valid` steps (at least two) the adaptive line takes: the span whose expected
/// squared velocity error at `last`, the noise's 2σ² / Σ (t - mean)² plus the lag's |a|² (last - mean)², is least.
/// σ² and the acceleration a come from the least-squares parabola through every valid step (the acceleration's own
/// sampling variance taken off its square, so noise alone does not read as acceleration). Fewer than four valid
/// steps leave no residual to estimate σ² from: the last two.
fn adaptive_span(valid: &[usize], last: usize, p: impl Fn(usize, usize) -> f64) -> usize {
    let n = valid.len();
    if n < 4 {
        return 2;
    }
    let Some((coef, rss, inv_cc)) = quadratic_fit(valid, last, &p) else { return 2 };
    let sigma2 = rss / (2.0 * (n as f64 - 3.0)); // per coordinate
                                                 // p'' = 2c per step², E[ĉ²] = c² + σ² [(XᵀX)⁻¹]₂₂ per coordinate.
    let acc2 = (4.0 * (coef[0] * coef[0] + coef[1] * coef[1] - 2.0 * sigma2 * inv_cc)).max(0.0);
    let mut best = (f64::INFINITY, 2);
    for m in 2..=n {
        let (_, mean_t, sxx) = line_fit(&valid[n - m..], &p);
        let lag = last as f64 - mean_t;
        let cost = 2.0 * sigma2 / sxx + acc2 * lag * lag;
        if cost < best.0 {
            best = (cost, m);
        }
    }
    best.1
}

/// The least-squares parabola `a + b τ + c τ²`, τ = t - last, through the positions `p(t, c)` at the steps `valid`
/// (at least three distinct): `[a, b, c]` of both coordinates from the 3 × 3 normal equations, solved by Cramer's rule,
/// with the determinant of those equations and `[(XᵀX)⁻¹]₂₂`.
struct Parabola {
    coef: [[f64; 3]; 2],
    det: f64,
    inv_cc: f64,
}

fn parabola(valid: &[usize], last: usize, p: impl Fn(usize, usize) -> f64) -> Parabola {
    let tau = |t: usize| t as f64 - last as f64;
    let s = |k: i32| valid.iter().map(|&t| tau(t).powi(k)).sum::<f64>();
    let (s0, s1, s2, s3, s4) = (s(0), s(1), s(2), s(3), s(4));
    let normal = [[s0, s1, s2], [s1, s2, s3], [s2, s3, s4]];
    let det = det3(normal);
    let mut coef = [[0.0; 3]; 2];
    for (c, out) in coef.iter_mut().enumerate() {
        let r = |k: i32| valid.iter().map(|&t| tau(t).powi(k) * p(t, c)).sum::<f64>();
        let rhs = [r(0), r(1), r(2)];
        for (col, o) in out.iter_mut().enumerate() {
            let mut m = normal;
            for (row, v) in m.iter_mut().zip(rhs) {
                row[col] = v;
            }
            *o = det3(m) / det;
        }
    }
    Parabola { coef, det, inv_cc: (s0 * s2 - s1 * s1) / det }
}

/// [`parabola`], or `None` if its normal equations are singular.
fn solved_parabola(valid: &[usize], last: usize, p: impl Fn(usize, usize) -> f64) -> Option<Parabola> {
    let fit = parabola(valid, last, p);
    (fit.det.abs().partial_cmp(&1e-12) == Some(std::cmp::Ordering::Greater)).then_some(fit)
}

/// The parabola through `valid` ([`parabola`]): `c` of both coordinates, the residual sum of squares over both and
/// `[(XᵀX)⁻¹]₂₂` (`None` if the normal equations are singular).
fn quadratic_fit(valid: &[usize], last: usize, p: impl Fn(usize, usize) -> f64) -> Option<([f64; 2], f64, f64)> {
    let fit = solved_parabola(valid, last, &p)?;
    let tau = |t: usize| t as f64 - last as f64;
    let rss = (0..2)
        .map(|c| {
            let [a, b, cc] = fit.coef[c];
            valid.iter().map(|&t| (p(t, c) - a - b * tau(t) - cc * tau(t).powi(2)).powi(2)).sum::<f64>()
        })
        .sum::<f64>();
    Some(([fit.coef[0][2], fit.coef[1][2]], rss, fit.inv_cc))
}

/// The least-squares parabola through the positions `p(t, c)` at the steps `valid` (at least three distinct), as its
/// value at every one of them, and the root mean square of the distances to it; `None` if the normal equations are
/// singular.
pub(crate) fn parabola_points(valid: &[usize], p: impl Fn(usize, usize) -> f64) -> Option<(Vec<[f64; 2]>, f64)> {
    let last = *valid.last()?;
    let fit = solved_parabola(valid, last, &p)?;
    let at = |t: usize, c: usize| {
        let tau = t as f64 - last as f64;
        let [a, b, cc] = fit.coef[c];
        a + b * tau + cc * tau * tau
    };
    let points: Vec<[f64; 2]> = valid.iter().map(|&t| [at(t, 0), at(t, 1)]).collect();
    let rss: f64 = valid.iter().zip(&points).map(|(&t, q)| (p(t, 0) - q[0]).powi(2) + (p(t, 1) - q[1]).powi(2)).sum();
    Some((points, (rss / valid.len() as f64).sqrt()))
}

fn det3(m: [[f64; 3]; 3]) -> f64 {
    m[0][0] * (m[1][1] * m[2][2] - m[1][2] * m[2][1]) - m[0][1] * (m[1][0] * m[2][2] - m[1][2] * m[2][0])
        + m[0][2] * (m[1][0] * m[2][1] - m[1][1] * m[2][0])
}

/// The slope at `last` (per step, both coordinates) of the least-squares parabola through the positions at the steps
/// `valid` (at least three distinct): its `b` ([`parabola`]).
fn quadratic_slope(valid: &[usize], last: usize, p: impl Fn(usize, usize) -> f64) -> [f64; 2] {
    let fit = parabola(valid, last, p);
    [fit.coef[0][1], fit.coef[1][1]]
}

/// The class of agent `i` of a traffic state whose last `classes` columns are its one-hot class, as an index into
/// them: the first column above 0.5, None where none is.
pub(crate) fn hot_class(state: ArrayView2<'_, f32>, i: usize, classes: usize) -> Option<usize> {
    let one_hot = state.ncols() - classes.min(state.ncols());
    (0..classes.min(state.ncols())).find(|&j| state[[i, one_hot + j]] > 0.5)
}

#[cfg(test)]
mod tests {
    use super::*;
    use ndarray::{array, Array2};

    /// A one-class model's classes (the state's one-hot column is 1).
    const ONE: &[AgentClass] = &[AgentClass::Vehicle];

    fn state(speed: f32, cos: f32, sin: f32) -> Array2<f32> {
        array![[speed, 0.0, 0.0, cos, sin, 0.5, 0.5, 1.0]]
    }

    #[test]
    fn constant_velocity_from_the_state() {
        let traj = Array3::<f32>::zeros((1, 3, 2));
        let mask = Array2::<f32>::ones((1, 3));
        let p = PriorSpec::constant_velocity(0.0);
        let r = p.rollout(traj.view(), mask.view(), state(2.0, 0.6, 0.8).view(), 0.5, 3, ONE).unwrap();
        // 2 m/s along (0.6, 0.8): 1 m per 0.5 s step.
        let want = array![[0.6f32, 0.8], [1.2, 1.6], [1.8, 2.4]];
        assert!(r.index_axis(ndarray::Axis(0), 0).iter().zip(&want).all(|(a, b)| (a - b).abs() < 1e-6), "{r}");
        let none = PriorSpec::NONE.rollout(traj.view(), mask.view(), state(2.0, 1.0, 0.0).view(), 0.5, 3, ONE).unwrap();
        assert!(none.iter().all(|v| *v == 0.0));
    }

    #[test]
    fn windowed_velocity_uses_the_observed_positions() {
        // Agent frame: the last step is the origin; 3 m behind it one second (two 0.5 s steps) earlier, with the
        // middle step missing. The state says 10 m/s, which the window ignores.
        let traj = array![[[-9.0f32, 0.0], [-3.0, 0.0], [0.0, 0.0], [0.0, 0.0]]];
        let mask = array![[1.0f32, 1.0, 0.0, 1.0]];
        let p = PriorSpec::constant_velocity(1.0);
        let r = p.rollout(traj.view(), mask.view(), state(10.0, 1.0, 0.0).view(), 0.5, 2, ONE).unwrap();
        // Steps 1..=3 lie within the window; step 1 is the earliest valid: 3 m over 1 s.
        assert_eq!(r.index_axis(ndarray::Axis(0), 0), array![[1.5, 0.0], [3.0, 0.0]]);
        // A single valid step falls back to the state's velocity.
        let mask = array![[0.0f32, 0.0, 0.0, 1.0]];
        let r = p.rollout(traj.view(), mask.view(), state(1.0, 1.0, 0.0).view(), 0.5, 1, ONE).unwrap();
        assert_eq!(r[[0, 0, 0]], 0.5);
    }

    #[test]
    fn least_squares_velocity_averages_noise_and_times_gaps() {
        // 1 m/s along x, sampled every 0.5 s with steps 2 and 4 dropped; +-0.1 m noise that the endpoints fit
        // takes in full and the least-squares line averages.
        let xs = [-3.0f32, -2.4, 0.0, -1.4, 0.0, -0.6, 0.1];
        let mut traj = Array3::<f32>::zeros((1, 7, 2));
        for t in 0..7 {
            traj[[0, t, 0]] = xs[t];
        }
        let mask = array![[1.0f32, 1.0, 0.0, 1.0, 0.0, 1.0, 1.0]];
        let lsq = PriorSpec { fit: VelocityFit::LeastSquares, ..PriorSpec::constant_velocity(3.0) };
        let r = lsq.rollout(traj.view(), mask.view(), state(9.0, 1.0, 0.0).view(), 0.5, 2, ONE).unwrap();
        // Hand-computed slope over t = 0, 1, 3, 5, 6 (mean 3, mean x -1.46): sum(dt dx) / sum(dt^2) = 12.9 / 26 m
        // per 0.5 s step, 0.992 m/s; two steps ahead 0.992 m.
        let v = 12.9 / 26.0 / 0.5;
        assert!((f64::from(r[[0, 1, 0]]) - v).abs() < 1e-5, "{r}");
        // The endpoints fit over the same window: (0.1 - -3.0) / 3 s.
        let ends = PriorSpec::constant_velocity(3.0);
        let r = ends.rollout(traj.view(), mask.view(), state(9.0, 1.0, 0.0).view(), 0.5, 1, ONE).unwrap();
        assert!((f64::from(r[[0, 0, 0]]) - 3.1 / 3.0 * 0.5).abs() < 1e-6);
    }

    #[test]
    fn quadratic_fit_tracks_acceleration() {
        // x = t^2 / 2 (1 m/s^2 from rest) at t = 0..=4 s with t = 2 missing: the velocity at t = 4 is 4 m/s, which
        // the parabola recovers exactly while the line lags (its slope is the velocity mid-window).
        let mut traj = Array3::<f32>::zeros((1, 5, 2));
        for t in 0..5 {
            traj[[0, t, 0]] = (t * t) as f32 / 2.0 - 8.0;
        }
        let mask = array![[1.0f32, 1.0, 0.0, 1.0, 1.0]];
        let quad = PriorSpec { fit: VelocityFit::Quadratic, ..PriorSpec::constant_velocity(4.0) };
        let r = quad.rollout(traj.view(), mask.view(), state(0.0, 1.0, 0.0).view(), 1.0, 1, ONE).unwrap();
        assert!((r[[0, 0, 0]] - 4.0).abs() < 1e-4, "{r}");
        let line = PriorSpec { fit: VelocityFit::LeastSquares, ..quad };
        let r = line.rollout(traj.view(), mask.view(), state(0.0, 1.0, 0.0).view(), 1.0, 1, ONE).unwrap();
        assert!(r[[0, 0, 0]] < 3.0, "{r}");
        // Standing is judged on the line: a parked car with one jittered last step stays put under the parabola too.
        let jitter = array![[[0.0f32, 0.0], [0.0, 0.0], [0.0, 0.0], [0.0, 0.0], [0.5, 0.0]]];
        let ones = Array2::<f32>::ones((1, 5));
        let held = PriorSpec { standing_mps: 0.3, ..quad };
        let r = held.rollout(jitter.view(), ones.view(), state(0.0, 1.0, 0.0).view(), 1.0, 1, ONE).unwrap();
        assert_eq!(r[[0, 0, 0]], 0.0);
        let r = quad.rollout(jitter.view(), ones.view(), state(0.0, 1.0, 0.0).view(), 1.0, 1, ONE).unwrap();
        assert!(r[[0, 0, 0]] > 0.3, "{r}");
        // Two valid steps: the line through them.
        let mask = array![[0.0f32, 0.0, 0.0, 1.0, 1.0]];
        let r = quad.rollout(traj.view(), mask.view(), state(0.0, 1.0, 0.0).view(), 1.0, 1, ONE).unwrap();
        assert!((r[[0, 0, 0]] - 3.5).abs() < 1e-5, "{r}");
    }

    #[test]
    fn standing_agents_stay_where_they_are() {
        // A slow drift of 0.1 m/s is under a 0.2 m/s threshold: the prior stays at the origin.
        let traj = array![[[-0.2f32, 0.0], [-0.1, 0.0], [0.0, 0.0]]];
        let mask = Array2::<f32>::ones((1, 3));
        let p = PriorSpec { standing_mps: 0.2, fit: VelocityFit::LeastSquares, ..PriorSpec::constant_velocity(1.0) };
        let r = p.rollout(traj.view(), mask.view(), state(0.1, 1.0, 0.0).view(), 1.0, 4, ONE).unwrap();
        assert!(r.iter().all(|v| *v == 0.0), "{r}");
        // Without the threshold it drifts on.
        let p = PriorSpec { standing_mps: 0.0, ..p };
        let r = p.rollout(traj.view(), mask.view(), state(0.1, 1.0, 0.0).view(), 1.0, 4, ONE).unwrap();
        assert!((r[[0, 3, 0]] - 0.4).abs() < 1e-6);
    }

    #[test]
    fn rejects_bad_shapes_and_windows() {
        let traj = Array3::<f32>::zeros((2, 3, 2));
        let mask = Array2::<f32>::ones((1, 3));
        let p = PriorSpec::constant_velocity(0.0);
        assert!(p.rollout(traj.view(), mask.view(), state(1.0, 1.0, 0.0).view(), 0.5, 2, ONE).is_err());
        let bad = PriorSpec::constant_velocity(f64::NAN);
        assert!(bad.validate().is_err());
        let json = r#"{"kind": "constant_velocity", "window_s": 0.8}"#;
        let parsed: PriorSpec = serde_json::from_str(json).unwrap();
        assert_eq!(parsed, PriorSpec::constant_velocity(0.8));
        assert!(serde_json::from_str::<PriorSpec>(r#"{"kind": "magic"}"#).is_err());
        let json = r#"{"kind": "constant_velocity", "window_s": 1.0, "fit": "least_squares", "standing_mps": 0.3}"#;
        let parsed: PriorSpec = serde_json::from_str(json).unwrap();
        assert_eq!((parsed.fit, parsed.standing_mps), (VelocityFit::LeastSquares, 0.3));
        for bad in [
            PriorSpec { standing_mps: -0.1, ..PriorSpec::constant_velocity(1.0) },
            PriorSpec { standing_mps: f64::NAN, ..PriorSpec::constant_velocity(1.0) },
            PriorSpec { fit: VelocityFit::LeastSquares, ..PriorSpec::constant_velocity(0.0) },
            PriorSpec { standing_mps: 0.2, ..PriorSpec::NONE },
        ] {
            assert!(bad.validate().is_err(), "{bad:?}");
        }
    }

    #[test]
    fn each_class_takes_its_own_estimate() {
        // Two agents on the same jittered track at 1 m/s, a vehicle and a pedestrian. The model-wide estimate is the
        // last two steps; the pedestrian's own a least-squares line over the window, which averages the jitter.
        let track = [[-3.0f32, 0.0], [-2.0, 0.2], [-1.0, -0.2], [0.0, 0.2]];
        let traj = Array3::from_shape_fn((2, 4, 2), |(_, t, c)| track[t][c]);
        let mask = Array2::<f32>::ones((2, 4));
        // Columns: 7 features, then one-hot over [vehicle, pedestrian].
        let mut st = Array2::<f32>::zeros((2, 9));
        st[[0, 7]] = 1.0;
        st[[1, 8]] = 1.0;
        let classes = [AgentClass::Vehicle, AgentClass::Pedestrian];
        let line = ClassPrior { window_s: 3.0, fit: VelocityFit::LeastSquares, standing_mps: 0.0 };
        let p = PriorSpec {
            by_class: ByClass { pedestrian: Some(line), ..ByClass::NONE },
            ..PriorSpec::constant_velocity(1.0)
        };
        let r = p.rollout(traj.view(), mask.view(), st.view(), 1.0, 1, &classes).unwrap();
        // The vehicle: (0, 0.2) - (-1, -0.2) = (1, 0.4) per step. The pedestrian: the line's slope, (1, 0.02).
        assert!((r[[0, 0, 0]] - 1.0).abs() < 1e-5 && (r[[0, 0, 1]] - 0.4).abs() < 1e-5, "{r}");
        assert!((r[[1, 0, 0]] - 1.0).abs() < 1e-5 && (r[[1, 0, 1]] - 0.02).abs() < 1e-5, "{r}");
        // The same prior without the override treats both alike.
        let r =
            PriorSpec { by_class: ByClass::NONE, ..p }.rollout(traj.view(), mask.view(), st.view(), 1.0, 1, &classes);
        let r = r.unwrap();
        assert_eq!(r.index_axis(ndarray::Axis(0), 0), r.index_axis(ndarray::Axis(0), 1));
        // A state without the one-hot columns is refused rather than read as no class.
        let narrow = st.slice(ndarray::s![.., ..8]).to_owned();
        assert!(p.rollout(traj.view(), mask.view(), narrow.view(), 1.0, 1, &classes).is_err());
    }

    #[test]
    fn per_class_estimates_parse_and_validate() {
        let json = r#"{"kind": "constant_velocity", "window_s": 2.0, "fit": "quadratic", "standing_mps": 0.3,
            "by_class": {"pedestrian": {"window_s": 2.0, "fit": "least_squares", "standing_mps": 0.3}}}"#;
        let p: PriorSpec = serde_json::from_str(json).unwrap();
        p.validate().unwrap();
        let ped = p.by_class.get(AgentClass::Pedestrian).unwrap();
        assert_eq!((ped.fit, ped.window_s), (VelocityFit::LeastSquares, 2.0));
        assert_eq!(p.by_class.get(AgentClass::Vehicle), None);
        assert_eq!(p.for_class(Some(AgentClass::Pedestrian)).fit, VelocityFit::LeastSquares);
        assert_eq!(p.for_class(Some(AgentClass::Vehicle)).fit, VelocityFit::Quadratic);
        // Written back only when set, so a model without per-class estimates keeps its metadata.
        let back = serde_json::to_string(&p).unwrap();
        assert_eq!(serde_json::from_str::<PriorSpec>(&back).unwrap(), p);
        assert!(!serde_json::to_string(&PriorSpec::constant_velocity(1.0)).unwrap().contains("by_class"));
        // A misspelt class or key is an error, not a silently ignored estimate.
        for bad in [
            r#"{"kind": "constant_velocity", "by_class": {"pedestrians": {}}}"#,
            r#"{"kind": "constant_velocity", "by_class": {"cyclist": {"window": 1.0}}}"#,
        ] {
            assert!(serde_json::from_str::<PriorSpec>(bad).is_err(), "{bad}");
        }
        let bad_window = ClassPrior { window_s: -1.0, fit: VelocityFit::Endpoints, standing_mps: 0.0 };
        let no_window = ClassPrior { window_s: 0.0, fit: VelocityFit::LeastSquares, standing_mps: 0.0 };
        for (by_class, kind) in [
            (ByClass { cyclist: Some(bad_window), ..ByClass::NONE }, PriorKind::ConstantVelocity),
            (ByClass { cyclist: Some(no_window), ..ByClass::NONE }, PriorKind::ConstantVelocity),
            (ByClass { cyclist: Some(ClassPrior { window_s: 1.0, ..no_window }), ..ByClass::NONE }, PriorKind::None),
        ] {
            let p = PriorSpec { kind, by_class, ..PriorSpec::NONE };
            let e = p.validate().unwrap_err().to_string();
            assert!(e.contains("by_class"), "{e}");
        }
    }

    #[test]
    fn adaptive_fit_takes_the_last_steps_of_a_clean_track_and_the_window_of_a_noisy_one() {
        let adaptive = PriorSpec { fit: VelocityFit::Adaptive, ..PriorSpec::constant_velocity(9.0) };
        let mask = Array2::<f32>::ones((1, 10));
        // Clean, accelerating: x = t² / 2 (velocity 9 at t = 9). The last two steps give 8.5, every longer line less.
        let clean = Array3::from_shape_fn((1, 10, 2), |(_, t, c)| if c == 0 { (t * t) as f32 / 2.0 } else { 0.0 });
        let r = adaptive.rollout(clean.view(), mask.view(), state(0.0, 1.0, 0.0).view(), 1.0, 1, ONE).unwrap();
        assert!((r[[0, 0, 0]] - 8.5).abs() < 1e-4, "{r}");
        // Steady at 1 m/s with ±0.3 m of jitter: the whole window's line, far closer to 1 than the last two steps.
        let jitter = [0.3f32, -0.3, 0.3, -0.3, 0.3, -0.3, 0.3, -0.3, 0.3, -0.3];
        let noisy = Array3::from_shape_fn((1, 10, 2), |(_, t, c)| if c == 0 { t as f32 + jitter[t] } else { 0.0 });
        let r = adaptive.rollout(noisy.view(), mask.view(), state(0.0, 1.0, 0.0).view(), 1.0, 1, ONE).unwrap();
        let line = PriorSpec { fit: VelocityFit::LeastSquares, ..adaptive };
        let want = line.rollout(noisy.view(), mask.view(), state(0.0, 1.0, 0.0).view(), 1.0, 1, ONE).unwrap();
        assert!((r[[0, 0, 0]] - want[[0, 0, 0]]).abs() < 1e-6 && (r[[0, 0, 0]] - 1.0).abs() < 0.15, "{r} {want}");
        // Three valid steps: the last two.
        let few = Array2::from_shape_fn((1, 10), |(_, t)| if t >= 7 { 1.0f32 } else { 0.0 });
        let r = adaptive.rollout(clean.view(), few.view(), state(0.0, 1.0, 0.0).view(), 1.0, 1, ONE).unwrap();
        assert!((r[[0, 0, 0]] - 8.5).abs() < 1e-4, "{r}");
        assert_eq!(VelocityFit::Adaptive.name(), "adaptive");
        let parsed: PriorSpec =
            serde_json::from_str(r#"{"kind": "constant_velocity", "window_s": 2, "fit": "adaptive"}"#).unwrap();
        assert_eq!(parsed.fit, VelocityFit::Adaptive);
    }
}
