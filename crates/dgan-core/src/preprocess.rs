//! Frame → the exact tensors the network receives. Training calls this same code through the Python bindings, so
//! training and inference cannot drift.

use crate::error::{invalid_frame, DganError, Result};
use crate::frame::Frame;
use crate::graph::{attention_radius, attention_zone_edges_within};
use crate::raster::rasterize_on;
use crate::spec::{GraphLayout, InputSpec, EDGE_FEATURES, STATE_FEATURES};
use crate::state::{traffic_states_with, TrafficState};
use crate::transform::{wrap_angle, AgentPose};
use ndarray::{Array1, Array2, Array3, Array4};

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

impl Neighbors {
    /// The padded layout of a directed edge list sorted by receiver (`edge_index (E, 2)`, `edge_features (E, F)`)
    /// over `n` agents.
    pub fn from_edges(n: usize, edge_index: &Array2<i64>, edge_features: &Array2<f32>) -> Result<Self> {
        let mut degree = vec![0usize; n];
        for r in edge_index.column(0) {
            let r = usize::try_from(*r).ok().filter(|r| *r < n).ok_or_else(|| invalid_frame("edge out of range"))?;
            degree[r] += 1;
        }
        let d = degree.iter().copied().max().unwrap_or(0).max(1);
        let f = edge_features.ncols();
        let mut index = Array2::from_shape_fn((n, d), |(i, _)| i as i64);
        let mut mask = Array2::<f32>::zeros((n, d));
        let mut features = Array3::<f32>::zeros((n, d, f));
        let mut slot = vec![0usize; n];
        for (e, row) in edge_index.rows().into_iter().enumerate() {
            let (r, k) = (row[0] as usize, slot[row[0] as usize]);
            index[[r, k]] = row[1];
            mask[[r, k]] = 1.0;
            features.slice_mut(ndarray::s![r, k, ..]).assign(&edge_features.row(e));
            slot[r] += 1;
        }
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

/// [`preprocess_within`] with the map crops drawn on at most `threads` threads ([`crate::raster::rasterize_on`]);
/// the tensors are the same whatever the threads.
pub fn preprocess_on(frame: &Frame, spec: &InputSpec, limits: &Limits, threads: usize) -> Result<Preprocessed> {
    build(frame, spec, limits, Some(threads)).map(|(pre, _)| pre)
}

/// [`preprocess_on`] with the map crops of a frame that has a map left for the caller to draw
/// ([`crate::raster::rasterize_rows`]; `inputs.map` is then `None`), e.g. on the threads of the parts of a frame that
/// run as separate network calls. The flag says whether the crops were left out.
pub fn preprocess_without_crops(frame: &Frame, spec: &InputSpec, limits: &Limits) -> Result<(Preprocessed, bool)> {
    build(frame, spec, limits, None)
}

/// The inputs, the map crops drawn on `crop_threads` threads, or left out (flag true) when that is None.
fn build(
    frame: &Frame,
    spec: &InputSpec,
    limits: &Limits,
    crop_threads: Option<usize>,
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
    let states = traffic_states_with(frame, spec.dt_s, spec.heading);
    let poses: Vec<AgentPose> = states.iter().map(TrafficState::pose).collect();

    let mut trajectory = Array3::<f32>::zeros((n, spec.t_obs, 2));
    let mut trajectory_mask = Array2::<f32>::zeros((n, spec.t_obs));
    let (pos, mask) = (frame.positions(), frame.mask());
    for (i, pose) in poses.iter().enumerate() {
        for t in 0..spec.t_obs {
            if mask[[i, t]] {
                let l = pose.to_local([pos[[i, t, 0]], pos[[i, t, 1]]]);
                trajectory[[i, t, 0]] = l[0] as f32;
                trajectory[[i, t, 1]] = l[1] as f32;
                trajectory_mask[[i, t]] = 1.0;
            }
        }
    }

    let mut state = Array2::<f32>::zeros((n, spec.state_dim()));
    for (i, (s, pose)) in states.iter().zip(&poses).enumerate() {
        let v = pose.vector_to_local(s.velocity);
        let (mc, ms) = if s.speed > 0.0 { (v[0] / s.speed, v[1] / s.speed) } else { (1.0, 0.0) };
        let row = [s.speed, s.acceleration, s.yaw_rate, mc, ms, s.length, s.width];
        debug_assert_eq!(row.len(), STATE_FEATURES.len());
        for (k, v) in row.iter().enumerate() {
            state[[i, k]] = *v as f32;
        }
        state[[i, STATE_FEATURES.len() + class_idx[i]]] = 1.0;
    }

    let centres: Vec<[f64; 2]> = states.iter().map(|s| s.position).collect();
    let radii: Vec<f64> =
        states.iter().map(|s| attention_radius(s.speed, spec.horizon_s(), spec.attention_lambda, s.length)).collect();
    let edges = attention_zone_edges_within(&centres, &radii, limits.max_edges)?;

    let mut neighbours: Vec<Vec<usize>> = (0..n).map(|i| vec![i]).collect();
    for [i, j] in &edges {
        neighbours[*i as usize].push(*j as usize);
        neighbours[*j as usize].push(*i as usize);
    }
    let degree = neighbours.iter().map(Vec::len).max().unwrap_or(0);
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
    let e = n + 2 * edges.len();
    let mut edge_index = Array2::<i64>::zeros((e, 2));
    let mut edge_features = Array2::<f32>::zeros((e, EDGE_FEATURES.len()));
    let mut row = 0;
    for (i, senders) in neighbours.iter_mut().enumerate() {
        senders.sort_unstable();
        let (pi, si) = (poses[i], states[i]);
        for &j in senders.iter() {
            let sj = states[j];
            let d = pi.to_local(sj.position);
            let dv = pi.vector_to_local([sj.velocity[0] - si.velocity[0], sj.velocity[1] - si.velocity[1]]);
            let dh = wrap_angle(sj.heading - si.heading);
            edge_index[[row, 0]] = i as i64;
            edge_index[[row, 1]] = j as i64;
            for (k, v) in [d[0], d[1], dv[0], dv[1], dh.cos(), dh.sin()].iter().enumerate() {
                edge_features[[row, k]] = *v as f32;
            }
            row += 1;
        }
    }

    let prior = spec.prior.rollout(
        trajectory.view(),
        trajectory_mask.view(),
        state.view(),
        spec.dt_s,
        spec.t_f,
        &spec.classes,
    )?;
    let (map, map_present) = match (&spec.map, frame.map()) {
        (None, _) => (None, None),
        (Some(m), Some(_)) => {
            let crops = crop_threads.map(|threads| rasterize_on(frame, &states, m, threads)).transpose()?;
            (crops, m.optional.then(|| Array1::ones(n)))
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
    };
    let neighbors = match spec.graph {
        GraphLayout::EdgeList => None,
        GraphLayout::Padded => Some(Neighbors::from_edges(n, &edge_index, &edge_features)?),
    };
    let later = spec.map.is_some() && map.is_none();
    let pre = Preprocessed {
        inputs: NetworkInputs {
            trajectory,
            trajectory_mask,
            state,
            edge_index,
            edge_features,
            map,
            map_present,
            neighbors,
        },
        prior,
        poses,
        states,
        radii,
        edges,
    };
    Ok((pre, later))
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
            }),
            prior: PriorSpec::constant_velocity(0.0),
            graph: GraphLayout::Padded,
            heading: HeadingSource::Measured,
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
