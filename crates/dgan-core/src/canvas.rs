//! Drawing into one pixmap: the vector map's elements, clipped to it (tiny-skia, anti-aliased, in the paper's
//! colours), a raster map resampled through its homography, and the agents' boxes. A canvas maps world metres to
//! its pixels through a pose and a [`MapSpec`]: an agent's heading-aligned crop ([`crate::raster`]) or a north-up
//! tile of the whole map ([`crate::tiles`]).

use crate::map::{MapElementKind, RasterMap, Rgb, VectorMap};
use crate::spec::MapSpec;
use crate::state::TrafficState;
use crate::transform::AgentPose;
use tiny_skia::{FillRule, LineCap, Paint, PathBuilder, Pixmap, Stroke, Transform};

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

/// A pixmap and how world metres map onto it.
pub(crate) struct Canvas<'a> {
    pub(crate) pixmap: Pixmap,
    pub(crate) spec: &'a MapSpec,
    pub(crate) pose: AgentPose,
    /// World bounds `[min_x, min_y, max_x, max_y]` of the pixmap, widened ([`world_bounds`]); elements wholly
    /// outside are skipped.
    pub(crate) view: [f64; 4],
    /// The narrowest line drawn, pixels: 1 for a crop; a tile drawn at a finer resolution than the crops it serves
    /// draws no line narrower than one of their pixels.
    pub(crate) min_width_px: f32,
}

/// World bounds `[min_x, min_y, max_x, max_y]` of an agent's crop, widened by a few pixels (line widths, joins).
pub(crate) fn world_bounds(spec: &MapSpec, pose: &AgentPose) -> [f64; 4] {
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

impl<'a> Canvas<'a> {
    /// A transparent (black) canvas of `spec`'s size with its pixels placed by `pose`, one-pixel lines at least.
    pub(crate) fn new(spec: &'a MapSpec, pose: AgentPose) -> Option<Self> {
        let pixmap = Pixmap::new(spec.width_px as u32, spec.height_px as u32)?;
        Some(Self { pixmap, spec, pose, view: world_bounds(spec, &pose), min_width_px: 1.0 })
    }
}

impl Canvas<'_> {
    /// Drawn width in pixels of a polyline kind: its width in metres, at least `min_width_px`. A crop's is
    /// [`line_width_px`] exactly.
    fn width_px(&self, kind: MapElementKind) -> f32 {
        if self.min_width_px == 1.0 {
            return line_width_px(self.spec, kind);
        }
        ((line_width_m(kind) / self.spec.resolution_m) as f32).max(self.min_width_px)
    }

    fn pixel(&self, world: [f64; 2]) -> (f64, f64) {
        let [u, v] = self.spec.local_to_pixel(self.pose.to_local(world));
        (u, v)
    }

    /// The pixel rectangle that geometry is clipped to: the crop, widened beyond any cap or miter join (miter
    /// limit 4: at most 2 widths from its vertex) of the widest line, so that clipping changes no pixel of the crop.
    fn clip_rect(&self) -> [f64; 4] {
        let margin = 2.0 * f64::from(self.width_px(MapElementKind::RoadEdge).max(1.0)) + 4.0;
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
            let stroke = Stroke { width: self.width_px(kind), line_cap: LineCap::Butt, ..Stroke::default() };
            self.pixmap.stroke_path(&path, &paint, &stroke, Transform::identity(), None);
        }
    }

    pub(crate) fn draw_vector(&mut self, map: &VectorMap) {
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

    pub(crate) fn draw_raster(&mut self, map: &RasterMap) {
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
    pub(crate) fn draw_boxes<'s>(&mut self, agents: impl Iterator<Item = &'s TrafficState>) {
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
    pub(crate) fn write_chw(&self, out: &mut [f32]) {
        let plane = self.spec.height_px * self.spec.width_px;
        let (r, rest) = out.split_at_mut(plane);
        let (g, b) = rest.split_at_mut(plane);
        for (k, px) in self.pixmap.data().chunks_exact(4).enumerate() {
            r[k] = UNIT[usize::from(px[0])];
            g[k] = UNIT[usize::from(px[1])];
            b[k] = UNIT[usize::from(px[2])];
        }
    }
}

/// `f32::from(v) / 255.0` for every byte `v`, computed once (exactly: the division is correctly rounded either way):
/// a crop's values without a division per channel and pixel, which was most of the cost of resampling tiles.
pub(crate) static UNIT: [f32; 256] = unit_table();

const fn unit_table() -> [f32; 256] {
    let mut table = [0.0f32; 256];
    let mut v = 0;
    while v < 256 {
        table[v] = v as f32 / 255.0;
        v += 1;
    }
    table
}

/// `x.round().clamp(0.0, 255.0) as u8` for the non-negative, finite values a bilinear sample of a u8 image gives,
/// exactly (rounding half away from zero), without a call to libm's `roundf` per channel and pixel.
#[inline]
pub(crate) fn round_u8(x: f32) -> u8 {
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
