//! The ONNX Runtime session: the only module of the engine that touches `ort`.
//!
//! ONNX Runtime is loaded at run time (`load-dynamic`) from a shared library, normally the
//! `libonnxruntime.so.*` the `onnxruntime` Python wheel ships in `onnxruntime/capi/`. Pass its absolute path in
//! [`PredictorOptions::onnxruntime_library`] or set `ORT_DYLIB_PATH`.

use crate::batch::{balanced_parts, join, take};
use crate::contract::{check_tensor, DType, ModelContract, METADATA_KEY};
use crate::contract::{
    INPUT_EDGE_FEATURES, INPUT_EDGE_INDEX, INPUT_MAP, INPUT_MAP_GRID, INPUT_MAP_PATCHES, INPUT_MAP_PRESENT,
    INPUT_MAP_SLOT, INPUT_NEIGHBOR_FEATURES, INPUT_NEIGHBOR_INDEX, INPUT_NEIGHBOR_MASK, INPUT_STATE, INPUT_TRAJECTORY,
    INPUT_TRAJECTORY_MASK, OUTPUT_ANCHOR_LOGITS, OUTPUT_CLASS_LOGITS, OUTPUT_MAP_FEATURES, OUTPUT_OFFSETS,
};
use crate::decode::{decode_on, Anchors, DecodeParams, Decoded, NetworkOutputs};
use crate::error::{DganError, Result};
use crate::frame::Frame;
use crate::limits::on_threads;
use crate::preprocess::{preprocess_for, preprocess_without_crops, Limits, NetworkInputs, Preprocessed};
use crate::raster::{rasterize_into, rasterize_rows};
use crate::spec::EDGE_FEATURES;
use crate::transform::AgentPose;
use ndarray::{s, Array2, Array3, Array4, ArrayView3, Axis, Ix2, Ix4};
use ort::session::{Session, SessionInputValue};
use ort::value::{Tensor, TensorElementType, TensorRef, ValueType};
use std::path::{Path, PathBuf};
use std::sync::atomic::{AtomicU64, AtomicUsize, Ordering};
use std::sync::{Mutex, MutexGuard, TryLockError};
use std::time::{Duration, Instant};

/// The most tiles of a kept-features model (contract 13) one network run computes.
const TILES_PER_RUN: usize = 64;

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

/// The most agents [`Predictor::predict_batch`] joins into one network call. Measured on 2 cores with the bundled
/// models: 64 real frames (1,000–2,900 agents) joined into one call ran at 0.74–0.92× a loop of `predict` for
/// three of them, since every agent is padded to the largest degree of any frame and the tensors outgrow the caches;
/// calls of about 200 agents were the fastest (0.96–1.54× a loop).
pub const BATCH_AGENTS_PER_CALL: usize = 256;

/// How a [`Predictor`] is built.
#[derive(Debug, Clone)]
pub struct PredictorOptions {
    /// Absolute path of the ONNX Runtime library; `None` reads `ORT_DYLIB_PATH`.
    pub onnxruntime_library: Option<PathBuf>,
    /// Threads one call may use: ONNX Runtime's threads inside one operator, and the threads that draw the map crops
    /// (and, in [`Predictor::predict_batch`], preprocess the frames). 1 (the default) keeps a call on its own
    /// thread, so that several predictors share a machine without competing; up to the machine's cores for the
    /// lowest latency of one call.
    pub intra_threads: usize,
    /// ONNX Runtime sessions of the model (at least 1): calls from several threads run concurrently on different
    /// sessions (a session runs one call at a time). More sessions cost memory and load time, not accuracy.
    pub sessions: usize,
    /// Where ONNX Runtime runs the network.
    pub execution_provider: ExecutionProvider,
    /// Bounds on the work one frame may cause (attention edges, input bytes).
    pub limits: Limits,
}

impl Default for PredictorOptions {
    fn default() -> Self {
        Self {
            onnxruntime_library: None,
            intra_threads: 1,
            sessions: 1,
            execution_provider: ExecutionProvider::Cpu,
            limits: Limits::default(),
        }
    }
}

/// Where ONNX Runtime runs the network. A provider the loaded ONNX Runtime library lacks is an error at load
/// ([`DganError::RuntimeLibrary`]), never a silent fall-back to the CPU.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub enum ExecutionProvider {
    /// ONNX Runtime's CPU kernels (every build has them).
    #[default]
    Cpu,
    /// NVIDIA CUDA on a GPU (needs the `onnxruntime-gpu` library and CUDA).
    Cuda {
        /// The GPU's index.
        device_id: i32,
    },
}

impl std::str::FromStr for ExecutionProvider {
    type Err = DganError;

    /// `"cpu"`, `"cuda"` or `"cuda:N"`.
    fn from_str(s: &str) -> Result<Self> {
        let bad =
            || DganError::InvalidSpec(format!("execution provider must be \"cpu\", \"cuda\" or \"cuda:N\", got {s:?}"));
        match s.trim().to_ascii_lowercase().as_str() {
            "cpu" => Ok(Self::Cpu),
            "cuda" => Ok(Self::Cuda { device_id: 0 }),
            other => {
                let id = other.strip_prefix("cuda:").ok_or_else(bad)?;
                let device_id = id.parse::<i32>().ok().filter(|d| (0..=1024).contains(d)).ok_or_else(bad)?;
                Ok(Self::Cuda { device_id })
            }
        }
    }
}

impl std::fmt::Display for ExecutionProvider {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self {
            Self::Cpu => write!(f, "cpu"),
            Self::Cuda { device_id } => write!(f, "cuda:{device_id}"),
        }
    }
}

/// The execution providers the loaded ONNX Runtime library offers, by dgan's names (`"cpu"`, `"cuda"`); loads the
/// library first (see [`init_onnxruntime`]).
pub fn available_execution_providers(onnxruntime_library: Option<&Path>) -> Result<Vec<&'static str>> {
    use ort::ep::ExecutionProvider as _;
    init_onnxruntime(onnxruntime_library)?;
    let mut out = vec!["cpu"];
    if ort::ep::CUDA::default().is_available().map_err(|e| DganError::RuntimeLibrary(e.to_string()))? {
        out.push("cuda");
    }
    Ok(out)
}

/// Most threads one operator may use: the machine's cores.
pub fn max_intra_threads() -> usize {
    crate::limits::cores()
}

/// Most sessions one predictor may hold.
pub const MAX_SESSIONS: usize = 64;

/// A frame of at least [`SPLIT_MIN_AGENTS`] agents runs as several concurrent network calls, one per lane, when its
/// attention graph's components share out so that no part holds more than `SPLIT_MAX_LOAD / lanes` of its agents
/// (0.6 on two cores): in a probe on the bundled scenes tiled to 32 and 256 agents (docs/speed.md), parts of 21 and 11
/// agents took 0.78-0.81 of one thread's time against 0.72 on two intra-op threads, of 18 and 14 0.65-0.71 against
/// 0.69, evenly shared parts 0.45-0.59 against 0.63-0.65.
pub const SPLIT_MAX_LOAD: f64 = 1.2;
/// The fewest agents a frame needs to be split across lanes.
pub const SPLIT_MIN_AGENTS: usize = 8;
/// With `threads` ≥ 2, a frame of fewer agents that does not split runs on one lane, single-threaded: at 8 agents
/// two intra-op threads took 1.11-1.40 of one thread's time (`hdmap`, `apolloscape`; docs/speed.md).
pub const INTRA_MIN_AGENTS: usize = 16;
/// [`INTRA_MIN_AGENTS`] for a model without a map, whose network has no convolution to share out: `apolloscape`'s
/// `predict` on two threads took 1.14, 1.07, 0.99 and 0.87 of one thread's time at 16, 24, 32 and 48 agents (bare
/// network 1.12, 1.03, 0.97, 0.83), where map models gain from 16 (`zara1` 0.71, `sdd` 0.92; docs/speed.md).
pub const INTRA_MIN_AGENTS_WITHOUT_MAP: usize = 32;
/// [`INTRA_MIN_AGENTS`] for a scene model (contract 12) whose frame does not split: `zara1`'s `predict` on two
/// intra-op threads took 1.02, 0.99, 0.98, 0.95, 0.88 and 0.85 of one thread's time at 16, 32, 48, 64, 96 and 256
/// agents in one call (docs/speed.md).
pub const INTRA_MIN_AGENTS_SCENE: usize = 64;

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

impl Prediction {
    /// A frame's prediction: its ids, its decoded modes (in frame order) and its graph's edges.
    fn of(frame: &Frame, d: Decoded, edges: Array2<i64>) -> Self {
        Self {
            agent_ids: frame.ids().to_vec(),
            trajectories: d.trajectories,
            probabilities: d.probabilities,
            class_probabilities: d.class_probabilities,
            mode_classes: d.mode_classes,
            edges,
        }
    }
}

/// `(E, 2)` the undirected attention-zone edges `[i, j]` as a prediction returns them.
pub fn edge_array(edges: &[[u32; 2]]) -> Array2<i64> {
    Array2::from_shape_fn((edges.len(), 2), |(e, k)| i64::from(edges[e][k]))
}

/// Where the wall time of one [`Predictor::predict_modes`] call went. A frame that runs as one network call has its
/// map crops, network and decoding timed apart; a frame split across lanes draws, runs and decodes each part on its own
/// thread, so those three are one figure there, `parts`.
#[derive(Debug, Clone, Copy, Default, PartialEq)]
pub struct PhaseTimes {
    /// The frame's tensors other than the map crops (states, transforms, graph, edge features, prior), on the calling
    /// thread.
    pub preprocess: Duration,
    /// The map crops, on up to `threads` threads (zero for a model without a map); of a model that keeps its map
    /// features (contract 13), the tiles it computes and every agent's reading of them.
    pub crops: Duration,
    /// The network call: tensors handed to ONNX Runtime, the run (copies to and from a GPU included), outputs read.
    pub network: Duration,
    /// Decoding the outputs into world-frame modes, on up to `threads` threads.
    pub decode: Duration,
    /// A split frame's parts (crops, network and decoding of each on its own lane), zero for a frame in one call.
    pub parts: Duration,
    /// The whole call.
    pub total: Duration,
}

/// A loaded, contract-checked DGAN model.
#[derive(Debug)]
pub struct Predictor {
    /// This predictor's number, unique in the process: the key of the map features it keeps with maps
    /// ([`crate::kept`]).
    id: u64,
    sessions: Vec<Mutex<Session>>,
    /// With `threads` ≥ 2 on the CPU, one single-threaded session per thread: the parts of a frame that splits
    /// ([`SPLIT_MAX_LOAD`]) and the network calls of [`Predictor::predict_batch`] run on them concurrently, where
    /// two sessions of `threads` intra-op threads each would fight for the cores (two frames in two threads on
    /// two-thread sessions: 0.68-1.10 of one thread's time, on single-threaded ones 0.51-0.88; docs/speed.md).
    lanes: Vec<Mutex<Session>>,
    next: AtomicUsize,
    contract: ModelContract,
    anchors: Anchors,
    /// The contract's top-mode scale per class (contract 14; empty without one).
    top_scale: Vec<f64>,
    /// The contract's still radius per class (contract 15; empty without one).
    still_radius: Vec<f64>,
    /// The contract's top-mean power per class (contract 16; empty without one).
    top_mean: Vec<f64>,
    path: PathBuf,
    limits: Limits,
    threads: usize,
    /// The memory of the last call's map crops, drawn into by the next ([`crate::raster::rasterize_into`]): large
    /// crops in fresh memory cost as much in page faults as in drawing. Empty for a model without a map.
    spare_crops: Mutex<Vec<f32>>,
    /// The phase times of the latest `predict_modes` call to finish.
    last_times: Mutex<Option<PhaseTimes>>,
}

/// One frame's prediction: its agents' rows `rows` of a batch's decode, or, where nothing was decoded (no agent in
/// the batch), an empty prediction of `empty = (modes, classes, T_f)`.
fn frame_prediction(
    frame: &Frame,
    decoded: Option<&Decoded>,
    rows: std::ops::Range<usize>,
    edges: Array2<i64>,
    (m, c, t_f): (usize, usize, usize),
) -> Prediction {
    let (a, b) = (rows.start, rows.end);
    match decoded {
        Some(d) => Prediction {
            agent_ids: frame.ids().to_vec(),
            trajectories: d.trajectories.slice(s![a..b, .., .., ..]).to_owned(),
            probabilities: d.probabilities.slice(s![a..b, ..]).to_owned(),
            class_probabilities: d.class_probabilities.slice(s![a..b, ..]).to_owned(),
            mode_classes: d.mode_classes.slice(s![a..b, ..]).to_owned(),
            edges,
        },
        None => Prediction {
            agent_ids: vec![],
            trajectories: Array4::zeros((0, m, t_f, 2)),
            probabilities: Array2::zeros((0, m)),
            class_probabilities: Array2::zeros((0, c)),
            mode_classes: Array2::zeros((0, m)),
            edges,
        },
    }
}

/// Refuses a session count or thread count out of bounds, before the model is read.
fn check_options(options: &PredictorOptions) -> Result<()> {
    if !(1..=MAX_SESSIONS).contains(&options.sessions) {
        return Err(DganError::InvalidSpec(format!(
            "sessions must be in 1..={MAX_SESSIONS}, got {}",
            options.sessions
        )));
    }
    let cores = max_intra_threads();
    if !(1..=cores).contains(&options.intra_threads) {
        return Err(DganError::InvalidSpec(format!(
            "threads must be in 1..={cores} (this machine's cores), got {}",
            options.intra_threads
        )));
    }
    Ok(())
}

/// The contract's JSON in the model's metadata, or an error that tells metadata that cannot be read (ONNX Runtime gives
/// no value for metadata that is not valid UTF-8) from none; `bytes` are the file's, `path` names it.
fn contract_json(session: &Session, bytes: &[u8], path: &Path) -> Result<String> {
    session
        .metadata()
        .map_err(|e| DganError::Contract(format!("cannot read metadata: {e}")))?
        .custom(METADATA_KEY)
        .filter(|s| !s.is_empty())
        .ok_or_else(|| {
            let key = format!("\"{METADATA_KEY}\"");
            // As ONNX's protobuf stores a metadata entry's key: field 1, length, the key, then field 2 (value).
            let mut entry = vec![0x0a, METADATA_KEY.len() as u8];
            entry.extend_from_slice(METADATA_KEY.as_bytes());
            entry.push(0x12);
            let present = bytes.windows(entry.len()).any(|w| w == entry.as_slice());
            DganError::Contract(if present {
                format!(
                    "{}: its {key} metadata cannot be read (not valid UTF-8, or damaged); export the model again",
                    path.display()
                )
            } else {
                format!(
                    "{} has no {key} metadata; export it with dgan's exporter (docs/model-contract.md)",
                    path.display()
                )
            })
        })
}

/// Refuses a graph whose inputs or outputs are not the contract's: an input it does not name, one it lacks, an
/// output missing, or any of another type or shape.
fn check_graph(session: &Session, contract: &ModelContract) -> Result<()> {
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
    Ok(())
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

/// The neighbours per agent a frame's network inputs are padded to (0 without a neighbour list).
fn degree_of(p: &Preprocessed) -> usize {
    p.inputs.neighbors.as_ref().map_or(0, |nb| nb.index.ncols())
}

/// One network call of `predict_batch`: the index of its first frame and its frames' inputs, to be joined.
type Call = (usize, Vec<Preprocessed>);

fn check_modes(modes: usize) -> Result<()> {
    if modes == 0 {
        return Err(DganError::InvalidSpec("modes must be at least 1".into()));
    }
    Ok(())
}

/// A session over the model's bytes (read and verified once, [`crate::integrity::read_verified`]); `path` names the
/// file in errors.
fn open_session(path: &Path, bytes: &[u8], options: &PredictorOptions) -> Result<Session> {
    let load_err = |e: ort::Error| DganError::ModelLoad { path: path.to_path_buf(), reason: e.to_string() };
    let builder_err = |e: ort::Error<ort::session::builder::SessionBuilder>| {
        DganError::RuntimeLibrary(format!("cannot configure the session: {e}"))
    };
    let mut builder = Session::builder()
        .map_err(|e| DganError::RuntimeLibrary(e.to_string()))?
        .with_intra_threads(options.intra_threads.max(1))
        .map_err(builder_err)?
        .with_inter_threads(1)
        .map_err(builder_err)?
        // Intra-op workers spin while a run needs them and stop when it ends, so that they do not take a core from
        // the next call's preprocessing (measured: docs/speed.md, `hdmap` at N = 256 on two threads 23-24 against
        // 31-33 ms; spinning off altogether was slower for the small models).
        .with_config_entry("session.force_spinning_stop", "1")
        .map_err(builder_err)?;
    if let ExecutionProvider::Cuda { device_id } = options.execution_provider {
        // Plain float32 products, as on the CPU: with ONNX Runtime's default TF32 the outputs moved by about 1e-3 m
        // and near-tied modes changed order (an H200, docs/speed.md).
        let cuda = ort::ep::CUDA::default().with_device_id(device_id).with_tf32(false).build().error_on_failure();
        builder = builder.with_execution_providers([cuda]).map_err(|e| {
            DganError::RuntimeLibrary(format!(
                "the CUDA execution provider (device {device_id}) cannot be used with this ONNX Runtime library: {e}; \
                 install onnxruntime-gpu, point onnxruntime_library (or ORT_DYLIB_PATH) at its libonnxruntime and \
                 put the CUDA and cuDNN libraries it was built for (libcublas, libcudnn, libcufft, libcurand) on \
                 LD_LIBRARY_PATH, or use the CPU"
            ))
        })?;
    }
    builder.commit_from_memory(bytes).map_err(load_err)
}

/// Which of a predictor's session pools a network call runs on.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum Pool {
    /// The sessions of `threads` intra-op threads, one call at a time each.
    Sessions,
    /// The single-threaded lanes, whose calls run concurrently (a split frame's parts, `predict_batch`'s calls).
    Lanes,
}

impl Pool {
    /// The threads a call on this pool decodes on: a lane's call keeps to its own thread beside the others.
    fn decode_threads(self, threads: usize) -> usize {
        match self {
            Pool::Sessions => threads,
            Pool::Lanes => 1,
        }
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
        check_options(options)?;
        // Before ONNX Runtime sees a byte of it; the sessions are built from these very bytes.
        let (bytes, digest) = crate::integrity::read_verified(&path)?;
        init_onnxruntime(options.onnxruntime_library.as_deref())?;
        let session = open_session(&path, &bytes, options)?;
        let contract = ModelContract::from_json(&contract_json(&session, &bytes, &path)?)?;
        if contract.weights_sha256 != digest {
            return Err(DganError::ModelLoad {
                path: path.clone(),
                reason: "the digest in its contract is not the one verified in the file".into(),
            });
        }
        let anchors = contract.anchors()?;
        let top_scale = contract.top_scales()?;
        let still_radius = contract.still_radii()?;
        let top_mean = contract.top_mean_powers()?;

        check_graph(&session, &contract)?;
        let mut sessions = vec![Mutex::new(session)];
        for _ in 1..options.sessions {
            sessions.push(Mutex::new(open_session(&path, &bytes, options)?));
        }
        let mut lanes = vec![];
        if options.intra_threads >= 2 && options.execution_provider == ExecutionProvider::Cpu {
            let single = PredictorOptions { intra_threads: 1, onnxruntime_library: None, ..*options };
            for _ in 0..options.intra_threads {
                lanes.push(Mutex::new(open_session(&path, &bytes, &single)?));
            }
        }
        static NEXT_ID: AtomicU64 = AtomicU64::new(1);
        Ok(Self {
            id: NEXT_ID.fetch_add(1, Ordering::Relaxed),
            sessions,
            lanes,
            next: AtomicUsize::new(0),
            spare_crops: Mutex::new(Vec::new()),
            last_times: Mutex::new(None),
            contract,
            anchors,
            top_scale,
            still_radius,
            top_mean,
            path,
            limits: options.limits,
            threads: options.intra_threads,
        })
    }

    /// This predictor's number, unique in the process: a scene model whose features are kept with the map
    /// (contract 13) keeps them under it, so that its later calls on the map read them.
    pub fn id(&self) -> u64 {
        self.id
    }

    /// How many ONNX Runtime sessions serve this predictor.
    pub fn sessions(&self) -> usize {
        self.sessions.len()
    }

    /// How many single-threaded sessions run the parts of a split frame and `predict_batch`'s calls concurrently
    /// (0 with one thread or on a GPU).
    pub fn lanes(&self) -> usize {
        self.lanes.len()
    }

    /// The first free session of `pool`, else one in turn, waited for. A lone caller keeps the same session, whose
    /// buffers stay in the caches (taking them in turn made one thread's `apolloscape` predict at N = 256 16% slower
    /// with two sessions than with one: docs/speed.md).
    fn session(&self, pool: Pool) -> Result<MutexGuard<'_, Session>> {
        let pool = self.pool(pool);
        let poisoned = || DganError::Inference("session lock poisoned".into());
        for session in pool {
            match session.try_lock() {
                Ok(guard) => return Ok(guard),
                Err(TryLockError::WouldBlock) => continue,
                Err(TryLockError::Poisoned(_)) => return Err(poisoned()),
            }
        }
        let start = self.next.fetch_add(1, Ordering::Relaxed) % pool.len().max(1);
        pool.get(start).ok_or_else(|| DganError::Inference("no session".into()))?.lock().map_err(|_| poisoned())
    }

    /// The sessions of `pool`.
    fn pool(&self, pool: Pool) -> &[Mutex<Session>] {
        match pool {
            Pool::Sessions => &self.sessions,
            Pool::Lanes => &self.lanes,
        }
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

    /// Predicts the `modes` most probable modes (at most K) for every agent. With `threads` ≥ 2, a frame whose
    /// attention graph falls into components that share out evenly ([`SPLIT_MAX_LOAD`]) runs as one network call per
    /// lane, concurrently; any other frame as one call on `threads` intra-op threads. Either way each agent's result
    /// is the one a single call gives, up to float rounding.
    pub fn predict_modes(&self, frame: &Frame, modes: usize) -> Result<Prediction> {
        check_modes(modes)?;
        let _in_flight = crate::raster::InFlight::enter();
        let started = Instant::now();
        let mut times = PhaseTimes::default();
        let spec = &self.contract.input;
        // The crops wait until the frame's parts are known (a split frame's are drawn on its parts' threads); a whole
        // frame's are drawn into the memory of the last call's.
        let (mut pre, mut later) = preprocess_without_crops(frame, spec, &self.limits, self.threads)?;
        times.preprocess = started.elapsed();
        if let (true, Some(m)) = (later, &spec.map) {
            // A scene model's rasters and grids (contract 12), timed as the crops they stand for: drawn before the
            // parts are known, since a part takes whole groups of them. A kept-features model's reads (contract 13)
            // are its own agents' alone, so a split frame's parts each find theirs on their lanes.
            if m.scene.is_some_and(|s| !(s.kept() && self.lanes.len() >= 2)) {
                pre.inputs.draw_scene(frame, &pre.states, m, Some(self.id))?;
                times.crops = started.elapsed().saturating_sub(times.preprocess);
                later = false;
            }
        }
        if self.lanes.len() >= 2 {
            if let Some(parts) = self.split(&pre) {
                let out = self.run_split(frame, pre, parts, later, modes)?;
                times.total = started.elapsed();
                times.parts = times.total.saturating_sub(times.preprocess);
                *self.last_times.lock().unwrap_or_else(|e| e.into_inner()) = Some(times);
                return Ok(out);
            }
        }
        if let (true, Some(m)) = (later, &spec.map) {
            if m.scene.is_some() {
                pre.inputs.draw_scene(frame, &pre.states, m, Some(self.id))?;
            } else {
                let spare = std::mem::take(&mut *self.spare_crops.lock().unwrap_or_else(|e| e.into_inner()));
                pre.inputs.map = Some(rasterize_into(frame, &pre.states, m, self.threads, spare)?);
            }
            times.crops = started.elapsed().saturating_sub(times.preprocess);
        }
        // A small frame on a lane: waking intra-op workers costs more than they give there.
        let pool = if pre.poses.len() < self.intra_min_agents() && !self.lanes.is_empty() {
            Pool::Lanes
        } else {
            Pool::Sessions
        };
        let mut out = self.run_and_decode(std::slice::from_ref(frame), vec![pre], modes, pool, Some(&mut times))?;
        times.total = started.elapsed();
        *self.last_times.lock().unwrap_or_else(|e| e.into_inner()) = Some(times);
        out.pop().ok_or_else(|| DganError::Inference("no prediction for the frame".into()))
    }

    /// The fewest agents of a frame that does not split for its network call to take the intra-op threads.
    fn intra_min_agents(&self) -> usize {
        match &self.contract.input.map {
            Some(m) if m.scene.is_some() => INTRA_MIN_AGENTS_SCENE,
            Some(_) => INTRA_MIN_AGENTS,
            None => INTRA_MIN_AGENTS_WITHOUT_MAP,
        }
    }

    /// Where the time of the latest [`Predictor::predict_modes`] call to finish went (with several threads predicting
    /// at once, whichever finished last); None before the first. Calls to [`Predictor::predict_batch`] are not timed.
    pub fn last_times(&self) -> Option<PhaseTimes> {
        *self.last_times.lock().unwrap_or_else(|e| e.into_inner())
    }

    /// The parts a frame runs as on the lanes, or None when it does not split well ([`SPLIT_MAX_LOAD`]): then one
    /// call on `threads` intra-op threads.
    fn split(&self, pre: &Preprocessed) -> Option<Vec<Vec<usize>>> {
        let (n, lanes) = (pre.poses.len(), self.lanes.len());
        if lanes < 2 || n < SPLIT_MIN_AGENTS {
            return None;
        }
        // A scene model's part takes whole groups of its rasters (each group's agents joined as if by edges).
        let mut edges = pre.edges.clone();
        if let (Some(grid), Some(slot)) = (&pre.inputs.map_grid, &pre.inputs.map_slot) {
            let most = grid.dim().1.max(1) as i64;
            let mut first: std::collections::HashMap<i64, u32> = std::collections::HashMap::new();
            for (i, s) in slot.iter().enumerate() {
                let f = *first.entry(s / most).or_insert(i as u32);
                if f != i as u32 {
                    edges.push([f, i as u32]);
                }
            }
        }
        let parts = balanced_parts(n, &edges, lanes);
        let largest = parts.iter().map(Vec::len).max().unwrap_or(n);
        (largest as f64 <= SPLIT_MAX_LOAD * n as f64 / lanes as f64).then_some(parts)
    }

    /// One frame as concurrent network calls, one per part (each closed under the graph's edges, so every agent
    /// sees the neighbours it would see in one call), each part's map crops (`crops_later`; a kept-features model's
    /// reads of its agents' tiles, [`crate::kept::kept_inputs`]) drawn, its network run and its outputs decoded on
    /// its thread; the rows put back in frame order.
    fn run_split(
        &self,
        frame: &Frame,
        pre: Preprocessed,
        parts: Vec<Vec<usize>>,
        crops_later: bool,
        modes: usize,
    ) -> Result<Prediction> {
        let parts: Vec<Vec<usize>> = parts.into_iter().filter(|p| !p.is_empty()).collect();
        let pre = &pre;
        let one = |rows: &Vec<usize>| -> Result<Decoded> {
            let mut inputs = take(&pre.inputs, rows)?;
            if let (true, Some(m)) = (crops_later, &self.contract.input.map) {
                if m.scene.is_some() {
                    // A kept-features model's part reads the tiles its own agents read.
                    let states: Vec<_> = rows.iter().map(|&i| pre.states[i]).collect();
                    inputs.draw_scene(frame, &states, m, Some(self.id))?;
                } else {
                    inputs.map = Some(rasterize_rows(frame, &pre.states, m, rows, 1)?);
                }
            }
            let still = self.still(&inputs)?;
            let outputs = self.run_on(Pool::Lanes, inputs)?;
            let prior = pre.prior.select(Axis(0), rows);
            let poses: Vec<_> = rows.iter().map(|&i| pre.poses[i]).collect();
            self.decode_outputs(&outputs, prior.view(), &still, &poses, modes, 1)
        };
        let panicked = || Err(DganError::Inference("a network thread panicked".into()));
        let decoded: Vec<Decoded> =
            on_threads(parts.iter().collect(), one, panicked).into_iter().collect::<Result<_>>()?;
        let parts: Vec<(&[usize], Decoded)> = parts.iter().map(Vec::as_slice).zip(decoded).collect();
        Ok(Prediction::of(frame, Decoded::gather(pre.poses.len(), &parts)?, edge_array(&pre.edges)))
    }

    /// Which agents of a network call's inputs are held at their prior (contract 15; empty without a still radius).
    fn still(&self, inputs: &NetworkInputs) -> Result<Vec<bool>> {
        let (t, m, st) = (inputs.trajectory.view(), inputs.trajectory_mask.view(), inputs.state.view());
        crate::decode::still_agents(t, m, st, &self.still_radius)
    }

    /// Decodes one network call's outputs ([`Predictor::run`]'s) on `threads`; `still` as [`Predictor::still`].
    fn decode_outputs(
        &self,
        (class_logits, anchor_logits, offsets): &(Array2<f32>, Array2<f32>, Array4<f32>),
        prior: ArrayView3<'_, f32>,
        still: &[bool],
        poses: &[AgentPose],
        modes: usize,
        threads: usize,
    ) -> Result<Decoded> {
        let out = NetworkOutputs {
            class_logits: class_logits.view(),
            anchor_logits: anchor_logits.view(),
            offsets: offsets.view(),
        };
        let params = DecodeParams {
            anchors: &self.anchors,
            prior: Some(prior),
            calibration: self.contract.calibration(),
            dt_s: self.contract.input.dt_s,
            top_scale: &self.top_scale,
            still,
            top_mean: &self.top_mean,
        };
        decode_on(out, params, poses, modes, threads)
    }

    /// Each frame of a batch preprocessed, in `threads` runs of consecutive frames, one thread each (each frame's crops
    /// on that thread). The first bad frame by index, whichever thread finished first, is named in the error.
    fn preprocess_batch(&self, frames: &[Frame]) -> Result<Vec<Preprocessed>> {
        let spec = &self.contract.input;
        let per_thread = frames.len().div_ceil(self.threads.max(1));
        let runs: Vec<&[Frame]> = frames.chunks(per_thread).collect();
        let preprocess = |part: &[Frame]| -> Vec<Result<Preprocessed>> {
            part.iter().map(|f| preprocess_for(f, spec, &self.limits, 1, self.id)).collect()
        };
        // A panicked thread returns nothing: each of its frames gets the error below.
        let panicked = Vec::new;
        let done: Vec<Vec<Result<Preprocessed>>> = on_threads(runs.clone(), preprocess, panicked);
        let mut pres = Vec::with_capacity(frames.len());
        for (part, results) in runs.iter().zip(done) {
            let (base, count) = (pres.len(), part.len());
            let mut results = results.into_iter();
            for i in 0..count {
                let p = results
                    .next()
                    .unwrap_or_else(|| Err(DganError::Inference("a preprocessing thread panicked".into())));
                pres.push(p.map_err(|e| e.context(&format!("frame {} of the batch", base + i)))?);
            }
        }
        Ok(pres)
    }

    /// Consecutive preprocessed frames joined into network calls (each with the index of its first frame); with
    /// lanes, calls small enough that every lane has work.
    fn batch_calls(&self, pres: Vec<Preprocessed>) -> Vec<Call> {
        let (frames, total) = (pres.len(), pres.iter().map(|p| p.poses.len()).sum::<usize>());
        let cap = if self.lanes.len() >= 2 {
            BATCH_AGENTS_PER_CALL.min(total.div_ceil(self.lanes.len()).max(1))
        } else {
            BATCH_AGENTS_PER_CALL
        };
        let mut groups: Vec<Call> = vec![];
        let mut pres = pres.into_iter().peekable();
        let mut start = 0;
        while start < frames {
            let (mut group, mut agents, mut degree) = (vec![], 0, 0);
            // A scene model's frames join only with frames of the same raster side (one (F, 3, S, S) input).
            let side = |p: &Preprocessed| p.inputs.map_grid.as_ref().and(p.inputs.map.as_ref()).map(|m| m.dim().2);
            while let Some(p) = pres.next_if(|p| {
                group.is_empty()
                    || (self.joins(agents + p.poses.len(), degree.max(degree_of(p)), cap)
                        && group.first().map(side) == Some(side(p)))
            }) {
                agents += p.poses.len();
                degree = degree.max(degree_of(&p));
                group.push(p);
            }
            let len = group.len();
            groups.push((start, group));
            start += len;
        }
        groups
    }

    /// Predicts several frames: each frame is preprocessed on its own (in parallel), consecutive frames' graphs are
    /// joined (disjoint, so nothing crosses between frames) into network calls of up to [`BATCH_AGENTS_PER_CALL`]
    /// agents (a larger frame runs alone), and the outputs are split again. With `threads` ≥ 2 the calls are smaller
    /// (every lane gets work) and run concurrently, one per lane ([`Predictor::lanes`]). Equal to calling
    /// [`Predictor::predict_modes`] on each frame, up to float rounding.
    pub fn predict_batch(&self, frames: &[Frame], modes: usize) -> Result<Vec<Prediction>> {
        check_modes(modes)?;
        let _in_flight = crate::raster::InFlight::enter();
        if frames.is_empty() {
            return Ok(vec![]);
        }
        let groups = self.batch_calls(self.preprocess_batch(frames)?);
        let call = |(start, group): Call, pool: Pool| {
            let end = start + group.len();
            self.run_and_decode(&frames[start..end], group, modes, pool, None)
        };
        if self.lanes.len() < 2 || groups.len() < 2 {
            let mut out = Vec::with_capacity(frames.len());
            for g in groups {
                out.extend(call(g, Pool::Sessions)?);
            }
            return Ok(out);
        }
        // The calls shared out over the lanes, each lane's in order, the most agents first to the least loaded.
        let mut per_lane: Vec<(usize, Vec<Call>)> = (0..self.lanes.len()).map(|_| (0, vec![])).collect();
        for g in groups {
            let agents: usize = g.1.iter().map(|p| p.poses.len()).sum();
            let lane = (0..per_lane.len()).min_by_key(|&l| per_lane[l].0).unwrap_or(0);
            per_lane[lane].0 += agents;
            per_lane[lane].1.push(g);
        }
        let work = |calls: Vec<Call>| -> Result<Vec<(usize, Vec<Prediction>)>> {
            calls.into_iter().map(|g| Ok((g.0, call(g, Pool::Lanes)?))).collect()
        };
        let panicked = || Err(DganError::Inference("a network thread panicked".into()));
        let mut by_start: Vec<(usize, Vec<Prediction>)> = vec![];
        for lane in on_threads(per_lane.into_iter().map(|l| l.1).collect(), work, panicked) {
            by_start.extend(lane?);
        }
        by_start.sort_by_key(|(start, _)| *start);
        Ok(by_start.into_iter().flat_map(|(_, p)| p).collect())
    }

    /// Whether frames of `agents` agents in all, padded to `degree` neighbours, join into one network call: at most
    /// `cap` agents ([`BATCH_AGENTS_PER_CALL`] or fewer) and `max_input_bytes` of inputs (each frame alone is within
    /// the limits).
    fn joins(&self, agents: usize, degree: usize, cap: usize) -> bool {
        agents <= cap && Limits::input_bytes(&self.contract.input, agents, degree) <= self.limits.max_input_bytes
    }

    fn run_and_decode(
        &self,
        frames: &[Frame],
        pres: Vec<Preprocessed>,
        modes: usize,
        pool: Pool,
        times: Option<&mut PhaseTimes>,
    ) -> Result<Vec<Prediction>> {
        let spec = &self.contract.input;
        let (c, k, t_f) = (spec.classes.len(), self.anchors.total(), spec.t_f);
        let m = modes.min(k);
        let mut inputs = Vec::with_capacity(pres.len());
        let (mut poses, mut priors, mut edges) = (vec![], vec![], vec![]);
        for p in pres {
            inputs.push(p.inputs);
            poses.extend(p.poses);
            priors.push(p.prior);
            edges.push(edge_array(&p.edges));
        }
        let (inputs, agent_ptr) = if inputs.len() == 1 {
            let n = poses.len();
            (inputs.pop().ok_or_else(|| DganError::Inference("no inputs".into()))?, vec![0, n])
        } else {
            let j = join(&inputs)?;
            (j.inputs, j.agent_ptr)
        };
        let decoded = if poses.is_empty() {
            None
        } else {
            Some(self.network_and_decode(inputs, priors, &poses, modes, pool, times)?)
        };
        let decoded = match (frames, decoded) {
            // One frame: its prediction is the whole decode, moved rather than sliced and copied.
            ([frame], Some(d)) => {
                let edges = edges.pop().ok_or_else(|| DganError::Inference("no edges for the frame".into()))?;
                return Ok(vec![Prediction::of(frame, d, edges)]);
            }
            (_, decoded) => decoded,
        };
        let empty = (m, c, t_f);
        Ok(frames
            .iter()
            .zip(edges)
            .enumerate()
            .map(|(f, (frame, edges))| {
                let (a, b) = (agent_ptr[f], agent_ptr[f + 1]);
                frame_prediction(frame, decoded.as_ref(), a..b, edges, empty)
            })
            .collect())
    }

    /// The network's outputs on `inputs` (a kept-features model's map read first), decoded against the frames'
    /// `priors` for agents at `poses`; `times`, if given, gets the network's and decoding's time and the reading's
    /// added to the crops'.
    fn network_and_decode(
        &self,
        inputs: NetworkInputs,
        mut priors: Vec<Array3<f32>>,
        poses: &[AgentPose],
        modes: usize,
        pool: Pool,
        times: Option<&mut PhaseTimes>,
    ) -> Result<Decoded> {
        // A kept-features model's reading of the map (and the tiles it had not kept) timed with the crops.
        let reading = Instant::now();
        let still = self.still(&inputs)?;
        let (inputs, patches) = self.read_kept(pool, inputs)?;
        let read = if patches.is_some() { reading.elapsed() } else { Duration::ZERO };
        let started = Instant::now();
        let outputs = self.run_read(pool, inputs, patches)?;
        let ran = started.elapsed();
        let prior = if priors.len() == 1 {
            priors.pop().ok_or_else(|| DganError::Inference("no prior".into()))?
        } else {
            let views: Vec<_> = priors.iter().map(|p| p.view()).collect();
            ndarray::concatenate(Axis(0), &views).map_err(|e| DganError::Inference(e.to_string()))?
        };
        let threads = pool.decode_threads(self.threads);
        let decoded = self.decode_outputs(&outputs, prior.view(), &still, poses, modes, threads)?;
        if let Some(times) = times {
            (times.network, times.decode) = (ran, started.elapsed().saturating_sub(ran));
            times.crops += read;
        }
        Ok(decoded)
    }

    /// Runs the network on preprocessed inputs; returns class logits, anchor logits and offsets.
    pub fn run(&self, inputs: NetworkInputs) -> Result<(Array2<f32>, Array2<f32>, Array4<f32>)> {
        self.run_on(Pool::Sessions, inputs)
    }

    /// A kept-features model's inputs (contract 13) made whole: the tiles of `map` that are not yet kept computed by
    /// a first run of the network (with one blank agent) and kept with their maps, then every agent's reading of the
    /// features ([`crate::kept::KeptReads::patches`]); `map` left with no tile for the second run. Other inputs as
    /// they are.
    fn read_kept(&self, pool: Pool, mut inputs: NetworkInputs) -> Result<(NetworkInputs, Option<Array4<f32>>)> {
        let Some(reads) = inputs.kept.take() else { return Ok((inputs, None)) };
        let tiles = inputs.map.take().ok_or_else(|| DganError::Inference("kept reads without tiles".into()))?;
        let side = tiles.dim().2;
        let new = if reads.new.is_empty() {
            None
        } else if tiles.dim().0 <= TILES_PER_RUN {
            Some(self.compute_tiles(pool, tiles)?)
        } else {
            // In runs of at most TILES_PER_RUN tiles, so that a frame that reads many bounds the network's memory.
            let mut rows = vec![];
            for start in (0..tiles.dim().0).step_by(TILES_PER_RUN) {
                let end = (start + TILES_PER_RUN).min(tiles.dim().0);
                rows.push(self.compute_tiles(pool, tiles.slice(s![start..end, .., .., ..]).to_owned())?);
            }
            let views: Vec<_> = rows.iter().map(|r| r.view()).collect();
            Some(ndarray::concatenate(Axis(0), &views).map_err(|e| DganError::Inference(e.to_string()))?)
        };
        if let Some(rows) = &new {
            reads.keep(rows.view())?;
        }
        let patches = reads.patches(new.as_ref().map(|r| r.view()))?;
        inputs.map = Some(Array4::zeros((0, 3, side, side)));
        Ok((inputs, Some(patches)))
    }

    /// The features `(T · t², C)` of the tiles `(T, 3, P, P)` (the output `map_features`): the network run on them
    /// with one blank agent.
    fn compute_tiles(&self, pool: Pool, tiles: Array4<f32>) -> Result<Array2<f32>> {
        let infer = |e: ort::Error| DganError::Inference(e.to_string());
        let spec = &self.contract.input;
        let m = spec.map.as_ref().ok_or_else(|| DganError::Inference("kept reads without a map".into()))?;
        let scene = m.scene.ok_or_else(|| DganError::Inference("kept reads without map.scene".into()))?;
        let (gh, gw) = m.scene_grid().unwrap_or((1, 1));
        let mut feed: Vec<(&str, SessionInputValue<'_>)> = vec![
            (INPUT_TRAJECTORY, Tensor::from_array(Array3::<f32>::zeros((1, spec.t_obs, 2))).map_err(infer)?.into()),
            (INPUT_TRAJECTORY_MASK, Tensor::from_array(Array2::<f32>::zeros((1, spec.t_obs))).map_err(infer)?.into()),
            (INPUT_STATE, Tensor::from_array(Array2::<f32>::zeros((1, spec.state_dim()))).map_err(infer)?.into()),
            (INPUT_NEIGHBOR_INDEX, Tensor::from_array(Array2::<i64>::zeros((1, 1))).map_err(infer)?.into()),
            (INPUT_NEIGHBOR_MASK, Tensor::from_array(Array2::<f32>::ones((1, 1))).map_err(infer)?.into()),
            (
                INPUT_NEIGHBOR_FEATURES,
                Tensor::from_array(Array3::<f32>::zeros((1, 1, EDGE_FEATURES.len()))).map_err(infer)?.into(),
            ),
            (INPUT_MAP, Tensor::from_array(tiles).map_err(infer)?.into()),
            (
                INPUT_MAP_PATCHES,
                Tensor::from_array(Array4::<f32>::zeros((1, scene.channels, gh, gw))).map_err(infer)?.into(),
            ),
        ];
        if m.optional {
            feed.push((INPUT_MAP_PRESENT, Tensor::from_array(ndarray::Array1::<f32>::zeros(1)).map_err(infer)?.into()));
        }
        let mut session = self.session(pool)?;
        let outputs = session.run(feed).map_err(infer)?;
        let rows = outputs
            .get(OUTPUT_MAP_FEATURES)
            .ok_or_else(|| DganError::Inference(format!("the model did not return {OUTPUT_MAP_FEATURES:?}")))?
            .try_extract_array::<f32>()
            .map_err(infer)?
            .into_dimensionality::<Ix2>()
            .map_err(|e| DganError::Inference(format!("{OUTPUT_MAP_FEATURES}: {e}")))?
            .to_owned();
        Ok(rows)
    }

    /// [`Predictor::run`] on the first free session of `pool`.
    fn run_on(&self, pool: Pool, inputs: NetworkInputs) -> Result<(Array2<f32>, Array2<f32>, Array4<f32>)> {
        let (inputs, patches) = self.read_kept(pool, inputs)?;
        self.run_read(pool, inputs, patches)
    }

    /// [`Predictor::run_on`] once a kept-features model's reading is done ([`Predictor::read_kept`]: `patches`).
    fn run_read(
        &self,
        pool: Pool,
        inputs: NetworkInputs,
        patches: Option<Array4<f32>>,
    ) -> Result<(Array2<f32>, Array2<f32>, Array4<f32>)> {
        let infer = |e: ort::Error| DganError::Inference(e.to_string());
        let kept = patches.is_some();
        let mut feed: Vec<(&str, SessionInputValue<'_>)> = vec![
            (INPUT_TRAJECTORY, Tensor::from_array(inputs.trajectory).map_err(infer)?.into()),
            (INPUT_TRAJECTORY_MASK, Tensor::from_array(inputs.trajectory_mask).map_err(infer)?.into()),
            (INPUT_STATE, Tensor::from_array(inputs.state).map_err(infer)?.into()),
        ];
        match inputs.neighbors {
            Some(nb) => {
                feed.push((INPUT_NEIGHBOR_INDEX, Tensor::from_array(nb.index).map_err(infer)?.into()));
                feed.push((INPUT_NEIGHBOR_MASK, Tensor::from_array(nb.mask).map_err(infer)?.into()));
                feed.push((INPUT_NEIGHBOR_FEATURES, Tensor::from_array(nb.features).map_err(infer)?.into()));
            }
            None => {
                feed.push((INPUT_EDGE_INDEX, Tensor::from_array(inputs.edge_index).map_err(infer)?.into()));
                feed.push((INPUT_EDGE_FEATURES, Tensor::from_array(inputs.edge_features).map_err(infer)?.into()));
            }
        }
        // The crops are lent to ONNX Runtime, and their memory kept for the next call's ([`Predictor::spare_crops`]).
        let map = inputs.map;
        if let Some(map) = &map {
            feed.push((INPUT_MAP, TensorRef::from_array_view(map).map_err(infer)?.into()));
        }
        if let Some(present) = inputs.map_present {
            feed.push((INPUT_MAP_PRESENT, Tensor::from_array(present).map_err(infer)?.into()));
        }
        if let (Some(grid), Some(slot)) = (inputs.map_grid, inputs.map_slot) {
            feed.push((INPUT_MAP_GRID, Tensor::from_array(grid).map_err(infer)?.into()));
            feed.push((INPUT_MAP_SLOT, Tensor::from_array(slot).map_err(infer)?.into()));
        }
        if let Some(p) = patches {
            feed.push((INPUT_MAP_PATCHES, Tensor::from_array(p).map_err(infer)?.into()));
        }
        let mut session = self.session(pool)?;
        let outputs = session.run(feed).map_err(infer)?;
        if let (Some(map), false) = (map, kept) {
            // The last call's, not the largest: a Predictor holds at most one call's crops beyond the call.
            *self.spare_crops.lock().unwrap_or_else(|e| e.into_inner()) = map.into_raw_vec_and_offset().0;
        }
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

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn execution_providers_parse_and_print() {
        assert_eq!("cpu".parse::<ExecutionProvider>().unwrap(), ExecutionProvider::Cpu);
        assert_eq!(" CUDA ".parse::<ExecutionProvider>().unwrap(), ExecutionProvider::Cuda { device_id: 0 });
        assert_eq!("cuda:3".parse::<ExecutionProvider>().unwrap(), ExecutionProvider::Cuda { device_id: 3 });
        assert_eq!(ExecutionProvider::Cuda { device_id: 3 }.to_string(), "cuda:3");
        for bad in ["", "gpu", "cuda:", "cuda:-1", "cuda:99999999999"] {
            assert!(matches!(bad.parse::<ExecutionProvider>(), Err(DganError::InvalidSpec(_))), "{bad}");
        }
    }

    #[test]
    fn thread_counts_are_bounded_by_the_cores() {
        let not_a_model = crate::manifest_dir().join("Cargo.toml");
        let options = PredictorOptions { intra_threads: max_intra_threads() + 1, ..Default::default() };
        let err = Predictor::load_with(&not_a_model, &options).unwrap_err();
        assert!(err.to_string().contains("this machine's cores"), "{err}");
        let options = PredictorOptions { intra_threads: 0, ..Default::default() };
        assert!(matches!(Predictor::load_with(&not_a_model, &options), Err(DganError::InvalidSpec(_))));
    }
}
