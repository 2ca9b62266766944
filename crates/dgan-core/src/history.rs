//! Time bases: detections at any times → a [`Frame`] on the model's grid, and the streaming [`Tracker`].
//!
//! A model observes `t_obs` steps `dt_s` apart ending at the current time. Users' data come at their own rate:
//! 10 Hz logs for a 0.4 s model, jittered timestamps, agents that vanish and return. [`frame_at`] builds the frame
//! at a time from per-agent detections, the one implementation behind `dgan.Frame.from_records` and the tracker:
//!
//! - an agent is in the frame when it has a detection at the current time;
//! - a grid time that matches a detection takes it; one between two detections at most `max_gap_s` apart is
//!   interpolated linearly; anything else is masked out (the agent was not seen then);
//! - data sparser than the grid (median spacing more than 5% above `dt_s`) are refused with
//!   [`DganError::SparseData`], never silently stretched, unless upsampling is asked for ([`frame_at_with`]): then
//!   data up to [`UPSAMPLE_LIMIT`]× sparser are interpolated onto the grid, bridging gaps up to 1.5× their spacing.

use crate::class::AgentClass;
use crate::error::{DganError, Result};
use crate::frame::Frame;
use ndarray::{Array2, Array3};
use std::collections::{BTreeMap, HashSet};

pub use crate::limits::TIME_TOLERANCE;

/// How much sparser than the grid the data may be (median spacing ≤ `dt_s · (1 + SPARSE_SLACK)`).
pub const SPARSE_SLACK: f64 = 0.05;

/// How much sparser than the grid data may be when upsampling is asked for (median spacing ≤
/// `dt_s · UPSAMPLE_LIMIT · (1 + SPARSE_SLACK)`): 2 Hz data on a 0.4 s grid, 0.8 s data on a 0.5 s grid.
pub const UPSAMPLE_LIMIT: f64 = 2.5;

/// What [`tracks_from_rows_with`] does with several rows of one agent at one time.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub enum Duplicates {
    /// Refuse the table ([`DganError::InvalidFrame`]): it is ambiguous.
    #[default]
    Error,
    /// Keep the first of them, in the table's row order.
    First,
    /// Keep the last of them, in the table's row order.
    Last,
    /// Their mean: positions, sizes and velocities averaged (NaN ignored), headings by their circular mean; the
    /// first row's class.
    Mean,
}

impl Duplicates {
    /// Every choice, by the name [`FromStr`](std::str::FromStr) reads (and the Python option takes).
    pub const ALL: [(&'static str, Self); 4] =
        [("error", Self::Error), ("first", Self::First), ("last", Self::Last), ("mean", Self::Mean)];
}

impl std::str::FromStr for Duplicates {
    type Err = DganError;

    fn from_str(s: &str) -> Result<Self> {
        Self::ALL.iter().find(|(name, _)| *name == s).map(|(_, d)| *d).ok_or_else(|| {
            let names: Vec<String> = Self::ALL.iter().map(|(n, _)| format!("{n:?}")).collect();
            DganError::InvalidSpec(format!("duplicates must be one of {}; got {s:?}", names.join(", ")))
        })
    }
}

/// One agent seen at one time: where, and whatever state the source gives.
#[derive(Debug, Clone, PartialEq)]
pub struct Detection {
    /// Seconds, on any clock shared by the detections.
    pub time_s: f64,
    /// World position in metres.
    pub position: [f64; 2],
    /// The class, `None` for the frame's default.
    pub class: Option<AgentClass>,
    /// World heading in radians, NaN if unknown.
    pub heading: f64,
    /// Length in metres, NaN for the class default.
    pub length: f64,
    /// Width in metres, NaN for the class default.
    pub width: f64,
    /// World velocity in m/s, NaN if unknown.
    pub velocity: [f64; 2],
}

impl Detection {
    /// A detection with a position only.
    pub fn at(time_s: f64, x: f64, y: f64) -> Self {
        Self {
            time_s,
            position: [x, y],
            class: None,
            heading: f64::NAN,
            length: f64::NAN,
            width: f64::NAN,
            velocity: [f64::NAN; 2],
        }
    }
}

/// The time grid of a model: `t_obs` steps `dt_s` apart; interpolation across gaps up to `max_gap_s`.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct TimeBase {
    /// Steps observed.
    pub t_obs: usize,
    /// Seconds between steps.
    pub dt_s: f64,
    /// The longest gap between two detections of an agent that is interpolated (default 1.5 · `dt_s`).
    pub max_gap_s: f64,
}

impl TimeBase {
    /// The grid with the default gap (1.5 · `dt_s`: one missing step of data at the model's rate is not bridged).
    pub fn new(t_obs: usize, dt_s: f64) -> Result<Self> {
        Self::with_max_gap(t_obs, dt_s, 1.5 * dt_s)
    }

    /// The grid with an explicit gap.
    pub fn with_max_gap(t_obs: usize, dt_s: f64, max_gap_s: f64) -> Result<Self> {
        if t_obs == 0 || t_obs > crate::spec::MAX_STEPS {
            return Err(DganError::InvalidSpec(format!(
                "t_obs must be in 1..={}, got {t_obs}",
                crate::spec::MAX_STEPS
            )));
        }
        if !(dt_s.is_finite() && dt_s > 0.0) {
            return Err(DganError::TimeBase(format!("dt must be a positive number of seconds, got {dt_s}")));
        }
        if !(max_gap_s.is_finite() && max_gap_s >= 0.0) {
            return Err(DganError::TimeBase(format!(
                "max_gap must be a non-negative number of seconds, got {max_gap_s}"
            )));
        }
        Ok(Self { t_obs, dt_s, max_gap_s })
    }

    /// The earliest detection time a frame at `now_s` can use: the oldest grid time less the longest gap bridged.
    /// [`frame_at`] reads from here and [`Tracker`] forgets what is older, so the two agree.
    fn window_start(&self, now_s: f64) -> f64 {
        self.time_of(now_s, 0) - self.max_gap_s - self.eps()
    }

    /// The grid time of step `k` (0 = oldest) for the current time `now_s`.
    fn time_of(&self, now_s: f64, k: usize) -> f64 {
        now_s - (self.t_obs - 1 - k) as f64 * self.dt_s
    }

    fn eps(&self) -> f64 {
        self.dt_s * TIME_TOLERANCE
    }
}

/// The position of a track (sorted by time) at `t`, if seen then or interpolable.
fn sample(track: &[Detection], t: f64, base: &TimeBase) -> Option<[f64; 2]> {
    let eps = base.eps();
    let j = track.partition_point(|d| d.time_s < t - eps);
    let next = track.get(j)?;
    if (next.time_s - t).abs() <= eps {
        return Some(next.position);
    }
    let prev = track.get(j.checked_sub(1)?)?;
    let gap = next.time_s - prev.time_s;
    if gap > base.max_gap_s + eps || gap <= 0.0 {
        return None;
    }
    let w = (t - prev.time_s) / gap;
    Some([
        prev.position[0] + w * (next.position[0] - prev.position[0]),
        prev.position[1] + w * (next.position[1] - prev.position[1]),
    ])
}

/// One track's positions at the times `at_s`, as a frame on `base` samples them: a detection within `base.dt_s` ·
/// [`TIME_TOLERANCE`] of a time is taken as it is, a time between two detections at most `base.max_gap_s` apart is
/// interpolated linearly, any other is `None` (no wider gap is bridged, nothing outside the track extrapolated).
/// Training resamples whole recordings onto another rate with it, so its tracks are the ones a frame of [`frame_at`]
/// would hold. `times_s` must increase strictly; times and positions must be finite.
pub fn sample_track(
    times_s: &[f64],
    positions: &[[f64; 2]],
    at_s: &[f64],
    base: &TimeBase,
) -> Result<Vec<Option<[f64; 2]>>> {
    if times_s.len() != positions.len() {
        return Err(DganError::InvalidFrame(format!(
            "a track needs one position per time, got {} times and {} positions",
            times_s.len(),
            positions.len()
        )));
    }
    if let Some(i) = times_s.iter().position(|t| !t.is_finite()) {
        return Err(DganError::InvalidFrame(format!("the track's time {i} is not finite: {}", times_s[i])));
    }
    if let Some(i) = positions.iter().position(|p| !(p[0].is_finite() && p[1].is_finite())) {
        return Err(DganError::InvalidFrame(format!("the track's position {i} is not finite: {:?}", positions[i])));
    }
    if let Some(w) = times_s.windows(2).find(|w| w[0] >= w[1]) {
        return Err(DganError::InvalidFrame(format!(
            "a track's times must increase strictly; got {} then {}",
            w[0], w[1]
        )));
    }
    if let Some(t) = at_s.iter().find(|t| !t.is_finite()) {
        return Err(DganError::InvalidFrame(format!("the times to sample at must be finite, got {t}")));
    }
    let track: Vec<Detection> = times_s.iter().zip(positions).map(|(&t, p)| Detection::at(t, p[0], p[1])).collect();
    Ok(at_s.iter().map(|&t| sample(&track, t, base)).collect())
}

/// The median spacing of the detections within the window of every agent, if any agent has two.
fn median_spacing(tracks: &[(i64, &[Detection])]) -> Option<f64> {
    let mut gaps: Vec<f64> =
        tracks.iter().flat_map(|(_, tr)| tr.windows(2).map(|w| w[1].time_s - w[0].time_s)).collect();
    if gaps.is_empty() {
        return None;
    }
    let mid = gaps.len() / 2;
    let (_, m, _) = gaps.select_nth_unstable_by(mid, f64::total_cmp);
    Some(*m)
}

/// Each track's detections a frame at `now_s` on `base` can use (checked sorted).
fn windows_at<'a>(
    tracks: &[(i64, &'a [Detection])],
    now_s: f64,
    base: &TimeBase,
) -> Result<Vec<(i64, &'a [Detection])>> {
    let eps = base.eps();
    let window_start = base.window_start(now_s);
    let mut windows: Vec<(i64, &[Detection])> = Vec::with_capacity(tracks.len());
    for (id, track) in tracks {
        if let Some(w) =
            track.windows(2).find(|w| w[0].time_s.partial_cmp(&w[1].time_s) != Some(std::cmp::Ordering::Less))
        {
            return Err(DganError::TimeBase(format!(
                "agent {id}: detections must have increasing, distinct times; got {} then {}",
                w[0].time_s, w[1].time_s
            )));
        }
        let lo = track.partition_point(|d| d.time_s < window_start);
        let hi = track.partition_point(|d| d.time_s <= now_s + eps);
        windows.push((*id, &track[lo..hi]));
    }
    Ok(windows)
}

/// Why data sampled every `spacing_s` cannot fill a grid `dt_s` apart, and what would.
fn sparse_message(spacing_s: f64, dt_s: f64, upsampling: bool) -> String {
    let ratio = spacing_s / dt_s;
    let how = if upsampling || ratio > UPSAMPLE_LIMIT * (1.0 + SPARSE_SLACK) {
        format!("more than {UPSAMPLE_LIMIT}× sparser cannot be resampled to its grid without inventing motion")
    } else {
        format!("upsampling (upsample=True in Python) interpolates data up to {UPSAMPLE_LIMIT}× sparser onto its grid")
    };
    format!(
        "the data are sampled every {spacing_s:.4} s (median), {ratio:.2}× the model's dt = {dt_s} s, sparser than \
         its grid; {how}"
    )
}

/// A frame built from detections, with how the data's rate met the grid.
#[derive(Debug, Clone)]
pub struct Resampled {
    /// The frame on the model's grid.
    pub frame: Frame,
    /// The data's median spacing within the window in seconds (`None` when no agent had two detections there).
    pub spacing_s: Option<f64>,
    /// Whether the data were sparser than the grid and interpolated onto it.
    pub upsampled: bool,
}

/// The frame at `now_s` from each agent's detections, sorted by time (checked), one track per id.
///
/// Agents without a detection at `now_s` are left out; ids keep the order given. `default_class` is used where a
/// detection carries no class. The frame's time base is `base.dt_s`. Data sparser than the grid are refused
/// ([`DganError::SparseData`]); [`frame_at_with`] can upsample them.
pub fn frame_at(
    tracks: &[(i64, &[Detection])],
    now_s: f64,
    base: &TimeBase,
    default_class: AgentClass,
) -> Result<Frame> {
    frame_at_with(tracks, now_s, base, default_class, false).map(|r| r.frame)
}

/// [`frame_at`], and with `upsample` data up to [`UPSAMPLE_LIMIT`]× sparser than the grid are interpolated onto
/// it: the gap bridged grows to at least 1.5× the data's median spacing (one missing detection is still not bridged).
pub fn frame_at_with(
    tracks: &[(i64, &[Detection])],
    now_s: f64,
    base: &TimeBase,
    default_class: AgentClass,
    upsample: bool,
) -> Result<Resampled> {
    frame_and_base_at(tracks, now_s, base, default_class, upsample).map(|(r, _)| r)
}

/// [`frame_at_with`] and the time base it sampled with (its gap widened where the data were upsampled).
fn frame_and_base_at(
    tracks: &[(i64, &[Detection])],
    now_s: f64,
    base: &TimeBase,
    default_class: AgentClass,
    upsample: bool,
) -> Result<(Resampled, TimeBase)> {
    if !now_s.is_finite() {
        return Err(DganError::TimeBase(format!("the current time must be finite, got {now_s}")));
    }
    let mut base = *base;
    let mut windows = windows_at(tracks, now_s, &base)?;
    let spacing_s = median_spacing(&windows);
    let mut upsampled = false;
    if let Some(spacing) = spacing_s {
        if spacing > base.dt_s * (1.0 + SPARSE_SLACK) {
            if !upsample || spacing > base.dt_s * UPSAMPLE_LIMIT * (1.0 + SPARSE_SLACK) {
                let message = sparse_message(spacing, base.dt_s, upsample);
                return Err(DganError::SparseData { spacing_s: spacing, message });
            }
            upsampled = true;
            base.max_gap_s = base.max_gap_s.max(1.5 * spacing);
            windows = windows_at(tracks, now_s, &base)?;
        }
    }
    let frame = frame_from_windows(windows, now_s, &base, default_class)?;
    Ok((Resampled { frame, spacing_s, upsampled }, base))
}

/// What each agent of a frame did next: its positions at the `t_f` grid times after the frame's current time.
#[derive(Debug, Clone)]
pub struct Future {
    /// `(N, t_f, 2)` world positions, NaN where the agent was not seen (nor interpolable).
    pub positions: Array3<f64>,
    /// `(N, t_f)` whether each step was seen.
    pub mask: Array2<bool>,
}

/// [`frame_at_with`], and what each of its agents did over the `t_f` grid steps after `now_s` ([`Future`]),
/// sampled from the same tracks as the frame samples their past (the same gaps bridged, nothing extrapolated): the
/// ground truth an evaluation scores the frame's prediction against, on the model's own grid.
pub fn frame_and_future_at(
    tracks: &[(i64, &[Detection])],
    now_s: f64,
    base: &TimeBase,
    default_class: AgentClass,
    upsample: bool,
    t_f: usize,
) -> Result<(Resampled, Future)> {
    if t_f > crate::spec::MAX_STEPS {
        return Err(DganError::InvalidSpec(format!("t_f must be in 0..={}, got {t_f}", crate::spec::MAX_STEPS)));
    }
    let (resampled, sampled_on) = frame_and_base_at(tracks, now_s, base, default_class, upsample)?;
    let ids = resampled.frame.ids();
    let mut positions = Array3::<f64>::from_elem((ids.len(), t_f, 2), f64::NAN);
    let mut mask = Array2::<bool>::from_elem((ids.len(), t_f), false);
    if t_f == 0 {
        return Ok((resampled, Future { positions, mask })); // a frame alone (`Frame.from_records`): no lookup
    }
    let by_id: std::collections::HashMap<i64, &[Detection]> = tracks.iter().copied().collect();
    for (i, id) in ids.iter().enumerate() {
        let track = by_id.get(id).copied().unwrap_or_default();
        for k in 0..t_f {
            if let Some(p) = sample(track, now_s + (k + 1) as f64 * sampled_on.dt_s, &sampled_on) {
                positions[[i, k, 0]] = p[0];
                positions[[i, k, 1]] = p[1];
                mask[[i, k]] = true;
            }
        }
    }
    Ok((resampled, Future { positions, mask }))
}

/// The frame of the agents seen at `now_s`, each sampled at the grid times.
fn frame_from_windows(
    windows: Vec<(i64, &[Detection])>,
    now_s: f64,
    base: &TimeBase,
    default_class: AgentClass,
) -> Result<Frame> {
    let eps = base.eps();
    let current: Vec<(i64, &[Detection])> =
        windows.into_iter().filter(|(_, w)| w.last().is_some_and(|d| (d.time_s - now_s).abs() <= eps)).collect();
    let (n, t) = (current.len(), base.t_obs);
    let mut positions = Array3::<f64>::from_elem((n, t, 2), f64::NAN);
    let mut mask = Array2::<bool>::from_elem((n, t), false);
    let mut classes = Vec::with_capacity(n);
    let (mut ids, mut headings, mut lengths, mut widths) =
        (Vec::with_capacity(n), Vec::with_capacity(n), Vec::with_capacity(n), Vec::with_capacity(n));
    let mut velocities = Array2::<f64>::from_elem((n, 2), f64::NAN);
    for (i, (id, track)) in current.iter().enumerate() {
        for k in 0..t {
            if let Some(p) = sample(track, base.time_of(now_s, k), base) {
                positions[[i, k, 0]] = p[0];
                positions[[i, k, 1]] = p[1];
                mask[[i, k]] = true;
            }
        }
        let last = track.last().ok_or_else(|| DganError::TimeBase("empty track".into()))?;
        ids.push(*id);
        classes.push(last.class.unwrap_or(default_class));
        headings.push(last.heading);
        lengths.push(last.length);
        widths.push(last.width);
        velocities[[i, 0]] = last.velocity[0];
        velocities[[i, 1]] = last.velocity[1];
    }
    Frame::new(positions, Some(mask), classes)?
        .with_ids(ids)?
        .with_headings(&headings)?
        .with_velocities(velocities.view())?
        .with_lengths(&lengths)?
        .with_widths(&widths)?
        .with_dt(base.dt_s)
}

/// Rows of a long table (one per agent and time, any order) grouped into tracks sorted by id, then time.
///
/// Two rows of one agent at the same time are refused, even when equal: the table is ambiguous
/// ([`tracks_from_rows_with`] can keep one or their mean).
pub fn tracks_from_rows(rows: Vec<(i64, Detection)>) -> Result<Vec<(i64, Vec<Detection>)>> {
    tracks_from_rows_with(rows, Duplicates::Error)
}

/// [`tracks_from_rows`], with several rows of one agent at one time resolved by `duplicates`.
pub fn tracks_from_rows_with(
    rows: Vec<(i64, Detection)>,
    duplicates: Duplicates,
) -> Result<Vec<(i64, Vec<Detection>)>> {
    let mut by_id: BTreeMap<i64, Vec<Detection>> = BTreeMap::new();
    for (id, d) in rows {
        if !d.time_s.is_finite() {
            return Err(DganError::InvalidFrame(format!("agent {id} has a row at a non-finite time {}", d.time_s)));
        }
        by_id.entry(id).or_default().push(d);
    }
    let mut out = Vec::with_capacity(by_id.len());
    for (id, mut track) in by_id {
        // Stable: rows at one time keep the table's order, which "first" and "last" follow.
        track.sort_by(|a, b| a.time_s.total_cmp(&b.time_s));
        if let Some(w) = track.windows(2).find(|w| w[0].time_s == w[1].time_s) {
            if duplicates == Duplicates::Error {
                return Err(DganError::InvalidFrame(format!(
                    "agent {id} has two rows at time {} s; keep one row per agent and time, or choose how \
                     (duplicates=\"first\", \"last\" or \"mean\" in Python)",
                    w[0].time_s
                )));
            }
            track = merge_duplicates(track, duplicates);
        }
        out.push((id, track));
    }
    Ok(out)
}

/// A track sorted by time with every run of equal times merged into one detection.
fn merge_duplicates(track: Vec<Detection>, how: Duplicates) -> Vec<Detection> {
    let mut out: Vec<Detection> = Vec::with_capacity(track.len());
    let mut group: Vec<Detection> = Vec::new();
    for d in track {
        if group.first().is_some_and(|g| g.time_s != d.time_s) {
            out.push(merge(std::mem::take(&mut group), how));
        }
        group.push(d);
    }
    if !group.is_empty() {
        out.push(merge(group, how));
    }
    out
}

fn merge(mut group: Vec<Detection>, how: Duplicates) -> Detection {
    match how {
        Duplicates::Last => group.pop().expect("a group holds a detection"),
        Duplicates::Mean if group.len() > 1 => {
            let mean = |f: &dyn Fn(&Detection) -> f64| {
                let v: Vec<f64> = group.iter().map(f).filter(|x| !x.is_nan()).collect();
                if v.is_empty() {
                    f64::NAN
                } else {
                    v.iter().sum::<f64>() / v.len() as f64
                }
            };
            let (s, c) = (mean(&|d| d.heading.sin()), mean(&|d| d.heading.cos()));
            let mut out = group[0].clone();
            out.position = [mean(&|d| d.position[0]), mean(&|d| d.position[1])];
            out.heading = if s.is_nan() { f64::NAN } else { s.atan2(c) };
            out.length = mean(&|d| d.length);
            out.width = mean(&|d| d.width);
            out.velocity = [mean(&|d| d.velocity[0]), mean(&|d| d.velocity[1])];
            out
        }
        _ => group.swap_remove(0),
    }
}

/// Streams of detections, one tick at a time, kept at a model's time base: agents appear, vanish and return; the
/// frame at any tick equals [`frame_at`] on the same detections given at once (agents by increasing id).
#[derive(Debug, Clone)]
pub struct Tracker {
    base: TimeBase,
    default_class: AgentClass,
    tracks: BTreeMap<i64, Vec<Detection>>,
    now_s: Option<f64>,
}

impl Tracker {
    /// An empty tracker on `base`; detections without a class get `default_class`.
    pub fn new(base: TimeBase, default_class: AgentClass) -> Self {
        Self { base, default_class, tracks: BTreeMap::new(), now_s: None }
    }

    /// The time base.
    pub fn time_base(&self) -> &TimeBase {
        &self.base
    }

    /// The latest tick's time, if any.
    pub fn now_s(&self) -> Option<f64> {
        self.now_s
    }

    /// Agents remembered (seen within the history window of the latest tick).
    pub fn len(&self) -> usize {
        self.tracks.len()
    }

    /// Whether no agent is remembered.
    pub fn is_empty(&self) -> bool {
        self.tracks.is_empty()
    }

    /// The ids of the agents remembered, increasing: a caller that maps its own ids to these can forget the rest.
    pub fn ids(&self) -> impl Iterator<Item = i64> + '_ {
        self.tracks.keys().copied()
    }

    /// What the tracker remembers: each agent's detections, oldest first, by id. With [`Tracker::now_s`], what
    /// [`Tracker::restore`] takes to give the same tracker back (a service saving its state, a copy to explore).
    pub fn tracks(&self) -> &BTreeMap<i64, Vec<Detection>> {
        &self.tracks
    }

    /// A tracker on `base` that remembers `tracks` (as [`Tracker::tracks`] gives them) at the latest tick `now_s`:
    /// its frames from there on are those of the tracker they were saved from. Refuses what no tracker could hold:
    /// detections without a tick (`now_s` None), after `now_s`, not in increasing time order, an empty track, or a
    /// time or position that is not finite.
    pub fn restore(
        base: TimeBase,
        default_class: AgentClass,
        tracks: BTreeMap<i64, Vec<Detection>>,
        now_s: Option<f64>,
    ) -> Result<Self> {
        let bad = |what: String| Err(DganError::InvalidFrame(format!("cannot restore the tracker: {what}")));
        match now_s {
            None if !tracks.is_empty() => return bad("detections but no tick".into()),
            Some(now) if !now.is_finite() => return bad(format!("the latest tick {now} is not finite")),
            _ => {}
        }
        let now = now_s.unwrap_or(f64::INFINITY);
        for (id, track) in &tracks {
            if track.is_empty() {
                return bad(format!("agent {id} has no detection"));
            }
            let finite = track.iter().all(|d| d.time_s.is_finite() && d.position.iter().all(|p| p.is_finite()));
            let ordered = track.windows(2).all(|w| w[0].time_s < w[1].time_s);
            if !finite || !ordered || track.last().is_some_and(|d| d.time_s > now) {
                return bad(format!("agent {id}'s detections are not finite, increasing times up to the latest tick"));
            }
        }
        let mut tracker = Self { base, default_class, tracks, now_s };
        if let Some(now) = now_s {
            tracker.forget(now);
        }
        Ok(tracker)
    }

    /// Adds one tick: every agent detected at `time_s` (unique ids). Ticks must come in increasing time order.
    /// Detections older than the history window are forgotten, so memory stays bounded.
    pub fn update(&mut self, time_s: f64, detections: Vec<(i64, Detection)>) -> Result<()> {
        if !time_s.is_finite() {
            return Err(DganError::TimeBase(format!("tick time must be finite, got {time_s}")));
        }
        if let Some(now) = self.now_s {
            if time_s <= now {
                return Err(DganError::TimeBase(format!(
                    "ticks must come in increasing time order: {time_s} s after {now} s"
                )));
            }
        }
        let mut seen = HashSet::with_capacity(detections.len());
        for (id, d) in &detections {
            if !seen.insert(*id) {
                return Err(DganError::InvalidFrame(format!("agent id {id} appears twice in one tick")));
            }
            if !(d.position[0].is_finite() && d.position[1].is_finite()) {
                return Err(DganError::InvalidFrame(format!("agent {id} has a non-finite position {:?}", d.position)));
            }
        }
        for (id, mut d) in detections {
            d.time_s = time_s;
            self.tracks.entry(id).or_default().push(d);
        }
        self.now_s = Some(time_s);
        self.forget(time_s);
        Ok(())
    }

    /// Drops what no later frame can use: detections before the window (keeping one before it for interpolation),
    /// and agents with nothing left.
    fn forget(&mut self, now_s: f64) {
        let start = self.base.window_start(now_s);
        self.tracks.retain(|_, track| {
            let lo = track.partition_point(|d| d.time_s < start);
            track.drain(..lo);
            !track.is_empty()
        });
    }

    /// The frame at the latest tick: the agents detected then, by increasing id.
    pub fn frame(&self) -> Result<Frame> {
        let now = self.now_s.ok_or_else(|| DganError::TimeBase("the tracker has had no tick yet".into()))?;
        let tracks: Vec<(i64, &[Detection])> = self.tracks.iter().map(|(id, t)| (*id, t.as_slice())).collect();
        frame_at(&tracks, now, &self.base, self.default_class)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn line(id: i64, times: &[f64], speed: f64) -> (i64, Vec<Detection>) {
        (id, times.iter().map(|&t| Detection::at(t, speed * t, 1.0)).collect())
    }

    #[test]
    fn dense_data_resample_to_the_grid_exactly_on_a_line() {
        let times: Vec<f64> = (0..=40).map(|i| f64::from(i) * 0.1).collect();
        let (id, tr) = line(7, &times, 2.0);
        let base = TimeBase::new(8, 0.4).unwrap();
        let f = frame_at(&[(id, &tr)], 4.0, &base, AgentClass::Pedestrian).unwrap();
        assert_eq!(f.ids(), &[7]);
        assert_eq!(f.dt_s(), Some(0.4));
        for k in 0..8 {
            let t = 4.0 - (7 - k) as f64 * 0.4;
            assert!((f.positions()[[0, k, 0]] - 2.0 * t).abs() < 1e-9);
            assert!(f.mask()[[0, k]]);
        }
    }

    #[test]
    fn a_track_is_sampled_as_a_frame_samples_it() {
        let times = [0.0, 0.5, 1.0, 2.0];
        let xy = [[0.0, 0.0], [1.0, 2.0], [2.0, 4.0], [4.0, 8.0]];
        let at = [0.0, 0.25, 1.0, 1.5, 2.0, 2.5, -0.1];
        let got = sample_track(&times, &xy, &at, &TimeBase::with_max_gap(1, 0.25, 0.5).unwrap()).unwrap();
        assert_eq!(got[0], Some([0.0, 0.0]));
        assert_eq!(got[1], Some([0.5, 1.0]));
        assert_eq!(got[2], Some([2.0, 4.0]));
        assert_eq!(got[3], None); // between 1.0 and 2.0: a gap of 1 s, wider than 0.5
        assert_eq!(got[4], Some([4.0, 8.0]));
        assert_eq!(&got[5..], &[None, None]); // nothing extrapolated

        // The same positions as a frame of the same grid holds, its gap (step 1.25) left out too.
        let times = [0.0, 0.25, 0.5, 0.75, 1.0, 1.5, 1.75];
        let xy: Vec<[f64; 2]> = times.iter().map(|&t| [3.0 * t, 1.0 - t * t]).collect();
        let track: Vec<Detection> = times.iter().zip(&xy).map(|(&t, p)| Detection::at(t, p[0], p[1])).collect();
        let base = TimeBase::new(8, 0.25).unwrap();
        let f = frame_at(&[(1, &track)], 1.75, &base, AgentClass::Pedestrian).unwrap();
        let grid: Vec<f64> = (0..8).map(|k| f64::from(k) * 0.25).collect();
        let samples = sample_track(&times, &xy, &grid, &base).unwrap();
        for (k, p) in samples.iter().enumerate() {
            assert_eq!(p.is_some(), f.mask()[[0, k]]);
            if let Some(p) = p {
                assert_eq!([f.positions()[[0, k, 0]], f.positions()[[0, k, 1]]], *p);
            }
        }
        assert!(samples[5].is_none());
    }

    #[test]
    fn a_future_is_the_frame_of_the_later_time() {
        // Agent 1 walks at 1 m/s with a jittered clock; agent 2 leaves after 2.0 s; agent 3 skips a step at 2.4 s.
        let base = TimeBase::new(4, 0.4).unwrap();
        let mut rows = Vec::new();
        for k in 0..12 {
            let t = f64::from(k) * 0.4;
            let jitter = if k % 2 == 0 { 0.01 } else { -0.01 };
            rows.push((1, Detection::at(t + jitter, t + jitter, 0.0)));
            if t <= 2.0 {
                rows.push((2, Detection::at(t, 0.0, t)));
            }
            if k != 6 {
                rows.push((3, Detection::at(t, -t, 1.0)));
            }
        }
        rows.push((1, Detection::at(1.2, 1.2, 0.0))); // the current time itself, as a row
        let tracks = tracks_from_rows(rows).unwrap();
        let views: Vec<(i64, &[Detection])> = tracks.iter().map(|(i, t)| (*i, t.as_slice())).collect();
        let (r, future) = frame_and_future_at(&views, 1.2, &base, AgentClass::Pedestrian, false, 5).unwrap();
        assert_eq!(r.frame.ids(), [1, 2, 3]);
        assert_eq!(future.positions.dim(), (3, 5, 2));
        // Each future step is what the frame ending at that step holds there.
        for k in 1..=5 {
            let later = frame_at(&views, 1.2 + 0.4 * f64::from(k), &base, AgentClass::Pedestrian);
            for (i, id) in [1, 2, 3].iter().enumerate() {
                let row = later.as_ref().ok().and_then(|f| f.ids().iter().position(|x| x == id));
                let seen = future.mask[[i, k as usize - 1]];
                if let (Some(j), true) = (row, seen) {
                    let f = later.as_ref().unwrap();
                    let p = [f.positions()[[j, 3, 0]], f.positions()[[j, 3, 1]]];
                    assert_eq!(p, [future.positions[[i, k as usize - 1, 0]], future.positions[[i, k as usize - 1, 1]]]);
                }
            }
        }
        assert!((future.positions[[0, 4, 0]] - 3.2).abs() < 1e-12); // interpolated across the jitter
        assert_eq!(future.mask.row(1).to_vec(), [true, true, false, false, false]); // gone after 2.0 s
        assert_eq!(future.mask.row(2).to_vec(), [true, true, false, true, true]); // the step it skipped
        assert!(future.positions[[1, 2, 0]].is_nan());
        let err = frame_and_future_at(&views, 1.2, &base, AgentClass::Pedestrian, false, 100_000).unwrap_err();
        assert!(matches!(err, DganError::InvalidSpec(_)), "{err}");
    }

    #[test]
    fn a_bad_track_is_refused() {
        let xy = [[0.0, 0.0], [1.0, 1.0]];
        let base = TimeBase::with_max_gap(1, 0.5, 1.0).unwrap();
        for (times, at) in [
            (vec![1.0, 0.0], vec![0.5]),
            (vec![0.0, 0.0], vec![0.5]),
            (vec![0.0, f64::NAN], vec![0.5]),
            (vec![0.0, 1.0], vec![f64::INFINITY]),
            (vec![0.0], vec![0.5]),
        ] {
            let err = sample_track(&times, &xy, &at, &base).unwrap_err();
            assert!(matches!(err, DganError::InvalidFrame(_)), "{err}");
        }
        let err = sample_track(&[0.0, 1.0], &[[0.0, f64::NAN], [1.0, 1.0]], &[0.5], &base).unwrap_err();
        assert!(matches!(err, DganError::InvalidFrame(_)), "{err}");
        assert_eq!(sample_track(&[], &[], &[0.5], &base).unwrap(), vec![None]);
    }

    #[test]
    fn gaps_are_masked_and_absent_agents_left_out() {
        let base = TimeBase::new(4, 1.0).unwrap();
        let (a, ta) = line(1, &[0.0, 1.0, 3.0], 1.0); // step 2 missing
        let (b, tb) = line(2, &[0.0, 1.0, 2.0], 1.0); // not seen now
        let f = frame_at(&[(a, &ta), (b, &tb)], 3.0, &base, AgentClass::Vehicle).unwrap();
        assert_eq!(f.ids(), &[1]);
        assert_eq!(f.mask().row(0).to_vec(), vec![true, true, false, true]);
        assert_eq!(f.classes(), &[AgentClass::Vehicle]);
    }

    #[test]
    fn sparse_data_and_bad_times_are_refused() {
        let base = TimeBase::new(4, 0.4).unwrap();
        let (a, ta) = line(1, &[0.0, 0.5, 1.0, 1.5], 1.0);
        let err = frame_at(&[(a, &ta)], 1.5, &base, AgentClass::Pedestrian).unwrap_err();
        assert!(matches!(err, DganError::SparseData { .. }), "{err}");
        assert!(err.to_string().contains("upsample=True"), "{err}");
        let (b, tb) = line(1, &[0.0, 0.4, 0.4], 1.0);
        assert!(matches!(frame_at(&[(b, &tb)], 0.4, &base, AgentClass::Pedestrian), Err(DganError::TimeBase(_))));
        assert!(TimeBase::new(4, 0.0).is_err());
        assert!(TimeBase::new(0, 0.4).is_err());
        assert!(matches!(TimeBase::with_max_gap(4, 0.4, -1.0), Err(DganError::TimeBase(_))));
    }

    #[test]
    fn upsampling_interpolates_data_up_to_the_limit_onto_the_grid() {
        let base = TimeBase::new(8, 0.4).unwrap();
        let times: Vec<f64> = (0..=8).map(|i| f64::from(i) * 0.5).collect(); // 2 Hz on a 0.4 s grid
        let (a, ta) = line(1, &times, 1.5);
        let r = frame_at_with(&[(a, &ta)], 4.0, &base, AgentClass::Pedestrian, true).unwrap();
        assert!(r.upsampled);
        assert_eq!(r.spacing_s, Some(0.5));
        assert!(r.frame.mask().iter().all(|&m| m));
        for k in 0..8 {
            let t = 4.0 - (7 - k) as f64 * 0.4;
            assert!((r.frame.positions()[[0, k, 0]] - 1.5 * t).abs() < 1e-9);
        }
        let dense = frame_at_with(&[(a, &ta)], 4.0, &TimeBase::new(8, 0.5).unwrap(), AgentClass::Pedestrian, true);
        assert!(!dense.unwrap().upsampled);
        let times: Vec<f64> = (0..=4).map(|i| f64::from(i) * 1.2).collect(); // 3× sparser
        let (b, tb) = line(2, &times, 1.0);
        let err = frame_at_with(&[(b, &tb)], 4.8, &base, AgentClass::Pedestrian, true).unwrap_err();
        assert!(matches!(err, DganError::SparseData { .. }), "{err}");
        assert!(err.to_string().contains("more than 2.5× sparser"), "{err}");
    }

    #[test]
    fn duplicate_rows_are_refused_or_merged_as_asked() {
        let rows = || {
            let mut a = Detection::at(1.0, 0.0, 0.0);
            a.heading = 3.1;
            let mut b = Detection::at(1.0, 2.0, 4.0);
            b.heading = -3.1;
            vec![(5, Detection::at(0.0, 9.0, 9.0)), (5, a), (5, b)]
        };
        let err = tracks_from_rows(rows()).unwrap_err();
        assert!(err.to_string().contains("duplicates="), "{err}");
        let pos = |how: Duplicates| tracks_from_rows_with(rows(), how).unwrap()[0].1[1].position;
        assert_eq!(pos(Duplicates::First), [0.0, 0.0]);
        assert_eq!(pos(Duplicates::Last), [2.0, 4.0]);
        assert_eq!(pos(Duplicates::Mean), [1.0, 2.0]);
        let mean = &tracks_from_rows_with(rows(), Duplicates::Mean).unwrap()[0].1;
        assert_eq!(mean.len(), 2);
        assert!((mean[1].heading.abs() - std::f64::consts::PI).abs() < 1e-9, "{}", mean[1].heading);
        assert!("median".parse::<Duplicates>().is_err());
        assert_eq!("mean".parse::<Duplicates>().unwrap(), Duplicates::Mean);
    }

    #[test]
    fn the_tracker_equals_the_frame_built_at_once() {
        let base = TimeBase::new(3, 0.4).unwrap();
        let mut tracker = Tracker::new(base, AgentClass::Pedestrian);
        let mut all: BTreeMap<i64, Vec<Detection>> = BTreeMap::new();
        for tick in 0..30 {
            let t = f64::from(tick) * 0.4;
            // agent 1 always; agent 2 vanishes for ticks 10..15; agent 3 appears at 20
            let mut dets = vec![(1, Detection::at(t, t, 0.0))];
            if !(10..15).contains(&tick) {
                dets.push((2, Detection::at(t, -t, 2.0)));
            }
            if tick >= 20 {
                dets.push((3, Detection::at(t, 0.0, t)));
            }
            for (id, d) in &dets {
                all.entry(*id).or_default().push(d.clone());
            }
            tracker.update(t, dets).unwrap();
            if tick == 13 {
                assert_eq!(tracker.ids().collect::<Vec<_>>(), [1], "agent 2 forgotten while away");
            }
            let streamed = tracker.frame().unwrap();
            let tracks: Vec<(i64, &[Detection])> = all.iter().map(|(i, v)| (*i, v.as_slice())).collect();
            let once = frame_at(&tracks, t, &base, AgentClass::Pedestrian).unwrap();
            assert_eq!(streamed.ids(), once.ids());
            assert_eq!(streamed.mask(), once.mask());
            let same = |a: f64, b: f64| a == b || (a.is_nan() && b.is_nan());
            assert!(streamed.positions().iter().zip(once.positions()).all(|(a, b)| same(*a, *b)));
        }
        assert!(tracker.len() <= 3);
        assert_eq!(tracker.ids().collect::<Vec<_>>(), [1, 2, 3]);
        assert!(tracker.update(1.0, vec![]).is_err());
        // Saved and restored, it goes on as the tracker it was saved from.
        let mut copy =
            Tracker::restore(base, AgentClass::Pedestrian, tracker.tracks().clone(), tracker.now_s()).unwrap();
        for t in [12.0, 12.4, 12.8] {
            tracker.update(t, vec![(1, Detection::at(t, t, 0.0)), (4, Detection::at(t, 1.0, t))]).unwrap();
            copy.update(t, vec![(1, Detection::at(t, t, 0.0)), (4, Detection::at(t, 1.0, t))]).unwrap();
            let (a, b) = (tracker.frame().unwrap(), copy.frame().unwrap());
            assert_eq!((a.ids(), a.mask()), (b.ids(), b.mask()));
            assert!(a.positions().iter().zip(b.positions()).all(|(x, y)| x == y || (x.is_nan() && y.is_nan())));
        }
        let late = BTreeMap::from([(1, vec![Detection::at(20.0, 0.0, 0.0)])]);
        assert!(Tracker::restore(base, AgentClass::Pedestrian, late.clone(), Some(12.8)).is_err());
        assert!(Tracker::restore(base, AgentClass::Pedestrian, late, None).is_err());
        let unordered = BTreeMap::from([(1, vec![Detection::at(1.0, 0.0, 0.0), Detection::at(0.6, 0.0, 0.0)])]);
        assert!(Tracker::restore(base, AgentClass::Pedestrian, unordered, Some(1.0)).is_err());
    }
}
