//! # dgan-core
//!
//! The engine of DGAN, the Dynamic Graph Attention Network for multi-modal trajectory prediction
//! (Dong et al., 2020): everything around the network, in pure Rust.
//!
//! - [`frame`]: the scene at t_obs, validated; [`map`]: raster and vector maps.
//! - [`state`]: speed, acceleration, heading and yaw rate from the history; [`transform`]: agent-centric SE(2).
//! - [`graph`]: the attention-zone graph r = v · T_f + λ · length, sub-quadratic and exact.
//! - [`raster`]: agent-centric RGB map crops in the paper's colours; [`scene`]: one raster of the scene that a map
//!   CNN reads once for every agent, and where each agent's crop lies in it.
//! - [`prior`]: the kinematic rollout the network refines.
//! - [`preprocess`]: frame → network inputs; [`decode`]: p(c) · p(k | c), anchors + offsets → world modes.
//! - [`history`]: detections at any times → frames on the model's time grid; the streaming [`history::Tracker`].
//! - [`batch`]: several frames as one graph, for [`Predictor::predict_batch`].
//! - [`limits`]: bounds and tolerances shared by several modules.
//! - [`contract`]: the model contract; [`runtime`]: the ONNX Runtime session and [`Predictor`].
//!
//! ```no_run
//! use dgan_core::{AgentClass, Frame, Predictor};
//! use ndarray::Array3;
//!
//! # fn main() -> dgan_core::Result<()> {
//! let predictor = Predictor::load("model.onnx")?; // ONNX Runtime from ORT_DYLIB_PATH
//! let positions = Array3::<f64>::zeros((1, 8, 2));
//! let frame = Frame::new(positions, None, vec![AgentClass::Pedestrian])?;
//! let prediction = predictor.predict(&frame)?;
//! println!("{:?}", prediction.probabilities);
//! # Ok(())
//! # }
//! ```
#![warn(missing_docs)]

pub mod batch;
pub mod canvas;
pub mod class;
pub mod contract;
pub mod decode;
pub mod error;
pub mod frame;
pub mod graph;
pub mod history;
pub mod integrity;
pub mod kept;
pub mod limits;
pub mod map;
pub mod preprocess;
pub mod prior;
pub mod raster;
pub mod runtime;
pub mod scene;
pub mod spec;
pub mod state;
pub mod tile_store;
pub mod tiles;
pub mod transform;

pub use class::AgentClass;
pub use contract::ModelContract;
pub use error::{DganError, Result};
pub use frame::Frame;
pub use history::{
    frame_and_future_at, frame_at, frame_at_with, sample_track, tracks_from_rows, tracks_from_rows_with, Detection,
    Duplicates, Future, Resampled, TimeBase, Tracker,
};
pub use map::{MapElement, MapElementKind, RasterMap, SceneMap, VectorMap};
pub use preprocess::Limits;
pub use prior::{PriorKind, PriorSpec, VelocityFit};
pub use runtime::{
    available_execution_providers, init_onnxruntime, ExecutionProvider, PhaseTimes, Prediction, Predictor,
    PredictorOptions,
};
pub use spec::{GraphLayout, HeadingSource, InputSpec, MapRender, MapSpec};

/// The crate's folder as cargo gives it to the running test (`CARGO_MANIFEST_DIR` at run time; the compile-time
/// value only as a fallback), so that a test binary reused from a checkout elsewhere still finds the repository.
#[cfg(test)]
pub(crate) fn manifest_dir() -> std::path::PathBuf {
    std::env::var_os("CARGO_MANIFEST_DIR").map_or_else(|| env!("CARGO_MANIFEST_DIR").into(), Into::into)
}
