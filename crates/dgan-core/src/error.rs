//! The one error type of the engine.

use std::path::PathBuf;

/// Everything that can go wrong in `dgan-core`. Each variant maps to its own Python exception class in the
/// bindings, so a caller can tell bad input from a bad model from a runtime failure.
#[derive(Debug, thiserror::Error)]
pub enum DganError {
    /// The frame's arrays are inconsistent or hold invalid values (NaN, infinities, wrong shapes, empty histories).
    #[error("invalid frame: {0}")]
    InvalidFrame(String),
    /// A class name or index that neither the engine nor the model knows.
    #[error("unknown class: {0}")]
    UnknownClass(String),
    /// The model's map branch needs a map and the frame has none.
    #[error("map required: {0}")]
    MapRequired(String),
    /// A scene whose attention graph or input tensors exceed the configured [`Limits`](crate::preprocess::Limits).
    #[error("scene too large: {0}")]
    SceneTooLarge(String),
    /// A frame's time base differs from the model's, or data cannot be resampled to it (too sparse, unordered).
    #[error("time base: {0}")]
    TimeBase(String),
    /// Data sampled more sparsely than a model's grid allows (see `history::frame_at_with`): refused rather than
    /// stretched. Python: `TimeBaseError` with the spacing as `spacing_s`.
    #[error("time base: {message}")]
    SparseData {
        /// The data's median spacing within the window, seconds.
        spacing_s: f64,
        /// What is wrong and what would fit.
        message: String,
    },
    /// A raster or vector map that cannot be used (bad image shape, singular homography, degenerate geometry).
    #[error("invalid map: {0}")]
    InvalidMap(String),
    /// A preprocessing or model specification that cannot be satisfied (e.g. zero steps, a negative resolution).
    #[error("invalid specification: {0}")]
    InvalidSpec(String),
    /// The model file does not exist.
    #[error("model file not found: {}", .0.display())]
    ModelNotFound(PathBuf),
    /// The model file exists but ONNX Runtime cannot read it (corrupt, truncated, not ONNX).
    #[error("cannot load model {}: {reason}", path.display())]
    ModelLoad {
        /// The file that failed to load.
        path: PathBuf,
        /// What ONNX Runtime said.
        reason: String,
    },
    /// The model loads but breaks the model contract (inputs, outputs or metadata); see `docs/model-contract.md`.
    #[error("model breaks the dgan model contract: {0}")]
    Contract(String),
    /// The ONNX Runtime shared library could not be found or loaded.
    #[error("ONNX Runtime library: {0}")]
    RuntimeLibrary(String),
    /// ONNX Runtime failed while running a loaded, contract-checked model.
    #[error("inference failed: {0}")]
    Inference(String),
}

impl DganError {
    /// The same error with `what` ("frame 3 of the batch") before its message; errors without a message of their
    /// own (a missing file, a sparse time base) are returned as they are.
    #[must_use]
    pub fn context(self, what: &str) -> Self {
        let at = |m: String| format!("{what}: {m}");
        match self {
            Self::InvalidFrame(m) => Self::InvalidFrame(at(m)),
            Self::UnknownClass(m) => Self::UnknownClass(at(m)),
            Self::MapRequired(m) => Self::MapRequired(at(m)),
            Self::SceneTooLarge(m) => Self::SceneTooLarge(at(m)),
            Self::TimeBase(m) => Self::TimeBase(at(m)),
            Self::InvalidMap(m) => Self::InvalidMap(at(m)),
            Self::InvalidSpec(m) => Self::InvalidSpec(at(m)),
            Self::Contract(m) => Self::Contract(at(m)),
            Self::Inference(m) => Self::Inference(at(m)),
            other => other,
        }
    }
}

/// Result alias of the engine.
pub type Result<T> = std::result::Result<T, DganError>;

pub(crate) fn invalid_frame(msg: impl Into<String>) -> DganError {
    DganError::InvalidFrame(msg.into())
}
