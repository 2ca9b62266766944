//! The kinematic prior: a physical rollout of each agent's motion that the network refines.
//!
//! A model whose contract declares a prior predicts its anchors and offsets *relative to this rollout*: mode k's
//! agent-frame trajectory is `prior + anchor_k + offset_k`, so a network with nothing to add falls back to physics
//! rather than to a k-means anchor. The rollout is computed here from the network's own input tensors
//! (`trajectory`, `trajectory_mask`, `state`), once, and training calls this same function through the bindings.

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

/// The prior a model declares: its kind and, for constant velocity, how the velocity is estimated.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize, Default)]
pub struct PriorSpec {
    /// The rollout.
    #[serde(default)]
    pub kind: PriorKind,
    /// 0: the traffic state's velocity (given, else the last two valid steps). > 0: the mean velocity over the
    /// last `window_s` seconds of the observed positions (`max(1, round(window_s / dt))` steps), which is less noisy.
    #[serde(default)]
    pub window_s: f64,
}

impl PriorSpec {
    /// No prior.
    pub const NONE: Self = Self { kind: PriorKind::None, window_s: 0.0 };

    /// Checks the velocity window.
    pub fn validate(&self) -> Result<()> {
        if !(self.window_s.is_finite() && (0.0..=60.0).contains(&self.window_s)) {
            return Err(DganError::InvalidSpec(format!(
                "prior.window_s must be between 0 and 60 seconds, got {}",
                self.window_s
            )));
        }
        Ok(())
    }

    /// The rollout of every agent, `(N, T_f, 2)` metres in each agent's frame, from the network inputs
    /// `trajectory (N, T_obs, 2)`, `trajectory_mask (N, T_obs)` and `state (N, S)` (columns as in
    /// [`crate::spec::STATE_FEATURES`]). Zero for [`PriorKind::None`].
    pub fn rollout(
        &self,
        trajectory: ArrayView3<'_, f32>,
        trajectory_mask: ArrayView2<'_, f32>,
        state: ArrayView2<'_, f32>,
        dt_s: f64,
        t_f: usize,
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
        let window = (self.window_s > 0.0).then(|| ((self.window_s / dt_s).round() as usize).max(1));
        for i in 0..n {
            let from_state = [
                f64::from(state[[i, 0]]) * f64::from(state[[i, 3]]),
                f64::from(state[[i, 0]]) * f64::from(state[[i, 4]]),
            ];
            let v = window
                .and_then(|k| {
                    let valid = |t: usize| trajectory_mask[[i, t]] > 0.5;
                    let last = (0..t_obs).rev().find(|&t| valid(t))?;
                    let first = (last.saturating_sub(k)..last).find(|&t| valid(t))?;
                    let span = (last - first) as f64 * dt_s;
                    let p = |t: usize, c: usize| f64::from(trajectory[[i, t, c]]);
                    Some([(p(last, 0) - p(first, 0)) / span, (p(last, 1) - p(first, 1)) / span])
                })
                .unwrap_or(from_state);
            for t in 0..t_f {
                let s = (t + 1) as f64 * dt_s;
                out[[i, t, 0]] = (v[0] * s) as f32;
                out[[i, t, 1]] = (v[1] * s) as f32;
            }
        }
        Ok(out)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use ndarray::{array, Array2};

    fn state(speed: f32, cos: f32, sin: f32) -> Array2<f32> {
        array![[speed, 0.0, 0.0, cos, sin, 0.5, 0.5, 1.0]]
    }

    #[test]
    fn constant_velocity_from_the_state() {
        let traj = Array3::<f32>::zeros((1, 3, 2));
        let mask = Array2::<f32>::ones((1, 3));
        let p = PriorSpec { kind: PriorKind::ConstantVelocity, window_s: 0.0 };
        let r = p.rollout(traj.view(), mask.view(), state(2.0, 0.6, 0.8).view(), 0.5, 3).unwrap();
        // 2 m/s along (0.6, 0.8): 1 m per 0.5 s step.
        let want = array![[0.6f32, 0.8], [1.2, 1.6], [1.8, 2.4]];
        assert!(r.index_axis(ndarray::Axis(0), 0).iter().zip(&want).all(|(a, b)| (a - b).abs() < 1e-6), "{r}");
        let none = PriorSpec::NONE.rollout(traj.view(), mask.view(), state(2.0, 1.0, 0.0).view(), 0.5, 3).unwrap();
        assert!(none.iter().all(|v| *v == 0.0));
    }

    #[test]
    fn windowed_velocity_uses_the_observed_positions() {
        // Agent frame: the last step is the origin; 3 m behind it one second (two 0.5 s steps) earlier, with the
        // middle step missing. The state says 10 m/s, which the window ignores.
        let traj = array![[[-9.0f32, 0.0], [-3.0, 0.0], [0.0, 0.0], [0.0, 0.0]]];
        let mask = array![[1.0f32, 1.0, 0.0, 1.0]];
        let p = PriorSpec { kind: PriorKind::ConstantVelocity, window_s: 1.0 };
        let r = p.rollout(traj.view(), mask.view(), state(10.0, 1.0, 0.0).view(), 0.5, 2).unwrap();
        // Steps 1..=3 lie within the window; step 1 is the earliest valid: 3 m over 1 s.
        assert_eq!(r.index_axis(ndarray::Axis(0), 0), array![[1.5, 0.0], [3.0, 0.0]]);
        // A single valid step falls back to the state's velocity.
        let mask = array![[0.0f32, 0.0, 0.0, 1.0]];
        let r = p.rollout(traj.view(), mask.view(), state(1.0, 1.0, 0.0).view(), 0.5, 1).unwrap();
        assert_eq!(r[[0, 0, 0]], 0.5);
    }

    #[test]
    fn rejects_bad_shapes_and_windows() {
        let traj = Array3::<f32>::zeros((2, 3, 2));
        let mask = Array2::<f32>::ones((1, 3));
        let p = PriorSpec { kind: PriorKind::ConstantVelocity, window_s: 0.0 };
        assert!(p.rollout(traj.view(), mask.view(), state(1.0, 1.0, 0.0).view(), 0.5, 2).is_err());
        let bad = PriorSpec { kind: PriorKind::ConstantVelocity, window_s: f64::NAN };
        assert!(bad.validate().is_err());
        let json = r#"{"kind": "constant_velocity", "window_s": 0.8}"#;
        let parsed: PriorSpec = serde_json::from_str(json).unwrap();
        assert_eq!(parsed, PriorSpec { kind: PriorKind::ConstantVelocity, window_s: 0.8 });
        assert!(serde_json::from_str::<PriorSpec>(r#"{"kind": "magic"}"#).is_err());
    }
}
