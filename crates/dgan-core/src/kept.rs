//! A scene model's map features kept with the map (contract 13, `map.scene.tile_px`): what depends only on the map
//! is computed once per map and model and reused by every later call.
//!
//! The features lie on a grid fixed in the world: global pixel `(k, l)` of the map at the crops' resolution `r` has
//! its centre at world `(k · r, −l · r)` (north up), and the network's features, `stride` pixels apart, are cut into
//! square tiles of `tile_px` pixels (`t = tile_px / stride` features a side). Tile `(i, j)` is drawn as a north-up
//! raster of its pixels and `halo_px` more each side ([`tile_raster`]) and the network keeps its features without the
//! halo's, the ones a raster without edges gives (the halo at least the CNN's reach). The network then reads each
//! agent's crop blocks' centres ([`crate::scene`]) bilinearly from a table of rows: the tiles kept from earlier calls
//! (input `map_rows`) and those this call computes (output `map_features`), four rows and weights per block centre
//! (`map_index`, `map_weight`), `grid_sample`'s reading (`align_corners = false`) of a raster without edges.

use crate::error::{DganError, Result};
use crate::frame::Frame;
use crate::map::SceneMap;
use crate::scene::{block_centres, scene_raster_of};
use crate::spec::{MapSpec, SceneSpec};
use crate::state::TrafficState;
use crate::tile_store::FeatureKey;
use crate::transform::AgentPose;
use ndarray::{Array2, Array4, Axis};
use std::collections::HashMap;
use std::f64::consts::FRAC_PI_2;
use std::sync::Arc;

/// The most tiles one call may compute (a frame spread wider is refused; each holds `tile_raster_px²` pixels).
pub const MAX_NEW_TILES: usize = 1024;

/// A tile this call computes, and where its features are kept once computed (None: nowhere, as
/// [`crate::preprocess::preprocess`] without a predictor gives them).
#[derive(Debug, Clone)]
pub struct NewTile {
    /// The tile on the world's grid, `(i, j)`.
    pub at: (i64, i64),
    /// The map that keeps it and its key there.
    pub keep: Option<(Arc<SceneMap>, FeatureKey)>,
}

/// A call's reading of kept features: blocks of `rows` rows each (a tile's `t²` features, or a blank block for a
/// frame without a map), the kept ones first and then the ones the call computes, and every agent's four rows and
/// weights per block centre into them.
#[derive(Debug, Clone)]
pub struct KeptReads {
    /// Rows per block (`t²`).
    pub rows: usize,
    /// The features' channels.
    pub channels: usize,
    /// The blocks of each agent's crop, `(rows, columns)`.
    pub grid: (usize, usize),
    /// The kept blocks (`rows · channels` each, row-major).
    pub kept: Vec<Arc<[f32]>>,
    /// The tiles the call computes, after the kept blocks, in the order of the `map` rasters.
    pub new: Vec<NewTile>,
    /// `(N, P · 4)` each agent's rows of the table, P its crop's blocks.
    pub index: Array2<i64>,
    /// `(N, P · 4)` their bilinear weights.
    pub weight: Array2<f32>,
}

impl KeptReads {
    /// The kept blocks as one `(K · rows, channels)` table (the input `map_rows`).
    pub fn table(&self) -> Array2<f32> {
        let mut out = Array2::<f32>::zeros((self.kept.len() * self.rows, self.channels));
        if let Some(flat) = out.as_slice_mut() {
            for (b, block) in self.kept.iter().enumerate() {
                flat[b * block.len()..(b + 1) * block.len()].copy_from_slice(block);
            }
        }
        out
    }

    /// Several calls' reads as one: every kept block first (in order), then every new tile (a tile of the same map
    /// and key computed once), each part's agents after the ones before; `rasters` the parts' `map` inputs.
    pub fn join(parts: &[(&KeptReads, &Array4<f32>)]) -> Result<(KeptReads, Array4<f32>)> {
        let first = parts.first().ok_or_else(|| DganError::InvalidSpec("no kept reads to join".into()))?.0;
        let (rows, channels, grid) = (first.rows, first.channels, first.grid);
        if parts.iter().any(|(p, _)| (p.rows, p.channels, p.grid) != (rows, channels, grid)) {
            return Err(DganError::InvalidSpec("cannot join kept reads of other tiles".into()));
        }
        let kept: Vec<Arc<[f32]>> = parts.iter().flat_map(|(p, _)| p.kept.iter().cloned()).collect();
        let (mut new, mut keep_new, mut seen) = (vec![], vec![], HashMap::new());
        // Each part's block → the joined block.
        let mut maps: Vec<Vec<usize>> = vec![];
        let mut kept_base = 0;
        for (p, _) in parts {
            let mut map: Vec<usize> = (kept_base..kept_base + p.kept.len()).collect();
            for (t, tile) in p.new.iter().enumerate() {
                let key = tile.keep.as_ref().map(|(m, k)| (Arc::as_ptr(m) as usize, *k));
                let at = match key.and_then(|k| seen.get(&k).copied()) {
                    Some(at) => at,
                    None => {
                        new.push(tile.clone());
                        keep_new.push((maps.len(), t));
                        if let Some(k) = key {
                            seen.insert(k, new.len() - 1);
                        }
                        new.len() - 1
                    }
                };
                map.push(kept.len() + at);
            }
            kept_base += p.kept.len();
            maps.push(map);
        }
        let raster_views: Vec<_> =
            keep_new.iter().map(|&(part, t)| parts[part].1.index_axis(Axis(0), t).insert_axis(Axis(0))).collect();
        let side = parts[0].1.dim().2;
        let rasters = if raster_views.is_empty() {
            Array4::zeros((0, 3, side, side))
        } else {
            ndarray::concatenate(Axis(0), &raster_views)
                .map_err(|e| DganError::InvalidSpec(format!("cannot join the tiles' rasters: {e}")))?
        };
        let index_parts: Vec<Array2<i64>> =
            parts.iter().zip(&maps).map(|((p, _), map)| p.index.mapv(|v| remap(v, rows, map))).collect();
        let views: Vec<_> = index_parts.iter().map(|a| a.view()).collect();
        let index = ndarray::concatenate(Axis(0), &views).map_err(|e| DganError::InvalidSpec(e.to_string()))?;
        let wviews: Vec<_> = parts.iter().map(|(p, _)| p.weight.view()).collect();
        let weight = ndarray::concatenate(Axis(0), &wviews).map_err(|e| DganError::InvalidSpec(e.to_string()))?;
        Ok((KeptReads { rows, channels, grid, kept, new, index, weight }, rasters))
    }

    /// The reads of the agents `rows` alone, with the blocks they read (in their order) and those blocks' rasters
    /// among `rasters`.
    pub fn take(&self, rasters: &Array4<f32>, agents: &[usize]) -> (KeptReads, Array4<f32>) {
        let index = self.index.select(Axis(0), agents);
        let mut used: Vec<usize> = index.iter().map(|&v| v as usize / self.rows.max(1)).collect();
        used.sort_unstable();
        used.dedup();
        let mut map = vec![0usize; self.kept.len() + self.new.len()];
        for (k, &b) in used.iter().enumerate() {
            map[b] = k;
        }
        let kept = used.iter().filter(|&&b| b < self.kept.len()).map(|&b| self.kept[b].clone()).collect();
        let new_tiles: Vec<usize> =
            used.iter().filter(|&&b| b >= self.kept.len()).map(|&b| b - self.kept.len()).collect();
        let reads = KeptReads {
            rows: self.rows,
            channels: self.channels,
            grid: self.grid,
            kept,
            new: new_tiles.iter().map(|&t| self.new[t].clone()).collect(),
            index: index.mapv(|v| remap(v, self.rows, &map)),
            weight: self.weight.select(Axis(0), agents),
        };
        (reads, rasters.select(Axis(0), &new_tiles))
    }

    /// Each agent's reading of the features `(N, channels, gh, gw)` (the input `map_patches`): for every block
    /// centre the weighted sum of its four rows, read from the kept blocks and then `new` (`(T · rows, channels)`, the
    /// tiles this call computed, the output `map_features` of its first run; None where it computed none).
    pub fn patches(&self, new: Option<ndarray::ArrayView2<'_, f32>>) -> Result<Array4<f32>> {
        let c = self.channels;
        let new_rows = new.as_ref().map_or(0, |n| n.nrows());
        if new_rows != self.new.len() * self.rows || new.as_ref().is_some_and(|n| n.ncols() != c) {
            return Err(DganError::Inference(format!(
                "map_features has {new_rows} rows for {} new tiles of {} rows and {c} channels",
                self.new.len(),
                self.rows
            )));
        }
        let new_flat = new.as_ref().map(|n| n.as_standard_layout());
        let mut blocks: Vec<&[f32]> = self.kept.iter().map(|b| &b[..]).collect();
        if let Some(flat) = new_flat.as_ref().and_then(|f| f.as_slice()) {
            blocks.extend(flat.chunks(self.rows * c));
        }
        read_blocks(&blocks, self.rows, c, &self.index, &self.weight, self.grid)
    }

    /// Keeps the features this call computed (`(T · rows, channels)`, the output `map_features`) with their maps.
    pub fn keep(&self, features: ndarray::ArrayView2<'_, f32>) -> Result<()> {
        if features.dim() != (self.new.len() * self.rows, self.channels) {
            return Err(DganError::Inference(format!(
                "map_features has shape {:?}, expected ({}, {}) for {} new tiles",
                features.dim(),
                self.new.len() * self.rows,
                self.channels,
                self.new.len()
            )));
        }
        for (t, tile) in self.new.iter().enumerate() {
            if let Some((map, key)) = &tile.keep {
                let block = features.slice(ndarray::s![t * self.rows..(t + 1) * self.rows, ..]);
                map.features().insert(*key, block.iter().copied().collect::<Vec<f32>>().into());
            }
        }
        Ok(())
    }
}

/// `(N, C, gh, gw)`: for every agent and block centre the weighted sum of its four rows (`index`, `weight`:
/// `(N, gh · gw · 4)`) of a table `(R, C)` (the rows of a call's kept and computed tiles, in that order):
/// [`KeptReads::patches`] of a table in one piece, as training and the research pipeline hold it.
pub fn read_rows(
    table: ndarray::ArrayView2<'_, f32>,
    index: &Array2<i64>,
    weight: &Array2<f32>,
    grid: (usize, usize),
) -> Result<Array4<f32>> {
    let table = table.as_standard_layout();
    let flat = table.as_slice().ok_or_else(|| DganError::InvalidSpec("the table is not contiguous".into()))?;
    let (rows, c) = table.dim();
    read_blocks(&[flat], rows.max(1), c, index, weight, grid)
}

/// [`read_rows`] of a table in blocks of `rows` rows of `c` channels each.
fn read_blocks(
    blocks: &[&[f32]],
    rows: usize,
    c: usize,
    index: &Array2<i64>,
    weight: &Array2<f32>,
    grid: (usize, usize),
) -> Result<Array4<f32>> {
    let (n, p4) = index.dim();
    let (gh, gw) = grid;
    if p4 != gh * gw * 4 || weight.dim() != (n, p4) {
        return Err(DganError::InvalidSpec(format!(
            "map reads of shape {:?} and weights {:?} for {gh} × {gw} blocks of four rows",
            index.dim(),
            weight.dim()
        )));
    }
    let mut out = Array4::<f32>::zeros((n, c, gh, gw));
    let total = blocks.iter().map(|b| b.len() / c.max(1)).sum::<usize>();
    let (index, weight) = (index.as_standard_layout(), weight.as_standard_layout());
    let (idx_all, w_all) = match (index.as_slice(), weight.as_slice()) {
        (Some(i), Some(w)) => (i, w),
        _ => return Err(DganError::InvalidSpec("map reads are not contiguous".into())),
    };
    let points = gh * gw;
    // Each block centre's four rows summed into `acc` (one vector operation a row), then laid out by channel.
    let mut acc = vec![0.0f32; c];
    for (a, mut patch) in out.outer_iter_mut().enumerate() {
        let patch = patch.as_slice_mut().ok_or_else(|| DganError::InvalidSpec("patch not contiguous".into()))?;
        let reads = &idx_all[a * p4..(a + 1) * p4];
        let weights = &w_all[a * p4..(a + 1) * p4];
        for p in 0..points {
            acc.fill(0.0);
            for k in p * 4..p * 4 + 4 {
                let i = usize::try_from(reads[k]).ok().filter(|i| *i < total).ok_or_else(|| {
                    DganError::InvalidSpec(format!("a map read's row {} is outside the table's {total} rows", reads[k]))
                })?;
                let (b, r) = (i / rows, i % rows);
                let row = blocks
                    .get(b)
                    .and_then(|blk| blk.get(r * c..(r + 1) * c))
                    .ok_or_else(|| DganError::InvalidSpec(format!("a map read's row {i} is outside its block")))?;
                let wt = weights[k];
                for (s, v) in acc.iter_mut().zip(row) {
                    *s += wt * v;
                }
            }
            for (ch, v) in acc.iter().enumerate() {
                patch[ch * points + p] = *v;
            }
        }
    }
    Ok(out)
}

/// Row `v` of a table of blocks of `rows` rows, its block renumbered by `map`.
fn remap(v: i64, rows: usize, map: &[usize]) -> i64 {
    let (b, r) = (v as usize / rows.max(1), v as usize % rows.max(1));
    (map.get(b).copied().unwrap_or(0) * rows + r) as i64
}

/// The north-up raster of tile `(i, j)` and its halo, `(3, P, P)` with `P = tile_px + 2 · halo_px`: the map drawn or
/// resampled as into a crop (no agents' boxes).
pub fn tile_raster(frame: &Frame, crop: &MapSpec, scene: SceneSpec, at: (i64, i64)) -> Result<ndarray::Array3<f32>> {
    let side = scene.tile_raster_px();
    scene_raster_of(frame, &[], crop, side, tile_pose(crop, scene, at))
}

/// The pose of tile `at`'s raster: north up, its middle pixel (of an even side, the one right of and below the
/// middle) at that pixel's place on the world's grid.
pub fn tile_pose(crop: &MapSpec, scene: SceneSpec, at: (i64, i64)) -> AgentPose {
    let (t, h, mid) = (scene.tile_px as i64, scene.halo_px as i64, (scene.tile_raster_px() / 2) as i64);
    let r = crop.resolution_m;
    AgentPose::new([(at.0 * t - h + mid) as f64 * r, -((at.1 * t - h + mid) as f64) * r], FRAC_PI_2)
}

/// Where a world point reads the features: its four corners `(column, row)` on the global feature grid with their
/// bilinear weights (`grid_sample`'s reading of a raster without edges, `align_corners = false`).
pub fn corners(world: [f64; 2], resolution_m: f64, stride: usize) -> [((i64, i64), f32); 4] {
    let s = stride as f64;
    // Pixel coordinates with edges at integers, then feature coordinates with centres at integers.
    let u = (world[0] / resolution_m + 0.5) / s - 0.5;
    let v = (-world[1] / resolution_m + 0.5) / s - 0.5;
    let (u0, v0) = (u.floor(), v.floor());
    let (du, dv) = (u - u0, v - v0);
    let (c, r) = (u0 as i64, v0 as i64);
    [
        ((c, r), ((1.0 - du) * (1.0 - dv)) as f32),
        ((c + 1, r), (du * (1.0 - dv)) as f32),
        ((c, r + 1), ((1.0 - du) * dv) as f32),
        ((c + 1, r + 1), (du * dv) as f32),
    ]
}

/// A frame's kept reads under a scene model with kept features, and the rasters `(T, 3, P, P)` of the tiles this
/// call computes: for a predictor (`model` its number) the tiles its earlier calls kept with the frame's map are read
/// from there; without one (`model` None), every tile the agents read is computed. A frame without a map reads one
/// blank block with zero weights (its agents' `map_present` is 0).
pub fn kept_inputs(
    frame: &Frame,
    states: &[TrafficState],
    crop: &MapSpec,
    scene: SceneSpec,
    model: Option<u64>,
) -> Result<(KeptReads, Array4<f32>)> {
    let t = scene.tile_features() as i64;
    let rows = (t * t) as usize;
    let side = scene.tile_raster_px();
    let grid = (crop.height_px.div_ceil(scene.stride), crop.width_px.div_ceil(scene.stride));
    let points = grid.0 * grid.1;
    let n = states.len();
    let mut index = Array2::<i64>::zeros((n, points * 4));
    let mut weight = Array2::<f32>::zeros((n, points * 4));
    let Some(map) = frame.shared_map() else {
        let blank: Arc<[f32]> = vec![0.0; rows * scene.channels].into();
        let reads = KeptReads { rows, channels: scene.channels, grid, kept: vec![blank], new: vec![], index, weight };
        return Ok((reads, Array4::zeros((0, 3, side, side))));
    };
    let weights = weight.as_slice_mut().ok_or_else(|| DganError::InvalidSpec("weights are not contiguous".into()))?;
    let (order, local) = corner_reads(states, crop, scene, points, weights);
    let (kept, new, block) = kept_then_new(&order, map, model, rows * scene.channels);
    if new.len() > MAX_NEW_TILES {
        return Err(DganError::SceneTooLarge(format!(
            "the agents read {} tiles of the map not yet computed, above {MAX_NEW_TILES} in one call; predict fewer \
             agents at once, or agents closer together",
            new.len()
        )));
    }
    for (slot, &(tile, row)) in index.iter_mut().zip(&local) {
        *slot = (block[tile] * rows) as i64 + row;
    }
    let mut rasters = Array4::<f32>::zeros((new.len(), 3, side, side));
    for (k, tile) in new.iter().enumerate() {
        rasters.index_axis_mut(Axis(0), k).assign(&tile_raster(frame, crop, scene, tile.at)?);
    }
    Ok((KeptReads { rows, channels: scene.channels, grid, kept, new, index, weight }, rasters))
}

/// The tiles an agent's corners fall in (in order of first use) and each corner's (tile's place there, row).
type CornerReads = (Vec<(i64, i64)>, Vec<(usize, i64)>);

/// Every agent's four feature corners per block centre of its crop: the tiles they fall in, in order of first use,
/// each corner's (tile's place in that order, row in the tile), and their bilinear weights written into `weights`
/// (`N · points · 4`).
fn corner_reads(
    states: &[TrafficState],
    crop: &MapSpec,
    scene: SceneSpec,
    points: usize,
    weights: &mut [f32],
) -> CornerReads {
    let t = scene.tile_features() as i64;
    let mut tiles: HashMap<(i64, i64), usize> = HashMap::new();
    let mut order: Vec<(i64, i64)> = vec![];
    let mut local: Vec<(usize, i64)> = Vec::with_capacity(states.len() * points * 4);
    let mut last: Option<((i64, i64), usize)> = None;
    let mut tile_of = |at: (i64, i64)| -> usize {
        // Neighbouring block centres mostly share a tile: the last one found is tried first.
        match last {
            Some((a, k)) if a == at => k,
            _ => {
                let k = *tiles.entry(at).or_insert_with(|| {
                    order.push(at);
                    order.len() - 1
                });
                last = Some((at, k));
                k
            }
        }
    };
    for (a, s) in states.iter().enumerate() {
        let pose = s.pose();
        for (p, world) in block_centres(&pose, crop, scene.stride).enumerate() {
            let four = corners(world, crop.resolution_m, scene.stride);
            let ((u, v), _) = four[0];
            let (lu, lv) = (u.rem_euclid(t), v.rem_euclid(t));
            if lu + 1 < t && lv + 1 < t {
                // All four corners in the first one's tile: its row and the three beside and below it.
                let (tile, row) = (tile_of((u.div_euclid(t), v.div_euclid(t))), lv * t + lu);
                local.extend([(tile, row), (tile, row + 1), (tile, row + t), (tile, row + t + 1)]);
            } else {
                for ((u, v), _) in four {
                    local.push((tile_of((u.div_euclid(t), v.div_euclid(t))), v.rem_euclid(t) * t + u.rem_euclid(t)));
                }
            }
            for (c, (_, w)) in four.into_iter().enumerate() {
                weights[(a * points + p) * 4 + c] = w;
            }
        }
    }
    (order, local)
}

/// The tiles of `order` split into those whose features `map` keeps for predictor `model` (of `len` values) and those
/// to compute, and each tile's block in the table (the kept ones first, then the new ones, each in `order`'s order).
fn kept_then_new(
    order: &[(i64, i64)],
    map: &Arc<SceneMap>,
    model: Option<u64>,
    len: usize,
) -> (Vec<Arc<[f32]>>, Vec<NewTile>, Vec<usize>) {
    let key = |at: (i64, i64)| model.map(|m| FeatureKey { model: m, i: at.0, j: at.1 });
    let found: Vec<Option<Arc<[f32]>>> =
        order.iter().map(|&at| key(at).and_then(|k| map.features().get(&k)).filter(|f| f.len() == len)).collect();
    let (mut kept, mut new, mut block) = (vec![], vec![], vec![0usize; order.len()]);
    for (b, f) in found.iter().enumerate() {
        if let Some(f) = f {
            block[b] = kept.len();
            kept.push(f.clone());
        }
    }
    for (b, &at) in order.iter().enumerate() {
        if found[b].is_none() {
            block[b] = kept.len() + new.len();
            new.push(NewTile { at, keep: key(at).map(|k| (map.clone(), k)) });
        }
    }
    (kept, new, block)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::class::AgentClass;
    use crate::map::RasterMap;
    use crate::scene::{crop_grid, scene_raster};
    use crate::state::traffic_states;
    use ndarray::{Array3, Array4};

    fn crop(stride: usize, tile_px: usize, halo_px: usize) -> MapSpec {
        let scene = Some(SceneSpec { min_px: 32, stride, tile_px, halo_px, channels: 3 });
        MapSpec { optional: true, scene, ..crate::scene::tests::crop(false) }
    }

    /// Agents near (100, 100) heading four ways, on a raster map whose colour encodes where it is (1 m = 2 px).
    fn frame() -> (Frame, Vec<TrafficState>) {
        let image = Array3::from_shape_fn((400, 400, 3), |(r, c, k)| [(c * 5 / 8) as u8, (r * 5 / 8) as u8, 90][k]);
        let map = RasterMap::new(image, [[2.0, 0.0, 0.0], [0.0, 2.0, 0.0], [0.0, 0.0, 1.0]]).unwrap();
        let headings = [0.0, FRAC_PI_2, 2.5, -1.0];
        let p = ndarray::Array3::from_shape_fn((4, 2, 2), |(i, t, d)| {
            [100.0 + 3.0 * i as f64, 100.0 - 2.0 * i as f64][d] + t as f64 * [headings[i].cos(), headings[i].sin()][d]
        });
        let f = Frame::new(p, None, vec![AgentClass::Pedestrian; 4]).unwrap().with_map(Arc::new(SceneMap::Raster(map)));
        let s = traffic_states(&f, 1.0);
        (f, s)
    }

    /// Each agent's reads of a table of rows `(R, C)`: `(N, P, C)`.
    fn read(reads: &KeptReads, table: &Array2<f32>) -> Array3<f32> {
        let (n, p4) = reads.index.dim();
        Array3::from_shape_fn((n, p4 / 4, reads.channels), |(a, p, c)| {
            (0..4).map(|k| reads.weight[[a, p * 4 + k]] * table[[reads.index[[a, p * 4 + k]] as usize, c]]).sum()
        })
    }

    /// The rows of tile rasters as "features" of stride 1 without a halo: each pixel a row.
    fn rows_of(rasters: &Array4<f32>) -> Array2<f32> {
        let (t, c, h, w) = rasters.dim();
        Array2::from_shape_fn((t * h * w, c), |(r, k)| rasters[[r / (h * w), k, (r % (h * w)) / w, r % w]])
    }

    #[test]
    fn tiles_read_where_one_raster_of_the_world_grid_holds_the_crops() {
        // Stride 1, no halo: the "features" are the tiles' pixels, so reading them must give what grid_sample reads
        // of one large north-up raster on the same world grid (its middle pixel at global pixel (200, -200)).
        let (f, s) = frame();
        let spec = crop(1, 16, 0);
        let (reads, rasters) = kept_inputs(&f, &s, &spec, spec.scene.unwrap(), None).unwrap();
        assert!(reads.kept.is_empty() && !reads.new.is_empty());
        assert_eq!(rasters.dim(), (reads.new.len(), 3, 16, 16));
        let got = read(&reads, &rows_of(&rasters));
        let pose = AgentPose::new([100.0, 100.0], FRAC_PI_2);
        let big = scene_raster(&f, &s, &spec, 256, pose).unwrap();
        let poses: Vec<AgentPose> = s.iter().map(TrafficState::pose).collect();
        let grid = crop_grid(&poses, &spec, 1, 256, &pose).unwrap();
        let (h, w) = (big.dim().1 as f32, big.dim().2 as f32);
        for a in 0..4 {
            for p in 0..32 * 31 {
                let (x, y) = (grid[[a, p / 31, p % 31, 0]], grid[[a, p / 31, p % 31, 1]]);
                let (u, v) = ((x + 1.0) * w / 2.0 - 0.5, (y + 1.0) * h / 2.0 - 0.5);
                let (u0, v0) = (u.floor(), v.floor());
                for c in 0..3 {
                    let mut want = 0.0;
                    for (du, dv) in [(0.0, 0.0), (1.0, 0.0), (0.0, 1.0), (1.0, 1.0)] {
                        let wt = (1.0 - (u - u0 - du).abs()) * (1.0 - (v - v0 - dv).abs());
                        want += wt * big[[c, (v0 + dv) as usize, (u0 + du) as usize]];
                    }
                    assert!((got[[a, p, c]] - want).abs() < 2e-3, "agent {a} block {p} channel {c}");
                }
            }
        }
    }

    #[test]
    fn a_predictors_kept_tiles_are_read_and_only_the_others_computed() {
        let (f, s) = frame();
        let spec = crop(4, 16, 8);
        let scene = spec.scene.unwrap();
        let (first, rasters) = kept_inputs(&f, &s, &spec, scene, Some(7)).unwrap();
        assert_eq!(rasters.dim(), (first.new.len(), 3, 32, 32));
        // "Features" of each computed tile: its number in every row and channel; kept as the predictor would.
        let rows = first.rows;
        let features = Array2::from_shape_fn((first.new.len() * rows, 3), |(r, _)| (r / rows) as f32);
        first.keep(features.view()).unwrap();
        let table = |r: &KeptReads| {
            let mut t = r.table();
            if !r.new.is_empty() {
                let new = Array2::from_shape_fn((r.new.len() * rows, 3), |(k, _)| {
                    first.new.iter().position(|n| n.at == r.new[k / rows].at).unwrap() as f32
                });
                t = ndarray::concatenate(Axis(0), &[t.view(), new.view()]).unwrap();
            }
            t
        };
        let want = read(&first, &table(&first));
        let (second, again) = kept_inputs(&f, &s, &spec, scene, Some(7)).unwrap();
        assert_eq!((second.kept.len(), second.new.len(), again.dim().0), (first.new.len(), 0, 0));
        assert_eq!(read(&second, &table(&second)), want);
        // The engine's reading of the kept blocks is the same sums, laid out (N, C, gh, gw).
        let patches = second.patches(None).unwrap();
        assert_eq!(patches.dim(), (4, 3, 8, 8));
        for (a, p, c) in [(0, 0, 0), (1, 17, 2), (3, 63, 1)] {
            assert!((patches[[a, c, p / 8, p % 8]] - want[[a, p, c]]).abs() < 1e-5);
        }
        assert!(second.patches(Some(features.view())).is_err()); // rows for tiles it does not compute
        let mut bad = second.index.clone();
        bad[[0, 0]] = 1 << 40;
        assert!(read_rows(table(&second).view(), &bad, &second.weight, second.grid).is_err());
        // Another predictor's, or none's, computes them all again.
        assert_eq!(kept_inputs(&f, &s, &spec, scene, Some(8)).unwrap().0.new.len(), first.new.len());
        // Joined with itself (the kept blocks twice, the new tiles once) and taken apart, each reads the same.
        let third = kept_inputs(&f, &s, &spec, scene, Some(9)).unwrap();
        let (joined, jr) = KeptReads::join(&[(&second, &again), (&third.0, &third.1), (&third.0, &third.1)]).unwrap();
        assert_eq!(
            (joined.kept.len(), joined.new.len(), jr.dim().0),
            (second.kept.len(), third.0.new.len(), third.0.new.len())
        );
        let (part, pr) = joined.take(&jr, &[9, 2]);
        assert_eq!(part.index.dim().0, 2);
        assert_eq!(pr.dim().0, part.new.len());
    }

    #[test]
    fn a_frame_without_a_map_reads_one_blank_block() {
        let (f, s) = frame();
        let spec = crop(4, 16, 8);
        let (reads, rasters) = kept_inputs(&f.without_map(), &s, &spec, spec.scene.unwrap(), Some(1)).unwrap();
        assert_eq!((reads.kept.len(), reads.new.len(), rasters.dim().0), (1, 0, 0));
        assert!(reads.index.iter().all(|&i| i == 0) && reads.weight.iter().all(|&w| w == 0.0));
        assert_eq!(reads.table().dim(), (16, 3));
    }

    #[test]
    fn corners_weigh_to_one_and_interpolate_the_feature_grid() {
        for (x, y) in [(0.0, 0.0), (3.3, -7.9), (-12.26, 5.5), (1e4, -3e3)] {
            let c = corners([x, y], 0.5, 4);
            assert!((c.iter().map(|(_, w)| *w as f64).sum::<f64>() - 1.0).abs() < 1e-6);
            let u: f64 = c.iter().map(|((cu, _), w)| *cu as f64 * *w as f64).sum();
            assert!((u - ((x / 0.5 + 0.5) / 4.0 - 0.5)).abs() < 1e-3, "{u}");
        }
    }
}
