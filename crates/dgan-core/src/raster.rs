//! Agent-centric, heading-aligned RGB crops of the scene map, one per agent, in the paper's colours.
//!
//! A vector map is drawn with anti-aliasing (tiny-skia): regions first (white bike lanes, grey crosswalks, pink
//! obstacles), then yellow road edges, solid and dashed white lane lines and green centre lines. A raster map is
//! resampled bilinearly through its homography. The agents themselves are drawn on top as blue boxes.

use crate::error::{DganError, Result};
use crate::frame::Frame;
use crate::map::{MapElementKind, RasterMap, SceneMap, VectorMap};
use crate::spec::MapSpec;
use crate::state::TrafficState;
use crate::transform::AgentPose;
use ndarray::Array4;
use rayon::prelude::*;
use rstar::primitives::GeomWithData;
use rstar::RTree;
use tiny_skia::{FillRule, LineCap, Paint, PathBuilder, Pixmap, Stroke, StrokeDash, Transform};

/// An RGB colour.
pub type Rgb = [u8; 3];

/// Median strips, barriers and other static obstacles.
pub const OBSTACLE: Rgb = [255, 105, 180];
/// Road boundaries.
pub const ROAD_EDGE: Rgb = [255, 255, 0];
/// Pedestrian crossings.
pub const CROSSWALK: Rgb = [128, 128, 128];
/// Bicycle lanes.
pub const BIKE_LANE: Rgb = [255, 255, 255];
/// Lane centre lines.
pub const CENTERLINE: Rgb = [0, 255, 0];
/// Dashed and solid lane lines.
pub const LANE_LINE: Rgb = [255, 255, 255];
/// Movable agents.
pub const AGENT: Rgb = [0, 0, 255];

/// Colour of each element kind.
pub fn colour(kind: MapElementKind) -> Rgb {
    match kind {
        MapElementKind::LaneCenterline => CENTERLINE,
        MapElementKind::LaneLineDashed | MapElementKind::LaneLineSolid => LANE_LINE,
        MapElementKind::RoadEdge => ROAD_EDGE,
        MapElementKind::Crosswalk => CROSSWALK,
        MapElementKind::BikeLane => BIKE_LANE,
        MapElementKind::Obstacle => OBSTACLE,
    }
}

/// Drawn width in metres of each polyline kind (at least one pixel is drawn).
fn line_width_m(kind: MapElementKind) -> f64 {
    match kind {
        MapElementKind::RoadEdge | MapElementKind::LaneCenterline => 0.3,
        _ => 0.15,
    }
}

/// Dash pattern of dashed lane lines, metres: 3 m painted, 6 m gap.
const DASH_M: (f64, f64) = (3.0, 6.0);

fn paint(rgb: Rgb) -> Paint<'static> {
    let mut p = Paint::default();
    p.set_color_rgba8(rgb[0], rgb[1], rgb[2], 255);
    p.anti_alias = true;
    p
}

struct Canvas<'a> {
    pixmap: Pixmap,
    spec: &'a MapSpec,
    pose: AgentPose,
}

impl Canvas<'_> {
    fn pixel(&self, world: [f64; 2]) -> (f32, f32) {
        let [u, v] = self.spec.local_to_pixel(self.pose.to_local(world));
        (u as f32, v as f32)
    }

    fn path(&self, points: &[[f64; 2]], close: bool) -> Option<tiny_skia::Path> {
        let mut pb = PathBuilder::new();
        for (k, p) in points.iter().enumerate() {
            let (u, v) = self.pixel(*p);
            if k == 0 {
                pb.move_to(u, v);
            } else {
                pb.line_to(u, v);
            }
        }
        if close {
            pb.close();
        }
        pb.finish()
    }

    fn fill(&mut self, points: &[[f64; 2]], rgb: Rgb) {
        if let Some(path) = self.path(points, true) {
            self.pixmap.fill_path(&path, &paint(rgb), FillRule::Winding, Transform::identity(), None);
        }
    }

    fn stroke(&mut self, points: &[[f64; 2]], kind: MapElementKind) {
        let Some(path) = self.path(points, false) else { return };
        let res = self.spec.resolution_m;
        let mut stroke = Stroke { width: (line_width_m(kind) / res).max(1.0) as f32, ..Stroke::default() };
        stroke.line_cap = LineCap::Butt;
        if kind == MapElementKind::LaneLineDashed {
            stroke.dash = StrokeDash::new(vec![(DASH_M.0 / res) as f32, (DASH_M.1 / res) as f32], 0.0);
        }
        self.pixmap.stroke_path(&path, &paint(colour(kind)), &stroke, Transform::identity(), None);
    }

    fn draw_vector(&mut self, map: &VectorMap) {
        let o = self.pose.origin();
        let reach = self.spec.reach_m();
        for e in map.elements() {
            let b = e.bbox();
            if b[0] > o[0] + reach || b[2] < o[0] - reach || b[1] > o[1] + reach || b[3] < o[1] - reach {
                continue;
            }
            if e.kind().is_polygon() {
                self.fill(e.points(), colour(e.kind()));
            } else {
                self.stroke(e.points(), e.kind());
            }
        }
    }

    fn draw_raster(&mut self, map: &RasterMap) {
        let (h, w) = (self.spec.height_px, self.spec.width_px);
        let data = self.pixmap.data_mut();
        for row in 0..h {
            for col in 0..w {
                let world = self.pose.to_world(self.spec.pixel_to_local(row, col));
                let rgb = map.project(world).map_or([0.0; 3], |uv| map.sample(uv));
                let k = (row * w + col) * 4;
                for ch in 0..3 {
                    data[k + ch] = rgb[ch].round().clamp(0.0, 255.0) as u8;
                }
                data[k + 3] = 255;
            }
        }
    }

    fn draw_box(&mut self, s: &TrafficState) {
        let pose = s.pose();
        let (hl, hw) = (s.length / 2.0, s.width / 2.0);
        let corners = [[hl, hw], [-hl, hw], [-hl, -hw], [hl, -hw]].map(|c| pose.to_world(c));
        self.fill(&corners, AGENT);
    }

    fn into_chw(self) -> Vec<f32> {
        let (h, w) = (self.spec.height_px, self.spec.width_px);
        let data = self.pixmap.data();
        let mut out = vec![0.0f32; 3 * h * w];
        for px in 0..h * w {
            for ch in 0..3 {
                out[ch * h * w + px] = f32::from(data[px * 4 + ch]) / 255.0;
            }
        }
        out
    }
}

/// Crops `(N, 3, H, W)` with values in [0, 1], one per agent, from the frame's map (black where there is none).
pub fn rasterize(frame: &Frame, states: &[TrafficState], spec: &MapSpec) -> Result<Array4<f32>> {
    spec.validate()?;
    if states.len() != frame.len() {
        return Err(DganError::InvalidFrame(format!("{} states for {} agents", states.len(), frame.len())));
    }
    let (h, w) = (spec.height_px, spec.width_px);
    let agents: RTree<GeomWithData<[f64; 2], usize>> =
        RTree::bulk_load(states.iter().enumerate().map(|(i, s)| GeomWithData::new(s.position, i)).collect());
    let max_half_diag = states.iter().map(|s| s.length.hypot(s.width) / 2.0).fold(0.0, f64::max);
    let reach = spec.reach_m() + max_half_diag;
    let crops: Vec<Vec<f32>> = states
        .par_iter()
        .map(|s| {
            let pixmap = Pixmap::new(w as u32, h as u32)
                .ok_or_else(|| DganError::InvalidSpec(format!("cannot allocate a {w}×{h} crop")))?;
            let mut canvas = Canvas { pixmap, spec, pose: s.pose() };
            match frame.map() {
                Some(SceneMap::Vector(m)) => canvas.draw_vector(m),
                Some(SceneMap::Raster(m)) => canvas.draw_raster(m),
                None => {}
            }
            if spec.draw_agents {
                for other in agents.locate_within_distance(s.position, reach * reach) {
                    canvas.draw_box(&states[other.data]);
                }
            }
            Ok(canvas.into_chw())
        })
        .collect::<Result<_>>()?;
    let flat: Vec<f32> = crops.concat();
    Array4::from_shape_vec((frame.len(), 3, h, w), flat)
        .map_err(|e| DganError::InvalidSpec(format!("raster buffer has the wrong size: {e}")))
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::class::AgentClass;
    use crate::map::MapElement;
    use crate::state::traffic_states;
    use ndarray::Array3;
    use std::sync::Arc;

    fn spec(draw_agents: bool) -> MapSpec {
        MapSpec { height_px: 40, width_px: 40, resolution_m: 0.5, agent_row: 30, agent_col: 20, draw_agents }
    }

    /// One agent at (100, 50) heading +y (north): its forward is image-up, its left (world -x) is image-left.
    fn frame_with(map: SceneMap) -> (Frame, Vec<TrafficState>) {
        let p = Array3::from_shape_fn((1, 2, 2), |(_, t, d)| if d == 0 { 100.0 } else { 49.0 + t as f64 });
        let f = Frame::new(p, None, vec![AgentClass::Pedestrian]).unwrap().with_map(Arc::new(map));
        let s = traffic_states(&f, 1.0);
        (f, s)
    }

    fn rgb(img: &Array4<f32>, row: usize, col: usize) -> [f32; 3] {
        [img[[0, 0, row, col]], img[[0, 1, row, col]], img[[0, 2, row, col]]]
    }

    #[test]
    fn vector_shapes_land_on_the_right_pixels() {
        // A crosswalk square 3.75..5.75 m ahead and 1.25..3.25 m to the left (world x 96.75..98.75,
        // y 53.75..55.75). The agent is at continuous (col, row) = (20.5, 30.5) and 1 m = 2 px, so the square
        // covers continuous rows 19..23 and cols 14..18: pixels rows 19..=22, cols 14..=17, exactly.
        let square = vec![[96.75, 53.75], [98.75, 53.75], [98.75, 55.75], [96.75, 55.75]];
        let cw = MapElement::new(MapElementKind::Crosswalk, square).unwrap();
        // A centre line along the agent's own path, world x = 100.
        let cl = MapElement::new(MapElementKind::LaneCenterline, vec![[100.0, 30.0], [100.0, 70.0]]).unwrap();
        let (f, s) = frame_with(SceneMap::Vector(VectorMap::new(vec![cw, cl])));
        let img = rasterize(&f, &s, &spec(false)).unwrap();
        assert_eq!(img.dim(), (1, 3, 40, 40));
        let grey = 128.0 / 255.0;
        for row in 19..=22 {
            for col in 14..=17 {
                let p = rgb(&img, row, col);
                assert!(p.iter().all(|c| (c - grey).abs() < 1e-6), "({row},{col}) = {p:?}");
            }
        }
        assert_eq!(rgb(&img, 18, 15), [0.0; 3]);
        assert_eq!(rgb(&img, 20, 18), [0.0; 3]);
        // The centre line runs up column 20 (the agent's column).
        for row in [0, 10, 39] {
            assert!(rgb(&img, row, 20)[1] > 0.4, "row {row}: {:?}", rgb(&img, row, 20));
            assert_eq!(rgb(&img, row, 25), [0.0; 3]);
        }
    }

    #[test]
    fn agents_are_blue_boxes() {
        let (f, s) = frame_with(SceneMap::Vector(VectorMap::default()));
        let img = rasterize(&f, &s, &spec(true)).unwrap();
        // A 0.5 × 0.5 m pedestrian covers exactly its own pixel.
        assert_eq!(rgb(&img, 30, 20), [0.0, 0.0, 1.0]);
        assert_eq!(rgb(&img, 29, 20), [0.0; 3]);
    }

    #[test]
    fn raster_map_is_resampled_through_the_homography() {
        // world_to_pixel = diag(2, 2, 1): 1 m = 2 px. Image columns u > 200 (world x > 100) are red.
        let mut image = Array3::<u8>::zeros((200, 400, 3));
        for v in 0..200 {
            for u in 201..400 {
                image[[v, u, 0]] = 255;
            }
        }
        let map = RasterMap::new(image, [[2.0, 0.0, 0.0], [0.0, 2.0, 0.0], [0.0, 0.0, 1.0]]).unwrap();
        let (f, s) = frame_with(SceneMap::Raster(map));
        let img = rasterize(&f, &s, &spec(false)).unwrap();
        // World +x is the agent's right: image columns right of the agent are red, left are black.
        assert_eq!(rgb(&img, 10, 30), [1.0, 0.0, 0.0]);
        assert_eq!(rgb(&img, 10, 10), [0.0; 3]);
    }
}
