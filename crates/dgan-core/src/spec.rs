//! What the network expects of its inputs: time base, classes, attention-zone λ and the map crop.
//! Written into every model's metadata (see `docs/model-contract.md`) and used by preprocessing.

use crate::class::AgentClass;
use crate::error::{DganError, Result};
use crate::prior::PriorSpec;
pub use crate::state::HeadingSource;
use serde::{Deserialize, Serialize};

/// The agent-centric map crop each agent's map branch sees.
///
/// The crop is `height_px × width_px` at `resolution_m` metres per pixel, heading-aligned: the agent's x axis
/// (forward) points up the image and its y axis (left) to the image's left. The agent sits at the centre of pixel
/// `(agent_row, agent_col)`.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct MapSpec {
    /// Crop height in pixels.
    pub height_px: usize,
    /// Crop width in pixels.
    pub width_px: usize,
    /// Metres per pixel.
    pub resolution_m: f64,
    /// Row of the agent's pixel (0 = top).
    pub agent_row: usize,
    /// Column of the agent's pixel (0 = left).
    pub agent_col: usize,
    /// Whether the agents are drawn into the crop as blue boxes.
    #[serde(default = "default_true")]
    pub draw_agents: bool,
    /// Whether the model also serves frames without a map (contract 2): it then takes a `map_present` input,
    /// 1 where the agent's crop holds a map and 0 where the crop is blank because the frame has none. A model
    /// whose map is not optional refuses frames without a map.
    #[serde(default)]
    pub optional: bool,
    /// How a vector map is drawn into the crops (contract 7); raster maps are always resampled per crop.
    #[serde(default)]
    pub render: MapRender,
    /// The classes whose agents read the map (contract 11), when the network reads it for them alone: the other
    /// agents' crops are left blank (zeros) instead of drawn, as the network never looks at them. Empty (the
    /// default): every agent's crop is drawn.
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub classes: Vec<AgentClass>,
    /// Contract 12: the network's map CNN reads rasters of the scene (one per group of agents) instead of a crop per
    /// agent ([`crate::scene`]); the crop's size, resolution and agent pixel then say where each agent reads them.
    /// None (the default): a crop per agent.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub scene: Option<SceneSpec>,
}

/// The most pixels a scene raster may have a side ([`SceneSpec`], [`crate::scene`]).
pub const MAX_SCENE_PX: usize = 2048;

/// How a model's map CNN reads the scene (contract 12): square rasters at the crops' resolution, north up, one per
/// group of agents whose crops meet ([`crate::scene::scene_inputs`]), at least `min_px` pixels a side and larger
/// where a group's crops reach farther (up to [`MAX_SCENE_PX`]; beyond, an agent reads no map); each agent reads the
/// network's features at the centres of its crop's `stride × stride` blocks ([`crate::scene::crop_grid`]).
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq, Hash, Serialize, Deserialize)]
pub struct SceneSpec {
    /// The raster's least side, pixels.
    pub min_px: usize,
    /// The side of a crop's blocks, pixels: the network's downsampling before the agents read it.
    pub stride: usize,
    /// Contract 13: the map's features are kept with the map, in tiles of this many pixels a side on a grid fixed
    /// in the world, each computed once per map and model ([`crate::kept`]); 0 (the default): rasters per call.
    #[serde(default, skip_serializing_if = "is_zero_px")]
    pub tile_px: usize,
    /// Contract 13: pixels of the map drawn around each tile (at least the CNN's reach), so that a tile's features
    /// are those of the map without edges.
    #[serde(default, skip_serializing_if = "is_zero_px")]
    pub halo_px: usize,
    /// Contract 13: the features' channels (the rows the engine keeps).
    #[serde(default, skip_serializing_if = "is_zero_px")]
    pub channels: usize,
}

fn is_zero_px(v: &usize) -> bool {
    *v == 0
}

/// The most pixels a kept tile's raster may have a side (its tile and both halos, [`SceneSpec::tile_px`]).
pub const MAX_TILE_RASTER_PX: usize = 512;

impl SceneSpec {
    /// Whether the features are kept with the map in tiles (contract 13).
    pub fn kept(&self) -> bool {
        self.tile_px > 0
    }

    /// The side of a kept tile's raster: its tile and a halo each side.
    pub fn tile_raster_px(&self) -> usize {
        self.tile_px + 2 * self.halo_px
    }

    /// The side of a kept tile in features (`tile_px / stride`).
    pub fn tile_features(&self) -> usize {
        self.tile_px / self.stride.max(1)
    }
}

/// How a vector map becomes the agents' crops (`map.render` of a contract-7 model).
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq, Hash, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum MapRender {
    /// Each agent's crop is drawn from the map's elements in the agent's own frame: the cost grows with the agents.
    #[default]
    Agent,
    /// The map is drawn once, north-up, into tiles at half the crop's pixel size that stay with the map for every
    /// later crop and call ([`crate::tiles`]); each call draws the agents' boxes once on copies of the tiles its crops
    /// read, and each crop pixel is the mean of the 2 × 2 tile pixels around its centre.
    Tiles,
}

fn default_true() -> bool {
    true
}

impl MapSpec {
    /// The largest crop side, pixels, that `render = "tiles"` serves: a crop then touches a few dozen tiles at most.
    pub const MAX_TILED_PX: usize = 256;

    /// Checks the crop's size, resolution and agent pixel.
    pub fn validate(&self) -> Result<()> {
        let bad = |m: String| Err(DganError::InvalidSpec(m));
        if !(1..=2048).contains(&self.height_px) || !(1..=2048).contains(&self.width_px) {
            return bad(format!("map crop must be 1..=2048 pixels a side, got {}×{}", self.height_px, self.width_px));
        }
        if !(self.resolution_m.is_finite() && self.resolution_m > 0.0) {
            return bad(format!("map resolution must be a positive number of metres, got {}", self.resolution_m));
        }
        if self.agent_row >= self.height_px || self.agent_col >= self.width_px {
            return bad(format!(
                "agent pixel ({}, {}) is outside the {}×{} crop",
                self.agent_row, self.agent_col, self.height_px, self.width_px
            ));
        }
        let side = Self::MAX_TILED_PX;
        if self.render == MapRender::Tiles && (self.height_px > side || self.width_px > side) {
            return bad(format!(
                "map render \"tiles\" serves crops of at most {side} pixels a side, got {}×{}; use \"agent\"",
                self.height_px, self.width_px
            ));
        }
        let mut sorted = self.classes.clone();
        sorted.sort();
        sorted.dedup();
        if sorted.len() != self.classes.len() {
            return bad(format!("map.classes repeat: {:?}", self.classes));
        }
        if let Some(scene) = &self.scene {
            let longest = self.height_px.max(self.width_px);
            if !(1..=longest).contains(&scene.stride) {
                return bad(format!(
                    "map.scene.stride must be 1..={longest} (the crop's longer side), got {}",
                    scene.stride
                ));
            }
            let most = MAX_SCENE_PX;
            if !(1..=most).contains(&scene.min_px) {
                return bad(format!("map.scene.min_px must be 1..={most} pixels, got {}", scene.min_px));
            }
            if self.render != MapRender::Agent || !self.classes.is_empty() {
                return bad("map.scene reads one raster for every agent: map.render \"tiles\" and map.classes do not \
                            apply to it"
                    .into());
            }
            let declared = [scene.tile_px, scene.halo_px, scene.channels];
            if scene.kept() || declared.iter().any(|v| *v > 0) {
                let s = scene.stride;
                if scene.tile_px == 0 || scene.tile_px % s != 0 || scene.halo_px % s != 0 {
                    return bad(format!(
                        "map.scene.tile_px and halo_px must be multiples of the stride {s} (tile_px at least one), \
                         got {} and {}",
                        scene.tile_px, scene.halo_px
                    ));
                }
                if scene.tile_raster_px() > MAX_TILE_RASTER_PX {
                    return bad(format!(
                        "a kept tile's raster (tile_px + 2 halo_px) must be at most {MAX_TILE_RASTER_PX} pixels, got {}",
                        scene.tile_raster_px()
                    ));
                }
                if !(1..=4096).contains(&scene.channels) {
                    return bad(format!("map.scene.channels must be 1..=4096, got {}", scene.channels));
                }
                if self.draw_agents {
                    return bad("kept map features (map.scene.tile_px) hold the map alone: draw_agents must be false \
                                (the agents' boxes change every call)"
                        .into());
                }
            }
        }
        Ok(())
    }

    /// The grid of each agent's reading of a scene model's raster, `(rows, columns)` of blocks; None for a crop model.
    pub fn scene_grid(&self) -> Option<(usize, usize)> {
        self.scene.map(|s| (self.height_px.div_ceil(s.stride), self.width_px.div_ceil(s.stride)))
    }

    /// Whether an agent of `class` gets a drawn crop ([`MapSpec::classes`]).
    pub fn reads(&self, class: AgentClass) -> bool {
        self.classes.is_empty() || self.classes.contains(&class)
    }

    /// The continuous image coordinates `(col, row)` of a point in the agent's frame (pixel centres at +0.5).
    pub fn local_to_pixel(&self, local: [f64; 2]) -> [f64; 2] {
        [
            self.agent_col as f64 + 0.5 - local[1] / self.resolution_m,
            self.agent_row as f64 + 0.5 - local[0] / self.resolution_m,
        ]
    }

    /// The point of the agent's frame at the centre of pixel `(row, col)`.
    pub fn pixel_to_local(&self, row: usize, col: usize) -> [f64; 2] {
        [
            (self.agent_row as f64 - row as f64) * self.resolution_m,
            (self.agent_col as f64 - col as f64) * self.resolution_m,
        ]
    }
}

/// The most steps a model may observe or predict (T_obs, T_f): a bound checked before anything is allocated, so
/// a model file claiming `t_f = 10⁹` is refused instead of exhausting memory.
pub const MAX_STEPS: usize = 1000;

/// Everything preprocessing needs to build the network's inputs from a frame.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct InputSpec {
    /// Seconds between steps.
    pub dt_s: f64,
    /// Observed steps T_obs (the last is t_obs).
    pub t_obs: usize,
    /// Predicted steps T_f.
    pub t_f: usize,
    /// The classes the model knows, in the order of its class logits and one-hot state features.
    pub classes: Vec<AgentClass>,
    /// λ of the attention zone r = speed · T_f · dt + λ · length.
    pub attention_lambda: f64,
    /// The map crop, or `None` for a model without a map branch.
    pub map: Option<MapSpec>,
    /// The kinematic prior the network's outputs are relative to (contract 2; none before).
    #[serde(default)]
    pub prior: PriorSpec,
    /// How the attention graph reaches the network (contract 3 adds the padded layout).
    #[serde(default)]
    pub graph: GraphLayout,
    /// Where each agent's heading comes from (contract 5; older models take measured headings).
    #[serde(default)]
    pub heading: HeadingSource,
    /// Contract 10: preprocessing first takes tracker noise out of the histories as
    /// [`Frame::denoised`](crate::frame::Frame::denoised) does with this gate (metres), so that every input (positions,
    /// states, graph, prior, crops) is built from the smoothed tracks; 0 (the default) = the histories as given.
    #[serde(default, skip_serializing_if = "is_zero")]
    pub denoise_gate_m: f64,
}

/// Whether a contract number is 0, its default (serde's `skip_serializing_if`: a default key is not written).
pub(crate) fn is_zero(v: &f64) -> bool {
    *v == 0.0
}

/// The largest denoising gate a model may declare, metres: beyond it every track would be kept as given anyway.
pub const MAX_DENOISE_GATE_M: f64 = 100.0;

/// How the attention-zone graph is given to the network.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum GraphLayout {
    /// `edge_index (E, 2)` and `edge_features (E, 6)`: directed edges sorted by receiver (contracts 1 and 2).
    #[default]
    EdgeList,
    /// `neighbor_index (N, D)`, `neighbor_mask (N, D)` and `neighbor_features (N, D, 6)`: each agent's senders
    /// (itself included) in ascending order, padded to the largest degree D of the frame (contract 3). The network
    /// then needs only gathers and dense reductions, which ONNX Runtime runs far faster than scatters.
    Padded,
}

/// The shortest step a model may declare, seconds (1 kHz): below it speeds and the prior overflow.
pub const MIN_DT_S: f64 = 1e-3;
/// The longest step a model may declare, seconds (an hour).
pub const MAX_DT_S: f64 = 3600.0;

impl InputSpec {
    /// Checks every field.
    pub fn validate(&self) -> Result<()> {
        let bad = |m: String| Err(DganError::InvalidSpec(m));
        if !(self.dt_s.is_finite() && (MIN_DT_S..=MAX_DT_S).contains(&self.dt_s)) {
            return bad(format!("dt_s must be a number of seconds in {MIN_DT_S}..={MAX_DT_S}, got {}", self.dt_s));
        }
        for (key, v) in [("t_obs", self.t_obs), ("t_f", self.t_f)] {
            if !(1..=MAX_STEPS).contains(&v) {
                return bad(format!("{key} must be in 1..={MAX_STEPS} steps, got {v}"));
            }
        }
        if self.classes.is_empty() {
            return bad("a model needs at least one class".into());
        }
        let mut sorted = self.classes.clone();
        sorted.sort();
        sorted.dedup();
        if sorted.len() != self.classes.len() {
            return bad(format!("classes repeat: {:?}", self.classes));
        }
        if !(self.attention_lambda.is_finite() && self.attention_lambda >= 0.0) {
            return bad(format!("attention_lambda must be finite and >= 0, got {}", self.attention_lambda));
        }
        if let Some(m) = &self.map {
            m.validate()?;
        }
        self.prior.validate()?;
        if let Some((c, _)) = self.prior.by_class.iter().find(|(c, _)| !self.classes.contains(c)) {
            return bad(format!("prior.by_class names {c}, which is not among the model's classes {:?}", self.classes));
        }
        if let Some(c) = self.map.iter().flat_map(|m| &m.classes).find(|c| !self.classes.contains(c)) {
            return bad(format!("map.classes names {c}, which is not among the model's classes {:?}", self.classes));
        }
        let gate = self.denoise_gate_m;
        if !(gate.is_finite() && (0.0..=MAX_DENOISE_GATE_M).contains(&gate)) {
            return bad(format!("denoise_gate_m must be a number of metres in [0, {MAX_DENOISE_GATE_M}], got {gate}"));
        }
        Ok(())
    }

    /// The prediction horizon T_f · dt in seconds.
    pub fn horizon_s(&self) -> f64 {
        self.t_f as f64 * self.dt_s
    }

    /// Index of a class in this model's class order.
    pub fn class_index(&self, class: AgentClass) -> Result<usize> {
        self.classes.iter().position(|c| *c == class).ok_or_else(|| {
            let names: Vec<_> = self.classes.iter().map(|c| c.name()).collect();
            DganError::UnknownClass(format!("{class}: this model knows only [{}]", names.join(", ")))
        })
    }

    /// Width of the traffic-state vector: 7 kinematic and size features plus one one-hot slot per class.
    pub fn state_dim(&self) -> usize {
        STATE_FEATURES.len() + self.classes.len()
    }
}

/// Names of the kinematic and size features at the start of each agent's traffic-state vector; a one-hot class
/// vector follows them.
pub const STATE_FEATURES: [&str; 7] =
    ["speed_mps", "acceleration_mps2", "yaw_rate_radps", "motion_cos", "motion_sin", "length_m", "width_m"];

/// Names of the per-edge features: the sender's position, velocity and heading in the receiver's frame.
pub const EDGE_FEATURES: [&str; 6] = ["dx_m", "dy_m", "dvx_mps", "dvy_mps", "heading_cos", "heading_sin"];

/// The state features that change sign when a scene is mirrored across the agents' x axes (y → −y): every input is
/// agent-centric, so training's mirror augmentation negates these, the y of every position, and nothing else.
pub const STATE_MIRRORED: [&str; 2] = ["yaw_rate_radps", "motion_sin"];

/// The edge features that change sign under the same mirroring.
pub const EDGE_MIRRORED: [&str; 3] = ["dy_m", "dvy_mps", "heading_sin"];

#[cfg(test)]
mod tests {
    use super::*;

    pub(crate) fn spec() -> InputSpec {
        InputSpec {
            dt_s: 0.4,
            t_obs: 8,
            t_f: 12,
            classes: vec![AgentClass::Pedestrian],
            attention_lambda: 0.5,
            map: Some(MapSpec {
                height_px: 32,
                width_px: 32,
                resolution_m: 0.5,
                agent_row: 24,
                agent_col: 16,
                draw_agents: true,
                optional: false,
                render: MapRender::Agent,
                classes: vec![],
                scene: None,
            }),
            prior: PriorSpec::NONE,
            graph: GraphLayout::EdgeList,
            heading: HeadingSource::Measured,
            denoise_gate_m: 0.0,
        }
    }

    #[test]
    fn validates() {
        assert!(spec().validate().is_ok());
        let mut s = spec();
        s.dt_s = 0.0;
        assert!(s.validate().is_err());
        let mut s = spec();
        s.classes = vec![AgentClass::Vehicle, AgentClass::Vehicle];
        assert!(s.validate().is_err());
        let mut s = spec();
        s.map.as_mut().unwrap().agent_row = 32;
        assert!(s.validate().is_err());
        assert!(spec().class_index(AgentClass::Vehicle).is_err());
    }

    #[test]
    fn map_classes_are_classes_of_the_model_once_each() {
        let with = |classes: Vec<AgentClass>| {
            let mut s = spec();
            s.map.as_mut().unwrap().classes = classes;
            s.validate()
        };
        assert!(with(vec![AgentClass::Pedestrian]).is_ok());
        let err = with(vec![AgentClass::Vehicle]).unwrap_err().to_string();
        assert!(err.contains("map.classes names vehicle"), "{err}");
        assert!(with(vec![AgentClass::Pedestrian, AgentClass::Pedestrian]).unwrap_err().to_string().contains("repeat"));
        let m = MapSpec { classes: vec![AgentClass::Cyclist], ..spec().map.unwrap() };
        assert!(
            m.reads(AgentClass::Cyclist)
                && !m.reads(AgentClass::Vehicle)
                && spec().map.unwrap().reads(AgentClass::Vehicle)
        );
    }

    #[test]
    fn pixel_and_local_agree() {
        let m = spec().map.unwrap();
        let local = m.pixel_to_local(3, 20);
        let px = m.local_to_pixel(local);
        assert!((px[0] - 20.5).abs() < 1e-12 && (px[1] - 3.5).abs() < 1e-12);
        // Straight ahead is straight up.
        assert_eq!(m.local_to_pixel([2.0, 0.0]), [16.5, 20.5]);
    }
}
