//! The scene raster a shared map CNN reads and each agent's crop grid in it (`dgan_core::scene`), for training.

use crate::error::{to_py, IntoPyResult};
use crate::frame::PyFrame;
use crate::geometry::poses;
use crate::preprocess::parse_spec;
use dgan_core::scene;
use dgan_core::state::traffic_states_with;
use dgan_core::transform::AgentPose;
use dgan_core::{DganError, InputSpec, MapSpec};
use numpy::{IntoPyArray, PyArray3, PyArray4, PyReadonlyArray2, PyReadonlyArrayDyn};
use pyo3::prelude::*;

fn map_of(spec: &InputSpec) -> PyResult<&MapSpec> {
    spec.map.as_ref().ok_or_else(|| to_py(DganError::InvalidSpec("the specification has no map".into())))
}

/// The square scene raster `(3, size_px, size_px)` of `frame`'s map at the spec's crop resolution, centred on
/// `origin` with image-up along `heading` (π/2: north up), the agents drawn as the spec's crops draw them.
#[pyfunction]
pub fn scene_raster<'py>(
    py: Python<'py>,
    frame: &PyFrame,
    spec_json: &str,
    size_px: usize,
    origin: [f64; 2],
    heading: f64,
) -> PyResult<Bound<'py, PyArray3<f32>>> {
    let spec = parse_spec(spec_json).py()?;
    let crop = map_of(&spec)?;
    if !(origin.iter().all(|v| v.is_finite()) && heading.is_finite()) {
        return Err(to_py(DganError::InvalidFrame(format!(
            "origin and heading must be finite, got {origin:?}, {heading}"
        ))));
    }
    let frame = &frame.inner;
    let raster = py
        .detach(|| {
            let states = traffic_states_with(frame, spec.dt_s, spec.heading);
            scene::scene_raster(frame, &states, crop, size_px, AgentPose::new(origin, heading))
        })
        .py()?;
    Ok(raster.into_pyarray(py))
}

/// Where each agent's crop (origins `(N, 2)`, headings `(N,)`) lies in the scene raster of [`scene_raster`]:
/// `(N, ⌈H / stride⌉, ⌈W / stride⌉, 2)` `grid_sample` coordinates of its `stride × stride` blocks' centres.
#[pyfunction]
#[allow(clippy::too_many_arguments)]
pub fn crop_grid<'py>(
    py: Python<'py>,
    origins: PyReadonlyArrayDyn<'py, f64>,
    headings: PyReadonlyArrayDyn<'py, f64>,
    spec_json: &str,
    stride: usize,
    size_px: usize,
    scene_origin: [f64; 2],
    scene_heading: f64,
) -> PyResult<Bound<'py, PyArray4<f32>>> {
    let spec = parse_spec(spec_json).py()?;
    let crop = map_of(&spec)?;
    let poses = poses(&origins, &headings)?;
    let finite = poses.iter().all(|p| p.origin().iter().all(|v| v.is_finite()) && p.heading().is_finite());
    if !(finite && scene_origin.iter().all(|v| v.is_finite()) && scene_heading.is_finite()) {
        return Err(to_py(DganError::InvalidFrame("origins, headings and the scene's pose must be finite".into())));
    }
    let scene_pose = AgentPose::new(scene_origin, scene_heading);
    let grid = scene::crop_grid(&poses, crop, stride, size_px, &scene_pose).py()?;
    Ok(grid.into_pyarray(py))
}

/// Each agent's reading `(N, C, gh, gw)` of a kept-features model's tiles (contract 13, `dgan_core::kept`): for every
/// block centre the weighted sum of its four rows (`index`, `weight` `(N, gh · gw · 4)`, as `dgan.preprocess` gives
/// them) of `rows` `(R, C)`, the kept rows followed by those of the tiles computed (the network's `map_features`).
#[pyfunction]
pub fn read_kept<'py>(
    py: Python<'py>,
    rows: PyReadonlyArray2<'py, f32>,
    index: PyReadonlyArray2<'py, i64>,
    weight: PyReadonlyArray2<'py, f32>,
    grid: (usize, usize),
) -> PyResult<Bound<'py, PyArray4<f32>>> {
    let (rows, index, weight) = (rows.as_array(), index.as_array().to_owned(), weight.as_array().to_owned());
    if rows.iter().any(|v| !v.is_finite()) || weight.iter().any(|v| !v.is_finite()) {
        return Err(to_py(DganError::InvalidSpec("rows and weights must be finite".into())));
    }
    let out = dgan_core::kept::read_rows(rows, &index, &weight, grid).py()?;
    Ok(out.into_pyarray(py))
}
