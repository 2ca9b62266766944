//! The scene at the current time t_obs: every agent's observed history and optional state, plus an optional map.

use crate::class::AgentClass;
use crate::error::{invalid_frame, Result};
use crate::map::SceneMap;
use ndarray::{Array2, Array3, ArrayView2};
use std::collections::HashSet;
use std::sync::Arc;

pub use crate::limits::MAX_COORDINATE_M;

/// The largest agent length or width, metres (an articulated bus is 25 m).
pub const MAX_SIZE_M: f64 = 100.0;
/// The largest speed a velocity may give, m/s (720 km/h).
pub const MAX_SPEED_MPS: f64 = 200.0;

/// The fewest valid steps an agent needs for [`Frame::denoised`] to judge its track (a parabola passes exactly
/// through three).
pub const DENOISE_MIN_STEPS: usize = 4;
/// The fewest agents whose denoising fits [`Frame::denoised_on`] shares out over threads (a fit costs about 0.2 µs).
pub const PARALLEL_DENOISE_FROM: usize = 1024;
/// Agents a thread fits at a time when denoising is shared out.
pub const DENOISE_AGENTS_PER_JOB: usize = 512;

/// The scene at the current time. Positions are world metres, oldest step first; the last step is t_obs.
///
/// Optional per-agent values use NaN for "not given for this agent": headings then come from the motion,
/// velocities from the history, lengths and widths from the class defaults.
#[derive(Debug, Clone)]
pub struct Frame {
    ids: Vec<i64>,
    classes: Vec<AgentClass>,
    positions: Array3<f64>,
    mask: Array2<bool>,
    headings: Vec<Option<f64>>,
    velocities: Vec<Option<[f64; 2]>>,
    lengths: Vec<f64>,
    widths: Vec<f64>,
    map: Option<Arc<SceneMap>>,
    dt_s: Option<f64>,
}

impl Frame {
    /// A frame of `N` agents from positions `(N, T, 2)`, a validity mask `(N, T)` (all valid if `None`) and
    /// one class per agent. Every agent needs at least one valid step, and valid positions must be finite.
    /// Ids default to `0..N`.
    pub fn new(positions: Array3<f64>, mask: Option<Array2<bool>>, classes: Vec<AgentClass>) -> Result<Self> {
        let (n, t, d) = positions.dim();
        if d != 2 {
            return Err(invalid_frame(format!("positions must have shape (N, T, 2), got ({n}, {t}, {d})")));
        }
        if n > 0 && t == 0 {
            return Err(invalid_frame("positions have no time steps (T = 0)"));
        }
        let mask = match mask {
            Some(m) => {
                if m.dim() != (n, t) {
                    return Err(invalid_frame(format!("mask must have shape (N, T) = ({n}, {t}), got {:?}", m.dim())));
                }
                m
            }
            None => Array2::from_elem((n, t), true),
        };
        if classes.len() != n {
            return Err(invalid_frame(format!("{} classes given for {n} agents", classes.len())));
        }
        for i in 0..n {
            let mut any = false;
            for s in 0..t {
                if !mask[[i, s]] {
                    continue;
                }
                any = true;
                let (x, y) = (positions[[i, s, 0]], positions[[i, s, 1]]);
                if !x.is_finite() || !y.is_finite() {
                    return Err(invalid_frame(format!(
                        "agent {i} has a non-finite position ({x}, {y}) at valid step {s}; mark the step invalid in \
                         the mask or fix the value"
                    )));
                }
                if x.abs().max(y.abs()) > MAX_COORDINATE_M {
                    return Err(invalid_frame(format!(
                        "agent {i} is at ({x}, {y}) m at step {s}, beyond ±{MAX_COORDINATE_M:e} m of the origin; \
                         positions are in metres"
                    )));
                }
            }
            if !any {
                return Err(invalid_frame(format!("agent {i} has no valid step in its mask")));
            }
        }
        let lengths = classes.iter().map(|c| c.default_length_m()).collect();
        let widths = classes.iter().map(|c| c.default_width_m()).collect();
        Ok(Self {
            ids: (0..n as i64).collect(),
            classes,
            positions: positions.as_standard_layout().to_owned(),
            mask: mask.as_standard_layout().to_owned(),
            headings: vec![None; n],
            velocities: vec![None; n],
            lengths,
            widths,
            map: None,
            dt_s: None,
        })
    }

    /// Sets the agents' ids, which must be unique.
    pub fn with_ids(mut self, ids: Vec<i64>) -> Result<Self> {
        self.check_len("ids", ids.len())?;
        let mut seen = HashSet::with_capacity(ids.len());
        if let Some(dup) = ids.iter().find(|id| !seen.insert(**id)) {
            return Err(invalid_frame(format!("agent id {dup} appears more than once")));
        }
        self.ids = ids;
        Ok(self)
    }

    /// Sets headings in radians (world frame); NaN means "not given" for that agent.
    pub fn with_headings(mut self, headings: &[f64]) -> Result<Self> {
        self.check_len("headings", headings.len())?;
        if let Some(i) = headings.iter().position(|h| h.is_infinite()) {
            return Err(invalid_frame(format!("heading of agent {i} is infinite")));
        }
        self.headings = headings.iter().map(|h| (!h.is_nan()).then_some(*h)).collect();
        Ok(self)
    }

    /// Sets current velocities `(N, 2)` in m/s (world frame); a NaN row means "not given" for that agent.
    pub fn with_velocities(mut self, velocities: ArrayView2<'_, f64>) -> Result<Self> {
        if velocities.ncols() != 2 {
            return Err(invalid_frame(format!("velocities must have shape (N, 2), got {:?}", velocities.dim())));
        }
        self.check_len("velocities", velocities.nrows())?;
        let mut out = Vec::with_capacity(velocities.nrows());
        for (i, row) in velocities.rows().into_iter().enumerate() {
            let (vx, vy) = (row[0], row[1]);
            if vx.is_nan() || vy.is_nan() {
                out.push(None);
            } else if vx.is_infinite() || vy.is_infinite() {
                return Err(invalid_frame(format!("velocity of agent {i} is infinite")));
            } else if vx.hypot(vy) > MAX_SPEED_MPS {
                return Err(invalid_frame(format!(
                    "velocity of agent {i} is ({vx}, {vy}) m/s, faster than {MAX_SPEED_MPS} m/s; velocities are in m/s"
                )));
            } else {
                out.push(Some([vx, vy]));
            }
        }
        self.velocities = out;
        Ok(self)
    }

    /// Sets lengths in metres; NaN keeps the class default.
    pub fn with_lengths(mut self, lengths: &[f64]) -> Result<Self> {
        self.check_len("lengths", lengths.len())?;
        Self::merge_sizes("length", &mut self.lengths, lengths)?;
        Ok(self)
    }

    /// Sets widths in metres; NaN keeps the class default.
    pub fn with_widths(mut self, widths: &[f64]) -> Result<Self> {
        self.check_len("widths", widths.len())?;
        Self::merge_sizes("width", &mut self.widths, widths)?;
        Ok(self)
    }

    /// Sets the time base: the seconds between the frame's steps. A model refuses a frame whose time base differs
    /// from its own ([`DganError::TimeBase`](crate::DganError::TimeBase)); a frame without one is taken as given.
    pub fn with_dt(mut self, dt_s: f64) -> Result<Self> {
        if !(dt_s.is_finite() && dt_s > 0.0) {
            return Err(crate::DganError::TimeBase(format!("dt must be a positive number of seconds, got {dt_s}")));
        }
        self.dt_s = Some(dt_s);
        Ok(self)
    }

    /// Attaches the scene's map.
    pub fn with_map(mut self, map: Arc<SceneMap>) -> Self {
        self.map = Some(map);
        self
    }

    /// The same agents without a map (a model whose map is optional then sees blank crops flagged absent).
    pub fn without_map(&self) -> Self {
        Self { map: None, ..self.clone() }
    }

    /// The same frame with tracker noise taken out of its histories: each agent whose valid positions (at least
    /// [`DENOISE_MIN_STEPS`]) lie off their least-squares parabola by `gate_m` metres or more (root mean square over
    /// those steps) has them replaced by that parabola's points; the others, the given states and the map are kept.
    /// Smooth annotated tracks (ETH/UCY's pedestrians over 3.2 s) follow a parabola within a few centimetres, so a
    /// gate near a tracker's noise leaves them as they were. Also the number of agents smoothed.
    pub fn denoised(&self, gate_m: f64) -> Result<(Self, usize)> {
        let (out, smoothed) = self.denoised_on(gate_m, 1)?;
        Ok((out.into_owned(), smoothed))
    }

    /// [`Frame::denoised`] fitted on up to `threads` threads for a large frame ([`PARALLEL_DENOISE_FROM`] agents or
    /// more, in jobs of [`DENOISE_AGENTS_PER_JOB`]), and the frame itself, not a copy, when no track is smoothed.
    pub fn denoised_on(&self, gate_m: f64, threads: usize) -> Result<(std::borrow::Cow<'_, Self>, usize)> {
        if !(gate_m.is_finite() && gate_m >= 0.0) {
            return Err(invalid_frame(format!(
                "the denoising gate must be a non-negative number of metres, got {gate_m}"
            )));
        }
        // Each job's agents `first..` and, for each it smooths, its row and the parabola's points at its valid steps.
        type Smoothed = Vec<(usize, Vec<[f64; 2]>)>;
        let fit = |first: usize, last: usize| -> Smoothed {
            let mut out = vec![];
            let mut valid = Vec::with_capacity(self.steps());
            for i in first..last {
                valid.clear();
                valid.extend((0..self.steps()).filter(|&t| self.mask[[i, t]]));
                if valid.len() < DENOISE_MIN_STEPS {
                    continue;
                }
                let p = |t: usize, c: usize| self.positions[[i, t, c]];
                if let Some((points, rms)) = crate::prior::parabola_points(&valid, p) {
                    if rms >= gate_m {
                        out.push((i, points));
                    }
                }
            }
            out
        };
        let n = self.len();
        let smoothed: Smoothed = if threads <= 1 || n < PARALLEL_DENOISE_FROM {
            fit(0, n)
        } else {
            let mut parts: Vec<Smoothed> = vec![vec![]; n.div_ceil(DENOISE_AGENTS_PER_JOB)];
            let jobs: Vec<(usize, &mut Smoothed)> =
                parts.iter_mut().enumerate().map(|(k, slot)| (k * DENOISE_AGENTS_PER_JOB, slot)).collect();
            let one = |(first, slot): (usize, &mut Smoothed)| -> Result<()> {
                *slot = fit(first, (first + DENOISE_AGENTS_PER_JOB).min(n));
                Ok(())
            };
            crate::limits::share_jobs(jobs, threads, one, || invalid_frame("a denoising thread panicked"))?;
            parts.into_iter().flatten().collect()
        };
        if smoothed.is_empty() {
            return Ok((std::borrow::Cow::Borrowed(self), 0));
        }
        let mut out = self.clone();
        for (i, points) in &smoothed {
            let valid = (0..self.steps()).filter(|&t| self.mask[[*i, t]]);
            for (t, q) in valid.zip(points) {
                out.positions[[*i, t, 0]] = q[0];
                out.positions[[*i, t, 1]] = q[1];
            }
        }
        Ok((std::borrow::Cow::Owned(out), smoothed.len()))
    }

    fn merge_sizes(what: &str, target: &mut [f64], given: &[f64]) -> Result<()> {
        for (i, (t, g)) in target.iter_mut().zip(given).enumerate() {
            if g.is_nan() {
                continue;
            }
            if !g.is_finite() || *g <= 0.0 || *g > MAX_SIZE_M {
                return Err(invalid_frame(format!(
                    "{what} of agent {i} must be a positive number of metres up to {MAX_SIZE_M}, got {g}"
                )));
            }
            *t = *g;
        }
        Ok(())
    }

    fn check_len(&self, what: &str, len: usize) -> Result<()> {
        if len != self.len() {
            return Err(invalid_frame(format!("{len} {what} given for {} agents", self.len())));
        }
        Ok(())
    }

    /// Number of agents N.
    pub fn len(&self) -> usize {
        self.ids.len()
    }

    /// Whether the scene has no agent.
    pub fn is_empty(&self) -> bool {
        self.ids.is_empty()
    }

    /// Number of observed steps T.
    pub fn steps(&self) -> usize {
        self.positions.dim().1
    }

    /// Agent ids.
    pub fn ids(&self) -> &[i64] {
        &self.ids
    }

    /// Agent classes.
    pub fn classes(&self) -> &[AgentClass] {
        &self.classes
    }

    /// Observed world positions `(N, T, 2)`.
    pub fn positions(&self) -> &Array3<f64> {
        &self.positions
    }

    /// Validity mask `(N, T)`.
    pub fn mask(&self) -> &Array2<bool> {
        &self.mask
    }

    /// Given headings (world radians), `None` where not given.
    pub fn headings(&self) -> &[Option<f64>] {
        &self.headings
    }

    /// Given velocities (world m/s), `None` where not given.
    pub fn velocities(&self) -> &[Option<[f64; 2]>] {
        &self.velocities
    }

    /// Lengths in metres (given or class default).
    pub fn lengths(&self) -> &[f64] {
        &self.lengths
    }

    /// Widths in metres (given or class default).
    pub fn widths(&self) -> &[f64] {
        &self.widths
    }

    /// Seconds between steps, if the frame knows its time base.
    pub fn dt_s(&self) -> Option<f64> {
        self.dt_s
    }

    /// Checks the frame's time base against a model's `dt_s` (relative tolerance 1e-6).
    pub fn check_dt(&self, model_dt_s: f64) -> Result<()> {
        match self.dt_s {
            Some(dt) if (dt - model_dt_s).abs() > model_dt_s * crate::limits::TIME_TOLERANCE => {
                let dt = (dt * 1e9).round() / 1e9;
                Err(crate::DganError::TimeBase(format!(
                    "the frame's steps are {dt} s apart but the model's are {model_dt_s} s; resample the data to the \
                     model's time base (dgan.Frame.from_records(..., dt={model_dt_s}) interpolates denser data)"
                )))
            }
            _ => Ok(()),
        }
    }

    /// The scene's map, if any.
    pub fn map(&self) -> Option<&SceneMap> {
        self.map.as_deref()
    }

    /// The scene's map as shared by the frames that hold it, if any.
    pub fn shared_map(&self) -> Option<&Arc<SceneMap>> {
        self.map.as_ref()
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::error::DganError;
    use ndarray::{array, Array3};

    fn two_agents() -> Array3<f64> {
        Array3::from_shape_fn((2, 3, 2), |(i, t, d)| (i * 10 + t) as f64 + d as f64 * 0.5)
    }

    #[test]
    fn denoising_shared_out_equals_one_thread_and_borrows_a_clean_frame() {
        // 3,000 agents walking, every third with ±0.2 m of jitter: the same smoothed frame on 1, 2 and 3 threads.
        let p = Array3::from_shape_fn((3000, 8, 2), |(i, t, d)| {
            let jitter = if i % 3 == 0 { [0.2, -0.2][t % 2] } else { 0.0 };
            [i as f64 * 50.0 + t as f64 * 0.4 + jitter, 0.01 * (t * t) as f64][d]
        });
        let f = Frame::new(p, None, vec![AgentClass::Pedestrian; 3000]).unwrap();
        let (one, count) = f.denoised(0.1).unwrap();
        assert_eq!(count, 1000);
        for threads in [2, 3] {
            let (many, n) = f.denoised_on(0.1, threads).unwrap();
            assert_eq!((many.positions(), n), (one.positions(), 1000), "{threads} threads");
        }
        // Nothing to smooth: the frame itself comes back, not a copy.
        let (clean, n) = one.denoised_on(0.1, 2).unwrap();
        assert!(matches!(clean, std::borrow::Cow::Borrowed(_)) && n == 0);
    }

    #[test]
    fn denoising_smooths_noisy_tracks_only() {
        // Agent 0 turns along a parabola exactly; agent 1 walks straight with ±0.2 m of jitter; agent 2 the same
        // jitter but only three valid steps; agent 3 jitters with a gap (step 2 missing).
        let jitter = |t: usize| if t.is_multiple_of(2) { 0.2 } else { -0.2 };
        let p = Array3::from_shape_fn((4, 8, 2), |(i, t, d)| {
            let t_f = t as f64;
            match (i, d) {
                (0, 0) => t_f * 0.5,
                (0, _) => 0.05 * t_f * t_f,
                (_, 0) => t_f * 0.4,
                (_, _) => jitter(t),
            }
        });
        let mut mask = Array2::from_elem((4, 8), true);
        for t in 0..5 {
            mask[[2, t]] = false;
        }
        mask[[3, 2]] = false;
        let f = Frame::new(p.clone(), Some(mask), vec![AgentClass::Pedestrian; 4]).unwrap();
        let (d, smoothed) = f.denoised(0.1).unwrap();
        assert_eq!(smoothed, 2, "the jittering agents with four or more steps");
        assert_eq!(d.positions().index_axis(ndarray::Axis(0), 0), p.index_axis(ndarray::Axis(0), 0));
        assert_eq!(d.positions().index_axis(ndarray::Axis(0), 2), p.index_axis(ndarray::Axis(0), 2));
        for i in [1, 3] {
            let valid: Vec<usize> = (0..8).filter(|&t| f.mask()[[i, t]]).collect();
            for &t in &valid {
                // The straight line through the jitter: x unchanged, y within a few cm of 0.
                assert!((d.positions()[[i, t, 0]] - t as f64 * 0.4).abs() < 1e-9, "{i} {t}");
                assert!(d.positions()[[i, t, 1]].abs() < 0.08, "{i} {t}: {}", d.positions()[[i, t, 1]]);
            }
        }
        assert_eq!(d.positions()[[3, 2, 1]], p[[3, 2, 1]], "a masked step is left alone");
        assert_eq!((d.mask(), d.ids(), d.classes()), (f.mask(), f.ids(), f.classes()));
        // A gate above the jitter leaves every track; a gate of 0 refits the clean parabola onto itself.
        assert_eq!(f.denoised(0.5).unwrap().1, 0);
        let (exact, n) = f.denoised(0.0).unwrap();
        assert_eq!(n, 3);
        let off =
            (&exact.positions().index_axis(ndarray::Axis(0), 0) - &p.index_axis(ndarray::Axis(0), 0)).mapv(f64::abs);
        assert!(off.iter().all(|v| *v < 1e-9), "{off}");
        for gate in [f64::NAN, -0.1, f64::INFINITY] {
            assert!(matches!(f.denoised(gate), Err(DganError::InvalidFrame(_))), "{gate}");
        }
    }

    #[test]
    fn accepts_a_valid_frame_and_fills_defaults() {
        let f = Frame::new(two_agents(), None, vec![AgentClass::Vehicle, AgentClass::Pedestrian]).unwrap();
        assert_eq!(f.len(), 2);
        assert_eq!(f.lengths(), &[4.5, 0.5]);
        let f = f.with_lengths(&[f64::NAN, 0.7]).unwrap().with_headings(&[0.3, f64::NAN]).unwrap();
        assert_eq!(f.lengths(), &[4.5, 0.7]);
        assert_eq!(f.headings(), &[Some(0.3), None]);
    }

    #[test]
    fn rejects_bad_frames() {
        let classes = vec![AgentClass::Vehicle, AgentClass::Pedestrian];
        let mut p = two_agents();
        p[[1, 2, 0]] = f64::NAN;
        assert!(matches!(Frame::new(p.clone(), None, classes.clone()), Err(DganError::InvalidFrame(_))));
        // The same NaN at a masked-out step is fine.
        let mask = array![[true, true, true], [true, true, false]];
        assert!(Frame::new(p, Some(mask), classes.clone()).is_ok());
        let empty = array![[true, true, true], [false, false, false]];
        let err = Frame::new(two_agents(), Some(empty), classes.clone()).unwrap_err();
        assert!(err.to_string().contains("agent 1 has no valid step"), "{err}");
        assert!(Frame::new(two_agents(), None, vec![AgentClass::Vehicle]).is_err());
        assert!(Frame::new(Array3::zeros((2, 3, 3)), None, classes.clone()).is_err());
        let f = Frame::new(two_agents(), None, classes).unwrap();
        assert!(f.clone().with_ids(vec![4, 4]).is_err());
        assert!(f.clone().with_lengths(&[1.0, -1.0]).is_err());
        assert!(f.clone().with_headings(&[f64::INFINITY, 0.0]).is_err());
        assert!(f.with_widths(&[1.0]).is_err());
    }

    #[test]
    fn empty_frame_is_valid() {
        let f = Frame::new(Array3::zeros((0, 8, 2)), None, vec![]).unwrap();
        assert!(f.is_empty());
    }
}
