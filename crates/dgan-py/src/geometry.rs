//! Agent-centric transforms and the attention-zone graph, for training code that must not re-implement them.

use crate::error::{to_py, IntoPyResult};
use dgan_core::graph::{attention_zone_edges, attention_zone_edges_brute_force};
use dgan_core::transform::AgentPose;
use dgan_core::DganError;
use ndarray::{Array2, Array3};
use numpy::{IntoPyArray, PyArray2, PyArray3, PyReadonlyArrayDyn};
use pyo3::prelude::*;

pub(crate) fn poses(
    origins: &PyReadonlyArrayDyn<'_, f64>,
    headings: &PyReadonlyArrayDyn<'_, f64>,
) -> PyResult<Vec<AgentPose>> {
    let (o, h) = (origins.as_array(), headings.as_array());
    if o.ndim() != 2 || o.shape()[1] != 2 || h.ndim() != 1 || h.len() != o.shape()[0] {
        return Err(to_py(DganError::InvalidFrame(format!(
            "origins must be (N, 2) and headings (N,), got {:?} and {:?}",
            o.shape(),
            h.shape()
        ))));
    }
    Ok((0..h.len()).map(|i| AgentPose::new([o[[i, 0]], o[[i, 1]]], h[i])).collect())
}

fn points_of(p: &PyReadonlyArrayDyn<'_, f64>, n: usize) -> PyResult<Array3<f64>> {
    let shape = p.as_array().shape().to_vec();
    let a =
        p.as_array().to_owned().into_dimensionality::<ndarray::Ix3>().ok().filter(|a| a.dim().0 == n && a.dim().2 == 2);
    a.ok_or_else(|| to_py(DganError::InvalidFrame(format!("points must have shape (N = {n}, T, 2), got {shape:?}"))))
}

fn map_points(p: Array3<f64>, poses: &[AgentPose], f: impl Fn(&AgentPose, [f64; 2]) -> [f64; 2]) -> Array3<f64> {
    let mut out = p;
    for (i, pose) in poses.iter().enumerate() {
        for t in 0..out.dim().1 {
            let q = f(pose, [out[[i, t, 0]], out[[i, t, 1]]]);
            out[[i, t, 0]] = q[0];
            out[[i, t, 1]] = q[1];
        }
    }
    out
}

fn transform<'py>(
    py: Python<'py>,
    points: PyReadonlyArrayDyn<'py, f64>,
    origins: PyReadonlyArrayDyn<'py, f64>,
    headings: PyReadonlyArrayDyn<'py, f64>,
    f: impl Fn(&AgentPose, [f64; 2]) -> [f64; 2],
) -> PyResult<Bound<'py, PyArray3<f64>>> {
    let poses = poses(&origins, &headings)?;
    let p = points_of(&points, poses.len())?;
    Ok(map_points(p, &poses, f).into_pyarray(py))
}

/// World points `(N, T, 2)` → each agent's frame (origin `(N, 2)`, heading `(N,)` radians).
#[pyfunction]
pub fn to_agent_frame<'py>(
    py: Python<'py>,
    points_world: PyReadonlyArrayDyn<'py, f64>,
    origins: PyReadonlyArrayDyn<'py, f64>,
    headings: PyReadonlyArrayDyn<'py, f64>,
) -> PyResult<Bound<'py, PyArray3<f64>>> {
    transform(py, points_world, origins, headings, |pose, q| pose.to_local(q))
}

/// Agent-frame points `(N, T, 2)` → the world frame.
#[pyfunction]
pub fn to_world_frame<'py>(
    py: Python<'py>,
    points_local: PyReadonlyArrayDyn<'py, f64>,
    origins: PyReadonlyArrayDyn<'py, f64>,
    headings: PyReadonlyArrayDyn<'py, f64>,
) -> PyResult<Bound<'py, PyArray3<f64>>> {
    transform(py, points_local, origins, headings, |pose, q| pose.to_world(q))
}

/// Undirected attention-zone edges `(E, 2)`, `i < j`, of circles `centres (N, 2)`, `radii (N,)`.
#[pyfunction]
#[pyo3(signature = (centres, radii, brute_force = false))]
pub fn attention_graph<'py>(
    py: Python<'py>,
    centres: PyReadonlyArrayDyn<'py, f64>,
    radii: PyReadonlyArrayDyn<'py, f64>,
    brute_force: bool,
) -> PyResult<Bound<'py, PyArray2<i64>>> {
    let (c, r) = (centres.as_array(), radii.as_array());
    if c.ndim() != 2 || c.shape()[1] != 2 || r.ndim() != 1 {
        return Err(to_py(DganError::InvalidFrame(format!(
            "centres must be (N, 2) and radii (N,), got {:?} and {:?}",
            c.shape(),
            r.shape()
        ))));
    }
    let centres: Vec<[f64; 2]> = c.rows().into_iter().map(|row| [row[0], row[1]]).collect();
    let radii: Vec<f64> = r.iter().copied().collect();
    let edges = py
        .detach(|| {
            if brute_force {
                attention_zone_edges_brute_force(&centres, &radii)
            } else {
                attention_zone_edges(&centres, &radii)
            }
        })
        .py()?;
    Ok(Array2::from_shape_fn((edges.len(), 2), |(e, k)| i64::from(edges[e][k])).into_pyarray(py))
}
