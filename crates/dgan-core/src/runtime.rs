//! The ONNX Runtime session: the only module of the engine that touches `ort`.
//!
//! ONNX Runtime is loaded at run time (`load-dynamic`) from a shared library, normally the
//! `libonnxruntime.so.*` the `onnxruntime` Python wheel ships in `onnxruntime/capi/`. Pass its absolute path in
//! [`PredictorOptions::onnxruntime_library`] or set `ORT_DYLIB_PATH`.

use crate::contract::{check_tensor, DType, ModelContract, METADATA_KEY};
use crate::contract::{
    INPUT_EDGE_FEATURES, INPUT_EDGE_INDEX, INPUT_MAP, INPUT_MAP_PRESENT, INPUT_STATE, INPUT_TRAJECTORY,
    INPUT_TRAJECTORY_MASK, OUTPUT_ANCHOR_LOGITS, OUTPUT_CLASS_LOGITS, OUTPUT_OFFSETS,
};
use crate::decode::{decode, Anchors, DecodeParams, NetworkOutputs};
use crate::error::{DganError, Result};
use crate::frame::Frame;
use crate::preprocess::{preprocess, NetworkInputs};
use ndarray::{Array2, Array4, Ix2, Ix4};
use ort::session::{Session, SessionInputValue};
use ort::value::{Tensor, TensorElementType, ValueType};
use std::path::{Path, PathBuf};
use std::sync::Mutex;

/// The environment variable naming the ONNX Runtime shared library.
pub const ORT_DYLIB_ENV: &str = "ORT_DYLIB_PATH";

static RUNTIME: Mutex<Option<PathBuf>> = Mutex::new(None);

/// Loads the ONNX Runtime shared library once per process: from `path`, else from `ORT_DYLIB_PATH`.
/// Later calls return the library already loaded; asking for a different file then is an error, since a process
/// holds one ONNX Runtime.
pub fn init_onnxruntime(path: Option<&Path>) -> Result<PathBuf> {
    let mut loaded = RUNTIME.lock().map_err(|_| DganError::RuntimeLibrary("runtime lock poisoned".into()))?;
    if let Some(current) = loaded.as_ref() {
        let same = path.is_none_or(|p| p.canonicalize().ok().as_deref() == current.canonicalize().ok().as_deref());
        if !same {
            return Err(DganError::RuntimeLibrary(format!(
                "ONNX Runtime is already loaded from {} in this process; it cannot also load {}",
                current.display(),
                path.map(|p| p.display().to_string()).unwrap_or_default()
            )));
        }
        return Ok(current.clone());
    }
    let path = match path {
        Some(p) => p.to_path_buf(),
        None => std::env::var_os(ORT_DYLIB_ENV).map(PathBuf::from).ok_or_else(|| {
            DganError::RuntimeLibrary(format!(
                "no ONNX Runtime library given: pass its path or set {ORT_DYLIB_ENV} to the libonnxruntime.so.* \
                 that the onnxruntime Python wheel ships in onnxruntime/capi/"
            ))
        })?,
    };
    if !path.is_absolute() {
        return Err(DganError::RuntimeLibrary(format!("{} is not an absolute path", path.display())));
    }
    if !path.is_file() {
        return Err(DganError::RuntimeLibrary(format!("{} does not exist", path.display())));
    }
    let builder = ort::init_from(&path).map_err(|e| DganError::RuntimeLibrary(e.to_string()))?;
    let _ = builder.with_name("dgan").commit();
    *loaded = Some(path.clone());
    Ok(path)
}

/// How a [`Predictor`] is built.
#[derive(Debug, Clone)]
pub struct PredictorOptions {
    /// Absolute path of the ONNX Runtime library; `None` reads `ORT_DYLIB_PATH`.
    pub onnxruntime_library: Option<PathBuf>,
    /// Threads ONNX Runtime may use inside one operator.
    pub intra_threads: usize,
}

impl Default for PredictorOptions {
    fn default() -> Self {
        Self { onnxruntime_library: None, intra_threads: 1 }
    }
}

/// The prediction for every agent of a frame.
#[derive(Debug, Clone)]
pub struct Prediction {
    /// The frame's agent ids, in row order.
    pub agent_ids: Vec<i64>,
    /// `(N, M, T_f, 2)` world-frame future positions, modes sorted by probability.
    pub trajectories: Array4<f64>,
    /// `(N, M)` mode probabilities p(c) · p(k | c).
    pub probabilities: Array2<f64>,
    /// `(N, C)` class probabilities p(c), in the model's class order.
    pub class_probabilities: Array2<f64>,
    /// `(N, M)` class index of each mode's anchor.
    pub mode_classes: Array2<i64>,
    /// `(E, 2)` undirected attention-zone edges `[i, j]` (`i < j`, row indices of the frame).
    pub edges: Array2<i64>,
}

/// A loaded, contract-checked DGAN model.
#[derive(Debug)]
pub struct Predictor {
    session: Mutex<Session>,
    contract: ModelContract,
    anchors: Anchors,
    path: PathBuf,
}

fn dtype_of(t: &ValueType) -> (Option<DType>, Vec<i64>) {
    match t {
        ValueType::Tensor { ty, shape, .. } => {
            let d = match ty {
                TensorElementType::Float32 => Some(DType::F32),
                TensorElementType::Int64 => Some(DType::I64),
                _ => None,
            };
            (d, shape.iter().copied().collect())
        }
        _ => (None, vec![]),
    }
}

impl Predictor {
    /// Loads a model with default options.
    pub fn load(path: impl AsRef<Path>) -> Result<Self> {
        Self::load_with(path, &PredictorOptions::default())
    }

    /// Loads a model, checks it against the contract and fails here, with a message, if it does not conform.
    pub fn load_with(path: impl AsRef<Path>, options: &PredictorOptions) -> Result<Self> {
        let path = path.as_ref().to_path_buf();
        if !path.is_file() {
            return Err(DganError::ModelNotFound(path));
        }
        init_onnxruntime(options.onnxruntime_library.as_deref())?;
        let load_err = |e: ort::Error| DganError::ModelLoad { path: path.clone(), reason: e.to_string() };
        let builder_err = |e: ort::Error<ort::session::builder::SessionBuilder>| {
            DganError::RuntimeLibrary(format!("cannot configure the session: {e}"))
        };
        let mut session = Session::builder()
            .map_err(|e| DganError::RuntimeLibrary(e.to_string()))?
            .with_intra_threads(options.intra_threads.max(1))
            .map_err(builder_err)?
            .with_inter_threads(1)
            .map_err(builder_err)?;
        let session = session.commit_from_file(&path).map_err(load_err)?;
        let json = session
            .metadata()
            .map_err(|e| DganError::Contract(format!("cannot read metadata: {e}")))?
            .custom(METADATA_KEY)
            .filter(|s| !s.is_empty())
            .ok_or_else(|| {
                DganError::Contract(format!(
                    "{} has no {METADATA_KEY:?} metadata; export it with dgan's exporter (docs/model-contract.md)",
                    path.display()
                ))
            })?;
        let contract = ModelContract::from_json(&json)?;
        let anchors = contract.anchors()?;

        let expected = contract.expected_inputs();
        for input in session.inputs() {
            let Some(want) = expected.iter().find(|w| w.name == input.name()) else {
                let names: Vec<_> = expected.iter().map(|w| w.name).collect();
                return Err(DganError::Contract(format!(
                    "unexpected input {:?}; the contract's inputs are {names:?}",
                    input.name()
                )));
            };
            let (dtype, shape) = dtype_of(input.dtype());
            check_tensor("input", want, dtype, &shape)?;
        }
        for want in &expected {
            if !session.inputs().iter().any(|i| i.name() == want.name) {
                return Err(DganError::Contract(format!("missing input {:?}", want.name)));
            }
        }
        for want in contract.expected_outputs()? {
            let out = session
                .outputs()
                .iter()
                .find(|o| o.name() == want.name)
                .ok_or_else(|| DganError::Contract(format!("missing output {:?}", want.name)))?;
            let (dtype, shape) = dtype_of(out.dtype());
            check_tensor("output", &want, dtype, &shape)?;
        }
        Ok(Self { session: Mutex::new(session), contract, anchors, path })
    }

    /// The model's contract (input specification, anchors, provenance).
    pub fn contract(&self) -> &ModelContract {
        &self.contract
    }

    /// The model's anchors.
    pub fn anchors(&self) -> &Anchors {
        &self.anchors
    }

    /// The file the model was loaded from.
    pub fn path(&self) -> &Path {
        &self.path
    }

    /// Predicts every mode (K = Σ K_c) for every agent.
    pub fn predict(&self, frame: &Frame) -> Result<Prediction> {
        self.predict_modes(frame, self.anchors.total())
    }

    /// Predicts the `modes` most probable modes (at most K) for every agent.
    pub fn predict_modes(&self, frame: &Frame, modes: usize) -> Result<Prediction> {
        if modes == 0 {
            return Err(DganError::InvalidSpec("modes must be at least 1".into()));
        }
        let spec = &self.contract.input;
        let pre = preprocess(frame, spec)?;
        let edges = Array2::from_shape_fn((pre.edges.len(), 2), |(e, k)| i64::from(pre.edges[e][k]));
        let n = frame.len();
        let (c, k, t_f) = (spec.classes.len(), self.anchors.total(), spec.t_f);
        if n == 0 {
            let m = modes.min(k);
            return Ok(Prediction {
                agent_ids: vec![],
                trajectories: Array4::zeros((0, m, t_f, 2)),
                probabilities: Array2::zeros((0, m)),
                class_probabilities: Array2::zeros((0, c)),
                mode_classes: Array2::zeros((0, m)),
                edges,
            });
        }
        let (class_logits, anchor_logits, offsets) = self.run(pre.inputs)?;
        let out = NetworkOutputs {
            class_logits: class_logits.view(),
            anchor_logits: anchor_logits.view(),
            offsets: offsets.view(),
        };
        let params = DecodeParams {
            anchors: &self.anchors,
            prior: Some(pre.prior.view()),
            temperature: self.contract.temperature,
        };
        let d = decode(out, params, &pre.poses, modes)?;
        Ok(Prediction {
            agent_ids: frame.ids().to_vec(),
            trajectories: d.trajectories,
            probabilities: d.probabilities,
            class_probabilities: d.class_probabilities,
            mode_classes: d.mode_classes,
            edges,
        })
    }

    /// Runs the network on preprocessed inputs; returns class logits, anchor logits and offsets.
    pub fn run(&self, inputs: NetworkInputs) -> Result<(Array2<f32>, Array2<f32>, Array4<f32>)> {
        let infer = |e: ort::Error| DganError::Inference(e.to_string());
        let mut feed: Vec<(&str, SessionInputValue<'_>)> = vec![
            (INPUT_TRAJECTORY, Tensor::from_array(inputs.trajectory).map_err(infer)?.into()),
            (INPUT_TRAJECTORY_MASK, Tensor::from_array(inputs.trajectory_mask).map_err(infer)?.into()),
            (INPUT_STATE, Tensor::from_array(inputs.state).map_err(infer)?.into()),
            (INPUT_EDGE_INDEX, Tensor::from_array(inputs.edge_index).map_err(infer)?.into()),
            (INPUT_EDGE_FEATURES, Tensor::from_array(inputs.edge_features).map_err(infer)?.into()),
        ];
        if let Some(map) = inputs.map {
            feed.push((INPUT_MAP, Tensor::from_array(map).map_err(infer)?.into()));
        }
        if let Some(present) = inputs.map_present {
            feed.push((INPUT_MAP_PRESENT, Tensor::from_array(present).map_err(infer)?.into()));
        }
        let mut session = self.session.lock().map_err(|_| DganError::Inference("session lock poisoned".into()))?;
        let outputs = session.run(feed).map_err(infer)?;
        let get = |name: &str| {
            outputs
                .get(name)
                .ok_or_else(|| DganError::Inference(format!("the model did not return {name:?}")))?
                .try_extract_array::<f32>()
                .map_err(infer)
        };
        fn shape_err(name: &'static str) -> impl Fn(ndarray::ShapeError) -> DganError {
            move |e| DganError::Inference(format!("{name}: {e}"))
        }
        let class_logits =
            get(OUTPUT_CLASS_LOGITS)?.into_dimensionality::<Ix2>().map_err(shape_err(OUTPUT_CLASS_LOGITS))?.to_owned();
        let anchor_logits = get(OUTPUT_ANCHOR_LOGITS)?
            .into_dimensionality::<Ix2>()
            .map_err(shape_err(OUTPUT_ANCHOR_LOGITS))?
            .to_owned();
        let offsets = get(OUTPUT_OFFSETS)?.into_dimensionality::<Ix4>().map_err(shape_err(OUTPUT_OFFSETS))?.to_owned();
        Ok((class_logits, anchor_logits, offsets))
    }
}
