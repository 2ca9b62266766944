//! The model contract: what a dgan ONNX model takes, gives and declares in its metadata. The prose version is
//! `docs/model-contract.md`; this module is the one the runtime checks against.

use crate::class::AgentClass;
use crate::decode::{check_top_scale, Anchors, Calibration, MAX_STILL_RADIUS_M, MAX_TOP_MEAN_POWER};
use crate::error::{DganError, Result};
use crate::prior::{PriorKind, PriorSpec, VelocityFit};
use crate::spec::{is_zero, GraphLayout, HeadingSource, InputSpec, MapRender, EDGE_FEATURES};
use ndarray::Array3;
use serde::{Deserialize, Serialize};
use std::collections::BTreeMap;

/// The contract version the exporter writes. Version 2 adds the kinematic prior, optional maps (`map_present`)
/// and the temperature of the anchor logits; version 3 the padded neighbour layout of the graph; version 4 the
/// sealed weights (`weights_sha256`); version 5 where headings come from (`heading`); version 6 how the prior's
/// velocity is fitted (`prior.fit`) and its standing threshold (`prior.standing_mps`); version 7 the tiled map
/// (`map.render`); version 8 each class's own velocity estimate (`prior.by_class`); version 9 a temperature that grows
/// with the agent's speed (`temperature_speed_exponent`) and a temperature of the class logits (`class_temperature`);
/// version 10 histories denoised before preprocessing (`denoise_gate_m`); version 11 the classes that read the map
/// (`map.classes`); version 12 rasters of the scene for the map CNN (`map.scene`: `map_grid`, `map_slot`); version 13
/// the map CNN's features kept with the map (`map.scene.tile_px`: input `map_patches`, output `map_features`); version
/// 14 the share of its residual over the prior that each class's most probable mode keeps (`top_scale`); version 15
/// the most probable mode held at the prior for agents whose history is still (`still_radius_m`); version 16 the most
/// probable mode as the probability-weighted mean of the modes (`top_mean_power`).
pub const CONTRACT_VERSION: u32 = 16;
/// The versions this engine reads: a version-1 model has no prior, a temperature of 1 and a map it cannot run
/// without; versions 1 and 2 take the graph as an edge list.
pub const SUPPORTED_CONTRACT_VERSIONS: [u32; 16] = [1, 2, 3, 4, 5, 6, 7, 8, 9, 10, 11, 12, 13, 14, 15, 16];
/// The farthest an anchor point may lie from the agent, metres (a horizon of minutes at motorway speed).
pub const MAX_ANCHOR_M: f64 = 1e5;
/// The most anchors a class may have (checked before the anchor arrays are allocated).
pub const MAX_ANCHORS_PER_CLASS: usize = 1024;

/// The largest |temperature_speed_exponent|: beyond it a few m/s would take the temperature out of its range.
pub const MAX_SPEED_EXPONENT: f64 = 10.0;

/// The ONNX `metadata_props` key holding the contract as JSON.
pub const METADATA_KEY: &str = "dgan_contract";

/// Input: agent-centric observed positions `(N, T_obs, 2)` f32, zero at invalid steps.
pub const INPUT_TRAJECTORY: &str = "trajectory";
/// Input: validity of each observed step `(N, T_obs)` f32, 1 or 0.
pub const INPUT_TRAJECTORY_MASK: &str = "trajectory_mask";
/// Input: traffic state `(N, 7 + C)` f32.
pub const INPUT_STATE: &str = "state";
/// Input: directed attention edges `(E, 2)` i64, `[receiver, sender]`, self-loops included, sorted by receiver.
pub const INPUT_EDGE_INDEX: &str = "edge_index";
/// Input: per-edge geometry `(E, 6)` f32, the sender seen from the receiver's frame.
pub const INPUT_EDGE_FEATURES: &str = "edge_features";
/// Input (map models only): agent-centric RGB crops `(N, 3, H, W)` f32 in [0, 1]; of a scene model (contract 12),
/// the call's scene rasters `(F, 3, S, S)`.
pub const INPUT_MAP: &str = "map";
/// Input (scene models, contract 12): `(F, M, gh, gw, 2)` f32, where the agents of each raster read it
/// (`grid_sample` coordinates of each crop block's centre), padded to the raster with the most agents, M.
pub const INPUT_MAP_GRID: &str = "map_grid";
/// Input (scene models, contract 12): `(N,)` i64, each agent's row of `map_grid` flattened to `(F · M, ..)`.
pub const INPUT_MAP_SLOT: &str = "map_slot";
/// Input (kept features, contract 13): `(N, C, gh, gw)` f32, each agent's reading of the map's features at its crop
/// blocks' centres (`map` then holds the rasters `(T, 3, P, P)` of the tiles to compute, none where the engine
/// reads them: [`crate::kept`]).
pub const INPUT_MAP_PATCHES: &str = "map_patches";
/// Output (kept features, contract 13): `(T · t², C)` f32, the features of the tiles of `map` (each tile's `t × t`
/// rows, row-major, in the order of its rasters), which the engine keeps with the map.
pub const OUTPUT_MAP_FEATURES: &str = "map_features";
/// Input (padded layout): `(N, D)` i64, each agent's senders, itself included, padded with its own row.
pub const INPUT_NEIGHBOR_INDEX: &str = "neighbor_index";
/// Input (padded layout): `(N, D)` f32, 1 for a real sender, 0 for padding.
pub const INPUT_NEIGHBOR_MASK: &str = "neighbor_mask";
/// Input (padded layout): `(N, D, 6)` f32, each sender seen from the agent (the columns of `edge_features`).
pub const INPUT_NEIGHBOR_FEATURES: &str = "neighbor_features";
/// Input (models with an optional map only): `(N,)` f32, 1 where the agent's crop holds a map, 0 where it is blank.
pub const INPUT_MAP_PRESENT: &str = "map_present";
/// Output: class logits `(N, C)` f32.
pub const OUTPUT_CLASS_LOGITS: &str = "class_logits";
/// Output: anchor logits `(N, K)` f32, K = Σ K_c, grouped by class in the model's class order.
pub const OUTPUT_ANCHOR_LOGITS: &str = "anchor_logits";
/// Output: agent-centric offsets from each anchor `(N, K, T_f, 2)` f32, metres.
pub const OUTPUT_OFFSETS: &str = "offsets";

/// Element type of a contract tensor.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum DType {
    /// 32-bit float.
    F32,
    /// 64-bit signed integer.
    I64,
}

/// One dimension of a contract tensor.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Dim {
    /// The dynamic agent count N.
    Agents,
    /// The dynamic directed-edge count E.
    Edges,
    /// The dynamic largest degree D of the padded layout.
    Degree,
    /// Another dynamic size (named): the frames of a call, the scene raster's side, the most agents of a frame.
    Dynamic(&'static str),
    /// A fixed size.
    Fixed(usize),
}

/// Name, element type and shape of one contract tensor.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct TensorSpec {
    /// ONNX name.
    pub name: &'static str,
    /// Element type.
    pub dtype: DType,
    /// Shape.
    pub dims: Vec<Dim>,
}

/// The contract as stored in a model's metadata under [`METADATA_KEY`].
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct ModelContract {
    /// Must equal [`CONTRACT_VERSION`].
    pub contract_version: u32,
    /// Length unit of positions, anchors and offsets; always `"m"`.
    pub units: String,
    /// The input specification (flattened into the same JSON object).
    #[serde(flatten)]
    pub input: InputSpec,
    /// Anchors per class name: `K_c × T_f` points `[x, y]` in the agent-centric frame, relative to the prior.
    pub anchors: BTreeMap<String, Vec<Vec<[f64; 2]>>>,
    /// The anchor logits are divided by this before their softmax (fitted on a validation split; 1 = as trained).
    #[serde(default = "unit_temperature")]
    pub temperature: f64,
    /// Contract 9: agent i's anchor temperature is `temperature · (1 + v_i)^temperature_speed_exponent`, v_i the
    /// speed of its kinematic prior (m/s); 0 (the default) = `temperature` for every agent. Needs a prior.
    #[serde(default, skip_serializing_if = "is_zero")]
    pub temperature_speed_exponent: f64,
    /// Contract 9: the class logits are divided by this before their softmax (1, the default: as trained).
    #[serde(default = "unit_temperature", skip_serializing_if = "is_one")]
    pub class_temperature: f64,
    /// Contract 14: per class name, the share s of its residual over the kinematic prior that the agent's most
    /// probable mode keeps when that class is the agent's most probable one (`prior + s · (anchor + offset)`; see
    /// [`crate::decode::DecodeParams::top_scale`]); a class not named keeps all of it (1). Each in [0, 1].
    #[serde(default, skip_serializing_if = "BTreeMap::is_empty")]
    pub top_scale: BTreeMap<String, f64>,
    /// Contract 15: per class name, a radius r (metres, in (0, 10]): an agent of that class whose every observed step
    /// is present and within r of its last observed position has its most probable mode at the prior alone (see
    /// [`crate::decode::still_agents`]); a class not named is never held.
    #[serde(default, skip_serializing_if = "BTreeMap::is_empty")]
    pub still_radius_m: BTreeMap<String, f64>,
    /// Contract 16: per class name, a power β (in (0, 64]): an agent whose most probable class that is has as its most
    /// probable mode the mean of all its modes weighted by p^β (see [`crate::decode::DecodeParams::top_mean`]); a
    /// class not named keeps the most probable mode as it is.
    #[serde(default, skip_serializing_if = "BTreeMap::is_empty")]
    pub top_mean_power: BTreeMap<String, f64>,
    /// A short model name.
    #[serde(default)]
    pub name: String,
    /// Free-form provenance (data, protocol, metrics).
    #[serde(default)]
    pub description: String,
    /// SHA-256 of the model file (contract 4, required there): see [`crate::integrity`].
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub weights_sha256: Option<String>,
    /// The rasteriser the model was trained with ([`crate::raster::RASTER_VERSION`]); absent in older exports.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub raster_version: Option<u32>,
    /// The features the model was trained with ([`crate::preprocess::PREPROCESS_VERSION`]); absent in older exports.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub preprocess_version: Option<u32>,
}

/// Parses JSON into `T` with an error that names the key and says what was wrong and what is allowed, in words
/// ("key `t_f`: invalid value: integer `-1`, expected usize (an integer ≥ 0)") rather than a line and column.
pub fn from_json_readably<T: serde::de::DeserializeOwned>(json: &str) -> std::result::Result<T, String> {
    let de = &mut serde_json::Deserializer::from_str(json);
    serde_path_to_error::deserialize(de).map_err(|e| {
        let path = e.path().to_string();
        let inner = e.into_inner();
        if inner.is_syntax() || inner.is_eof() {
            // Where, as text: the line and column of a one-line document say little.
            let line = json.lines().nth(inner.line().saturating_sub(1)).unwrap_or("");
            let at = line.char_indices().map(|(i, _)| i).nth(inner.column().saturating_sub(1)).unwrap_or(line.len());
            let from = line[..at].char_indices().rev().nth(30).map_or(0, |(i, _)| i);
            let near: String = line[from..].chars().take(50).collect();
            return format!("not valid JSON ({}) near `{near}`", readable(&inner.to_string()));
        }
        keyed(&path, &inner.to_string())
    })
}

/// [`from_json_readably`] for an already parsed JSON value.
pub fn from_value_readably<T: serde::de::DeserializeOwned>(value: serde_json::Value) -> std::result::Result<T, String> {
    serde_path_to_error::deserialize(value).map_err(|e| keyed(&e.path().to_string(), &e.inner().to_string()))
}

fn readable(msg: &str) -> String {
    let msg = msg.rfind(" at line ").map_or(msg, |cut| &msg[..cut]);
    msg.replace("expected usize", "expected a whole number ≥ 0")
        .replace("expected u32", "expected a whole number ≥ 0")
        .replace("expected f64", "expected a number")
}

fn keyed(path: &str, msg: &str) -> String {
    let msg = readable(msg);
    if path == "." || path.is_empty() {
        msg
    } else {
        format!("key `{path}`: {msg}")
    }
}

fn unit_temperature() -> f64 {
    1.0
}

fn is_one(v: &f64) -> bool {
    *v == 1.0
}

impl ModelContract {
    /// Parses and checks the metadata JSON.
    pub fn from_json(json: &str) -> Result<Self> {
        let bad = |e: String| DganError::Contract(format!("metadata {METADATA_KEY:?} is not a valid contract: {e}"));
        let value: serde_json::Value = from_json_readably(json).map_err(bad)?;
        // The input specification's keys first: the contract flattens them, which would hide their names.
        from_value_readably::<InputSpec>(value.clone()).map_err(bad)?;
        let c: ModelContract = from_value_readably(value).map_err(bad)?;
        c.validate()?;
        Ok(c)
    }

    /// Serialises the contract to the metadata JSON.
    pub fn to_json(&self) -> Result<String> {
        serde_json::to_string(self).map_err(|e| DganError::Contract(e.to_string()))
    }

    /// Checks the version, units, input specification and anchors.
    pub fn validate(&self) -> Result<()> {
        if !SUPPORTED_CONTRACT_VERSIONS.contains(&self.contract_version) {
            return Err(DganError::Contract(format!(
                "contract_version {} is not supported; this engine reads versions {SUPPORTED_CONTRACT_VERSIONS:?}",
                self.contract_version
            )));
        }
        self.check_engine_versions()?;
        self.check_keys_of_version()?;
        match (self.contract_version >= 4, &self.weights_sha256) {
            (true, None) => {
                return Err(DganError::Contract(
                    "a contract_version 4 model must declare weights_sha256, the digest its exporter sealed it with"
                        .into(),
                ))
            }
            (false, Some(_)) => {
                return Err(DganError::Contract("weights_sha256 is a contract-4 key".into()));
            }
            _ => {}
        }
        self.check_calibration()?;
        self.top_scales()?;
        self.still_radii()?;
        self.top_mean_powers()?;
        if self.units != "m" {
            return Err(DganError::Contract(format!("units must be \"m\", got {:?}", self.units)));
        }
        self.input.validate().map_err(|e| DganError::Contract(e.to_string()))?;
        self.anchors().map(|_| ())
    }

    /// Refuses a model exported with another rasteriser or preprocessing than this engine's: its inputs would differ.
    fn check_engine_versions(&self) -> Result<()> {
        let engine = [
            ("raster_version", self.raster_version, crate::raster::RASTER_VERSION),
            ("preprocess_version", self.preprocess_version, crate::preprocess::PREPROCESS_VERSION),
        ];
        for (key, declared, ours) in engine {
            if declared.is_some_and(|v| v != ours) {
                return Err(DganError::Contract(format!(
                    "the model was exported with {key} {}, this engine's is {ours}: its inputs would differ from \
                     those it was trained on; use the dgan release it was exported with, or re-export it",
                    declared.unwrap_or_default()
                )));
            }
        }
        Ok(())
    }

    /// Refuses a key declared by a model of a contract version older than the key, and a scene model without the
    /// padded graph layout.
    fn check_keys_of_version(&self) -> Result<()> {
        let (input, prior) = (&self.input, &self.input.prior);
        let map = input.map.as_ref();
        let scene = map.and_then(|m| m.scene);
        let render = map.map_or(MapRender::Agent, |m| m.render);
        let keys: [(u32, bool, &str); 11] = [
            (
                2,
                *prior != PriorSpec::NONE || map.is_some_and(|m| m.optional) || self.temperature != 1.0,
                "prior, map.optional and temperature are contract-2 keys; a contract_version 1 model cannot \
                 declare them",
            ),
            (
                3,
                input.graph != GraphLayout::EdgeList,
                "graph = \"padded\" is a contract-3 key; versions 1 and 2 take an edge list",
            ),
            (
                5,
                input.heading != HeadingSource::Measured,
                "heading is a contract-5 key; versions 1 to 4 take measured headings",
            ),
            (
                6,
                prior.fit != VelocityFit::Endpoints || prior.standing_mps != 0.0,
                "prior.fit and prior.standing_mps are contract-6 keys; versions 1 to 5 fit endpoints and never clamp \
                 standing agents",
            ),
            (
                8,
                !prior.by_class.is_empty(),
                "prior.by_class is a contract-8 key; versions 1 to 7 take one velocity estimate for every class",
            ),
            (
                8,
                prior.fit == VelocityFit::Adaptive,
                "prior.fit \"adaptive\" is contract 8; versions 6 and 7 fit endpoints, a line or a parabola",
            ),
            (
                10,
                input.denoise_gate_m != 0.0,
                "denoise_gate_m is a contract-10 key; versions 1 to 9 take the histories as given",
            ),
            (12, scene.is_some(), "map.scene is a contract-12 key; versions 1 to 11 take a crop per agent"),
            (
                13,
                scene.is_some_and(|s| s.kept()),
                "map.scene.tile_px is a contract-13 key; version 12 reads rasters of the scene per call",
            ),
            (
                11,
                map.is_some_and(|m| !m.classes.is_empty()),
                "map.classes is a contract-11 key; versions 1 to 10 draw every agent's crop",
            ),
            (
                7,
                render != MapRender::Agent,
                "map.render is a contract-7 key; versions 1 to 6 draw each agent's crop (\"agent\")",
            ),
        ];
        if let Some((_, _, message)) =
            keys.iter().find(|(since, declared, _)| self.contract_version < *since && *declared)
        {
            return Err(DganError::Contract((*message).into()));
        }
        if scene.is_some() && input.graph != GraphLayout::Padded {
            return Err(DganError::Contract("a scene model (map.scene) takes the padded graph layout".into()));
        }
        Ok(())
    }

    /// The temperatures decoding applies.
    pub fn calibration(&self) -> Calibration {
        Calibration {
            temperature: self.temperature,
            speed_exponent: self.temperature_speed_exponent,
            class_temperature: self.class_temperature,
        }
    }

    /// Each class's top-mode scale, in the model's class order (1 where the contract names none); empty without any.
    pub fn top_scales(&self) -> Result<Vec<f64>> {
        if self.top_scale.is_empty() {
            return Ok(Vec::new());
        }
        let older = "versions 1 to 13 keep every mode as the network gives it";
        self.by_class("top_scale", &self.top_scale, 14, older)?;
        if self.input.prior.kind == PriorKind::None {
            return Err(DganError::Contract(
                "top_scale scales a mode's residual over the kinematic prior; this model declares none".into(),
            ));
        }
        let scales: Vec<f64> =
            self.input.classes.iter().map(|c| self.top_scale.get(c.name()).copied().unwrap_or(1.0)).collect();
        check_top_scale(&scales, scales.len())?;
        Ok(scales)
    }

    /// Each class's still radius, in the model's class order (0 where the contract names none); empty without any.
    pub fn still_radii(&self) -> Result<Vec<f64>> {
        if self.still_radius_m.is_empty() {
            return Ok(Vec::new());
        }
        self.by_class("still_radius_m", &self.still_radius_m, 15, "versions 1 to 14 hold no agent at its prior")?;
        if let Some((k, r)) = self.still_radius_m.iter().find(|(_, r)| !(**r > 0.0 && **r <= MAX_STILL_RADIUS_M)) {
            return Err(DganError::Contract(format!(
                "still_radius_m of {k:?} must lie in (0, {MAX_STILL_RADIUS_M}] metres, got {r}"
            )));
        }
        Ok(self.input.classes.iter().map(|c| self.still_radius_m.get(c.name()).copied().unwrap_or(0.0)).collect())
    }

    /// Each class's top-mean power, in the model's class order (0 where the contract names none); empty without any.
    pub fn top_mean_powers(&self) -> Result<Vec<f64>> {
        if self.top_mean_power.is_empty() {
            return Ok(Vec::new());
        }
        let older = "versions 1 to 15 keep the most probable mode as decoded";
        self.by_class("top_mean_power", &self.top_mean_power, 16, older)?;
        if let Some((k, b)) = self.top_mean_power.iter().find(|(_, b)| !(**b > 0.0 && **b <= MAX_TOP_MEAN_POWER)) {
            return Err(DganError::Contract(format!(
                "top_mean_power of {k:?} must lie in (0, {MAX_TOP_MEAN_POWER}], got {b}"
            )));
        }
        Ok(self.input.classes.iter().map(|c| self.top_mean_power.get(c.name()).copied().unwrap_or(0.0)).collect())
    }

    /// Checks a per-class key of the decoding (`top_scale`, `still_radius_m`, `top_mean_power`): a contract-`since` key (`older`: what
    /// the versions before it do instead) whose names are all among the model's classes.
    fn by_class(&self, key: &str, values: &BTreeMap<String, f64>, since: u32, older: &str) -> Result<()> {
        if self.contract_version < since {
            return Err(DganError::Contract(format!("{key} is a contract-{since} key; {older}")));
        }
        if let Some(extra) = values.keys().find(|k| !self.input.classes.iter().any(|c| c.name() == *k)) {
            return Err(DganError::Contract(format!(
                "{key} given for {extra:?}, which is not among the classes ({})",
                class_names(&self.input.classes)
            )));
        }
        Ok(())
    }

    fn check_calibration(&self) -> Result<()> {
        let (lo, hi) = (Calibration::MIN_TEMPERATURE, Calibration::MAX_TEMPERATURE);
        for (key, t) in [("temperature", self.temperature), ("class_temperature", self.class_temperature)] {
            if !(t.is_finite() && (lo..=hi).contains(&t)) {
                return Err(DganError::Contract(format!("{key} must be a number in [{lo}, {hi}], got {t}")));
            }
        }
        let exponent = self.temperature_speed_exponent;
        if !(exponent.is_finite() && (-MAX_SPEED_EXPONENT..=MAX_SPEED_EXPONENT).contains(&exponent)) {
            return Err(DganError::Contract(format!(
                "temperature_speed_exponent must be a number in [-{MAX_SPEED_EXPONENT}, {MAX_SPEED_EXPONENT}], got \
                 {exponent}"
            )));
        }
        if self.contract_version < 9 && (exponent != 0.0 || self.class_temperature != 1.0) {
            return Err(DganError::Contract(
                "temperature_speed_exponent and class_temperature are contract-9 keys; versions 1 to 8 take one \
                 temperature of the anchor logits"
                    .into(),
            ));
        }
        if exponent != 0.0 && self.input.prior.kind == PriorKind::None {
            return Err(DganError::Contract(
                "temperature_speed_exponent reads the speed of the kinematic prior; this model declares none".into(),
            ));
        }
        Ok(())
    }

    /// The anchors as arrays, in the model's class order.
    pub fn anchors(&self) -> Result<Anchors> {
        let t_f = self.input.t_f;
        let mut sets = Vec::with_capacity(self.input.classes.len());
        for class in &self.input.classes {
            let rows = self
                .anchors
                .get(class.name())
                .ok_or_else(|| DganError::Contract(format!("no anchors for class {class}")))?;
            if rows.is_empty() || rows.len() > MAX_ANCHORS_PER_CLASS {
                return Err(DganError::Contract(format!(
                    "anchors of {class}: {} given, a class needs 1..={MAX_ANCHORS_PER_CLASS}",
                    rows.len()
                )));
            }
            let mut arr = Array3::zeros((rows.len(), t_f, 2));
            for (k, anchor) in rows.iter().enumerate() {
                if anchor.len() != t_f {
                    return Err(DganError::Contract(format!(
                        "anchor {k} of {class} has {} points, expected T_f = {t_f}",
                        anchor.len()
                    )));
                }
                for (t, p) in anchor.iter().enumerate() {
                    if !p.iter().all(|v| v.is_finite() && v.abs() <= MAX_ANCHOR_M) {
                        return Err(DganError::Contract(format!(
                            "anchor {k} of {class} has the point {p:?} at step {t}; anchors are finite metres within \
                             ±{MAX_ANCHOR_M}"
                        )));
                    }
                    arr[[k, t, 0]] = p[0];
                    arr[[k, t, 1]] = p[1];
                }
            }
            sets.push(arr);
        }
        if let Some(extra) = self.anchors.keys().find(|k| !self.input.classes.iter().any(|c| c.name() == *k)) {
            return Err(DganError::Contract(format!("anchors given for {extra:?}, which is not among the classes")));
        }
        Anchors::new(self.input.classes.clone(), sets)
    }

    /// The inputs a model under this contract must take, exactly.
    pub fn expected_inputs(&self) -> Vec<TensorSpec> {
        expected_inputs(&self.input)
    }

    /// The outputs a model under this contract must give (others are ignored).
    pub fn expected_outputs(&self) -> Result<Vec<TensorSpec>> {
        let k = self.anchors()?.total();
        let c = self.input.classes.len();
        let mut out = vec![
            TensorSpec { name: OUTPUT_CLASS_LOGITS, dtype: DType::F32, dims: vec![Dim::Agents, Dim::Fixed(c)] },
            TensorSpec { name: OUTPUT_ANCHOR_LOGITS, dtype: DType::F32, dims: vec![Dim::Agents, Dim::Fixed(k)] },
            TensorSpec {
                name: OUTPUT_OFFSETS,
                dtype: DType::F32,
                dims: vec![Dim::Agents, Dim::Fixed(k), Dim::Fixed(self.input.t_f), Dim::Fixed(2)],
            },
        ];
        if let Some(scene) = self.input.map.as_ref().and_then(|m| m.scene).filter(|s| s.kept()) {
            let dims = vec![Dim::Dynamic("the computed tiles' rows"), Dim::Fixed(scene.channels)];
            out.push(TensorSpec { name: OUTPUT_MAP_FEATURES, dtype: DType::F32, dims });
        }
        Ok(out)
    }
}

/// The network inputs of an input specification.
pub fn expected_inputs(spec: &InputSpec) -> Vec<TensorSpec> {
    let mut v = vec![
        TensorSpec {
            name: INPUT_TRAJECTORY,
            dtype: DType::F32,
            dims: vec![Dim::Agents, Dim::Fixed(spec.t_obs), Dim::Fixed(2)],
        },
        TensorSpec { name: INPUT_TRAJECTORY_MASK, dtype: DType::F32, dims: vec![Dim::Agents, Dim::Fixed(spec.t_obs)] },
        TensorSpec { name: INPUT_STATE, dtype: DType::F32, dims: vec![Dim::Agents, Dim::Fixed(spec.state_dim())] },
    ];
    match spec.graph {
        GraphLayout::EdgeList => {
            v.push(TensorSpec { name: INPUT_EDGE_INDEX, dtype: DType::I64, dims: vec![Dim::Edges, Dim::Fixed(2)] });
            v.push(TensorSpec {
                name: INPUT_EDGE_FEATURES,
                dtype: DType::F32,
                dims: vec![Dim::Edges, Dim::Fixed(EDGE_FEATURES.len())],
            });
        }
        GraphLayout::Padded => {
            let nd = vec![Dim::Agents, Dim::Degree];
            v.push(TensorSpec { name: INPUT_NEIGHBOR_INDEX, dtype: DType::I64, dims: nd.clone() });
            v.push(TensorSpec { name: INPUT_NEIGHBOR_MASK, dtype: DType::F32, dims: nd });
            v.push(TensorSpec {
                name: INPUT_NEIGHBOR_FEATURES,
                dtype: DType::F32,
                dims: vec![Dim::Agents, Dim::Degree, Dim::Fixed(EDGE_FEATURES.len())],
            });
        }
    }
    if let Some(m) = &spec.map {
        let dims = match m.scene {
            None => vec![Dim::Agents, Dim::Fixed(3), Dim::Fixed(m.height_px), Dim::Fixed(m.width_px)],
            Some(s) if s.kept() => {
                let side = Dim::Fixed(s.tile_raster_px());
                vec![Dim::Dynamic("the computed tiles T"), Dim::Fixed(3), side, side]
            }
            Some(_) => {
                let side = Dim::Dynamic("the scene raster's side");
                vec![Dim::Dynamic("the rasters F"), Dim::Fixed(3), side, side]
            }
        };
        v.push(TensorSpec { name: INPUT_MAP, dtype: DType::F32, dims });
        if m.optional {
            v.push(TensorSpec { name: INPUT_MAP_PRESENT, dtype: DType::F32, dims: vec![Dim::Agents] });
        }
        if let (Some((gh, gw)), Some(s)) = (m.scene_grid(), m.scene.filter(|s| s.kept())) {
            let dims = vec![Dim::Agents, Dim::Fixed(s.channels), Dim::Fixed(gh), Dim::Fixed(gw)];
            v.push(TensorSpec { name: INPUT_MAP_PATCHES, dtype: DType::F32, dims });
        } else if let Some((gh, gw)) = m.scene_grid() {
            let (frames, most) = (Dim::Dynamic("the rasters F"), Dim::Dynamic("a raster's most agents M"));
            let dims = vec![frames, most, Dim::Fixed(gh), Dim::Fixed(gw), Dim::Fixed(2)];
            v.push(TensorSpec { name: INPUT_MAP_GRID, dtype: DType::F32, dims });
            v.push(TensorSpec { name: INPUT_MAP_SLOT, dtype: DType::I64, dims: vec![Dim::Agents] });
        }
    }
    v
}

/// Checks one tensor a model declares (`shape` with -1 for dynamic dimensions) against its contract entry.
pub fn check_tensor(kind: &str, want: &TensorSpec, dtype: Option<DType>, shape: &[i64]) -> Result<()> {
    let fail = |m: String| Err(DganError::Contract(format!("{kind} {:?}: {m}", want.name)));
    if dtype != Some(want.dtype) {
        return fail(format!("element type is {dtype:?}, the contract says {:?}", want.dtype));
    }
    if shape.len() != want.dims.len() {
        return fail(format!("has rank {} (shape {shape:?}), the contract says rank {}", shape.len(), want.dims.len()));
    }
    for (axis, (got, dim)) in shape.iter().zip(&want.dims).enumerate() {
        match dim {
            Dim::Agents | Dim::Edges | Dim::Degree | Dim::Dynamic(_) if *got >= 0 => {
                let what = match dim {
                    Dim::Agents => "the agent count N",
                    Dim::Edges => "the edge count E",
                    Dim::Dynamic(name) => name,
                    _ => "the largest degree D",
                };
                return fail(format!(
                    "axis {axis} is fixed to {got}; it must be dynamic ({what}) - export with a dynamic axis"
                ));
            }
            Dim::Fixed(n) if *got >= 0 && *got as usize != *n => {
                return fail(format!("axis {axis} is {got}, the contract says {n} (shape {shape:?})"))
            }
            _ => {}
        }
    }
    Ok(())
}

/// The agent classes named in a contract, for error messages.
pub fn class_names(classes: &[AgentClass]) -> String {
    classes.iter().map(|c| c.name()).collect::<Vec<_>>().join(", ")
}

#[cfg(test)]
mod tests {
    use super::*;

    fn json() -> String {
        r#"{"contract_version": 1, "units": "m", "dt_s": 0.4, "t_obs": 8, "t_f": 2,
            "classes": ["vehicle", "pedestrian"], "attention_lambda": 0.5, "map": null,
            "anchors": {"vehicle": [[[1, 0], [2, 0]]], "pedestrian": [[[0, 0], [0, 1]], [[0, 0], [1, 1]]]}}"#
            .into()
    }

    #[test]
    fn parses_and_round_trips() {
        let c = ModelContract::from_json(&json()).unwrap();
        assert_eq!(c.anchors().unwrap().per_class(), vec![1, 2]);
        assert_eq!(ModelContract::from_json(&c.to_json().unwrap()).unwrap(), c);
        assert_eq!(c.expected_inputs().len(), 5);
        assert_eq!(c.expected_outputs().unwrap()[1].dims, vec![Dim::Agents, Dim::Fixed(3)]);
    }

    #[test]
    fn anchors_and_time_steps_out_of_bounds_are_refused() {
        let far = json().replace("[[[1, 0], [2, 0]]]", "[[[1, 0], [1.7e308, 0]]]");
        let err = ModelContract::from_json(&far).and_then(|c| c.anchors().map(|_| ())).unwrap_err();
        assert!(err.to_string().contains("anchors are finite metres within"), "{err}");
        for dt in ["1e-300", "1e9"] {
            let err = ModelContract::from_json(&json().replace("\"dt_s\": 0.4", &format!("\"dt_s\": {dt}")));
            assert!(err.unwrap_err().to_string().contains("dt_s must be a number of seconds in"), "{dt}");
        }
    }

    #[test]
    fn version_2_declares_prior_temperature_and_optional_maps() {
        let v2 = json().replace("\"contract_version\": 1", "\"contract_version\": 2").replace(
            "\"map\": null",
            "\"map\": {\"height_px\": 8, \"width_px\": 8, \"resolution_m\": 1, \"agent_row\": 4, \"agent_col\": 4, \
             \"optional\": true}, \"prior\": {\"kind\": \"constant_velocity\", \"window_s\": 0.8}, \"temperature\": 1.5",
        );
        let c = ModelContract::from_json(&v2).unwrap();
        assert_eq!(c.temperature, 1.5);
        assert_eq!(c.input.prior.kind, crate::prior::PriorKind::ConstantVelocity);
        let names: Vec<_> = c.expected_inputs().iter().map(|t| t.name).collect();
        assert_eq!(names.last(), Some(&INPUT_MAP_PRESENT));
        // Version 3 takes the padded layout.
        let v3 = v2
            .replace("\"contract_version\": 2", "\"contract_version\": 3")
            .replace("\"temperature\"", "\"graph\": \"padded\", \"temperature\"");
        let names: Vec<_> = ModelContract::from_json(&v3).unwrap().expected_inputs().iter().map(|t| t.name).collect();
        assert_eq!(&names[3..6], &[INPUT_NEIGHBOR_INDEX, INPUT_NEIGHBOR_MASK, INPUT_NEIGHBOR_FEATURES]);
        // Version 1: no prior, temperature 1.
        let v1 = ModelContract::from_json(&json()).unwrap();
        assert_eq!((v1.input.prior, v1.temperature), (PriorSpec::NONE, 1.0));
        assert_eq!(v1.input.heading, HeadingSource::Measured);
        // Version 5 says where headings come from.
        let v5 = v3.replace("\"contract_version\": 3", "\"contract_version\": 5").replace(
            "\"temperature\"",
            &format!(
                "\"weights_sha256\": \"{}\", \"heading\": \"motion_when_moving\", \"temperature\"",
                "0".repeat(64)
            ),
        );
        assert_eq!(ModelContract::from_json(&v5).unwrap().input.heading, HeadingSource::MotionWhenMoving);
        // Version 6 fits the prior's velocity by least squares and holds standing agents; version 5 cannot.
        let robust = "\"window_s\": 0.8, \"fit\": \"least_squares\", \"standing_mps\": 0.3";
        let v6 = v5.replace("\"contract_version\": 5", "\"contract_version\": 6").replace("\"window_s\": 0.8", robust);
        let prior = ModelContract::from_json(&v6).unwrap().input.prior;
        assert_eq!((prior.fit, prior.standing_mps), (VelocityFit::LeastSquares, 0.3));
        let v5_robust = v5.replace("\"window_s\": 0.8", robust);
        assert!(matches!(ModelContract::from_json(&v5_robust), Err(DganError::Contract(_))));
        // Version 7 may draw the crops from tiles of the map; version 6 cannot.
        let tiles = "\"optional\": true, \"render\": \"tiles\"";
        let v7 = v6.replace("\"contract_version\": 6", "\"contract_version\": 7").replace("\"optional\": true", tiles);
        let map = ModelContract::from_json(&v7).unwrap().input.map.unwrap();
        assert_eq!(map.render, MapRender::Tiles);
        assert_eq!(ModelContract::from_json(&v6).unwrap().input.map.unwrap().render, MapRender::Agent);
        let err = ModelContract::from_json(&v6.replace("\"optional\": true", tiles)).unwrap_err().to_string();
        assert!(err.contains("map.render is a contract-7 key"), "{err}");
        let err = ModelContract::from_json(&v7.replace("\"tiles\"", "\"tile\"")).unwrap_err().to_string();
        assert!(err.contains("tile"), "{err}");
        // Version 8 gives a class its own velocity estimate; version 7 cannot, and the class must be the model's.
        let own =
            "\"standing_mps\": 0.3, \"by_class\": {\"pedestrian\": {\"window_s\": 2.0, \"fit\": \"least_squares\"}}";
        let v8 = v7.replace("\"contract_version\": 7", "\"contract_version\": 8").replace("\"standing_mps\": 0.3", own);
        let prior = ModelContract::from_json(&v8).unwrap().input.prior;
        assert_eq!(prior.by_class.get(AgentClass::Pedestrian).map(|c| c.fit), Some(VelocityFit::LeastSquares));
        let err = ModelContract::from_json(&v7.replace("\"standing_mps\": 0.3", own)).unwrap_err().to_string();
        assert!(err.contains("prior.by_class is a contract-8 key"), "{err}");
        let err = ModelContract::from_json(&v8.replace("\"pedestrian\": {", "\"cyclist\": {")).unwrap_err().to_string();
        assert!(err.contains("not among the model's classes"), "{err}");
        let adaptive = v7.replace("\"least_squares\"", "\"adaptive\"");
        let err = ModelContract::from_json(&adaptive).unwrap_err().to_string();
        assert!(err.contains("\"adaptive\" is contract 8"), "{err}");
        let v8 = adaptive.replace("\"contract_version\": 7", "\"contract_version\": 8");
        assert_eq!(ModelContract::from_json(&v8).unwrap().input.prior.fit, VelocityFit::Adaptive);
        // Version 9: a temperature growing with speed and one of the class logits; version 8 cannot.
        let calibrated = "\"temperature_speed_exponent\": 0.5, \"class_temperature\": 3.0, \"temperature\"";
        let v9 =
            v8.replace("\"contract_version\": 8", "\"contract_version\": 9").replace("\"temperature\"", calibrated);
        let c = ModelContract::from_json(&v9).unwrap();
        let want = Calibration { temperature: 1.5, speed_exponent: 0.5, class_temperature: 3.0 };
        assert_eq!(c.calibration(), want);
        assert_eq!(ModelContract::from_json(&c.to_json().unwrap()).unwrap(), c);
        let err = ModelContract::from_json(&v8.replace("\"temperature\"", calibrated)).unwrap_err().to_string();
        assert!(err.contains("contract-9 keys"), "{err}");
        for (bad, says) in [
            ("\"temperature_speed_exponent\": 11.0", "temperature_speed_exponent must be"),
            ("\"class_temperature\": 0.0", "class_temperature must be"),
        ] {
            let key = bad.split(':').next().unwrap_or_default();
            let text = v9.replace(&format!("{key}: {}", if key.contains("class") { "3.0" } else { "0.5" }), bad);
            let err = ModelContract::from_json(&text).unwrap_err().to_string();
            assert!(err.contains(says), "{bad}: {err}");
        }
        let no_prior = v9.replace("\"kind\": \"constant_velocity\"", "\"kind\": \"none\"");
        let err = ModelContract::from_json(&no_prior).unwrap_err().to_string();
        assert!(err.contains("declares none"), "{err}");
        // Version 8's single temperature is version 9's with exponent 0 and class temperature 1.
        assert_eq!(ModelContract::from_json(&v8).unwrap().calibration(), Calibration::single(1.5));
        // Version 10 denoises the histories first; version 9 cannot, and the gate is a sane number of metres.
        let gated = "\"denoise_gate_m\": 0.1, \"units\"";
        let v10 = v9.replace("\"contract_version\": 9", "\"contract_version\": 10").replace("\"units\"", gated);
        let c = ModelContract::from_json(&v10).unwrap();
        assert_eq!(c.input.denoise_gate_m, 0.1);
        assert_eq!(ModelContract::from_json(&c.to_json().unwrap()).unwrap(), c);
        assert_eq!(ModelContract::from_json(&v9).unwrap().input.denoise_gate_m, 0.0);
        assert!(!ModelContract::from_json(&v9).unwrap().to_json().unwrap().contains("denoise_gate_m"));
        let err = ModelContract::from_json(&v9.replace("\"units\"", gated)).unwrap_err().to_string();
        assert!(err.contains("denoise_gate_m is a contract-10 key"), "{err}");
        for bad in ["-0.1", "1000.0", "\"x\""] {
            let err = ModelContract::from_json(&v10.replace("0.1, \"units\"", &format!("{bad}, \"units\"")));
            assert!(err.unwrap_err().to_string().contains("denoise_gate_m"), "{bad}");
        }
        // Version 11 may name the classes whose crops are drawn; version 10 draws every agent's.
        let readers = "\"render\": \"tiles\", \"classes\": [\"pedestrian\"]";
        let v11 = v10
            .replace("\"contract_version\": 10", "\"contract_version\": 11")
            .replace("\"render\": \"tiles\"", readers);
        let c = ModelContract::from_json(&v11).unwrap();
        assert_eq!(c.input.map.as_ref().unwrap().classes, vec![AgentClass::Pedestrian]);
        assert_eq!(ModelContract::from_json(&c.to_json().unwrap()).unwrap(), c);
        assert!(!ModelContract::from_json(&v10).unwrap().to_json().unwrap().contains("\"classes\": [\"pedestrian\"]"));
        let err = ModelContract::from_json(&v10.replace("\"render\": \"tiles\"", readers)).unwrap_err().to_string();
        assert!(err.contains("map.classes is a contract-11 key"), "{err}");
        let err = ModelContract::from_json(&v11.replace("[\"pedestrian\"]", "[\"cyclist\"]")).unwrap_err().to_string();
        assert!(err.contains("map.classes names cyclist"), "{err}");
        // Version 12 reads one raster of the scene per frame: map_grid and map_slot follow map_present.
        let scene = "\"render\": \"agent\", \"scene\": {\"min_px\": 64, \"stride\": 4}";
        let v12 =
            v10.replace("\"contract_version\": 10", "\"contract_version\": 12").replace("\"render\": \"tiles\"", scene);
        let c = ModelContract::from_json(&v12).unwrap();
        let m = c.input.map.as_ref().unwrap();
        assert_eq!(m.scene, Some(crate::spec::SceneSpec { min_px: 64, stride: 4, ..Default::default() }));
        assert_eq!(ModelContract::from_json(&c.to_json().unwrap()).unwrap(), c);
        let inputs = c.expected_inputs();
        let names: Vec<_> = inputs.iter().map(|t| t.name).collect();
        assert_eq!(&names[6..], [INPUT_MAP, INPUT_MAP_PRESENT, INPUT_MAP_GRID, INPUT_MAP_SLOT]);
        let (gh, gw) = m.scene_grid().unwrap();
        assert_eq!(inputs[8].dims[2..], [Dim::Fixed(gh), Dim::Fixed(gw), Dim::Fixed(2)]);
        assert!(matches!(inputs[6].dims[2], Dim::Dynamic(_)));
        let err = check_tensor("input", &inputs[6], Some(DType::F32), &[-1, 3, 64, 64]).unwrap_err().to_string();
        assert!(err.contains("must be dynamic (the scene raster's side)"), "{err}");
        let err = ModelContract::from_json(&v10.replace("\"render\": \"tiles\"", scene)).unwrap_err().to_string();
        assert!(err.contains("map.scene is a contract-12 key"), "{err}");
        let edges = v12.replace("\"graph\": \"padded\", ", "");
        let err = ModelContract::from_json(&edges).unwrap_err().to_string();
        assert!(err.contains("takes the padded graph layout"), "{err}");
        for (bad, says) in [("\"stride\": 4", "\"stride\": 0"), ("\"min_px\": 64", "\"min_px\": 99999")] {
            let err = ModelContract::from_json(&v12.replace(bad, says)).unwrap_err().to_string();
            assert!(err.contains("map.scene."), "{err}");
        }
        let tiled = v12.replace("\"render\": \"agent\"", "\"render\": \"tiles\"");
        assert!(ModelContract::from_json(&tiled).unwrap_err().to_string().contains("do not apply"));

        // Version 13 keeps the features with the map: the tiles' rasters, the kept rows and the reads, and an output.
        let kept = "\"stride\": 4, \"tile_px\": 64, \"halo_px\": 16, \"channels\": 16";
        let v13 = v12.replace("\"contract_version\": 12", "\"contract_version\": 13").replace("\"stride\": 4", kept);
        let err = ModelContract::from_json(&v13).unwrap_err().to_string();
        assert!(err.contains("draw_agents must be false"), "{err}");
        let v13 = v13.replace("\"render\": \"agent\"", "\"draw_agents\": false, \"render\": \"agent\"");
        let c = ModelContract::from_json(&v13).unwrap();
        let names: Vec<_> = c.expected_inputs().iter().map(|t| t.name).collect();
        assert_eq!(&names[6..], [INPUT_MAP, INPUT_MAP_PRESENT, INPUT_MAP_PATCHES]);
        assert_eq!(c.expected_inputs()[6].dims[2], Dim::Fixed(96));
        assert_eq!(c.expected_outputs().unwrap()[3].name, OUTPUT_MAP_FEATURES);
        let older = v13.replace("\"contract_version\": 13", "\"contract_version\": 12");
        assert!(ModelContract::from_json(&older).unwrap_err().to_string().contains("contract-13 key"));
        for (bad, says) in [("\"halo_px\": 16", "\"halo_px\": 6"), ("\"tile_px\": 64", "\"tile_px\": 600")] {
            let err = ModelContract::from_json(&v13.replace(bad, says)).unwrap_err().to_string();
            assert!(err.contains("tile_px"), "{err}");
        }
        let err = ModelContract::from_json(&v13.replace("\"channels\": 16", "\"channels\": 0")).unwrap_err();
        assert!(err.to_string().contains("channels"), "{err}");

        // Versions 14 to 16, the decoding's per-class keys: the share of its residual over the prior that the most
        // probable mode keeps (unnamed classes keep all of it), the radius of a still history held at the prior
        // (unnamed classes are never held) and the power of the weighted mean taken as the most probable mode
        // (unnamed classes keep it as decoded). Each is refused below its version, for a class the model lacks and
        // out of its range.
        struct Key {
            version: u32,
            name: &'static str,
            values: fn(&ModelContract) -> Result<Vec<f64>>,
            class: &'static str,
            good: f64,
            want: [f64; 2],
            bad: &'static [f64],
            range: &'static str,
        }
        let keys = [
            Key {
                version: 14,
                name: "top_scale",
                values: ModelContract::top_scales,
                class: "pedestrian",
                good: 0.25,
                want: [1.0, 0.25],
                bad: &[1.5, -0.1],
                range: "[0, 1]",
            },
            Key {
                version: 15,
                name: "still_radius_m",
                values: ModelContract::still_radii,
                class: "pedestrian",
                good: 0.05,
                want: [0.0, 0.05],
                bad: &[0.0, 11.0, -0.1],
                range: "(0, 10]",
            },
            Key {
                version: 16,
                name: "top_mean_power",
                values: ModelContract::top_mean_powers,
                class: "vehicle",
                good: 2.0,
                want: [2.0, 0.0],
                bad: &[0.0, 65.0, -1.0],
                range: "(0, 64]",
            },
        ];
        let mut base = v13;
        for Key { version, name: key, values, class, good, want, bad, range } in keys {
            base = base.replace(
                &format!("\"contract_version\": {}", version - 1),
                &format!("\"contract_version\": {version}"),
            );
            assert!(values(&ModelContract::from_json(&base).unwrap()).unwrap().is_empty(), "{key}");
            let with =
                |class: &str, v: f64| base.replace("\"units\"", &format!("\"{key}\": {{\"{class}\": {v}}}, \"units\""));
            let c = ModelContract::from_json(&with(class, good)).unwrap();
            assert_eq!(values(&c).unwrap(), want, "{key}");
            assert_eq!(ModelContract::from_json(&c.to_json().unwrap()).unwrap(), c);
            let older = with(class, good).replace(
                &format!("\"contract_version\": {version}"),
                &format!("\"contract_version\": {}", version - 1),
            );
            let mut cases =
                vec![(older, format!("contract-{version} key")), (with("truck", good), "not among the classes".into())];
            cases.extend(bad.iter().map(|&v| (with(class, v), range.to_string())));
            for (case, says) in cases {
                let err = ModelContract::from_json(&case).unwrap_err().to_string();
                assert!(err.contains(&says), "{key}: {err}");
            }
        }
    }

    #[test]
    fn a_model_from_another_rasteriser_or_preprocessing_is_refused() {
        let ours = crate::raster::RASTER_VERSION;
        let same = json().replace("\"units\"", &format!("\"raster_version\": {ours}, \"units\""));
        assert_eq!(ModelContract::from_json(&same).unwrap().raster_version, Some(ours));
        let other = json().replace("\"units\"", &format!("\"preprocess_version\": {}, \"units\"", ours + 7));
        let err = ModelContract::from_json(&other).unwrap_err().to_string();
        assert!(err.contains("preprocess_version 8, this engine's is 1"), "{err}");
        assert_eq!(ModelContract::from_json(&json()).unwrap().raster_version, None);
    }

    #[test]
    fn rejects_broken_contracts() {
        let cases = [
            json().replace("\"contract_version\": 1", "\"contract_version\": 4"),
            // heading is a contract-5 key
            json().replace("\"map\": null", "\"map\": null, \"heading\": \"motion\""),
            json().replace("\"map\": null", "\"map\": null, \"graph\": \"padded\""),
            json().replace("\"map\": null", "\"map\": null, \"temperature\": 2.0"),
            json()
                .replace("\"contract_version\": 1", "\"contract_version\": 2")
                .replace("\"map\": null", "\"map\": null, \"temperature\": -1"),
            json().replace("\"units\": \"m\"", "\"units\": \"px\""),
            json().replace("\"vehicle\": [[[1, 0], [2, 0]]], ", ""),
            json().replace("[[1, 0], [2, 0]]", "[[1, 0]]"),
            json().replace("\"t_obs\": 8", "\"t_obs\": 0"),
            json().replace("\"vehicle\", \"pedestrian\"]", "\"vehicle\", \"truck\"]"),
            "not json".into(),
        ];
        for case in cases {
            assert!(matches!(ModelContract::from_json(&case), Err(DganError::Contract(_))), "{case}");
        }
    }

    #[test]
    fn tensor_checks() {
        let spec = &expected_inputs(&ModelContract::from_json(&json()).unwrap().input)[0];
        assert!(check_tensor("input", spec, Some(DType::F32), &[-1, 8, 2]).is_ok());
        assert!(check_tensor("input", spec, Some(DType::F32), &[-1, -1, 2]).is_ok());
        assert!(check_tensor("input", spec, Some(DType::F32), &[5, 8, 2]).is_err());
        assert!(check_tensor("input", spec, Some(DType::F32), &[-1, 7, 2]).is_err());
        assert!(check_tensor("input", spec, Some(DType::I64), &[-1, 8, 2]).is_err());
        assert!(check_tensor("input", spec, Some(DType::F32), &[-1, 8]).is_err());
    }
}
