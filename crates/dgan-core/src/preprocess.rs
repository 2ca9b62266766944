//! Frame → the exact tensors the network receives. Training calls this same code through the Python bindings, so
//! training and inference cannot drift.

use crate::error::{invalid_frame, DganError, Result};
use crate::frame::Frame;
use crate::graph::{attention_radius, attention_zone_edges_on};
use crate::limits::share_jobs;
use crate::raster::{rasterize_on, threads_in_flight};
use crate::spec::{GraphLayout, InputSpec, MapSpec, EDGE_FEATURES, STATE_FEATURES};
use crate::state::{traffic_states_with, TrafficState};
use crate::transform::{wrap_angle, AgentPose};
use ndarray::{Array1, Array2, Array3, Array4, Array5};

/// The version of the features (state and edge columns, agent-centric transforms, graph, prior). Bump it with any
/// change to what the network receives: exporters write it into each model's contract (`preprocess_version`), a
/// model exported with another is refused, and the training window cache is keyed by it.
pub const PREPROCESS_VERSION: u32 = 1;

/// The network's input tensors (see `docs/model-contract.md`).
#[derive(Debug, Clone)]
pub struct NetworkInputs {
    /// `(N, T_obs, 2)` agent-centric observed positions, zero at invalid steps.
    pub trajectory: Array3<f32>,
    /// `(N, T_obs)` 1 where a step was observed, else 0.
    pub trajectory_mask: Array2<f32>,
    /// `(N, 7 + C)` traffic state: speed, acceleration, yaw rate, direction of motion in the agent frame (cos, sin),
    /// length, width, one-hot class.
    pub state: Array2<f32>,
    /// `(E, 2)` directed edges `[receiver, sender]`, self-loops included, sorted.
    pub edge_index: Array2<i64>,
    /// `(E, 6)` the sender's position, velocity relative to the receiver's, and heading, in the receiver's frame.
    pub edge_features: Array2<f32>,
    /// `(N, 3, H, W)` agent-centric map crops, for models with a map branch (zeros where the frame has no map).
    pub map: Option<Array4<f32>>,
    /// `(N,)` 1 where the crop holds a map, 0 where the frame has none: for models whose map is optional.
    pub map_present: Option<Array1<f32>>,
    /// `(F, M, gh, gw, 2)` where each frame's agents read its scene raster (`map`, `(F, 3, S, S)`), padded to the
    /// frame with the most agents: for scene models (contract 12, [`crate::scene`]).
    pub map_grid: Option<Array5<f32>>,
    /// `(N,)` each agent's row of `map_grid` flattened to `(F · M, ..)`: for scene models.
    pub map_slot: Option<Array1<i64>>,
    /// For scene models whose features are kept with the map (contract 13, [`crate::kept`]): the kept rows the call
    /// reads and each agent's rows and weights; `map` then holds the rasters of the tiles the call computes.
    pub kept: Option<crate::kept::KeptReads>,
    /// The same graph as each agent's padded list of senders, for models of the padded layout (contract 3).
    pub neighbors: Option<Neighbors>,
}

/// Each agent's senders (itself included, ascending), padded to the frame's largest degree D.
#[derive(Debug, Clone)]
pub struct Neighbors {
    /// `(N, D)` sender rows; padding repeats the agent's own row.
    pub index: Array2<i64>,
    /// `(N, D)` 1 for a real sender, 0 for padding.
    pub mask: Array2<f32>,
    /// `(N, D, 6)` the sender seen from the agent (as `edge_features`); 0 on padding.
    pub features: Array3<f32>,
}

/// A job of [`Neighbors::padded_on`]: its number and the rows of `index`, `mask` and `features` it writes.
type PaddedRows<'a> = (usize, &'a mut [i64], &'a mut [f32], &'a mut [f32]);

impl Neighbors {
    /// The padded layout of a directed edge list sorted by receiver (`edge_index (E, 2)`, `edge_features (E, F)`)
    /// over `n` agents.
    pub fn from_edges(n: usize, edge_index: &Array2<i64>, edge_features: &Array2<f32>) -> Result<Self> {
        Self::from_edges_on(n, edge_index, edge_features, 1)
    }

    /// [`Neighbors::from_edges`], the agents of a large frame whose edges are sorted by receiver shared out over up to
    /// `threads` threads in jobs of [`RECEIVERS_PER_JOB`] (each writes its agents' rows, padding included, so that the
    /// pages of the tensors are first touched in parallel too). The same tensors whatever the threads.
    pub fn from_edges_on(
        n: usize,
        edge_index: &Array2<i64>,
        edge_features: &Array2<f32>,
        threads: usize,
    ) -> Result<Self> {
        let mut degree = vec![0usize; n];
        for r in edge_index.column(0) {
            let r = usize::try_from(*r).ok().filter(|r| *r < n).ok_or_else(|| invalid_frame("edge out of range"))?;
            degree[r] += 1;
        }
        let d = degree.iter().copied().max().unwrap_or(0).max(1);
        let f = edge_features.ncols();
        let sorted = edge_index.column(0).iter().zip(edge_index.column(0).iter().skip(1)).all(|(a, b)| a <= b);
        if threads >= 2 && sorted && edge_index.nrows() >= PARALLEL_EDGES_FROM {
            return Self::padded_on(&degree, d, edge_index, edge_features, threads);
        }
        let mut index = Array2::from_shape_fn((n, d), |(i, _)| i as i64);
        let mut mask = Array2::<f32>::zeros((n, d));
        let mut features = Array3::<f32>::zeros((n, d, f));
        let mut slot = vec![0usize; n];
        let standard = edge_features.as_standard_layout();
        let from = standard.as_slice().ok_or_else(|| invalid_frame("edge features are not contiguous"))?;
        let to = features.as_slice_mut().ok_or_else(|| invalid_frame("neighbour features are not contiguous"))?;
        for (e, row) in edge_index.rows().into_iter().enumerate() {
            let (r, k) = (row[0] as usize, slot[row[0] as usize]);
            index[[r, k]] = row[1];
            mask[[r, k]] = 1.0;
            to[(r * d + k) * f..(r * d + k + 1) * f].copy_from_slice(&from[e * f..(e + 1) * f]);
            slot[r] += 1;
        }
        Ok(Self { index, mask, features })
    }

    /// The padded layout of edges sorted by receiver, each agent's `degree` senders then padding, on `threads`.
    fn padded_on(
        degree: &[usize],
        d: usize,
        edge_index: &Array2<i64>,
        edge_features: &Array2<f32>,
        threads: usize,
    ) -> Result<Self> {
        let (n, f) = (degree.len(), edge_features.ncols());
        let start = offsets_of(degree);
        let standard = edge_features.as_standard_layout();
        let from = standard.as_slice().ok_or_else(|| invalid_frame("edge features are not contiguous"))?;
        let senders = edge_index.column(1);
        let mut index = Array2::<i64>::zeros((n, d));
        let mut mask = Array2::<f32>::zeros((n, d));
        let mut features = Array3::<f32>::zeros((n, d, f));
        let not_contiguous = || invalid_frame("neighbour tensors are not contiguous");
        let index_rows = index.as_slice_mut().ok_or_else(not_contiguous)?.chunks_mut(d * RECEIVERS_PER_JOB);
        let mask_rows = mask.as_slice_mut().ok_or_else(not_contiguous)?.chunks_mut(d * RECEIVERS_PER_JOB);
        let feature_rows = features.as_slice_mut().ok_or_else(not_contiguous)?.chunks_mut(d * f * RECEIVERS_PER_JOB);
        let jobs: Vec<PaddedRows<'_>> =
            index_rows.zip(mask_rows).zip(feature_rows).enumerate().map(|(job, ((i, m), f))| (job, i, m, f)).collect();
        let one = |(job, index, mask, features): PaddedRows<'_>| {
            let first = job * RECEIVERS_PER_JOB;
            for (k, r) in (first..first + index.len() / d).enumerate() {
                for slot in 0..d {
                    let at = k * d + slot;
                    if slot < degree[r] {
                        let e = start[r] + slot;
                        index[at] = senders[e];
                        mask[at] = 1.0;
                        features[at * f..(at + 1) * f].copy_from_slice(&from[e * f..(e + 1) * f]);
                    } else {
                        index[at] = r as i64;
                        mask[at] = 0.0;
                        features[at * f..(at + 1) * f].fill(0.0);
                    }
                }
            }
            Ok(())
        };
        share_jobs(jobs, threads, one, || DganError::InvalidFrame("a neighbour-writing thread panicked".into()))?;
        Ok(Self { index, mask, features })
    }
}

/// A preprocessed frame: network inputs plus the geometry needed to decode and inspect the outputs.
#[derive(Debug, Clone)]
pub struct Preprocessed {
    /// The network inputs.
    pub inputs: NetworkInputs,
    /// `(N, T_f, 2)` the kinematic prior in each agent's frame (zeros for a model without one); decoding adds it.
    pub prior: Array3<f32>,
    /// Each agent's frame at t_obs.
    pub poses: Vec<AgentPose>,
    /// Each agent's traffic state.
    pub states: Vec<TrafficState>,
    /// Each agent's attention radius, metres.
    pub radii: Vec<f64>,
    /// Undirected attention-zone edges `[i, j]`, `i < j`.
    pub edges: Vec<[u32; 2]>,
}

/// Bounds on the work one frame may cause, checked before the memory is allocated; a scene beyond them is refused
/// with [`DganError::SceneTooLarge`], naming the size and the limit.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Limits {
    /// Most undirected attention edges (default 200,000: 2,000 agents of 200 neighbours each).
    pub max_edges: usize,
    /// Most bytes of the network's input tensors (default 2 GiB; the map crops dominate: 3 · H · W · 4 bytes an
    /// agent).
    pub max_input_bytes: usize,
}

impl Default for Limits {
    fn default() -> Self {
        Self { max_edges: 200_000, max_input_bytes: 2 << 30 }
    }
}

impl Limits {
    /// The bytes of the input tensors of `n` agents with at most `degree` senders each (itself included).
    pub fn input_bytes(spec: &InputSpec, n: usize, degree: usize) -> usize {
        let map = spec.map.as_ref().map_or(0, |m| 3 * m.height_px * m.width_px + 1);
        let per_agent = spec.t_obs * 3 + spec.state_dim() + map + spec.t_f * 2 + degree * (2 + 1 + EDGE_FEATURES.len());
        n.saturating_mul(per_agent).saturating_mul(4)
    }
}

/// A byte count for people: `1.4 MiB`, `2.00 GiB`.
pub(crate) fn human_bytes(bytes: usize) -> String {
    let b = bytes as f64;
    if b >= f64::from(1u32 << 30) {
        format!("{:.2} GiB", b / f64::from(1u32 << 30))
    } else if b >= f64::from(1u32 << 20) {
        format!("{:.1} MiB", b / f64::from(1u32 << 20))
    } else {
        format!("{:.1} KiB", b / 1024.0)
    }
}

/// Builds the network inputs of a frame, within the default [`Limits`].
pub fn preprocess(frame: &Frame, spec: &InputSpec) -> Result<Preprocessed> {
    preprocess_within(frame, spec, &Limits::default())
}

/// Builds the network inputs of a frame, refusing one beyond `limits` before allocating for it.
pub fn preprocess_within(frame: &Frame, spec: &InputSpec, limits: &Limits) -> Result<Preprocessed> {
    preprocess_on(frame, spec, limits, crate::limits::cores())
}

/// [`preprocess_within`] on at most `threads` threads, shared with the other predictions in flight: the map crops
/// ([`crate::raster::rasterize_on`]) and a large frame's edge rows and kinematic prior. The tensors are the same
/// whatever the threads.
pub fn preprocess_on(frame: &Frame, spec: &InputSpec, limits: &Limits, threads: usize) -> Result<Preprocessed> {
    build(frame, spec, limits, threads, true, None).map(|(pre, _)| pre)
}

/// [`preprocess_on`] for the predictor numbered `model`: a scene model whose features are kept with the map
/// (contract 13) reads the tiles that predictor kept before instead of computing them again.
pub fn preprocess_for(
    frame: &Frame,
    spec: &InputSpec,
    limits: &Limits,
    threads: usize,
    model: u64,
) -> Result<Preprocessed> {
    build(frame, spec, limits, threads, true, Some(model)).map(|(pre, _)| pre)
}

/// [`preprocess_on`] with the map crops of a frame that has a map left for the caller to draw
/// ([`crate::raster::rasterize_rows`]; `inputs.map` is then `None`), e.g. on the threads of the parts of a frame that
/// run as separate network calls; a large frame's edge rows and prior on up to `threads` threads. The flag says
/// whether the crops were left out.
pub fn preprocess_without_crops(
    frame: &Frame,
    spec: &InputSpec,
    limits: &Limits,
    threads: usize,
) -> Result<(Preprocessed, bool)> {
    build(frame, spec, limits, threads, false, None)
}

/// Receivers a thread takes at a time when the edge rows are shared out.
const RECEIVERS_PER_JOB: usize = 256;
/// The fewest directed edges worth sharing out: below, one thread writes them.
const PARALLEL_EDGES_FROM: usize = 20_000;

/// Where each agent's rows start in rows grouped by agent, `counts[i]` rows for agent `i`, and their total last
/// (`N + 1` values).
fn offsets_of(counts: &[usize]) -> Vec<usize> {
    let mut offsets = Vec::with_capacity(counts.len() + 1);
    offsets.push(0);
    for c in counts {
        offsets.push(offsets[offsets.len() - 1] + c);
    }
    offsets
}

/// Each agent's senders, itself included, as one list of sender rows cut by `offsets` (`N + 1`; receiver `i`'s senders
/// are `senders[offsets[i]..offsets[i + 1]]`, unsorted): built from the undirected edges without a list per agent.
struct Senders {
    senders: Vec<u32>,
    offsets: Vec<usize>,
}

impl Senders {
    fn of(n: usize, edges: &[[u32; 2]]) -> Self {
        let mut degree = vec![1usize; n];
        for [i, j] in edges {
            degree[*i as usize] += 1;
            degree[*j as usize] += 1;
        }
        let offsets = offsets_of(&degree);
        let mut senders = vec![0u32; offsets[n]];
        let mut next: Vec<usize> = offsets[..n].to_vec();
        for (i, slot) in next.iter_mut().enumerate() {
            senders[*slot] = i as u32;
            *slot += 1;
        }
        for [i, j] in edges {
            senders[next[*i as usize]] = *j;
            next[*i as usize] += 1;
            senders[next[*j as usize]] = *i;
            next[*j as usize] += 1;
        }
        Self { senders, offsets }
    }

    /// The largest number of senders of one agent (0 without agents).
    fn degree(&self) -> usize {
        self.offsets.windows(2).map(|w| w[1] - w[0]).max().unwrap_or(0)
    }
}

/// `(E, 2)` directed edges `[receiver, sender]` and their `(E, 6)` features, receivers in order and each one's senders
/// ascending (sorted here), written on up to `threads` threads in jobs of [`RECEIVERS_PER_JOB`] receivers: the same
/// rows whatever the threads.
fn edge_rows(
    mut graph: Senders,
    states: &[TrafficState],
    poses: &[AgentPose],
    threads: usize,
) -> Result<(Array2<i64>, Array2<f32>)> {
    let f = EDGE_FEATURES.len();
    let (e, n) = (graph.senders.len(), graph.offsets.len() - 1);
    let mut edge_index = Array2::<i64>::zeros((e, 2));
    let mut edge_features = Array2::<f32>::zeros((e, f));
    let offsets = &graph.offsets;
    // Receivers `first..last` whose senders are `senders`, their rows `index` and `features`.
    let write = |(first, last, senders, index, features): (usize, usize, &mut [u32], &mut [i64], &mut [f32])| {
        let base = offsets[first];
        let mut row = 0;
        for i in first..last {
            let mine = &mut senders[offsets[i] - base..offsets[i + 1] - base];
            mine.sort_unstable();
            let (pi, si) = (poses[i], states[i]);
            for &j in mine.iter() {
                let sj = states[j as usize];
                let d = pi.to_local(sj.position);
                let dv = pi.vector_to_local([sj.velocity[0] - si.velocity[0], sj.velocity[1] - si.velocity[1]]);
                let dh = wrap_angle(sj.heading - si.heading);
                index[2 * row] = i as i64;
                index[2 * row + 1] = i64::from(j);
                for (k, v) in [d[0], d[1], dv[0], dv[1], dh.cos(), dh.sin()].iter().enumerate() {
                    features[f * row + k] = *v as f32;
                }
                row += 1;
            }
        }
        Ok(())
    };
    let index = edge_index.as_slice_mut().ok_or_else(|| invalid_frame("edge index is not contiguous"))?;
    let features = edge_features.as_slice_mut().ok_or_else(|| invalid_frame("edge features are not contiguous"))?;
    if threads <= 1 || e < PARALLEL_EDGES_FROM {
        write((0, n, &mut graph.senders, index, features))?;
    } else {
        // Each job's receivers with their senders and the rows they write, cut from the arrays in order.
        let mut jobs = Vec::with_capacity(n.div_ceil(RECEIVERS_PER_JOB));
        let (mut senders, mut index, mut features) = (graph.senders.as_mut_slice(), index, features);
        for first in (0..n).step_by(RECEIVERS_PER_JOB) {
            let last = (first + RECEIVERS_PER_JOB).min(n);
            let rows = offsets[last] - offsets[first];
            let (mine_s, rest_s) = std::mem::take(&mut senders).split_at_mut(rows);
            let (mine_i, rest_i) = std::mem::take(&mut index).split_at_mut(2 * rows);
            let (mine_f, rest_f) = std::mem::take(&mut features).split_at_mut(f * rows);
            (senders, index, features) = (rest_s, rest_i, rest_f);
            jobs.push((first, last, mine_s, mine_i, mine_f));
        }
        share_jobs(jobs, threads, write, || DganError::InvalidFrame("an edge-writing thread panicked".into()))?;
    }
    Ok((edge_index, edge_features))
}

/// Agents a thread takes at a time when the kinematic prior is shared out.
const PRIOR_AGENTS_PER_JOB: usize = 256;
/// The fewest agents worth sharing the prior out for (a windowed fit costs about 1.5 µs an agent).
const PARALLEL_PRIOR_FROM: usize = 1024;

/// The kinematic prior of every agent ([`crate::prior::PriorSpec::rollout`]), on up to `threads` threads for a large
/// frame, in jobs of [`PRIOR_AGENTS_PER_JOB`] agents: each agent's rows are its own, the same whatever the threads.
fn prior_rows(
    spec: &InputSpec,
    trajectory: &Array3<f32>,
    mask: &Array2<f32>,
    state: &Array2<f32>,
    threads: usize,
) -> Result<Array3<f32>> {
    let n = trajectory.dim().0;
    let roll = |a: usize, b: usize| {
        let rows = ndarray::s![a..b, ..];
        let (t, m, x) = (trajectory.slice(ndarray::s![a..b, .., ..]), mask.slice(rows), state.slice(rows));
        spec.prior.rollout(t, m, x, spec.dt_s, spec.t_f, &spec.classes)
    };
    let per = 2 * spec.t_f;
    if threads <= 1 || n < PARALLEL_PRIOR_FROM || per == 0 {
        return roll(0, n);
    }
    let mut out = Array3::<f32>::zeros((n, spec.t_f, 2));
    let flat = out.as_slice_mut().ok_or_else(|| invalid_frame("the prior is not contiguous"))?;
    let jobs: Vec<(usize, &mut [f32])> = flat
        .chunks_mut(per * PRIOR_AGENTS_PER_JOB)
        .enumerate()
        .map(|(k, rows)| (k * PRIOR_AGENTS_PER_JOB, rows))
        .collect();
    let one = |(first, rows): (usize, &mut [f32])| -> Result<()> {
        let part = roll(first, first + rows.len() / per)?;
        let part = part.as_slice().ok_or_else(|| invalid_frame("a share of the prior is not contiguous"))?;
        rows.copy_from_slice(part);
        Ok(())
    };
    share_jobs(jobs, threads, one, || DganError::InvalidFrame("a prior thread panicked".into()))?;
    Ok(out)
}

/// The inputs on up to `threads` threads, with the map crops when `crops`, or without them (flag true).
fn build(
    frame: &Frame,
    spec: &InputSpec,
    limits: &Limits,
    threads: usize,
    crops: bool,
    model: Option<u64>,
) -> Result<(Preprocessed, bool)> {
    spec.validate()?;
    frame.check_dt(spec.dt_s)?;
    let n = frame.len();
    if n > 0 && frame.steps() != spec.t_obs {
        return Err(invalid_frame(format!(
            "the frame has {} observed steps but the model observes T_obs = {}",
            frame.steps(),
            spec.t_obs
        )));
    }
    let class_idx: Vec<usize> = frame.classes().iter().map(|c| spec.class_index(*c)).collect::<Result<_>>()?;
    // The threads of this call, shared with the other predictions in flight (the crops share theirs themselves).
    let shared = threads_in_flight(threads);
    // Contract 10: every input from the denoised histories (the map and given states are kept; the frame itself when
    // no track is smoothed), fitted on the call's threads for a large frame.
    let denoised;
    let frame = if spec.denoise_gate_m > 0.0 {
        denoised = frame.denoised_on(spec.denoise_gate_m, shared)?.0;
        &*denoised
    } else {
        frame
    };
    let states = traffic_states_with(frame, spec.dt_s, spec.heading);
    let poses: Vec<AgentPose> = states.iter().map(TrafficState::pose).collect();

    let (trajectory, trajectory_mask) = trajectory_rows(frame, &poses, spec.t_obs);
    let state = state_rows(&states, &poses, &class_idx, spec.state_dim());

    let centres: Vec<[f64; 2]> = states.iter().map(|s| s.position).collect();
    let radii: Vec<f64> =
        states.iter().map(|s| attention_radius(s.speed, spec.horizon_s(), spec.attention_lambda, s.length)).collect();
    let edges = attention_zone_edges_on(&centres, &radii, limits.max_edges, shared)?;

    let graph = Senders::of(n, &edges);
    check_input_bytes(spec, limits, n, graph.degree())?;
    let (edge_index, edge_features) = edge_rows(graph, &states, &poses, shared)?;

    let prior = prior_rows(spec, &trajectory, &trajectory_mask, &state, shared)?;
    let (map, map_present) = map_rows(frame, &states, spec.map.as_ref(), threads, crops)?;
    let neighbors = match spec.graph {
        GraphLayout::EdgeList => None,
        GraphLayout::Padded => Some(Neighbors::from_edges_on(n, &edge_index, &edge_features, shared)?),
    };
    let mut pre = Preprocessed {
        inputs: NetworkInputs {
            trajectory,
            trajectory_mask,
            state,
            edge_index,
            edge_features,
            map,
            map_present,
            map_grid: None,
            map_slot: None,
            kept: None,
            neighbors,
        },
        prior,
        poses,
        states,
        radii,
        edges,
    };
    if let (true, Some(m)) = (crops, &spec.map) {
        pre.inputs.draw_scene(frame, &pre.states, m, model)?;
    }
    let later = spec.map.is_some() && pre.inputs.map.is_none();
    Ok((pre, later))
}

/// Each agent's observed positions in its own frame (`(N, T_obs, 2)`, zeros where unobserved) and their mask.
fn trajectory_rows(frame: &Frame, poses: &[AgentPose], t_obs: usize) -> (Array3<f32>, Array2<f32>) {
    let n = poses.len();
    let mut trajectory = Array3::<f32>::zeros((n, t_obs, 2));
    let mut trajectory_mask = Array2::<f32>::zeros((n, t_obs));
    let (pos, mask) = (frame.positions(), frame.mask());
    for (i, pose) in poses.iter().enumerate() {
        for t in 0..t_obs {
            if mask[[i, t]] {
                let l = pose.to_local([pos[[i, t, 0]], pos[[i, t, 1]]]);
                trajectory[[i, t, 0]] = l[0] as f32;
                trajectory[[i, t, 1]] = l[1] as f32;
                trajectory_mask[[i, t]] = 1.0;
            }
        }
    }
    (trajectory, trajectory_mask)
}

/// Each agent's traffic-state row ([`STATE_FEATURES`], its motion's direction in its own frame) and its class's
/// one-hot column (`class_idx`), `(N, state_dim)`.
fn state_rows(states: &[TrafficState], poses: &[AgentPose], class_idx: &[usize], state_dim: usize) -> Array2<f32> {
    let mut state = Array2::<f32>::zeros((states.len(), state_dim));
    for (i, (s, pose)) in states.iter().zip(poses).enumerate() {
        let v = pose.vector_to_local(s.velocity);
        let (mc, ms) = if s.speed > 0.0 { (v[0] / s.speed, v[1] / s.speed) } else { (1.0, 0.0) };
        let row = [s.speed, s.acceleration, s.yaw_rate, mc, ms, s.length, s.width];
        debug_assert_eq!(row.len(), STATE_FEATURES.len());
        for (k, v) in row.iter().enumerate() {
            state[[i, k]] = *v as f32;
        }
        state[[i, STATE_FEATURES.len() + class_idx[i]]] = 1.0;
    }
    state
}

/// Refuses a frame whose network inputs (`n` agents, up to `degree` senders each) would exceed the Predictor's
/// `max_input_bytes`, before any of them is allocated.
fn check_input_bytes(spec: &InputSpec, limits: &Limits, n: usize, degree: usize) -> Result<()> {
    let bytes = Limits::input_bytes(spec, n, degree);
    if bytes > limits.max_input_bytes {
        return Err(DganError::SceneTooLarge(format!(
            "the network's inputs for {n} agents (up to {degree} senders each{}) take {}, above the limit of {} \
             (max_input_bytes of the Predictor); predict fewer agents at once",
            spec.map.as_ref().map_or(String::new(), |m| format!(", map crops of {}×{} px", m.height_px, m.width_px)),
            human_bytes(bytes),
            human_bytes(limits.max_input_bytes)
        )));
    }
    Ok(())
}

/// A crop model's map crops `(N, 3, H, W)` and `map_present` flags `(N,)`, each if the model takes it.
type MapRows = (Option<Array4<f32>>, Option<Array1<f32>>);

/// The map crops (drawn on up to `threads` threads when `crops`; all-zero for an optional map the frame lacks) and
/// the `map_present` flags of a crop model; a scene model's flags only (its rasters are drawn later,
/// [`NetworkInputs::draw_scene`]); nothing without a map branch. A required map the frame lacks is refused.
fn map_rows(
    frame: &Frame,
    states: &[TrafficState],
    spec: Option<&MapSpec>,
    threads: usize,
    crops: bool,
) -> Result<MapRows> {
    let n = frame.len();
    Ok(match (spec, frame.map()) {
        (None, _) => (None, None),
        // A scene model's rasters are drawn once the inputs hold the states (NetworkInputs::draw_scene).
        (Some(m), present) if m.scene.is_some() && (present.is_some() || m.optional || n == 0) => {
            let flag = if present.is_some() { 1.0 } else { 0.0 };
            (None, m.optional.then(|| Array1::from_elem(n, flag)))
        }
        (Some(m), Some(_)) => {
            let drawn = crops.then(|| rasterize_on(frame, states, m, threads)).transpose()?;
            (drawn, m.optional.then(|| Array1::ones(n)))
        }
        (Some(m), None) if m.optional || n == 0 => {
            (Some(Array4::zeros((n, 3, m.height_px, m.width_px))), m.optional.then(|| Array1::zeros(n)))
        }
        (Some(_), None) => {
            return Err(DganError::MapRequired(
                "this model's map branch needs a map and the frame has none: pass the scene's map in the frame \
                 (map=dgan.VectorMap(...), dgan.RasterMap(...) or dgan.scene_map(name)), or use a model trained \
                 with optional maps (contract 2, map.optional = true), which serves frames without one"
                    .into(),
            ))
        }
    })
}

impl NetworkInputs {
    /// A scene model's rasters, grids and slots (contract 12, [`crate::scene::scene_inputs`]), or, where its
    /// features are kept with the map (contract 13), the rasters of the tiles this call computes and every agent's
    /// reads ([`crate::kept::kept_inputs`]; `model` the predictor's number, whose kept tiles are read), drawn into
    /// these inputs; nothing for a crop model (`crop.scene` None).
    pub fn draw_scene(
        &mut self,
        frame: &Frame,
        states: &[TrafficState],
        crop: &MapSpec,
        model: Option<u64>,
    ) -> Result<()> {
        match crop.scene {
            Some(scene) if scene.kept() => {
                let (reads, rasters) = crate::kept::kept_inputs(frame, states, crop, scene, model)?;
                (self.map, self.kept) = (Some(rasters), Some(reads));
            }
            Some(scene) => {
                let (raster, grid, slot) = crate::scene::scene_inputs(frame, states, crop, scene)?;
                (self.map, self.map_grid, self.map_slot) = (Some(raster), Some(grid), Some(slot));
            }
            None => {}
        }
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::class::AgentClass;
    use crate::prior::PriorSpec;
    use crate::spec::HeadingSource;
    use crate::spec::MapSpec;
    use ndarray::Array3;

    fn spec(map: bool) -> InputSpec {
        spec_with(map, false)
    }

    fn spec_with(map: bool, optional: bool) -> InputSpec {
        InputSpec {
            dt_s: 0.5,
            t_obs: 3,
            t_f: 4,
            classes: vec![AgentClass::Vehicle, AgentClass::Pedestrian],
            attention_lambda: 0.5,
            map: map.then_some(MapSpec {
                height_px: 8,
                width_px: 8,
                resolution_m: 1.0,
                agent_row: 6,
                agent_col: 4,
                draw_agents: true,
                optional,
                render: crate::spec::MapRender::Agent,
                classes: vec![],
                scene: None,
            }),
            prior: PriorSpec::constant_velocity(0.0),
            graph: GraphLayout::Padded,
            heading: HeadingSource::Measured,
            denoise_gate_m: 0.0,
        }
    }

    #[test]
    fn builds_inputs() {
        // Agent 0 walks +x at 1 m/s; agent 1 stands 2 m ahead of it at t_obs; agent 2 is 1 km away.
        let mut p = Array3::zeros((3, 3, 2));
        for t in 0..3 {
            p[[0, t, 0]] = 0.5 * t as f64;
            p[[1, t, 0]] = 3.0;
            p[[2, t, 0]] = 1000.0;
        }
        let f = Frame::new(p, None, vec![AgentClass::Pedestrian, AgentClass::Pedestrian, AgentClass::Vehicle]).unwrap();
        let pre = preprocess(&f, &spec_with(true, true)).unwrap();
        let x = &pre.inputs;
        assert_eq!(x.trajectory.dim(), (3, 3, 2));
        assert_eq!(x.trajectory[[0, 0, 0]], -1.0);
        assert_eq!(x.state.row(0).to_vec(), vec![1.0, 0.0, 0.0, 1.0, 0.0, 0.5, 0.5, 0.0, 1.0]);
        assert_eq!(x.state[[2, 7]], 1.0);
        // r0 = 1 m/s · 2 s + 0.5 · 0.5 m = 2.25, r1 = 0.25: 2 m apart, they meet; agent 2 is alone.
        assert_eq!(pre.edges, vec![[0, 1]]);
        let ei: Vec<[i64; 2]> = x.edge_index.rows().into_iter().map(|r| [r[0], r[1]]).collect();
        assert_eq!(ei, vec![[0, 0], [0, 1], [1, 0], [1, 1], [2, 2]]);
        // Agent 1 seen from agent 0: 2 m ahead, closing at 1 m/s.
        assert_eq!(x.edge_features.row(1).to_vec(), vec![2.0, 0.0, -1.0, 0.0, 1.0, 0.0]);
        // No map in the frame, optional map: blank crops flagged absent.
        assert_eq!(x.map.as_ref().map(|m| m.dim()), Some((3, 3, 8, 8)));
        assert!(x.map.as_ref().unwrap().iter().all(|v| *v == 0.0));
        assert_eq!(x.map_present.as_ref().unwrap().to_vec(), vec![0.0; 3]);
        // Constant velocity: agent 0 moves 1 m/s ahead, 0.5 m per step.
        assert_eq!(pre.prior[[0, 3, 0]], 2.0);
        assert_eq!(pre.prior[[1, 3, 0]], 0.0);
        assert!(preprocess(&f, &spec(false)).unwrap().inputs.map.is_none());
        // The padded layout: agent 0 hears itself and agent 1, agent 2 only itself (D = 2).
        let nb = x.neighbors.as_ref().unwrap();
        assert_eq!(nb.index.row(0).to_vec(), vec![0, 1]);
        assert_eq!(nb.index.row(2).to_vec(), vec![2, 2]);
        assert_eq!(nb.mask.row(2).to_vec(), vec![1.0, 0.0]);
        assert_eq!(nb.features.slice(ndarray::s![0, 1, ..]).to_vec(), x.edge_features.row(1).to_vec());
        // A map that is not optional is required.
        assert!(matches!(preprocess(&f, &spec(true)), Err(DganError::MapRequired(_))));
    }

    #[test]
    fn edge_rows_are_the_same_whatever_the_threads() {
        // 300 agents within a few metres of each other, walking every way: 89,700 directed edges, shared out.
        let p = Array3::from_shape_fn((300, 3, 2), |(i, t, d)| {
            let a = i as f64 * 0.7;
            let start = if d == 0 { (i % 17) as f64 * 0.3 } else { (i / 17) as f64 * 0.3 };
            start + t as f64 * 0.4 * if d == 0 { a.cos() } else { a.sin() }
        });
        let f = Frame::new(p, None, vec![AgentClass::Pedestrian; 300]).unwrap();
        let one = preprocess_on(&f, &spec(false), &Limits::default(), 1).unwrap();
        assert!(one.inputs.edge_index.nrows() > PARALLEL_EDGES_FROM, "{}", one.inputs.edge_index.nrows());
        for threads in [2, 3, 8] {
            let many = preprocess_on(&f, &spec(false), &Limits::default(), threads).unwrap();
            assert_eq!(many.inputs.edge_index, one.inputs.edge_index, "{threads} threads");
            assert_eq!(many.inputs.edge_features, one.inputs.edge_features, "{threads} threads");
            let (a, b) = (many.inputs.neighbors.unwrap(), one.inputs.neighbors.as_ref().unwrap().clone());
            assert_eq!((a.index, a.mask, a.features), (b.index, b.mask, b.features), "{threads} threads");
        }
        // Edges not sorted by receiver are laid out one by one, whatever the threads.
        let rev: Vec<usize> = (0..one.inputs.edge_index.nrows()).rev().collect();
        let (ei, ef) = (
            one.inputs.edge_index.select(ndarray::Axis(0), &rev),
            one.inputs.edge_features.select(ndarray::Axis(0), &rev),
        );
        let (a, b) =
            (Neighbors::from_edges_on(300, &ei, &ef, 4).unwrap(), Neighbors::from_edges(300, &ei, &ef).unwrap());
        assert_eq!((a.index, a.mask, a.features), (b.index, b.mask, b.features));
        // Receivers in order, each one's senders ascending, itself among them.
        let ei = &one.inputs.edge_index;
        assert!(ei.rows().into_iter().zip(ei.rows().into_iter().skip(1)).all(|(a, b)| (a[0], a[1]) < (b[0], b[1])));
        assert_eq!(ei.nrows(), 300 + 2 * one.edges.len());
    }

    #[test]
    fn the_prior_is_the_same_whatever_the_threads() {
        // 1,300 agents far apart (no edges), walking with jitter: a windowed, adaptive, standing-aware prior, shared out.
        let p = Array3::from_shape_fn((1300, 3, 2), |(i, t, d)| {
            let jitter = ((i * 7 + t * 3 + d) % 5) as f64 * 0.02;
            let walk = if i % 4 == 0 { 0.0 } else { t as f64 * 0.3 * (1.0 + (i % 3) as f64) };
            i as f64 * 100.0 * (1 - d) as f64 + walk + jitter
        });
        let f = Frame::new(p, None, vec![AgentClass::Pedestrian; 1300]).unwrap();
        let prior = PriorSpec {
            fit: crate::prior::VelocityFit::Adaptive,
            standing_mps: 0.3,
            ..PriorSpec::constant_velocity(1.0)
        };
        let spec = InputSpec { prior, ..spec(false) };
        let one = preprocess_on(&f, &spec, &Limits::default(), 1).unwrap();
        assert!(one.prior.iter().any(|v| *v != 0.0) && one.prior.iter().any(|v| *v == 0.0));
        for threads in [2, 3, 8] {
            assert_eq!(preprocess_on(&f, &spec, &Limits::default(), threads).unwrap().prior, one.prior, "{threads}");
        }
        let direct = spec.prior.rollout(
            one.inputs.trajectory.view(),
            one.inputs.trajectory_mask.view(),
            one.inputs.state.view(),
            spec.dt_s,
            spec.t_f,
            &spec.classes,
        );
        assert_eq!(direct.unwrap(), one.prior);
    }

    #[test]
    fn a_denoising_spec_builds_every_input_from_the_denoised_frame() {
        // Agent 0 walks with 0.2 m jitter, agent 1 walks smoothly beside it.
        let p = Array3::from_shape_fn((2, 6, 2), |(i, t, d)| {
            let jitter = if i == 0 { [0.2, -0.2][t % 2] } else { 0.0 };
            [t as f64 * 0.5 + jitter, i as f64 * 1.5][d]
        });
        let spec3 = |gate: f64| InputSpec { t_obs: 6, denoise_gate_m: gate, ..spec(false) };
        let f = Frame::new(p, None, vec![AgentClass::Pedestrian; 2]).unwrap();
        let (smoothed, count) = f.denoised(0.05).unwrap();
        assert_eq!(count, 1);
        let (with, direct, without) = (
            preprocess(&f, &spec3(0.05)).unwrap(),
            preprocess(&smoothed, &spec3(0.0)).unwrap(),
            preprocess(&f, &spec3(0.0)).unwrap(),
        );
        assert_eq!(with.inputs.trajectory, direct.inputs.trajectory);
        assert_eq!(with.inputs.state, direct.inputs.state);
        assert_eq!(with.inputs.edge_features, direct.inputs.edge_features);
        assert_eq!(with.prior, direct.prior);
        assert_ne!(with.inputs.trajectory, without.inputs.trajectory);
        // A gate above the jitter keeps the histories as given.
        assert_eq!(preprocess(&f, &spec3(5.0)).unwrap().inputs.trajectory, without.inputs.trajectory);
        for bad in [-0.1, f64::NAN, f64::INFINITY, 1e3] {
            assert!(matches!(preprocess(&f, &spec3(bad)), Err(DganError::InvalidSpec(_))), "{bad}");
        }
    }

    #[test]
    fn rejects_mismatches() {
        let f = Frame::new(Array3::zeros((1, 5, 2)), None, vec![AgentClass::Pedestrian]).unwrap();
        assert!(matches!(preprocess(&f, &spec(false)), Err(DganError::InvalidFrame(_))));
        let f = Frame::new(Array3::zeros((1, 3, 2)), None, vec![AgentClass::Cyclist]).unwrap();
        assert!(matches!(preprocess(&f, &spec(false)), Err(DganError::UnknownClass(_))));
        let empty = Frame::new(Array3::zeros((0, 3, 2)), None, vec![]).unwrap();
        let pre = preprocess(&empty, &spec(true)).unwrap();
        assert_eq!(pre.inputs.edge_index.dim(), (0, 2));
        assert_eq!(pre.inputs.map.map(|m| m.dim()), Some((0, 3, 8, 8)));
    }
}
