//! Scene maps: a raster map (an RGB image and its world→pixel homography, as ETH/UCY and Stanford Drone provide)
//! or a vector map (typed polylines and polygons of a semantic HD map, in world metres).

use crate::error::{DganError, Result};
use crate::tile_store::{FeatureStore, TileStore};
use nalgebra::{Matrix3, Vector3};
use ndarray::Array3;
use std::fmt;
use std::str::FromStr;
use std::sync::OnceLock;

/// A map of the scene, shared by every frame of it.
#[derive(Debug, Clone)]
pub enum SceneMap {
    /// An image of the scene with its homography.
    Raster(RasterMap),
    /// Typed polylines and polygons in world metres.
    Vector(VectorMap),
}

impl SceneMap {
    /// Scene models' features of this map kept for every later call ([`crate::kept`]), shared by every frame that
    /// holds it.
    pub fn features(&self) -> &FeatureStore {
        match self {
            SceneMap::Raster(m) => &m.features,
            SceneMap::Vector(m) => &m.features,
        }
    }
}

/// An RGB image of the scene and the homography from world metres to its pixels.
///
/// Pixel coordinates are `(u, v)` = (column, row), with integer values at pixel centres.
#[derive(Debug, Clone)]
pub struct RasterMap {
    image: Array3<u8>,
    world_to_pixel: Matrix3<f64>,
    /// The homography's last row is `(0, 0, 1)` (every ETH/UCY and Stanford Drone map): the projection's `z` is
    /// exactly 1 at every finite point, so [`RasterMap::project`] skips the division, which changes no bit.
    affine: bool,
    /// Scene models' features of this map ([`crate::kept`]).
    features: FeatureStore,
    /// The image as indices into a few colours, where it has at most [`MAX_PALETTE`] (the semantic masks of
    /// ETH/UCY): half a byte a pixel instead of three, so the scattered reads of a crop's bilinear taps hit a cache
    /// a sixth the size. Built by the first [`RasterMap::sample`] (under a millisecond for a 720 × 576 mask), which
    /// reads it when there is one and returns the same values to the bit.
    palette: OnceLock<Option<Palette>>,
}

/// The most colours [`RasterMap`] keeps an indexed copy of its image for.
const MAX_PALETTE: usize = 16;

/// An image as one colour index a pixel, two to a byte (the even column in the low half), row after row of
/// `stride` bytes, and its colours.
#[derive(Debug, Clone)]
struct Palette {
    index: Vec<u8>,
    stride: usize,
    colours: Vec<[u8; 3]>,
}

impl Palette {
    /// The image's indexed copy, or None if it has more than [`MAX_PALETTE`] colours (a photograph: given up at the
    /// first colour too many, so it costs little).
    fn of(image: &Array3<u8>) -> Option<Self> {
        let data = image.as_slice()?;
        let (h, w, _) = image.dim();
        let stride = w.div_ceil(2);
        let mut colours: Vec<[u8; 3]> = Vec::new();
        let mut index = vec![0u8; stride * h];
        let (mut last, mut last_k) = ([0u8; 3], None::<u8>);
        for (src, dst) in data.chunks_exact(3 * w).zip(index.chunks_exact_mut(stride)) {
            for (col, px) in src.chunks_exact(3).enumerate() {
                let c = [px[0], px[1], px[2]];
                let k = match last_k {
                    Some(k) if last == c => k,
                    _ => {
                        let k = match colours.iter().position(|&p| p == c) {
                            Some(k) => k,
                            None if colours.len() < MAX_PALETTE => {
                                colours.push(c);
                                colours.len() - 1
                            }
                            None => return None,
                        };
                        let k = u8::try_from(k).ok()?;
                        (last, last_k) = (c, Some(k));
                        k
                    }
                };
                dst[col / 2] |= k << (4 * (col % 2));
            }
        }
        Some(Self { index, stride, colours })
    }

    /// The colour of pixel `(row, col)`, inside the image.
    #[inline]
    fn colour(&self, row: usize, col: usize) -> [u8; 3] {
        let k = (self.index[row * self.stride + col / 2] >> (4 * (col % 2))) & 0x0f;
        self.colours[usize::from(k)]
    }
}

impl RasterMap {
    /// Checks and wraps an `(H, W, 3)` RGB image and its 3×3 world→pixel homography (row-major).
    pub fn new(image: Array3<u8>, world_to_pixel: [[f64; 3]; 3]) -> Result<Self> {
        let (h, w, c) = image.dim();
        if h == 0 || w == 0 || c != 3 {
            return Err(DganError::InvalidMap(format!(
                "raster image must have shape (H, W, 3) with H, W > 0, got ({h}, {w}, {c})"
            )));
        }
        let m = Matrix3::from_row_slice(&world_to_pixel.concat());
        if m.iter().any(|v| !v.is_finite()) {
            return Err(DganError::InvalidMap("world_to_pixel holds NaN or infinite values".into()));
        }
        let det = m.determinant();
        if !det.is_normal() {
            return Err(DganError::InvalidMap(format!("world_to_pixel is singular (determinant {det:e})")));
        }
        let affine = world_to_pixel[2] == [0.0, 0.0, 1.0];
        let image = image.as_standard_layout().to_owned();
        Ok(Self { image, world_to_pixel: m, affine, features: FeatureStore::default(), palette: OnceLock::new() })
    }

    /// Reads a PNG or JPEG image (converted to RGB) and pairs it with its world→pixel homography.
    pub fn from_file(path: impl AsRef<std::path::Path>, world_to_pixel: [[f64; 3]; 3]) -> Result<Self> {
        let path = path.as_ref();
        let img = image::open(path)
            .map_err(|e| DganError::InvalidMap(format!("cannot read image {}: {e}", path.display())))?
            .into_rgb8();
        let (w, h) = img.dimensions();
        let image = Array3::from_shape_vec((h as usize, w as usize, 3), img.into_raw())
            .map_err(|e| DganError::InvalidMap(format!("image {}: {e}", path.display())))?;
        Self::new(image, world_to_pixel)
    }

    /// The image, `(H, W, 3)`.
    pub fn image(&self) -> &Array3<u8> {
        &self.image
    }

    /// The world→pixel homography.
    pub fn world_to_pixel(&self) -> &Matrix3<f64> {
        &self.world_to_pixel
    }

    /// Projects a world point to continuous pixel coordinates `(u, v)`; `None` behind the projection's horizon.
    #[inline]
    pub fn project(&self, world: [f64; 2]) -> Option<[f64; 2]> {
        let p = self.world_to_pixel * Vector3::new(world[0], world[1], 1.0);
        if self.affine {
            // z = 0·x + 0·y + 1 = 1 exactly; a point at infinity gives NaN coordinates, which sample as black (as
            // `None` does).
            return Some([p.x, p.y]);
        }
        if p.z.abs() < 1e-12 || !p.z.is_finite() {
            return None;
        }
        Some([p.x / p.z, p.y / p.z])
    }

    /// Bilinear sample of the image at continuous pixel `(u, v)`; black outside the image.
    #[inline]
    pub fn sample(&self, uv: [f64; 2]) -> [f32; 3] {
        let (h, w, _) = self.image.dim();
        let (u, v) = (uv[0], uv[1]);
        if !(u > -1.0 && v > -1.0 && u < w as f64 && v < h as f64) {
            return [0.0; 3];
        }
        let (c0, r0) = (floor_i64(u), floor_i64(v));
        let (fu, fv) = ((u - c0 as f64) as f32, (v - r0 as f64) as f32);
        let mut out = [0.0f32; 3];
        // The four taps in the same order and arithmetic as ever; reading the row-major image (or its indexed copy,
        // whose colours are the same bytes) directly where all four lie inside it (almost every pixel of a crop),
        // with bounds checks only along the image's edges.
        let data = self.image.as_slice();
        let palette = self.palette.get_or_init(|| Palette::of(&self.image));
        let inside = r0 >= 0 && c0 >= 0 && r0 + 1 < h as i64 && c0 + 1 < w as i64;
        for (dv, wv) in [(0i64, 1.0 - fv), (1, fv)] {
            for (du, wu) in [(0i64, 1.0 - fu), (1, fu)] {
                let (row, col) = (r0 + dv, c0 + du);
                let wgt = wu * wv;
                if wgt == 0.0 {
                    continue;
                }
                let rgb: [u8; 3] = match (palette, data) {
                    (Some(p), _) if inside => p.colour(row as usize, col as usize),
                    (None, Some(data)) if inside => {
                        let k = (row as usize * w + col as usize) * 3;
                        [data[k], data[k + 1], data[k + 2]]
                    }
                    _ => {
                        if row < 0 || col < 0 || row >= h as i64 || col >= w as i64 {
                            continue;
                        }
                        let (r, c) = (row as usize, col as usize);
                        [self.image[[r, c, 0]], self.image[[r, c, 1]], self.image[[r, c, 2]]]
                    }
                };
                for (o, v) in out.iter_mut().zip(rgb) {
                    *o += wgt * f32::from(v);
                }
            }
        }
        out
    }
}

/// `x.floor()` as an integer, for `x` within ±2⁶² (exact; a compare instead of a call to libm's `floor`, which the
/// baseline x86-64 target cannot inline, in the innermost loop of raster maps).
#[inline]
fn floor_i64(x: f64) -> i64 {
    let t = x as i64; // truncates toward zero
    if (t as f64) > x {
        t - 1
    } else {
        t
    }
}

/// The element types of a vector map, each drawn in the paper's colour.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum MapElementKind {
    /// Lane centre line (polyline, green).
    LaneCenterline,
    /// Dashed lane line (polyline, dotted white).
    LaneLineDashed,
    /// Solid lane or edge line (polyline, solid white).
    LaneLineSolid,
    /// Road boundary or curb (polyline, yellow).
    RoadEdge,
    /// Pedestrian crossing (polygon, grey).
    Crosswalk,
    /// Bicycle lane (polygon, white region).
    BikeLane,
    /// Median, barrier or other static obstacle (polygon, pink).
    Obstacle,
}

/// An RGB colour.
pub type Rgb = [u8; 3];

/// How one element kind is named and drawn: a row of [`PALETTE`].
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct KindStyle {
    /// The kind.
    pub kind: MapElementKind,
    /// Its name in the Python API, vector-map JSON and `dgan._dgan.CONTRACT`.
    pub name: &'static str,
    /// A filled polygon (else a polyline).
    pub polygon: bool,
    /// The paper's colour.
    pub colour: Rgb,
    /// Drawn line width in metres (at least one pixel is drawn); 0 for polygons.
    pub width_m: f64,
}

const fn style(kind: MapElementKind, name: &'static str, polygon: bool, colour: Rgb, width_m: f64) -> KindStyle {
    KindStyle { kind, name, polygon, colour, width_m }
}

/// Every element kind, in drawing order (regions first, then lines): the one table a new kind is added to (with its
/// variant above). Python, training and the tests read it through `dgan._dgan.CONTRACT`; drawing changes bump
/// [`crate::raster::RASTER_VERSION`].
pub const PALETTE: [KindStyle; 7] = [
    style(MapElementKind::BikeLane, "bike_lane", true, [255, 255, 255], 0.0),
    style(MapElementKind::Crosswalk, "crosswalk", true, [128, 128, 128], 0.0),
    style(MapElementKind::Obstacle, "obstacle", true, [255, 105, 180], 0.0),
    style(MapElementKind::RoadEdge, "road_edge", false, [255, 255, 0], 0.3),
    style(MapElementKind::LaneLineSolid, "lane_line_solid", false, [255, 255, 255], 0.15),
    style(MapElementKind::LaneLineDashed, "lane_line_dashed", false, [255, 255, 255], 0.15),
    style(MapElementKind::LaneCenterline, "lane_centerline", false, [0, 255, 0], 0.3),
];

impl MapElementKind {
    /// Every kind, in drawing order (regions first, then lines): the kinds of [`PALETTE`].
    pub const ALL: [MapElementKind; PALETTE.len()] = {
        let mut out = [MapElementKind::BikeLane; PALETTE.len()];
        let mut i = 0;
        while i < PALETTE.len() {
            out[i] = PALETTE[i].kind;
            i += 1;
        }
        out
    };

    /// The kind's row of [`PALETTE`].
    pub fn style(self) -> &'static KindStyle {
        PALETTE.iter().find(|s| s.kind == self).expect("every kind has a row in PALETTE")
    }

    /// The name used in the Python API.
    pub fn name(self) -> &'static str {
        self.style().name
    }

    /// Whether the element is a filled polygon (else a polyline).
    pub fn is_polygon(self) -> bool {
        self.style().polygon
    }
}

impl fmt::Display for MapElementKind {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(self.name())
    }
}

impl FromStr for MapElementKind {
    type Err = DganError;

    fn from_str(s: &str) -> Result<Self> {
        Self::ALL.into_iter().find(|k| k.name() == s.trim()).ok_or_else(|| {
            let names: Vec<_> = Self::ALL.iter().map(|k| k.name()).collect();
            DganError::InvalidMap(format!("unknown map element kind {s:?}; known kinds: {}", names.join(", ")))
        })
    }
}

/// How far (metres) the drawn outline of an element may stray from its vertices: dense source polylines (Waymo and
/// nuScenes lanes carry a vertex every 0.5–1 m) are drawn through the fewest vertices within this distance: at most a
/// fifth of a pixel at the crop resolutions of the bundled models (0.25–1 m per pixel).
pub const DRAW_TOLERANCE_M: f64 = 0.05;

/// One typed polyline or polygon, in world metres.
#[derive(Debug, Clone)]
pub struct MapElement {
    kind: MapElementKind,
    points: Vec<[f64; 2]>,
    drawn: Vec<[f64; 2]>,
    bbox: [f64; 4],
}

/// Vertices per stretch when [`simplify`] falls back to stretches (see there).
pub const SIMPLIFY_CHUNK: usize = 256;
/// Distance evaluations per vertex that [`simplify`] allows Ramer–Douglas–Peucker on a whole polyline.
pub const SIMPLIFY_WORK_PER_VERTEX: usize = 64;

/// The vertices of `points` to keep so that no dropped vertex is farther than `tolerance` from the simplified line
/// (the first and last are always kept): Ramer–Douglas–Peucker on the whole polyline, which takes about
/// `n · log n` steps on real maps; it is quadratic in the worst case (a zigzag), so past
/// [`SIMPLIFY_WORK_PER_VERTEX`]` · n` steps it starts again stretch by stretch ([`SIMPLIFY_CHUNK`] vertices, each
/// stretch's ends kept): the work is bounded by about `(64 + 256) · n` whatever the geometry.
fn simplify(points: &[[f64; 2]], tolerance: f64) -> Vec<[f64; 2]> {
    let mut budget = SIMPLIFY_WORK_PER_VERTEX.saturating_mul(points.len()).max(1 << 16);
    if let Some(out) = simplify_all(points, tolerance, &mut budget) {
        return out;
    }
    let mut out = vec![points[0]];
    let mut start = 0;
    while start + 1 < points.len() {
        let end = (start + SIMPLIFY_CHUNK - 1).min(points.len() - 1);
        let mut unlimited = usize::MAX; // a stretch of 256 vertices costs at most 256² / 2
        let stretch = simplify_all(&points[start..=end], tolerance, &mut unlimited);
        out.extend_from_slice(&stretch.unwrap_or_else(|| points[start..=end].to_vec())[1..]);
        start = end;
    }
    out
}

/// Ramer–Douglas–Peucker, or `None` once `budget` distance evaluations are spent.
fn simplify_all(points: &[[f64; 2]], tolerance: f64, budget: &mut usize) -> Option<Vec<[f64; 2]>> {
    fn distance(p: [f64; 2], a: [f64; 2], b: [f64; 2]) -> f64 {
        let (dx, dy) = (b[0] - a[0], b[1] - a[1]);
        let len2 = dx * dx + dy * dy;
        let t = if len2 > 0.0 { (((p[0] - a[0]) * dx + (p[1] - a[1]) * dy) / len2).clamp(0.0, 1.0) } else { 0.0 };
        (p[0] - a[0] - t * dx).hypot(p[1] - a[1] - t * dy)
    }
    if points.len() < 3 {
        return Some(points.to_vec());
    }
    let mut keep = vec![false; points.len()];
    keep[0] = true;
    keep[points.len() - 1] = true;
    let mut stack = vec![(0, points.len() - 1)];
    while let Some((a, b)) = stack.pop() {
        *budget = budget.checked_sub(b - a)?;
        let (mut worst, mut at) = (0.0, a);
        for i in a + 1..b {
            let d = distance(points[i], points[a], points[b]);
            if d > worst {
                (worst, at) = (d, i);
            }
        }
        if worst > tolerance {
            keep[at] = true;
            stack.push((a, at));
            stack.push((at, b));
        }
    }
    Some(points.iter().zip(keep).filter_map(|(p, k)| k.then_some(*p)).collect())
}

impl MapElement {
    /// Checks an element: finite points, at least 2 for a polyline and 3 for a polygon.
    pub fn new(kind: MapElementKind, points: Vec<[f64; 2]>) -> Result<Self> {
        let min = if kind.is_polygon() { 3 } else { 2 };
        if points.len() < min {
            return Err(DganError::InvalidMap(format!("a {kind} needs at least {min} points, got {}", points.len())));
        }
        if points.iter().flatten().any(|v| !v.is_finite()) {
            return Err(DganError::InvalidMap(format!("a {kind} has NaN or infinite coordinates")));
        }
        if let Some(p) = points.iter().find(|p| p[0].abs().max(p[1].abs()) > crate::limits::MAX_COORDINATE_M) {
            return Err(DganError::InvalidMap(format!(
                "a {kind} has a vertex at ({}, {}) m, beyond ±{:e} m of the origin; maps are in metres",
                p[0],
                p[1],
                crate::limits::MAX_COORDINATE_M
            )));
        }
        let mut bbox = [f64::INFINITY, f64::INFINITY, f64::NEG_INFINITY, f64::NEG_INFINITY];
        for p in &points {
            bbox = [bbox[0].min(p[0]), bbox[1].min(p[1]), bbox[2].max(p[0]), bbox[3].max(p[1])];
        }
        let drawn = simplify(&points, DRAW_TOLERANCE_M);
        Ok(Self { kind, points, drawn, bbox })
    }

    /// Its kind.
    pub fn kind(&self) -> MapElementKind {
        self.kind
    }

    /// Its vertices, world metres.
    pub fn points(&self) -> &[[f64; 2]] {
        &self.points
    }

    /// The vertices it is drawn through: [`Self::points`] simplified to within [`DRAW_TOLERANCE_M`].
    pub fn drawn_points(&self) -> &[[f64; 2]] {
        &self.drawn
    }

    /// Axis-aligned bounds `[min_x, min_y, max_x, max_y]`.
    pub fn bbox(&self) -> [f64; 4] {
        self.bbox
    }
}

/// A semantic vector map: typed polylines and polygons in world metres.
#[derive(Debug, Clone, Default)]
pub struct VectorMap {
    elements: Vec<MapElement>,
    tiles: TileStore,
    features: FeatureStore,
}

impl VectorMap {
    /// A map of the given elements, kept in drawing order (regions under lines).
    pub fn new(mut elements: Vec<MapElement>) -> Self {
        elements.sort_by_key(|e| MapElementKind::ALL.iter().position(|k| *k == e.kind));
        Self { elements, tiles: TileStore::default(), features: FeatureStore::default() }
    }

    /// The elements, in drawing order.
    pub fn elements(&self) -> &[MapElement] {
        &self.elements
    }

    /// The tiles drawn of this map so far ([`crate::tiles`]), shared by every frame that holds it.
    pub fn tiles(&self) -> &TileStore {
        &self.tiles
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use ndarray::Array3;

    #[test]
    fn the_palette_holds_every_kind_once_in_drawing_order() {
        use MapElementKind::*;
        let every = [LaneCenterline, LaneLineDashed, LaneLineSolid, RoadEdge, Crosswalk, BikeLane, Obstacle];
        for kind in every {
            assert_eq!(PALETTE.iter().filter(|s| s.kind == kind).count(), 1, "{kind:?}");
            assert_eq!(kind.name().parse::<MapElementKind>().unwrap(), kind);
            assert_eq!(kind.is_polygon(), kind.style().width_m == 0.0, "{kind:?}");
        }
        let regions = PALETTE.iter().take_while(|s| s.polygon).count();
        assert!(PALETTE[regions..].iter().all(|s| !s.polygon), "regions are drawn before lines");
    }

    #[test]
    fn dense_lines_are_drawn_through_few_vertices_within_tolerance() {
        // A straight line sampled every 0.5 m keeps its two ends; a quarter circle of radius 10 m sampled every degree
        // keeps few vertices, none of the dropped ones farther than the tolerance from the kept outline.
        let straight: Vec<[f64; 2]> = (0..=100).map(|i| [i as f64 * 0.5, 3.0]).collect();
        assert_eq!(simplify(&straight, DRAW_TOLERANCE_M), vec![[0.0, 3.0], [50.0, 3.0]]);
        let arc: Vec<[f64; 2]> =
            (0..=90).map(|d| (d as f64).to_radians()).map(|a| [10.0 * a.cos(), 10.0 * a.sin()]).collect();
        let kept = simplify(&arc, DRAW_TOLERANCE_M);
        assert!(kept.len() < 30 && kept.len() > 5, "{} vertices", kept.len());
        for p in &arc {
            let near = kept.windows(2).any(|w| {
                let (a, b) = (w[0], w[1]);
                let (dx, dy) = (b[0] - a[0], b[1] - a[1]);
                let t = (((p[0] - a[0]) * dx + (p[1] - a[1]) * dy) / (dx * dx + dy * dy)).clamp(0.0, 1.0);
                (p[0] - a[0] - t * dx).hypot(p[1] - a[1] - t * dy) <= DRAW_TOLERANCE_M + 1e-12
            });
            assert!(near, "{p:?} strays from the simplified arc");
        }
        let e = MapElement::new(MapElementKind::LaneCenterline, straight.clone()).unwrap();
        assert_eq!(e.points().len(), 101, "the element keeps its own vertices");
        assert_eq!(e.drawn_points().len(), 2);
    }

    #[test]
    fn raster_rejects_bad_inputs() {
        let ident = [[1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0]];
        assert!(RasterMap::new(Array3::zeros((4, 4, 3)), ident).is_ok());
        assert!(matches!(RasterMap::new(Array3::zeros((4, 4, 1)), ident), Err(DganError::InvalidMap(_))));
        assert!(matches!(RasterMap::new(Array3::zeros((0, 4, 3)), ident), Err(DganError::InvalidMap(_))));
        let singular = [[1.0, 0.0, 0.0], [2.0, 0.0, 0.0], [0.0, 0.0, 1.0]];
        assert!(matches!(RasterMap::new(Array3::zeros((4, 4, 3)), singular), Err(DganError::InvalidMap(_))));
        let nan = [[f64::NAN, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0]];
        assert!(matches!(RasterMap::new(Array3::zeros((4, 4, 3)), nan), Err(DganError::InvalidMap(_))));
    }

    #[test]
    fn reads_images_from_files() {
        let path = crate::manifest_dir().join("../../python/dgan/data/scenes/zara1/rgb.jpg");
        let ident = [[1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0]];
        let m = RasterMap::from_file(&path, ident).unwrap();
        assert_eq!(m.image().dim(), (576, 720, 3));
        assert!(matches!(RasterMap::from_file("/nonexistent.png", ident), Err(DganError::InvalidMap(_))));
    }

    #[test]
    fn bilinear_sample_interpolates_between_centres() {
        let mut img = Array3::<u8>::zeros((1, 2, 3));
        img[[0, 1, 0]] = 200;
        let m = RasterMap::new(img, [[1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0]]).unwrap();
        assert_eq!(m.sample([0.0, 0.0])[0], 0.0);
        assert_eq!(m.sample([1.0, 0.0])[0], 200.0);
        assert!((m.sample([0.5, 0.0])[0] - 100.0).abs() < 1e-4);
        assert_eq!(m.sample([5.0, 0.0]), [0.0; 3]);
    }

    #[test]
    fn an_image_of_few_colours_samples_the_same_through_its_indexed_copy() {
        // Four colours in blocks, as a semantic mask: indexed; the same image sampled without the copy gives the
        // same bits at every point, inside, along the edges and outside.
        let colours = [[0u8, 0, 0], [255, 255, 255], [128, 64, 3], [7, 200, 90]];
        let image = Array3::from_shape_fn((37, 53, 3), |(r, c, k)| colours[(r / 5 + c / 7) % 4][k]);
        let h = [[1.7, 0.2, 3.0], [-0.1, -1.3, 40.0], [0.0, 0.0, 1.0]];
        let indexed = RasterMap::new(image.clone(), h).unwrap();
        let plain = RasterMap::new(image, h).unwrap();
        plain.palette.set(None).unwrap();
        for k in 0..20_000 {
            let uv = [(k as f64 * 0.0137).sin() * 30.0 + 26.0, (k as f64 * 0.0071).cos() * 22.0 + 18.0];
            assert_eq!(indexed.sample(uv).map(f32::to_bits), plain.sample(uv).map(f32::to_bits), "{uv:?}");
        }
        assert_eq!(indexed.palette.get().and_then(|p| p.as_ref()).map(|p| p.colours.len()), Some(4));
        // A photograph keeps no copy.
        let photo = Array3::from_shape_fn((8, 8, 3), |(r, c, k)| (r * 31 + c * 7 + k) as u8);
        let photo = RasterMap::new(photo, h).unwrap();
        photo.sample([3.0, 3.0]);
        assert!(photo.palette.get().is_some_and(Option::is_none));
    }

    #[test]
    fn an_affine_homography_projects_as_the_division_does() {
        // The same homography times 2 has last row (0, 0, 2): it takes the division, which by 2 is exact.
        let h = [[47.5, 0.3, 1.0], [-0.2, -41.9, 576.0], [0.0, 0.0, 1.0]];
        let doubled = h.map(|row| row.map(|v| 2.0 * v));
        let image = Array3::<u8>::zeros((4, 4, 3));
        let (affine, general) = (RasterMap::new(image.clone(), h).unwrap(), RasterMap::new(image, doubled).unwrap());
        assert!(affine.affine && !general.affine);
        for k in 0..1000 {
            let world = [(k as f64 * 0.37).sin() * 1e3, (k as f64 * 0.11).cos() * 37.0 + k as f64];
            assert_eq!(affine.project(world), general.project(world), "{world:?}");
        }
        let far = affine.project([f64::INFINITY, 0.0]).unwrap();
        assert_eq!(affine.sample(far), [0.0; 3]); // black, as a point the division refuses
    }

    #[test]
    fn elements_are_checked_and_ordered() {
        assert!(MapElement::new(MapElementKind::Crosswalk, vec![[0.0, 0.0], [1.0, 0.0]]).is_err());
        assert!(MapElement::new(MapElementKind::RoadEdge, vec![[0.0, 0.0], [f64::NAN, 0.0]]).is_err());
        let line = MapElement::new(MapElementKind::LaneCenterline, vec![[0.0, 0.0], [1.0, 0.0]]).unwrap();
        let poly = MapElement::new(MapElementKind::Crosswalk, vec![[0.0, 0.0], [1.0, 0.0], [1.0, 1.0]]).unwrap();
        let map = VectorMap::new(vec![line, poly]);
        assert_eq!(map.elements()[0].kind(), MapElementKind::Crosswalk);
        assert_eq!("road_edge".parse::<MapElementKind>().unwrap(), MapElementKind::RoadEdge);
        assert!("river".parse::<MapElementKind>().is_err());
    }

    #[test]
    fn simplification_work_is_bounded_on_a_zigzag_and_far_vertices_are_refused() {
        // A zigzag is Ramer–Douglas–Peucker's worst case: quadratic, 66 s for 10⁵ vertices before the bound.
        let zig: Vec<[f64; 2]> = (0..100_000).map(|i| [i as f64 * 0.01, f64::from(i % 2) * 0.2]).collect();
        let started = std::time::Instant::now();
        let e = MapElement::new(MapElementKind::LaneCenterline, zig.clone()).unwrap();
        assert!(started.elapsed().as_secs_f64() < 5.0, "{:?}", started.elapsed());
        assert!(e.drawn_points().len() > zig.len() * 9 / 10); // a 0.2 m zigzag cannot be drawn through few
        let far = vec![[0.0, 0.0], [1e30, 5.0]];
        let err = MapElement::new(MapElementKind::RoadEdge, far).unwrap_err();
        assert!(err.to_string().contains("beyond ±1e9 m"), "{err}");
    }

    #[test]
    fn exact_floor_matches_the_library() {
        for x in [-0.999, -0.5, -0.0, 0.0, 0.3, 1.0, 1.999_999_999, 12345.5, -1e-300, 4.0e15 + 0.5] {
            assert_eq!(floor_i64(x), x.floor() as i64, "{x}");
        }
    }
}
