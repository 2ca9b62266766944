//! A vector map drawn once, north-up, into square tiles that stay with the map ([`VectorMap::tiles`]), the agents'
//! boxes drawn once per call on copies of the tiles its crops read ([`Overlay`]), and each crop resampled from those
//! (`map.render = "tiles"`): the map's cost is paid once per tile, not once per agent and call, and the boxes' once
//! per tile, not once per crop.
//!
//! Tiles are drawn by the same canvas as the crops ([`crate::canvas`]) at half the crop's pixel size, lines no
//! narrower than one crop pixel, on a grid fixed in the world (tile `(i, j)` holds the world's tile pixels
//! `(row, col)` with `col ∈ [128 i, 128 i + 128)` and `row ∈ [128 j, 128 j + 128)`, the pixel `(row, col)` centred
//! at world `(col · r, −row · r)` for the tiles' resolution `r`): a tile is the same whichever crop or thread asked
//! for it first, so crops do not depend on the order of the agents, the calls or the threads.

use crate::canvas::{world_bounds, Canvas, UNIT};
use crate::error::{DganError, Result};
use crate::limits::share_jobs;
use crate::map::VectorMap;
use crate::spec::{MapRender, MapSpec};
use crate::state::TrafficState;
use crate::tile_store::TileKey;
use crate::transform::AgentPose;
use std::collections::HashMap;
use std::sync::Arc;

/// Tile side, pixels (a power of two: tile indices by shifts).
pub const TILE_PX: usize = 128;
const TILE_SHIFT: u32 = 7;
/// A tile pixel's column (row) within its tile: `c & MASK`.
const MASK: i64 = TILE_PX as i64 - 1;
/// Tile pixels per crop pixel along each axis.
pub const SUPERSAMPLE: f64 = 2.0;

/// The tiles' resolution for crops of `spec`, metres per pixel.
fn tile_resolution(spec: &MapSpec) -> f64 {
    spec.resolution_m / SUPERSAMPLE
}

/// The canvas of tile `(i, j)` at resolution `res` (north-up; its pixel `(row, col)` centred at the world's
/// `((128 i + col) · res, −(128 j + row) · res)`), blank.
fn tile_canvas(tile_spec: &MapSpec, i: i64, j: i64) -> Option<Canvas<'_>> {
    let side = TILE_PX as f64 * tile_spec.resolution_m;
    // Heading +y: the frame's forward is north (image up), its left is west (image left).
    let pose = AgentPose::new([i as f64 * side, -(j as f64) * side], std::f64::consts::FRAC_PI_2);
    let mut canvas = Canvas::new(tile_spec, pose)?;
    canvas.min_width_px = SUPERSAMPLE as f32;
    Some(canvas)
}

/// The specification of the tiles serving crops of `spec`.
fn tile_spec(spec: &MapSpec) -> MapSpec {
    MapSpec {
        height_px: TILE_PX,
        width_px: TILE_PX,
        resolution_m: tile_resolution(spec),
        agent_row: 0,
        agent_col: 0,
        draw_agents: false,
        optional: false,
        render: MapRender::Agent,
        classes: vec![],
        scene: None,
    }
}

/// A canvas's pixels as `TILE_PX² × 3` bytes of RGB.
fn rgb_of(canvas: &Canvas<'_>) -> Vec<u8> {
    let mut rgb = vec![0u8; TILE_PX * TILE_PX * 3];
    for (out, px) in rgb.chunks_exact_mut(3).zip(canvas.pixmap.data().chunks_exact(4)) {
        out.copy_from_slice(&px[..3]);
    }
    rgb
}

/// Tile `(i, j)` of `map` for crops of `spec`, `TILE_PX² × 3` bytes of RGB (row-major; black where nothing is
/// drawn), from the map's store or drawn now and kept there.
pub(crate) fn tile(map: &VectorMap, spec: &MapSpec, i: i64, j: i64) -> Arc<[u8]> {
    let res = tile_resolution(spec);
    let key = TileKey { resolution_bits: res.to_bits(), i, j };
    if let Some(t) = map.tiles().get(&key) {
        return t;
    }
    let tile_spec = tile_spec(spec);
    let rgb = match tile_canvas(&tile_spec, i, j) {
        Some(mut canvas) => {
            canvas.draw_vector(map);
            rgb_of(&canvas)
        }
        None => vec![0u8; TILE_PX * TILE_PX * 3],
    };
    map.tiles().insert(key, rgb.into())
}

/// The tile pixels `[c0, c1] × [r0, r1]` under a crop of world bounds `view` (one pixel more each side for the taps)
/// and the tiles `[i0, i1] × [j0, j1]` holding them.
fn span(view: [f64; 4], res: f64) -> ([i64; 4], [i64; 4]) {
    let (c0, c1) = ((view[0] / res).floor() as i64 - 1, (view[2] / res).ceil() as i64 + 1);
    let (r0, r1) = ((-view[3] / res).floor() as i64 - 1, (-view[1] / res).ceil() as i64 + 1);
    ([c0, c1, r0, r1], [c0 >> TILE_SHIFT, c1 >> TILE_SHIFT, r0 >> TILE_SHIFT, r1 >> TILE_SHIFT])
}

/// The tiles one call's crops read, the agents' boxes drawn on those that boxes reach (the map's kept tiles stay
/// without them): boxes are drawn once per tile rather than once per crop.
pub(crate) struct Overlay {
    tiles: HashMap<(i64, i64), Arc<[u8]>>,
    /// The same tiles laid side by side in one array of 2 × 2 means, when the frame's tiles are close enough together
    /// and few enough ([`Mosaic::new`]): each crop then reads it instead of copying its own patch and averaging it.
    mosaic: Option<Mosaic>,
}

/// Tile pixels a crop reads, as one row-major RGB array of `width` pixels a row whose pixel `(0, 0)` is the world's
/// tile pixel `(r_base, c_base)`: the pixels themselves, or (`averaged`) at each pixel the rounded mean of the 2 × 2
/// pixels from it rightwards and down, the value a crop pixel takes (one read instead of four).
struct Source<'a> {
    bytes: &'a [u8],
    width: usize,
    c_base: i64,
    r_base: i64,
    averaged: bool,
}

/// The tiles `[i0, i0 + across) × [j0, j0 + down)` in one array (black where no crop reads), as the rounded means of
/// each pixel's 2 × 2 block ([`Source::averaged`]; the last row and column, which no crop reads, left black).
struct Mosaic {
    bytes: Vec<u8>,
    i0: i64,
    j0: i64,
    across: usize,
    down: usize,
}

/// The largest mosaic, in tiles, as a multiple of the tiles the crops read: a frame spread over a wide area with
/// few tiles under its crops copies a patch per crop instead.
const MOSAIC_MAX_SPREAD: usize = 4;
/// The largest mosaic, in tiles (24 MB, built from as much again): a frame whose crops cover more copies a patch per
/// crop instead, so that the memory of a call stays bounded whatever the frame's extent.
const MOSAIC_MAX_TILES: usize = 512;
/// The fewest crops per tile for which a mosaic pays: below, averaging whole tiles costs more than it saves (`hdmap`
/// on one thread: 8 crops over 12 tiles 0.25 ms of crops with per-crop patches, 0.33 with a mosaic; 32 over 17, 0.87
/// against 0.83; 64 over 21, 1.71 against 1.40; 256 over 33, 6.34 against 4.43).
const MOSAIC_MIN_CROPS_PER_TILE: f64 = 1.5;
/// Mosaic rows a thread averages at a time.
const ROWS_PER_JOB: usize = 64;

impl Mosaic {
    /// The tiles `tiles` in one array, written on up to `threads` threads a band of tiles at a time, then averaged in
    /// bands of [`ROWS_PER_JOB`] rows; None when they spread too far ([`MOSAIC_MAX_SPREAD`]), would take more than
    /// [`MOSAIC_MAX_TILES`] or serve too few of the call's `crops` ([`MOSAIC_MIN_CROPS_PER_TILE`]).
    fn new(tiles: &HashMap<(i64, i64), Arc<[u8]>>, crops: usize, threads: usize) -> Result<Option<Self>> {
        if (crops as f64) < MOSAIC_MIN_CROPS_PER_TILE * tiles.len() as f64 {
            return Ok(None);
        }
        let Some(i0) = tiles.keys().map(|k| k.0).min() else { return Ok(None) };
        let (i1, j0, j1) = (
            tiles.keys().map(|k| k.0).max().unwrap_or(i0),
            tiles.keys().map(|k| k.1).min().unwrap_or(0),
            tiles.keys().map(|k| k.1).max().unwrap_or(0),
        );
        let (across, down) = ((i1 - i0 + 1) as usize, (j1 - j0 + 1) as usize);
        let cells = across.saturating_mul(down);
        if cells > MOSAIC_MAX_SPREAD * tiles.len() || cells > MOSAIC_MAX_TILES {
            return Ok(None);
        }
        let band = TILE_PX * across * TILE_PX * 3;
        let mut bytes = vec![0u8; band * down];
        let row_bytes = TILE_PX * 3;
        let fill = |(j, out): (usize, &mut [u8])| -> Result<()> {
            for i in 0..across {
                let Some(t) = tiles.get(&(i0 + i as i64, j0 + j as i64)) else { continue };
                for (r, src) in t.chunks_exact(row_bytes).enumerate() {
                    let at = (r * across + i) * row_bytes;
                    out[at..at + row_bytes].copy_from_slice(src);
                }
            }
            Ok(())
        };
        let jobs: Vec<(usize, &mut [u8])> = bytes.chunks_mut(band).enumerate().collect();
        share_jobs(jobs, threads, fill, || DganError::InvalidSpec("a tile-copying thread panicked".into()))?;
        // Each row's 2 × 2 means from it and the next, a band of rows at a time: the taps every crop pixel reads,
        // summed once for the call in order through memory rather than per crop pixel along a rotated walk.
        let stride = across * row_bytes;
        let rows = TILE_PX * down;
        let mut averaged = vec![0u8; bytes.len()];
        let mean = |(first, out): (usize, &mut [u8])| -> Result<()> {
            for (k, dst) in out.chunks_exact_mut(stride).enumerate() {
                let r = first + k;
                if r + 1 >= rows {
                    break;
                }
                let (top, bottom) = (&bytes[r * stride..(r + 1) * stride], &bytes[(r + 1) * stride..(r + 2) * stride]);
                let taps = top.iter().zip(&top[3..]).zip(bottom.iter().zip(&bottom[3..]));
                for (d, ((a, b), (c, e))) in dst.iter_mut().zip(taps) {
                    let sum = u16::from(*a) + u16::from(*b) + u16::from(*c) + u16::from(*e);
                    *d = ((sum + 2) >> 2) as u8;
                }
            }
            Ok(())
        };
        let jobs: Vec<(usize, &mut [u8])> =
            averaged.chunks_mut(stride * ROWS_PER_JOB).enumerate().map(|(k, c)| (k * ROWS_PER_JOB, c)).collect();
        share_jobs(jobs, threads, mean, || DganError::InvalidSpec("a tile-averaging thread panicked".into()))?;
        Ok(Some(Self { bytes: averaged, i0, j0, across, down }))
    }

    /// The mosaic as a source, if it holds every tile pixel of `[c0, c1] × [r0, r1]`.
    fn holding(&self, [c0, c1, r0, r1]: [i64; 4]) -> Option<Source<'_>> {
        let (c_base, r_base) = (self.i0 * TILE_PX as i64, self.j0 * TILE_PX as i64);
        let (width, height) = ((self.across * TILE_PX) as i64, (self.down * TILE_PX) as i64);
        let inside = c0 >= c_base && c1 < c_base + width && r0 >= r_base && r1 < r_base + height;
        inside.then_some(Source { bytes: &self.bytes, width: width as usize, c_base, r_base, averaged: true })
    }
}

impl Overlay {
    /// Every tile under the crops of world bounds `views`, from `map`'s tiles with the boxes of `boxes(bounds)` (the
    /// agents whose box may reach world bounds `bounds`) drawn on, built on up to `threads` threads.
    pub(crate) fn new<'s, F>(
        map: &VectorMap,
        spec: &MapSpec,
        views: &[[f64; 4]],
        boxes: F,
        threads: usize,
    ) -> Result<Self>
    where
        F: Fn([f64; 4]) -> Vec<&'s TrafficState> + Sync,
    {
        let res = tile_resolution(spec);
        let mut wanted: Vec<(i64, i64)> = views
            .iter()
            .flat_map(|v| {
                let [i0, i1, j0, j1] = span(*v, res).1;
                (j0..=j1).flat_map(move |j| (i0..=i1).map(move |i| (i, j)))
            })
            .collect();
        wanted.sort_unstable();
        wanted.dedup();
        let tile_spec = tile_spec(spec);
        let one = |&(i, j): &(i64, i64)| -> ((i64, i64), Arc<[u8]>) {
            let base = tile(map, spec, i, j);
            let side = TILE_PX as f64 * res;
            let half = res / 2.0;
            let bounds = [
                i as f64 * side - half,
                -((j + 1) as f64) * side + half,
                (i + 1) as f64 * side - half,
                -(j as f64) * side + half,
            ];
            let near = boxes(bounds);
            let Some(mut canvas) = (!near.is_empty()).then(|| tile_canvas(&tile_spec, i, j)).flatten() else {
                return ((i, j), base);
            };
            for (px, rgb) in canvas.pixmap.data_mut().chunks_exact_mut(4).zip(base.chunks_exact(3)) {
                px[..3].copy_from_slice(rgb);
                px[3] = 255;
            }
            canvas.draw_boxes(near.into_iter());
            ((i, j), rgb_of(&canvas).into())
        };
        let tiles = if threads <= 1 || wanted.len() < 2 {
            wanted.iter().map(one).collect()
        } else {
            // One tile at a time, taken by each thread as it finishes one: tiles under many boxes cost many times
            // those under none, which contiguous shares left on one thread.
            let mut drawn: Vec<Option<Arc<[u8]>>> = vec![None; wanted.len()];
            let jobs: Vec<_> = wanted.iter().zip(drawn.iter_mut()).collect();
            let draw = |(key, slot): (&(i64, i64), &mut Option<Arc<[u8]>>)| {
                *slot = Some(one(key).1);
                Ok(())
            };
            share_jobs(jobs, threads, draw, || DganError::InvalidSpec("a tile-drawing thread panicked".into()))?;
            wanted.iter().zip(drawn).filter_map(|(key, tile)| tile.map(|t| (*key, t))).collect()
        };
        let mosaic = Mosaic::new(&tiles, views.len(), threads)?;
        Ok(Self { tiles, mosaic })
    }

    /// Whether the crops read the overlay's tiles from one mosaic.
    #[cfg(test)]
    pub(crate) fn has_mosaic(&self) -> bool {
        self.mosaic.is_some()
    }

    /// Tile `(i, j)`, if the overlay holds it.
    pub(crate) fn get(&self, i: i64, j: i64) -> Option<Arc<[u8]>> {
        self.tiles.get(&(i, j)).cloned()
    }

    /// [`resample_chw`] from the overlay's tiles (from its mosaic when that holds the crop; `map`'s own tiles for
    /// any the overlay lacks): the same values either way.
    pub(crate) fn resample_chw(&self, map: &VectorMap, spec: &MapSpec, pose: &AgentPose, out: &mut [f32]) {
        let res = tile_resolution(spec);
        let (px, _) = span(world_bounds(spec, pose), res);
        match self.mosaic.as_ref().and_then(|m| m.holding(px)) {
            Some(source) => sample_chw(spec, pose, px, &source, out),
            None => resample_chw(spec, pose, |i, j| self.get(i, j).unwrap_or_else(|| tile(map, spec, i, j)), out),
        }
    }
}

/// Writes the crop of the agent at `pose` into `out` (`(3, H, W)` channel-major, in [0, 1], every value written) from
/// the tiles `fetch(i, j)` gives: each crop pixel the mean of the 2 × 2 tile pixels around its centre, opaque.
pub(crate) fn resample_chw(spec: &MapSpec, pose: &AgentPose, fetch: impl Fn(i64, i64) -> Arc<[u8]>, out: &mut [f32]) {
    let res = tile_resolution(spec);
    // The tiles under the crop (its world bounds in tile pixels, one pixel more each side for the taps).
    let ([c0, c1, r0, r1], [i0, i1, j0, j1]) = span(world_bounds(spec, pose), res);
    let across = (i1 - i0 + 1) as usize;
    let grid: Vec<Arc<[u8]>> =
        (j0..=j1).flat_map(|j| (i0..=i1).map(move |i| (i, j))).map(|(i, j)| fetch(i, j)).collect();
    // The crop's bounds as one patch of tile pixels, rows (r0..=r1) by columns (c0..=c1), copied row by row from the
    // tiles (every byte written, none zeroed first): the taps below then read one array, whatever tile they fall in.
    let (ph, pw) = ((r1 - r0 + 1) as usize, (c1 - c0 + 1) as usize);
    let mut patch: Vec<u8> = Vec::with_capacity(ph * pw * 3);
    for r in r0..=r1 {
        let (j, tr) = (r >> TILE_SHIFT, (r & MASK) as usize);
        let mut c = c0;
        while c <= c1 {
            let (i, tc) = (c >> TILE_SHIFT, (c & MASK) as usize);
            let n = (TILE_PX - tc).min((c1 - c + 1) as usize);
            let t = &grid[(j - j0) as usize * across + (i - i0) as usize];
            let from = (tr * TILE_PX + tc) * 3;
            patch.extend_from_slice(&t[from..from + n * 3]);
            c += n as i64;
        }
    }
    let source = Source { bytes: &patch, width: pw, c_base: c0, r_base: r0, averaged: false };
    sample_chw(spec, pose, [c0, c1, r0, r1], &source, out);
}

/// The crop of the agent at `pose` into `out` from `source`, which holds its tile pixels `[c0, c1] × [r0, r1]`
/// ([`span`]): each crop pixel the mean of the 2 × 2 tile pixels around its centre.
fn sample_chw(spec: &MapSpec, pose: &AgentPose, [c0, c1, r0, r1]: [i64; 4], source: &Source<'_>, out: &mut [f32]) {
    let res = tile_resolution(spec);
    let (ph, pw) = ((r1 - r0 + 1) as usize, (c1 - c0 + 1) as usize);
    // Where the crop's patch starts in the source, and the source's rows.
    let (first, stride) =
        (((r0 - source.r_base) as usize * source.width + (c0 - source.c_base) as usize) * 3, source.width * 3);
    let patch = &source.bytes[first..];
    // World position of pixel (0, 0) and its steps along a row and down a column, in patch pixels.
    let at = |row: usize, col: usize| {
        let w = pose.to_world(spec.pixel_to_local(row, col));
        [w[0] / res - c0 as f64, -w[1] / res - r0 as f64]
    };
    let (o, right, down) = (at(0, 0), at(0, 1), at(1, 0));
    let (dc, dr) = ([right[0] - o[0], right[1] - o[1]], [down[0] - o[0], down[1] - o[1]]);
    let (w, plane) = (spec.width_px, spec.width_px * spec.height_px);
    // Within the patch by construction (its bounds hold every pixel centre, one pixel to spare); clamped so that a
    // rounding at its edge cannot read outside it.
    let (last_c, last_r) = (pw as f64 - 2.0, ph as f64 - 2.0);
    let (red, rest) = out.split_at_mut(plane);
    let (green, blue) = rest.split_at_mut(plane);
    let rows = red.chunks_exact_mut(w).zip(green.chunks_exact_mut(w)).zip(blue.chunks_exact_mut(w));
    for (row, ((red, green), blue)) in rows.enumerate() {
        let fr = row as f64;
        let (mut gc, mut gr) = (o[0] + fr * dr[0], o[1] + fr * dr[1]);
        for ((r, g), b) in red.iter_mut().zip(green.iter_mut()).zip(blue.iter_mut()) {
            // The 2 × 2 tile pixels around the crop pixel's centre (non-negative: truncation is the floor), averaged:
            // a box one crop pixel wide, as a crop drawn per agent covers its pixels.
            let (cc, rr) = (gc.clamp(0.0, last_c) as usize, gr.clamp(0.0, last_r) as usize);
            let k = rr * stride + cc * 3;
            if source.averaged {
                let px = &patch[k..k + 3];
                (*r, *g, *b) = (UNIT[usize::from(px[0])], UNIT[usize::from(px[1])], UNIT[usize::from(px[2])]);
            } else {
                let (top, bottom) = (six(&patch[k..k + 6]), six(&patch[k + stride..k + stride + 6]));
                let mean = |ch: usize| {
                    let sum =
                        u16::from(top[ch]) + u16::from(top[ch + 3]) + u16::from(bottom[ch]) + u16::from(bottom[ch + 3]);
                    UNIT[usize::from((sum + 2) >> 2)]
                };
                (*r, *g, *b) = (mean(0), mean(1), mean(2));
            }
            gc += dc[0];
            gr += dc[1];
        }
    }
}

/// Six bytes of a slice of six.
#[inline]
fn six(s: &[u8]) -> [u8; 6] {
    let mut out = [0u8; 6];
    out.copy_from_slice(s);
    out
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_mosaic_stays_within_its_bounds() {
        let blank: Arc<[u8]> = vec![0u8; TILE_PX * TILE_PX * 3].into();
        let grid = |across: i64, down: i64| -> HashMap<(i64, i64), Arc<[u8]>> {
            (0..across).flat_map(|i| (0..down).map(move |j| (i, j))).map(|k| (k, blank.clone())).collect()
        };
        // A 4 × 2 block of tiles: one mosaic of eight tiles, rows of 4 × 128 pixels.
        let m = Mosaic::new(&grid(4, 2), 12, 2).unwrap().unwrap();
        assert_eq!((m.across, m.down, m.bytes.len()), (4, 2, 8 * TILE_PX * TILE_PX * 3));
        // Two tiles far apart: their bounding rectangle is mostly empty, so no mosaic.
        let apart: HashMap<_, _> = [((0, 0), blank.clone()), ((40, 0), blank.clone())].into_iter().collect();
        assert!(Mosaic::new(&apart, 12, 1).unwrap().is_none());
        // More tiles than the cap, however close: no mosaic either.
        assert!(Mosaic::new(&grid(32, 17), 1000, 1).unwrap().is_none());
        assert!(Mosaic::new(&HashMap::new(), 12, 1).unwrap().is_none());
        // Too few crops for its eight tiles: each copies its own patch.
        assert!(Mosaic::new(&grid(4, 2), 11, 1).unwrap().is_none());
    }
}
