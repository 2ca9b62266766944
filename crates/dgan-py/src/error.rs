//! The one place where engine errors become Python exceptions: each `DganError` variant maps to its own class of
//! `dgan.exceptions` (each also a subclass of the matching built-in, e.g. `ValueError`).

use dgan_core::DganError;
use pyo3::exceptions::PyRuntimeError;
use pyo3::prelude::*;
use pyo3::types::PyType;

fn class_name(err: &DganError) -> &'static str {
    match err {
        DganError::InvalidFrame(_) => "InvalidFrameError",
        DganError::UnknownClass(_) => "UnknownClassError",
        DganError::MapRequired(_) => "MapRequiredError",
        DganError::TimeBase(_) | DganError::SparseData { .. } => "TimeBaseError",
        DganError::SceneTooLarge(_) => "SceneTooLargeError",
        DganError::InvalidMap(_) => "InvalidMapError",
        DganError::InvalidSpec(_) => "InvalidSpecError",
        DganError::ModelNotFound(_) => "ModelNotFoundError",
        DganError::ModelLoad { .. } => "ModelLoadError",
        DganError::Contract(_) => "ContractError",
        DganError::RuntimeLibrary(_) => "RuntimeLibraryError",
        DganError::Inference(_) => "InferenceError",
    }
}

/// Converts an engine error into the matching `dgan.exceptions` instance.
pub fn to_py(err: DganError) -> PyErr {
    Python::attach(|py| {
        let name = class_name(&err);
        let class = py
            .import("dgan.exceptions")
            .and_then(|m| m.getattr(name))
            .and_then(|c| c.cast_into::<PyType>().map_err(PyErr::from));
        match class {
            Ok(cls) => {
                let out = PyErr::from_type(cls, err.to_string());
                if let DganError::SparseData { spacing_s, .. } = err {
                    // What the Python side needs to name the models whose step fits the data.
                    let _ = out.value(py).setattr("spacing_s", spacing_s);
                }
                out
            }
            Err(e) => PyRuntimeError::new_err(format!("{err} (and dgan.exceptions.{name} is unavailable: {e})")),
        }
    })
}

/// `Result` → `PyResult` through [`to_py`].
pub trait IntoPyResult<T> {
    /// Converts the error, if any.
    fn py(self) -> PyResult<T>;
}

impl<T> IntoPyResult<T> for dgan_core::Result<T> {
    fn py(self) -> PyResult<T> {
        self.map_err(to_py)
    }
}

/// An engine `InvalidFrame` error as a Python exception.
pub fn invalid_frame(msg: impl Into<String>) -> PyErr {
    to_py(DganError::InvalidFrame(msg.into()))
}
