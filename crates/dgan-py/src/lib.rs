//! The native module `dgan._dgan`: a thin shell over `dgan-core`. Each file wraps one area of the core; this file
//! only assembles them. The Python package `dgan` adds the Pythonic surface.

mod constants;
mod error;
mod frame;
mod geometry;
mod history;
mod predictor;
mod preprocess;
mod scene;

use pyo3::prelude::*;

/// Loads the ONNX Runtime library (absolute path) once per process; returns the path in use.
#[pyfunction]
fn init_onnxruntime(path: Option<std::path::PathBuf>) -> PyResult<std::path::PathBuf> {
    use error::IntoPyResult;
    dgan_core::init_onnxruntime(path.as_deref()).py()
}

#[pymodule]
fn _dgan(m: &Bound<'_, PyModule>) -> PyResult<()> {
    m.add("__version__", env!("CARGO_PKG_VERSION"))?;
    m.add("CONTRACT_VERSION", dgan_core::contract::CONTRACT_VERSION)?;
    m.add("CONTRACT", constants::contract(m.py())?)?;
    m.add("DUPLICATES", dgan_core::Duplicates::ALL.map(|(name, _)| name).to_vec())?;
    m.add("UPSAMPLE_LIMIT", dgan_core::history::UPSAMPLE_LIMIT)?;
    m.add("SPARSE_SLACK", dgan_core::history::SPARSE_SLACK)?;
    m.add_class::<frame::PyFrame>()?;
    m.add_class::<frame::PyRasterMap>()?;
    m.add_class::<frame::PyVectorMap>()?;
    m.add_class::<predictor::PyPredictor>()?;
    m.add_class::<predictor::PyPrediction>()?;
    m.add_class::<history::PyTracker>()?;
    m.add_function(wrap_pyfunction!(history::frames_from_rows, m)?)?;
    m.add_function(wrap_pyfunction!(history::sample_track, m)?)?;
    m.add_function(wrap_pyfunction!(preprocess::preprocess, m)?)?;
    m.add_function(wrap_pyfunction!(preprocess::validate_spec, m)?)?;
    m.add_function(wrap_pyfunction!(preprocess::kinematic_prior, m)?)?;
    m.add_function(wrap_pyfunction!(preprocess::still_agents, m)?)?;
    m.add_function(wrap_pyfunction!(geometry::to_agent_frame, m)?)?;
    m.add_function(wrap_pyfunction!(geometry::to_world_frame, m)?)?;
    m.add_function(wrap_pyfunction!(geometry::attention_graph, m)?)?;
    m.add_function(wrap_pyfunction!(scene::scene_raster, m)?)?;
    m.add_function(wrap_pyfunction!(scene::crop_grid, m)?)?;
    m.add_function(wrap_pyfunction!(scene::read_kept, m)?)?;
    m.add_function(wrap_pyfunction!(init_onnxruntime, m)?)?;
    m.add_function(wrap_pyfunction!(predictor::available_execution_providers, m)?)?;
    m.add_function(wrap_pyfunction!(predictor::seal_model, m)?)?;
    Ok(())
}
