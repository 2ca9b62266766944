//! `Predictor`: a loaded, contract-checked model; `predict` runs with the GIL released.

use crate::error::IntoPyResult;
use crate::frame::PyFrame;
use dgan_core::{ExecutionProvider, Limits, Prediction, Predictor, PredictorOptions};
use numpy::IntoPyArray;
use pyo3::prelude::*;
use pyo3::types::PyDict;
use std::path::PathBuf;

/// A DGAN model around an ONNX Runtime session (see `dgan.Predictor`).
#[derive(Debug)]
#[pyclass(name = "Predictor", module = "dgan._dgan", frozen)]
pub struct PyPredictor {
    inner: Predictor,
}

fn prediction_dict<'py>(py: Python<'py>, p: Prediction) -> PyResult<Bound<'py, PyDict>> {
    let d = PyDict::new(py);
    d.set_item("agent_ids", p.agent_ids.into_pyarray(py))?;
    d.set_item("trajectories", p.trajectories.into_pyarray(py))?;
    d.set_item("probabilities", p.probabilities.into_pyarray(py))?;
    d.set_item("class_probabilities", p.class_probabilities.into_pyarray(py))?;
    d.set_item("mode_classes", p.mode_classes.into_pyarray(py))?;
    d.set_item("edges", p.edges.into_pyarray(py))?;
    Ok(d)
}

#[pymethods]
impl PyPredictor {
    #[new]
    #[pyo3(signature = (path, onnxruntime_library, intra_threads = 1, sessions = 1, execution_provider = "cpu", limits = None))]
    fn new(
        py: Python<'_>,
        path: PathBuf,
        onnxruntime_library: Option<PathBuf>,
        intra_threads: usize,
        sessions: usize,
        execution_provider: &str,
        limits: Option<(usize, usize)>,
    ) -> PyResult<Self> {
        let execution_provider: ExecutionProvider = execution_provider.parse().py()?;
        let limits =
            limits.map_or_else(Limits::default, |(max_edges, max_input_bytes)| Limits { max_edges, max_input_bytes });
        let options = PredictorOptions { onnxruntime_library, intra_threads, sessions, execution_provider, limits };
        let inner = py.detach(|| Predictor::load_with(&path, &options)).py()?;
        Ok(Self { inner })
    }

    /// The model contract as JSON.
    #[getter]
    fn contract_json(&self) -> PyResult<String> {
        self.inner.contract().to_json().py()
    }

    /// K = Σ K_c.
    #[getter]
    fn num_modes(&self) -> usize {
        self.inner.anchors().total()
    }

    /// ONNX Runtime sessions serving concurrent calls.
    #[getter]
    fn sessions(&self) -> usize {
        self.inner.sessions()
    }

    #[getter]
    fn path(&self) -> PathBuf {
        self.inner.path().to_path_buf()
    }

    /// Predicts several frames in one network call; returns one dict of numpy arrays per frame.
    fn predict_batch<'py>(
        &self,
        py: Python<'py>,
        frames: Vec<PyRef<'py, PyFrame>>,
        modes: usize,
    ) -> PyResult<Vec<Bound<'py, PyDict>>> {
        let frames: Vec<dgan_core::Frame> = frames.iter().map(|f| f.inner.clone()).collect();
        let out = py.detach(|| self.inner.predict_batch(&frames, modes)).py()?;
        out.into_iter().map(|p| prediction_dict(py, p)).collect()
    }

    /// Predicts the top `modes` modes of every agent; returns a dict of numpy arrays.
    fn predict<'py>(&self, py: Python<'py>, frame: &PyFrame, modes: usize) -> PyResult<Bound<'py, PyDict>> {
        let frame = &frame.inner;
        let p = py.detach(|| self.inner.predict_modes(frame, modes)).py()?;
        prediction_dict(py, p)
    }
}

/// The execution providers the ONNX Runtime library at `onnxruntime_library` offers (`"cpu"`, `"cuda"`).
#[pyfunction]
pub fn available_execution_providers(onnxruntime_library: Option<PathBuf>) -> PyResult<Vec<&'static str>> {
    dgan_core::available_execution_providers(onnxruntime_library.as_deref()).py()
}

/// Seals a model file in place with the SHA-256 digest of its bytes (its contract holds 64 zeros as
/// `weights_sha256`); returns the digest.
#[pyfunction]
pub fn seal_model(path: PathBuf) -> PyResult<String> {
    dgan_core::integrity::seal(&path).py()
}
