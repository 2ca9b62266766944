//! `preprocess`: the exact tensors the network receives, for training and inspection.

use crate::error::IntoPyResult;
use crate::frame::PyFrame;
use dgan_core::preprocess::{preprocess_on, Limits};
use dgan_core::{DganError, InputSpec};
use ndarray::Array2;
use numpy::{IntoPyArray, PyArray1, PyArray3, PyReadonlyArray2, PyReadonlyArray3};
use pyo3::prelude::*;
use pyo3::types::PyDict;

pub(crate) fn parse_spec(json: &str) -> dgan_core::Result<InputSpec> {
    let spec: InputSpec = dgan_core::contract::from_json_readably(json)
        .map_err(|e| DganError::InvalidSpec(format!("not an input specification: {e}")))?;
    spec.validate()?;
    Ok(spec)
}

/// Checks an input specification given as JSON; returns it normalised.
#[pyfunction]
pub fn validate_spec(json: &str) -> PyResult<String> {
    let spec = parse_spec(json).py()?;
    serde_json::to_string(&spec).map_err(|e| crate::error::to_py(DganError::InvalidSpec(e.to_string())))
}

/// The network inputs of `frame` under the JSON input specification, plus the agent-centric frames (`origin`,
/// `heading`), traffic states, attention radii and undirected `edges`; the map crops drawn on at most `threads`
/// threads (all the machine's cores if `None`; the tensors are the same whatever the threads).
#[pyfunction]
#[pyo3(signature = (frame, spec_json, threads = None))]
pub fn preprocess<'py>(
    py: Python<'py>,
    frame: &PyFrame,
    spec_json: &str,
    threads: Option<usize>,
) -> PyResult<Bound<'py, PyDict>> {
    let spec = parse_spec(spec_json).py()?;
    let cores = dgan_core::limits::cores();
    let threads = match threads {
        None => cores,
        Some(t) if (1..=cores).contains(&t) => t,
        Some(t) => {
            return Err(crate::error::to_py(DganError::InvalidSpec(format!(
                "threads must be in 1..={cores} (this machine's cores), got {t}"
            ))))
        }
    };
    let frame = &frame.inner;
    let pre = py.detach(|| preprocess_on(frame, &spec, &Limits::default(), threads)).py()?;
    let d = PyDict::new(py);
    let x = pre.inputs;
    d.set_item("trajectory", x.trajectory.into_pyarray(py))?;
    d.set_item("trajectory_mask", x.trajectory_mask.into_pyarray(py))?;
    d.set_item("state", x.state.into_pyarray(py))?;
    d.set_item("edge_index", x.edge_index.into_pyarray(py))?;
    d.set_item("edge_features", x.edge_features.into_pyarray(py))?;
    if let Some(m) = x.map {
        d.set_item("map", m.into_pyarray(py))?;
    }
    if let Some(m) = x.map_present {
        d.set_item("map_present", m.into_pyarray(py))?;
    }
    if let (Some(g), Some(s)) = (x.map_grid, x.map_slot) {
        d.set_item("map_grid", g.into_pyarray(py))?;
        d.set_item("map_slot", s.into_pyarray(py))?;
    }
    if let Some(k) = x.kept {
        d.set_item("map_rows", k.table().into_pyarray(py))?;
        d.set_item("map_index", k.index.into_pyarray(py))?;
        d.set_item("map_weight", k.weight.into_pyarray(py))?;
    }
    if let Some(nb) = x.neighbors {
        d.set_item("neighbor_index", nb.index.into_pyarray(py))?;
        d.set_item("neighbor_mask", nb.mask.into_pyarray(py))?;
        d.set_item("neighbor_features", nb.features.into_pyarray(py))?;
    }
    d.set_item("prior", pre.prior.into_pyarray(py))?;
    let n = pre.poses.len();
    d.set_item("origin", Array2::from_shape_fn((n, 2), |(i, k)| pre.poses[i].origin()[k]).into_pyarray(py))?;
    d.set_item("heading", pre.poses.iter().map(|p| p.heading()).collect::<Vec<_>>().into_pyarray(py))?;
    d.set_item("speed", pre.states.iter().map(|s| s.speed).collect::<Vec<_>>().into_pyarray(py))?;
    d.set_item("radius", pre.radii.into_pyarray(py))?;
    let edges = dgan_core::runtime::edge_array(&pre.edges);
    d.set_item("edges", edges.into_pyarray(py))?;
    Ok(d)
}

/// The kinematic prior `(N, T_f, 2)` (agent frame) of the spec, from network inputs `trajectory (N, T_obs, 2)`,
/// `trajectory_mask (N, T_obs)` and `state (N, S)`: the engine's own rollout, for training on the residuals.
#[pyfunction]
pub fn kinematic_prior<'py>(
    py: Python<'py>,
    trajectory: PyReadonlyArray3<'py, f32>,
    trajectory_mask: PyReadonlyArray2<'py, f32>,
    state: PyReadonlyArray2<'py, f32>,
    spec_json: &str,
) -> PyResult<Bound<'py, PyArray3<f32>>> {
    let spec = parse_spec(spec_json).py()?;
    let (t, m, s) = (trajectory.as_array(), trajectory_mask.as_array(), state.as_array());
    let prior = py.detach(|| spec.prior.rollout(t, m, s, spec.dt_s, spec.t_f, &spec.classes)).py()?;
    Ok(prior.into_pyarray(py))
}

/// Contract 15: which agents' histories are still (`dgan_core::decode::still_agents`), from network inputs
/// `trajectory (N, T_obs, 2)`, `trajectory_mask (N, T_obs)` and `state (N, 7 + C)` and a radius per class (metres,
/// the model's class order; 0: never held).
#[pyfunction]
pub fn still_agents<'py>(
    py: Python<'py>,
    trajectory: PyReadonlyArray3<'py, f32>,
    trajectory_mask: PyReadonlyArray2<'py, f32>,
    state: PyReadonlyArray2<'py, f32>,
    radius: Vec<f64>,
) -> PyResult<Bound<'py, PyArray1<bool>>> {
    let (t, m, s) = (trajectory.as_array(), trajectory_mask.as_array(), state.as_array());
    let still = dgan_core::decode::still_agents(t, m, s, &radius).py()?;
    Ok(still.into_pyarray(py))
}
