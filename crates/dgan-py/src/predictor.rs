//! `Predictor`: a loaded, contract-checked model; `predict` runs with the GIL released.

use crate::error::IntoPyResult;
use crate::frame::PyFrame;
use dgan_core::{ExecutionProvider, Limits, Prediction, Predictor, PredictorOptions};
use numpy::{IntoPyArray, PyArray1, PyArray2, PyArray4};
use pyo3::prelude::*;
use std::path::PathBuf;

/// A DGAN model around an ONNX Runtime session (see `dgan.Predictor`).
#[derive(Debug)]
#[pyclass(name = "Predictor", module = "dgan._dgan", frozen)]
pub struct PyPredictor {
    inner: Predictor,
}

/// What the engine predicted for one frame, its arrays handed to numpy without a copy (`dgan.Prediction` adds the
/// ids as given, the classes and the time base). A new output is a field here, of `dgan_core::Prediction` and of
/// `dgan.Prediction`.
#[pyclass(name = "Prediction", module = "dgan._dgan", frozen)]
pub struct PyPrediction {
    /// `(N,)` the engine's agent codes.
    #[pyo3(get)]
    agent_ids: Py<PyArray1<i64>>,
    /// `(N, M, T_f, 2)` world-frame modes, most probable first.
    #[pyo3(get)]
    trajectories: Py<PyArray4<f64>>,
    /// `(N, M)` p(c) · p(k | c).
    #[pyo3(get)]
    probabilities: Py<PyArray2<f64>>,
    /// `(N, C)` p(c).
    #[pyo3(get)]
    class_probabilities: Py<PyArray2<f64>>,
    /// `(N, M)` class index of each mode's anchor.
    #[pyo3(get)]
    mode_classes: Py<PyArray2<i64>>,
    /// `(E, 2)` undirected attention-zone edges.
    #[pyo3(get)]
    edges: Py<PyArray2<i64>>,
    /// The frame's measured headings against its agents' motion, when `predict` was asked to check them.
    #[pyo3(get)]
    headings: Headings,
    /// The frame's speeds against its agents' classes, when `predict` was asked to check them.
    #[pyo3(get)]
    speeds: Speeds,
}

/// A frame's speeds against what its agents' classes can do (`dgan_core::state::check_speeds`): `(class, moving
/// agents of it, their median speed in the frame's units per second, the class's plausible median in m/s, whether
/// it exceeds that)`, or `None` when not asked or when no class has enough moving agents to judge.
type Speeds = Option<(&'static str, usize, f64, f64, bool)>;

/// How well a frame's measured headings follow its agents' motion (`dgan_core::state::check_headings`): `(moving
/// agents, median error in degrees, the largest |heading|, whether some |heading| > 2π, whether enough agents move to
/// judge by the motion, whether they most likely follow another convention)`, or `None` when not asked or when the
/// frame has no measured heading.
type Headings = Option<(usize, f64, f64, bool, bool, bool)>;

fn native_prediction(py: Python<'_>, p: Prediction, (headings, speeds): (Headings, Speeds)) -> PyPrediction {
    PyPrediction {
        agent_ids: ndarray::Array1::from(p.agent_ids).into_pyarray(py).unbind(),
        trajectories: p.trajectories.into_pyarray(py).unbind(),
        probabilities: p.probabilities.into_pyarray(py).unbind(),
        class_probabilities: p.class_probabilities.into_pyarray(py).unbind(),
        mode_classes: p.mode_classes.into_pyarray(py).unbind(),
        edges: p.edges.into_pyarray(py).unbind(),
        headings,
        speeds,
    }
}

/// The checks `predict` was asked for, at the model's time base (`dgan_core::state::check_frame`): `(headings,
/// speeds)`.
fn checks(frame: &dgan_core::Frame, dt_s: f64, headings: bool, speeds: bool) -> (Headings, Speeds) {
    use dgan_core::state::{check_frame, plausible_median_speed_mps};
    let (h, s) = check_frame(frame, dt_s, headings, speeds);
    (
        h.map(|c| {
            (c.moving, c.median_error_deg, c.largest_rad, c.beyond_two_pi(), c.judged_by_motion(), c.disagrees())
        }),
        s.map(|c| (c.class.name(), c.moving, c.median_speed, plausible_median_speed_mps(c.class), c.implausible())),
    )
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

    /// Single-threaded sessions for the parts of a split frame and predict_batch's concurrent calls.
    #[getter]
    fn lanes(&self) -> usize {
        self.inner.lanes()
    }

    #[getter]
    fn path(&self) -> PathBuf {
        self.inner.path().to_path_buf()
    }

    /// The latest predict call's phase times in milliseconds (`preprocess`, `crops`, `network`, `decode`, `parts`,
    /// `total`), or None before the first.
    #[getter]
    fn last_timings(&self) -> Option<Vec<(&'static str, f64)>> {
        self.inner.last_times().map(|t| {
            let ms = |d: std::time::Duration| d.as_secs_f64() * 1e3;
            vec![
                ("preprocess", ms(t.preprocess)),
                ("crops", ms(t.crops)),
                ("network", ms(t.network)),
                ("decode", ms(t.decode)),
                ("parts", ms(t.parts)),
                ("total", ms(t.total)),
            ]
        })
    }

    /// Predicts several frames in as few network calls as fit; one prediction per frame (each with its frame's
    /// heading check when `check_headings`, and its speed check when `check_speeds`).
    #[pyo3(signature = (frames, modes, check_headings = false, check_speeds = false))]
    fn predict_batch<'py>(
        &self,
        py: Python<'py>,
        frames: Vec<PyRef<'py, PyFrame>>,
        modes: usize,
        check_headings: bool,
        check_speeds: bool,
    ) -> PyResult<Vec<PyPrediction>> {
        let frames: Vec<dgan_core::Frame> = frames.iter().map(|f| f.inner.clone()).collect();
        let dt_s = self.inner.contract().input.dt_s;
        let (out, found) = py.detach(|| {
            let found: Vec<_> = frames.iter().map(|f| checks(f, dt_s, check_headings, check_speeds)).collect();
            (self.inner.predict_batch(&frames, modes), found)
        });
        let out = out.py()?;
        Ok(out.into_iter().zip(found).map(|(p, c)| native_prediction(py, p, c)).collect())
    }

    /// Predicts the top `modes` modes of every agent; with `check_headings`, also checks the frame's measured
    /// headings against its agents' motion, and with `check_speeds` its agents' speeds against their classes (in
    /// the same call, on the same frame).
    #[pyo3(signature = (frame, modes, check_headings = false, check_speeds = false))]
    fn predict(
        &self,
        py: Python<'_>,
        frame: &PyFrame,
        modes: usize,
        check_headings: bool,
        check_speeds: bool,
    ) -> PyResult<PyPrediction> {
        let frame = &frame.inner;
        let dt_s = self.inner.contract().input.dt_s;
        let (p, found) =
            py.detach(|| (self.inner.predict_modes(frame, modes), checks(frame, dt_s, check_headings, check_speeds)));
        Ok(native_prediction(py, p.py()?, found))
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
