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
use rstar::primitives::GeomWithData;
use rstar::{RTree, AABB};
use std::sync::atomic::{AtomicUsize, Ordering};
use tiny_skia::{FillRule, LineCap, Paint, PathBuilder, Pixmap, Stroke, Transform};

pub use crate::map::Rgb;

/// The version of the rasteriser (colours, widths, drawing order, anti-aliasing, agent boxes). Bump it with any
/// change to what a crop holds: exporters write it into each model's contract (`raster_version`), a model exported
/// with another is refused, and the training window cache is keyed by it.
pub const RASTER_VERSION: u32 = 1;

/// Movable agents.
pub const AGENT: Rgb = [0, 0, 255];

/// Colour of each element kind (its row of [`crate::map::PALETTE`]).
pub fn colour(kind: MapElementKind) -> Rgb {
    kind.style().colour
}

/// Drawn width in metres of each polyline kind (at least one pixel is drawn; [`crate::map::PALETTE`]).
fn line_width_m(kind: MapElementKind) -> f64 {
    kind.style().width_m
}

/// Dash pattern of dashed lane lines, metres: 3 m painted, 6 m gap.
const DASH_M: (f64, f64) = (3.0, 6.0);

/// Liang–Barsky: the part `[t0, t1]` (fractions of the segment) of `a → b` inside `rect = [x0, y0, x1, y1]`.
fn clip_segment(a: (f64, f64), b: (f64, f64), rect: [f64; 4]) -> Option<(f64, f64)> {
    let (dx, dy) = (b.0 - a.0, b.1 - a.1);
    let (mut t0, mut t1) = (0.0f64, 1.0f64);
    for (p, q) in [(-dx, a.0 - rect[0]), (dx, rect[2] - a.0), (-dy, a.1 - rect[1]), (dy, rect[3] - a.1)] {
        if p == 0.0 {
            if q < 0.0 {
                return None;
            }
        } else {
            let r = q / p;
            if p < 0.0 {
                t0 = t0.max(r);
            } else {
                t1 = t1.min(r);
            }
        }
    }
    (t0 <= t1).then_some((t0, t1))
}

/// Adds a polyline `px` (pixels, f64) to `pb`, clipped to `rect`: only the parts of its segments inside the rectangle,
/// so the work and the coordinates handed to the rasteriser stay bounded whatever the geometry (a segment of 10⁷ m,
/// a stray vertex at 10⁸ m). Segments that meet inside the rectangle stay one subpath, so their joins are those of
/// the whole line. With `dash = (on, period)` (pixels) only the painted stretches are added, phased by the arc
/// length from the line's start.
fn add_clipped(pb: &mut PathBuilder, px: &[(f64, f64)], rect: [f64; 4], dash: Option<(f64, f64)>) {
    let mut s = 0.0f64;
    let mut down = false;
    for w in px.windows(2) {
        let (a, b) = (w[0], w[1]);
        // A segment wholly on one side of the rectangle: nothing to draw (most segments of a map, per crop).
        let outside =
            a.0.max(b.0) < rect[0] || a.0.min(b.0) > rect[2] || a.1.max(b.1) < rect[1] || a.1.min(b.1) > rect[3];
        let clipped = if outside { None } else { clip_segment(a, b, rect) };
        let Some((f0, f1)) = clipped else {
            down = false;
            if dash.is_some() {
                s += (b.0 - a.0).hypot(b.1 - a.1);
            }
            continue;
        };
        let at = |f: f64| ((a.0 + (b.0 - a.0) * f) as f32, (a.1 + (b.1 - a.1) * f) as f32);
        if f0 > 0.0 {
            down = false;
        }
        match dash {
            None => {
                if !down {
                    let (u, v) = at(f0);
                    pb.move_to(u, v);
                }
                let (u, v) = at(f1);
                pb.line_to(u, v);
                down = true;
            }
            Some((on, period)) => {
                let len = (b.0 - a.0).hypot(b.1 - a.1);
                let frac = |t: f64| if len > 0.0 { t / len } else { 0.0 };
                let (t0, t1) = (f0 * len, f1 * len);
                let mut t = t0;
                while t < t1 {
                    let phase = (s + t).rem_euclid(period);
                    let (painted, left) = if phase < on { (true, on - phase) } else { (false, period - phase) };
                    let end = (t + left.max(1e-3)).min(t1);
                    if painted {
                        if !down {
                            let (u, v) = at(frac(t));
                            pb.move_to(u, v);
                            down = true;
                        }
                        let (u, v) = at(frac(end));
                        pb.line_to(u, v);
                    } else {
                        down = false;
                    }
                    t = end;
                }
                s += len;
            }
        }
        if f1 < 1.0 {
            down = false;
        }
    }
}

/// Sutherland–Hodgman: the polygon `px` clipped to `rect` (its parts outside cannot colour the crop).
fn clip_polygon(px: &[(f64, f64)], rect: [f64; 4]) -> Vec<(f64, f64)> {
    let mut out = px.to_vec();
    // (axis, bound, whether inside is at or above the bound)
    for (axis, v, above) in [(0, rect[0], true), (0, rect[2], false), (1, rect[1], true), (1, rect[3], false)] {
        let inside = |p: (f64, f64), v: f64| {
            let x = if axis == 0 { p.0 } else { p.1 };
            if above {
                x >= v
            } else {
                x <= v
            }
        };
        let input = std::mem::take(&mut out);
        let Some(&last) = input.last() else { break };
        let mut prev = last;
        for &cur in &input {
            let cross = |a: (f64, f64), b: (f64, f64)| {
                let (pa, pb) = if axis == 0 { (a.0, b.0) } else { (a.1, b.1) };
                let t = (v - pa) / (pb - pa);
                (a.0 + (b.0 - a.0) * t, a.1 + (b.1 - a.1) * t)
            };
            match (inside(prev, v), inside(cur, v)) {
                (true, true) => out.push(cur),
                (true, false) => out.push(cross(prev, cur)),
                (false, true) => {
                    out.push(cross(prev, cur));
                    out.push(cur);
                }
                (false, false) => {}
            }
            prev = cur;
        }
    }
    out
}

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
    /// World bounds `[min_x, min_y, max_x, max_y]` of the crop ([`world_bounds`]).
    view: [f64; 4],
}

/// World bounds `[min_x, min_y, max_x, max_y]` of an agent's crop, widened by a few pixels (line widths, joins).
fn world_bounds(spec: &MapSpec, pose: &AgentPose) -> [f64; 4] {
    let (h, w) = (spec.height_px as f64, spec.width_px as f64);
    let (r, c) = (spec.agent_row as f64 + 0.5, spec.agent_col as f64 + 0.5);
    let pad = 2.0 * line_width_px(spec, MapElementKind::RoadEdge) as f64 + 2.0;
    let mut b = [f64::INFINITY, f64::INFINITY, f64::NEG_INFINITY, f64::NEG_INFINITY];
    for (row, col) in [(-pad, -pad), (-pad, w + pad), (h + pad, -pad), (h + pad, w + pad)] {
        // Rows grow backwards and columns to the agent's right (see `MapSpec::local_to_pixel`).
        let p = pose.to_world([(r - row) * spec.resolution_m, (c - col) * spec.resolution_m]);
        b = [b[0].min(p[0]), b[1].min(p[1]), b[2].max(p[0]), b[3].max(p[1])];
    }
    b
}

/// Drawn width in pixels of a polyline kind: its width in metres, at least one pixel.
fn line_width_px(spec: &MapSpec, kind: MapElementKind) -> f32 {
    (line_width_m(kind) / spec.resolution_m).max(1.0) as f32
}

impl Canvas<'_> {
    fn pixel(&self, world: [f64; 2]) -> (f64, f64) {
        let [u, v] = self.spec.local_to_pixel(self.pose.to_local(world));
        (u, v)
    }

    /// The pixel rectangle that geometry is clipped to: the crop, widened beyond any cap or miter join (miter
    /// limit 4: at most 2 widths from its vertex) of the widest line, so that clipping changes no pixel of the crop.
    fn clip_rect(&self) -> [f64; 4] {
        let margin = 2.0 * f64::from(line_width_px(self.spec, MapElementKind::RoadEdge).max(1.0)) + 4.0;
        [-margin, -margin, self.spec.width_px as f64 + margin, self.spec.height_px as f64 + margin]
    }

    /// Adds a closed polygon to `pb`, clipped to the crop.
    fn add_polygon(&self, pb: &mut PathBuilder, points: &[[f64; 2]]) {
        let px: Vec<(f64, f64)> = points.iter().map(|p| self.pixel(*p)).collect();
        let clipped = clip_polygon(&px, self.clip_rect());
        if clipped.len() < 3 {
            return;
        }
        for (k, (u, v)) in clipped.iter().enumerate() {
            if k == 0 {
                pb.move_to(*u as f32, *v as f32);
            } else {
                pb.line_to(*u as f32, *v as f32);
            }
        }
        pb.close();
    }

    /// Adds a polyline to `pb`, clipped to the crop ([`add_clipped`]); dashed lines are cut into their dashes,
    /// phased from the whole line's start.
    fn add_polyline(&self, pb: &mut PathBuilder, points: &[[f64; 2]], kind: MapElementKind) {
        let px: Vec<(f64, f64)> = points.iter().map(|p| self.pixel(*p)).collect();
        let dash = (kind == MapElementKind::LaneLineDashed).then(|| {
            let res = self.spec.resolution_m;
            (DASH_M.0 / res, (DASH_M.0 + DASH_M.1) / res)
        });
        add_clipped(pb, &px, self.clip_rect(), dash);
    }

    /// Draws one kind's elements, batched into one path: a fill for regions, a butt-capped stroke for lines.
    fn flush(&mut self, kind: MapElementKind, pb: PathBuilder) {
        let Some(path) = pb.finish() else { return };
        let paint = paint(colour(kind));
        if kind.is_polygon() {
            self.pixmap.fill_path(&path, &paint, FillRule::Winding, Transform::identity(), None);
        } else {
            let stroke = Stroke { width: line_width_px(self.spec, kind), line_cap: LineCap::Butt, ..Stroke::default() };
            self.pixmap.stroke_path(&path, &paint, &stroke, Transform::identity(), None);
        }
    }

    fn draw_vector(&mut self, map: &VectorMap) {
        let view = self.view;
        let mut batch: Option<(MapElementKind, PathBuilder)> = None;
        for e in map.elements() {
            let b = e.bbox();
            if b[0] > view[2] || b[2] < view[0] || b[1] > view[3] || b[3] < view[1] {
                continue;
            }
            if batch.as_ref().is_some_and(|(k, _)| *k != e.kind()) {
                if let Some((k, pb)) = batch.take() {
                    self.flush(k, pb);
                }
            }
            let (_, pb) = batch.get_or_insert_with(|| (e.kind(), PathBuilder::new()));
            if e.kind().is_polygon() {
                self.add_polygon(pb, e.drawn_points());
            } else {
                self.add_polyline(pb, e.drawn_points(), e.kind());
            }
        }
        if let Some((k, pb)) = batch {
            self.flush(k, pb);
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
                    data[k + ch] = round_u8(rgb[ch]);
                }
                data[k + 3] = 255;
            }
        }
    }

    /// Draws the agents' boxes, in one fill.
    fn draw_boxes<'s>(&mut self, agents: impl Iterator<Item = &'s TrafficState>) {
        let mut pb = PathBuilder::new();
        for s in agents {
            let pose = s.pose();
            let (hl, hw) = (s.length / 2.0, s.width / 2.0);
            self.add_polygon(&mut pb, &[[hl, hw], [-hl, hw], [-hl, -hw], [hl, -hw]].map(|c| pose.to_world(c)));
        }
        if let Some(path) = pb.finish() {
            self.pixmap.fill_path(&path, &paint(AGENT), FillRule::Winding, Transform::identity(), None);
        }
    }

    /// Writes the crop into `out`, `(3, H, W)` channel-major, scaled to [0, 1].
    fn write_chw(&self, out: &mut [f32]) {
        let plane = self.spec.height_px * self.spec.width_px;
        let (r, rest) = out.split_at_mut(plane);
        let (g, b) = rest.split_at_mut(plane);
        for (k, px) in self.pixmap.data().chunks_exact(4).enumerate() {
            r[k] = f32::from(px[0]) / 255.0;
            g[k] = f32::from(px[1]) / 255.0;
            b[k] = f32::from(px[2]) / 255.0;
        }
    }
}

/// `x.round().clamp(0.0, 255.0) as u8` for the non-negative, finite values a bilinear sample of a u8 image gives,
/// exactly (rounding half away from zero), without a call to libm's `roundf` per channel and pixel.
#[inline]
fn round_u8(x: f32) -> u8 {
    if x.is_nan() || x <= 0.0 {
        return 0; // also NaN, as `as u8` would give
    }
    if x >= 255.0 {
        return 255;
    }
    let t = x as u32; // truncates; the fraction x - t is exact below 2²³
    let up = u32::from(x - t as f32 >= 0.5);
    (t + up) as u8
}

/// Predictions in flight in this process: the rasteriser shares the cores among them (two threads predicting at once
/// on two cores each draw on their own thread instead of both spawning helpers that then compete).
static IN_FLIGHT: AtomicUsize = AtomicUsize::new(0);

/// Marks a prediction in flight for as long as it lives.
#[derive(Debug)]
pub(crate) struct InFlight;

impl InFlight {
    pub(crate) fn enter() -> Self {
        IN_FLIGHT.fetch_add(1, Ordering::SeqCst);
        Self
    }
}

impl Drop for InFlight {
    fn drop(&mut self) {
        IN_FLIGHT.fetch_sub(1, Ordering::SeqCst);
    }
}

/// Crops `(N, 3, H, W)` with values in [0, 1], one per agent, from the frame's map (black where there is none),
/// drawn on up to all the machine's cores ([`rasterize_on`]).
pub fn rasterize(frame: &Frame, states: &[TrafficState], spec: &MapSpec) -> Result<Array4<f32>> {
    rasterize_on(frame, states, spec, crate::limits::cores())
}

/// [`rasterize`] on at most `threads` threads (the calling one included), shared with the other predictions in
/// flight in this process, and at least 8 crops to a thread. The crops are the same whatever the threads.
pub fn rasterize_on(frame: &Frame, states: &[TrafficState], spec: &MapSpec, threads: usize) -> Result<Array4<f32>> {
    spec.validate()?;
    if states.len() != frame.len() {
        return Err(DganError::InvalidFrame(format!("{} states for {} agents", states.len(), frame.len())));
    }
    let (h, w) = (spec.height_px, spec.width_px);
    let agents: RTree<GeomWithData<[f64; 2], usize>> =
        RTree::bulk_load(states.iter().enumerate().map(|(i, s)| GeomWithData::new(s.position, i)).collect());
    let max_half_diag = states.iter().map(|s| s.length.hypot(s.width) / 2.0).fold(0.0, f64::max);
    let mut out = Array4::<f32>::zeros((frame.len(), 3, h, w));
    let flat = out.as_slice_mut().ok_or_else(|| DganError::InvalidSpec("raster buffer is not contiguous".into()))?;
    let draw = |crop: &mut [f32], s: &TrafficState| -> Result<()> {
        let pixmap = Pixmap::new(w as u32, h as u32)
            .ok_or_else(|| DganError::InvalidSpec(format!("cannot allocate a {w}×{h} crop")))?;
        let pose = s.pose();
        let view = world_bounds(spec, &pose);
        let mut canvas = Canvas { pixmap, spec, pose, view };
        match frame.map() {
            Some(SceneMap::Vector(m)) => canvas.draw_vector(m),
            Some(SceneMap::Raster(m)) => canvas.draw_raster(m),
            None => {}
        }
        if spec.draw_agents {
            // Every agent whose box can reach into the crop.
            let d = max_half_diag;
            let near = AABB::from_corners([view[0] - d, view[1] - d], [view[2] + d, view[3] + d]);
            canvas.draw_boxes(agents.locate_in_envelope(&near).map(|o| &states[o.data]));
        }
        canvas.write_chw(crop);
        Ok(())
    };
    // Scoped threads that end with the call, rather than a pool whose idle workers keep spinning on the cores that
    // ONNX Runtime runs on next (on two cores that cost as much as the parallel drawing saved).
    let per = 3 * h * w;
    let threads = (threads / IN_FLIGHT.load(Ordering::SeqCst).max(1)).min(states.len() / 8).max(1);
    if threads == 1 {
        for (crop, s) in flat.chunks_mut(per).zip(states) {
            draw(crop, s)?;
        }
    } else {
        let agents_per_thread = states.len().div_ceil(threads);
        std::thread::scope(|scope| {
            let draw = &draw;
            let handles: Vec<_> = flat
                .chunks_mut(per * agents_per_thread)
                .zip(states.chunks(agents_per_thread))
                .map(|(crops, part)| {
                    scope.spawn(move || crops.chunks_mut(per).zip(part).try_for_each(|(crop, s)| draw(crop, s)))
                })
                .collect();
            handles.into_iter().try_for_each(|handle| {
                handle.join().map_err(|_| DganError::InvalidSpec("a rasterising thread panicked".into()))?
            })
        })?;
    }
    Ok(out)
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
        MapSpec {
            height_px: 40,
            width_px: 40,
            resolution_m: 0.5,
            agent_row: 30,
            agent_col: 20,
            draw_agents,
            optional: false,
        }
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
    fn long_dashed_lines_keep_their_pattern_inside_the_crop() {
        // A dashed line along the agent's own path from 1 km behind to 1 km ahead, a vertex every 0.5 m (the crop
        // draws only the part near it, dashed from its arc length): 3 m painted from y = -1000, then 6 m of gap.
        let line: Vec<[f64; 2]> = (0..=4000).map(|i| [100.0, -1000.0 + i as f64 * 0.5]).collect();
        let el = MapElement::new(MapElementKind::LaneLineDashed, line).unwrap();
        let (f, s) = frame_with(SceneMap::Vector(VectorMap::new(vec![el])));
        let img = rasterize(&f, &s, &spec(false)).unwrap();
        let mut checked = (0, 0);
        for row in 0..40 {
            // Pixel rows span world y in [50 + (29.5 - row) / 2, 50 + (30.5 - row) / 2].
            let (lo, hi) = (50.0 + (29.5 - row as f64) / 2.0 + 1000.0, 50.0 + (30.5 - row as f64) / 2.0 + 1000.0);
            let (plo, phi) = (lo.rem_euclid(9.0), hi.rem_euclid(9.0));
            let white = rgb(&img, row, 20)[0];
            if plo < phi && phi <= 3.0 {
                assert!(white > 0.9, "row {row} lies inside a dash: {white}");
                checked.0 += 1;
            } else if plo < phi && plo >= 3.0 {
                assert_eq!(white, 0.0, "row {row} lies in a gap");
                checked.1 += 1;
            }
        }
        assert!(checked.0 >= 8 && checked.1 >= 16, "{checked:?}");
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

    #[test]
    fn pathological_geometry_costs_little_and_draws_what_is_inside() {
        // A dashed line with one 6·10⁷ m segment through the crop, a stray vertex 10⁸ m away, a huge polygon:
        // each used to hang the rasteriser (dashing the whole segment, stroking coordinates far outside).
        let els = vec![
            MapElement::new(MapElementKind::LaneLineDashed, vec![[100.0, -3e7], [100.0, 3e7]]).unwrap(),
            MapElement::new(MapElementKind::RoadEdge, vec![[95.0, 40.0], [95.0, 60.0], [1e8, 61.0]]).unwrap(),
            MapElement::new(MapElementKind::Obstacle, vec![[104.0, 55.0], [1e8, 55.0], [104.0, 1e8]]).unwrap(),
        ];
        let (f, s) = frame_with(SceneMap::Vector(VectorMap::new(els)));
        let started = std::time::Instant::now();
        let img = rasterize(&f, &s, &spec(false)).unwrap();
        assert!(started.elapsed().as_secs_f64() < 1.0, "{:?}", started.elapsed());
        // The dashed line runs along the agent's column (x = 100), some rows painted and some not.
        let painted = (0..40).filter(|&r| rgb(&img, r, 20)[0] > 0.9).count();
        assert!((5..35).contains(&painted), "{painted}");
        // The road edge at x = 95 (10 px left of the agent) is yellow; the polygon covers x > 104 above y = 55.
        assert_eq!(rgb(&img, 25, 10), [1.0, 1.0, 0.0]);
        assert!((rgb(&img, 5, 35)[0] - 1.0).abs() < 1e-6); // obstacle pink: (255, 105, 180)
    }

    #[test]
    fn crops_do_not_depend_on_the_threads() {
        // 40 agents along a road with lines, regions and their boxes: one thread and several draw the same bytes.
        let p =
            Array3::from_shape_fn((40, 2, 2), |(i, t, d)| if d == 0 { 90.0 + i as f64 * 0.7 } else { 49.0 + t as f64 });
        let classes = vec![AgentClass::Vehicle; 40];
        let line = MapElement::new(MapElementKind::LaneLineDashed, vec![[80.0, 0.0], [130.0, 100.0]]).unwrap();
        let region =
            MapElement::new(MapElementKind::Crosswalk, vec![[95.0, 50.0], [99.0, 50.0], [99.0, 54.0]]).unwrap();
        let map = Arc::new(SceneMap::Vector(VectorMap::new(vec![line, region])));
        let f = Frame::new(p, None, classes).unwrap().with_map(map);
        let s = traffic_states(&f, 1.0);
        let one = rasterize_on(&f, &s, &spec(true), 1).unwrap();
        for threads in [2, 3, 5] {
            assert_eq!(rasterize_on(&f, &s, &spec(true), threads).unwrap(), one, "{threads} threads");
        }
        assert!(one.iter().any(|v| *v > 0.0));
    }

    #[test]
    fn exact_rounding_matches_the_library() {
        let mut x = 0.0f32;
        while x < 256.0 {
            assert_eq!(round_u8(x), x.round().clamp(0.0, 255.0) as u8, "{x}");
            x = f32::from_bits(x.to_bits() + 997);
        }
        for x in [0.5f32, 1.5, 254.5, 0.49999997, 255.49, 300.0, -3.0, f32::NAN] {
            assert_eq!(round_u8(x), x.round().clamp(0.0, 255.0) as u8, "{x}");
        }
    }
}
