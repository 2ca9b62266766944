//! The scene's map as one raster that a map CNN reads once for every agent (issue 26; the paper's own design), and
//! where each agent's crop lies in it.
//!
//! An agent's crop ([`crate::raster`]) costs its own drawing and its own pass of the map CNN, so the map's cost grows
//! with the agents. Here the map is drawn once into a square raster around the frame ([`scene_raster`], the agents'
//! boxes drawn once on it), the network's CNN runs once over it, and each agent reads the CNN's features at the
//! centres of its crop's `stride × stride` blocks ([`crop_grid`]: coordinates for ONNX's and PyTorch's
//! `grid_sample`, `align_corners = false`), in its own heading-aligned frame. Training and the engine both take the
//! raster and the grid from here.

use crate::error::{DganError, Result};
use crate::frame::Frame;
use crate::map::SceneMap;
use crate::spec::{MapRender, MapSpec, SceneSpec};
use crate::state::TrafficState;
use crate::transform::AgentPose;
use ndarray::{Array1, Array3, Array4, Array5, Axis};
use std::f64::consts::FRAC_PI_2;

pub use crate::spec::MAX_SCENE_PX;

/// [`scene_raster`] with the boxes of `drawn` alone (the agents within reach of it).
pub(crate) fn scene_raster_of(
    frame: &Frame,
    drawn: &[TrafficState],
    crop: &MapSpec,
    size_px: usize,
    pose: AgentPose,
) -> Result<Array3<f32>> {
    let spec = scene_spec(crop, size_px)?;
    let mut canvas = crate::canvas::Canvas::new(&spec, pose)
        .ok_or_else(|| DganError::InvalidSpec(format!("cannot allocate a {size_px}×{size_px} scene raster")))?;
    match frame.map() {
        Some(SceneMap::Vector(m)) => canvas.draw_vector(m),
        Some(SceneMap::Raster(m)) => canvas.draw_raster(m),
        None => {}
    }
    if crop.draw_agents {
        canvas.draw_boxes(drawn.iter());
    }
    let mut out = Array3::<f32>::zeros((3, size_px, size_px));
    let flat = out.as_slice_mut().ok_or_else(|| DganError::InvalidSpec("scene raster is not contiguous".into()))?;
    canvas.write_chw(flat);
    Ok(out)
}

/// The square scene raster of `size_px` pixels a side at the crop's resolution (`crop.resolution_m`), centred on
/// `pose`'s origin with its image-up along `pose`'s heading (a heading of π/2 puts world north up), `(3, size_px,
/// size_px)` with values in [0, 1] (the origin at the middle pixel's centre: of an even size, the one right of and
/// below the middle): the frame's map resampled or drawn as the crops are (black where there is none
/// or no map), and, if `crop.draw_agents`, every agent of `states` as a blue box, each drawn once.
pub fn scene_raster(
    frame: &Frame,
    states: &[TrafficState],
    crop: &MapSpec,
    size_px: usize,
    pose: AgentPose,
) -> Result<Array3<f32>> {
    if states.len() != frame.len() {
        return Err(DganError::InvalidFrame(format!("{} states for {} agents", states.len(), frame.len())));
    }
    scene_raster_of(frame, states, crop, size_px, pose)
}

/// A scene raster's side grows in steps of this many pixels (so that frames of one batch mostly share it).
pub const SCENE_STEP_PX: usize = 32;

/// A frame's inputs under a scene model (contract 12). Its agents fall into groups whose crops meet (two agents are
/// in one group when the boxes of their crops' corners intersect, and so on through the group), so that a frame of
/// scattered groups is not one raster mostly empty: each group gets its own raster, north up and centred on the middle
/// of its box, every raster of one side S, the least multiple of [`SCENE_STEP_PX`] at or above both `scene.min_px` and
/// each group box's longer side in pixels plus 2 (at most [`MAX_SCENE_PX`]: beyond it an agent reads zeros, as
/// without a map); where one raster of the whole frame (the same rule, one group) holds no more pixels than the
/// groups' together, that one. Each is blank where the frame has no map, with the boxes of the agents within reach. Returns the
/// rasters `(G, 3, S, S)` (groups in the order of their first agent; one blank raster for a frame without agents),
/// each group's agents' grids in its raster `(G, M, gh, gw, 2)` ([`crop_grid`]; zeros past a group's agents, M the
/// largest group) and each agent's row of them flattened `(N,)`: its group · M + its place in the group.
pub fn scene_inputs(
    frame: &Frame,
    states: &[TrafficState],
    crop: &MapSpec,
    scene: SceneSpec,
) -> Result<(Array4<f32>, Array5<f32>, Array1<i64>)> {
    let poses: Vec<AgentPose> = states.iter().map(TrafficState::pose).collect();
    let boxes: Vec<[f64; 4]> = poses.iter().map(|p| crop_box(crop, p)).collect();
    let (mut groups, mut centres, mut side) = layout(&boxes, groups_of(&boxes), crop.resolution_m, scene.min_px);
    // One raster for the whole frame where the groups' rasters would hold more pixels (groups of unequal reach).
    let whole = layout(&boxes, vec![(0..boxes.len()).collect()], crop.resolution_m, scene.min_px);
    if groups.len() > 1 && whole.2 * whole.2 <= groups.len() * side * side {
        (groups, centres, side) = whole;
    }
    if centres.is_empty() {
        centres.push([0.0, 0.0]);
    }
    let most = groups.iter().map(Vec::len).max().unwrap_or(0);
    let (gh, gw) =
        crop.scene_grid().unwrap_or((crop.height_px.div_ceil(scene.stride), crop.width_px.div_ceil(scene.stride)));
    let mut rasters = Array4::<f32>::zeros((centres.len(), 3, side, side));
    let mut grids = Array5::<f32>::zeros((centres.len(), most, gh, gw, 2));
    let mut slots = Array1::<i64>::zeros(poses.len());
    // Every agent's box reaches at most this far from its position.
    let reach =
        states.iter().map(|s| s.length.hypot(s.width) / 2.0).fold(0.0, f64::max) + side as f64 * crop.resolution_m;
    for (k, centre) in centres.iter().enumerate() {
        let pose = AgentPose::new(*centre, FRAC_PI_2);
        if frame.map().is_some() {
            let near: Vec<TrafficState> = states
                .iter()
                .filter(|s| (s.position[0] - centre[0]).abs() <= reach && (s.position[1] - centre[1]).abs() <= reach)
                .copied()
                .collect();
            let raster = scene_raster_of(frame, &near, crop, side, pose)?;
            rasters.index_axis_mut(Axis(0), k).assign(&raster);
        }
        let Some(members) = groups.get(k) else { continue };
        let mine: Vec<AgentPose> = members.iter().map(|&i| poses[i]).collect();
        let grid = crop_grid(&mine, crop, scene.stride, side, &pose)?;
        grids.slice_mut(ndarray::s![k, ..members.len(), .., .., ..]).assign(&grid);
        for (place, &i) in members.iter().enumerate() {
            slots[i] = (k * most + place) as i64;
        }
    }
    Ok((rasters, grids, slots))
}

/// `groups` of agents with each one's raster centre (the middle of its box of crop corners) and their rasters' one
/// side: the least multiple of [`SCENE_STEP_PX`] at or above `min_px` and every group box's longer side in pixels
/// plus 2, at most [`MAX_SCENE_PX`]. Groups without agents are dropped.
fn layout(
    boxes: &[[f64; 4]],
    groups: Vec<Vec<usize>>,
    resolution_m: f64,
    min_px: usize,
) -> (Vec<Vec<usize>>, Vec<[f64; 2]>, usize) {
    let groups: Vec<Vec<usize>> = groups.into_iter().filter(|g| !g.is_empty()).collect();
    let mut side = min_px;
    let mut centres = Vec::with_capacity(groups.len());
    for g in &groups {
        let b = g.iter().fold([f64::INFINITY, f64::INFINITY, f64::NEG_INFINITY, f64::NEG_INFINITY], |b, &i| {
            let v = boxes[i];
            [b[0].min(v[0]), b[1].min(v[1]), b[2].max(v[2]), b[3].max(v[3])]
        });
        side = side.max((((b[2] - b[0]).max(b[3] - b[1]) / resolution_m).ceil() as usize).saturating_add(2));
        centres.push([(b[0] + b[2]) / 2.0, (b[1] + b[3]) / 2.0]);
    }
    (groups, centres, side.div_ceil(SCENE_STEP_PX).saturating_mul(SCENE_STEP_PX).min(MAX_SCENE_PX))
}

/// The box `[min_x, min_y, max_x, max_y]` of the corners of an agent's crop (its outer pixel edges).
fn crop_box(crop: &MapSpec, pose: &AgentPose) -> [f64; 4] {
    let (h, w, r) = (crop.height_px as f64, crop.width_px as f64, crop.resolution_m);
    let (row, col) = (crop.agent_row as f64 + 0.5, crop.agent_col as f64 + 0.5);
    let mut b = [f64::INFINITY, f64::INFINITY, f64::NEG_INFINITY, f64::NEG_INFINITY];
    for (y, x) in [(0.0, 0.0), (0.0, w), (h, 0.0), (h, w)] {
        let p = pose.to_world([(row - y) * r, (col - x) * r]);
        b = [b[0].min(p[0]), b[1].min(p[1]), b[2].max(p[0]), b[3].max(p[1])];
    }
    b
}

/// The groups of boxes that intersect (touching counts), through any chain of them: each group's indices ascending,
/// the groups in the order of their lowest index.
pub fn groups_of(boxes: &[[f64; 4]]) -> Vec<Vec<usize>> {
    // Sweep along x: each box meets the boxes that start before it ends.
    let mut order: Vec<usize> = (0..boxes.len()).collect();
    order.sort_by(|&a, &b| boxes[a][0].total_cmp(&boxes[b][0]));
    let order = &order;
    let meet = order.iter().enumerate().flat_map(move |(k, &a)| {
        order[k + 1..]
            .iter()
            .take_while(move |&&b| boxes[b][0] <= boxes[a][2])
            .filter(move |&&b| boxes[b][1] <= boxes[a][3] && boxes[a][1] <= boxes[b][3])
            .map(move |&b| (a, b))
    });
    crate::graph::components(boxes.len(), meet)
}

/// The scene raster's own geometry: `crop`'s resolution and drawing, `size_px` square, centred.
fn scene_spec(crop: &MapSpec, size_px: usize) -> Result<MapSpec> {
    crop.validate()?;
    if !(1..=MAX_SCENE_PX).contains(&size_px) {
        return Err(DganError::InvalidSpec(format!(
            "a scene raster must be 1..={MAX_SCENE_PX} pixels a side, got {size_px}"
        )));
    }
    let half = size_px / 2;
    Ok(MapSpec {
        height_px: size_px,
        width_px: size_px,
        agent_row: half,
        agent_col: half,
        render: MapRender::Agent,
        classes: vec![],
        scene: None,
        ..crop.clone()
    })
}

/// The world positions of the centres of an agent's crop's `stride × stride` blocks (the agent at `pose`), row-major
/// over `(⌈H / stride⌉, ⌈W / stride⌉)`: the rows from the crop's top, the columns laid out symmetrically about the
/// agent's, so that a mirrored crop's blocks are its blocks with their columns reversed (training mirrors the scene
/// with its agents).
pub(crate) fn block_centres<'a>(
    pose: &'a AgentPose,
    crop: &'a MapSpec,
    stride: usize,
) -> impl Iterator<Item = [f64; 2]> + 'a {
    let (gh, gw) = (crop.height_px.div_ceil(stride), crop.width_px.div_ceil(stride));
    let half = stride as f64 / 2.0;
    (0..gh * gw).map(move |k| {
        let (bi, bj) = (k / gw, k % gw);
        // The block's centre in the crop's continuous pixels (edges at integers), then the agent's frame.
        let row = (bi * stride) as f64 + half;
        let col = crop.agent_col as f64 + 0.5 + (bj as f64 - (gw as f64 - 1.0) / 2.0) * stride as f64;
        let local = [
            (crop.agent_row as f64 + 0.5 - row) * crop.resolution_m,
            (crop.agent_col as f64 + 0.5 - col) * crop.resolution_m,
        ];
        pose.to_world(local)
    })
}

/// Where each agent's crop (`crop`, the agent at `poses[i]`) lies in the scene raster of [`scene_raster`]
/// (`size_px`, placed by `scene_pose`): `(N, ⌈H / stride⌉, ⌈W / stride⌉, 2)`, for each `stride × stride` block of the
/// crop (row-major, the crop's own rows and columns; the rows from the crop's top, the columns centred on the
/// agent's column) the `(x, y)` of its centre in the raster's `grid_sample` coordinates (x along columns, y along
/// rows, −1 and 1 at the raster's outer edges; beyond them outside it).
pub fn crop_grid(
    poses: &[AgentPose],
    crop: &MapSpec,
    stride: usize,
    size_px: usize,
    scene_pose: &AgentPose,
) -> Result<Array4<f32>> {
    let scene = scene_spec(crop, size_px)?;
    if stride == 0 || stride > crop.height_px.max(crop.width_px) {
        return Err(DganError::InvalidSpec(format!(
            "the grid's stride must be 1..={} (the crop's longer side), got {stride}",
            crop.height_px.max(crop.width_px)
        )));
    }
    let (gh, gw) = (crop.height_px.div_ceil(stride), crop.width_px.div_ceil(stride));
    let mut out = Array4::<f32>::zeros((poses.len(), gh, gw, 2));
    let side = size_px as f64;
    for (i, pose) in poses.iter().enumerate() {
        for (k, world) in block_centres(pose, crop, stride).enumerate() {
            let [u, v] = scene.local_to_pixel(scene_pose.to_local(world));
            out[[i, k / gw, k % gw, 0]] = (2.0 * u / side - 1.0) as f32;
            out[[i, k / gw, k % gw, 1]] = (2.0 * v / side - 1.0) as f32;
        }
    }
    Ok(out)
}

#[cfg(test)]
pub(crate) mod tests {
    use super::*;
    use crate::class::AgentClass;
    use crate::map::RasterMap;
    use crate::raster::rasterize;
    use crate::state::traffic_states;
    use std::f64::consts::FRAC_PI_2;
    use std::sync::Arc;

    /// A crop of 32 × 31 pixels at 0.5 m, the agent at row 24, column 15.
    pub(crate) fn crop(draw_agents: bool) -> MapSpec {
        MapSpec {
            height_px: 32,
            width_px: 31,
            resolution_m: 0.5,
            agent_row: 24,
            agent_col: 15,
            draw_agents,
            optional: false,
            render: MapRender::Agent,
            classes: vec![],
            scene: None,
        }
    }

    /// A raster map whose pixel colour encodes where it is: red = column / 400, green = row / 400 (1 m = 2 px).
    fn gradient_frame(headings: &[f64]) -> (Frame, Vec<TrafficState>) {
        let mut image = Array3::<u8>::zeros((400, 400, 3));
        for v in 0..400 {
            for u in 0..400 {
                image[[v, u, 0]] = (u * 255 / 400) as u8;
                image[[v, u, 1]] = (v * 255 / 400) as u8;
            }
        }
        let map = RasterMap::new(image, [[2.0, 0.0, 0.0], [0.0, 2.0, 0.0], [0.0, 0.0, 1.0]]).unwrap();
        let n = headings.len();
        let p = Array3::from_shape_fn((n, 2, 2), |(i, t, d)| {
            let base = [100.0 + 3.0 * i as f64, 100.0 - 2.0 * i as f64][d];
            base + t as f64 * [headings[i].cos(), headings[i].sin()][d]
        });
        let f = Frame::new(p, None, vec![AgentClass::Pedestrian; n]).unwrap().with_map(Arc::new(SceneMap::Raster(map)));
        let s = traffic_states(&f, 1.0);
        (f, s)
    }

    /// Bilinear `grid_sample` (align_corners = false, zeros outside) of channel `c` of `img (3, H, W)` at `(x, y)`.
    fn sample(img: &Array3<f32>, c: usize, x: f32, y: f32) -> f32 {
        let (h, w) = (img.dim().1 as f32, img.dim().2 as f32);
        let (u, v) = ((x + 1.0) * w / 2.0 - 0.5, (y + 1.0) * h / 2.0 - 0.5);
        let (u0, v0) = (u.floor(), v.floor());
        let mut acc = 0.0;
        for (du, dv) in [(0.0, 0.0), (1.0, 0.0), (0.0, 1.0), (1.0, 1.0)] {
            let (uu, vv) = (u0 + du, v0 + dv);
            let wt = (1.0 - (u - uu).abs()) * (1.0 - (v - vv).abs());
            if uu >= 0.0 && vv >= 0.0 && uu < w && vv < h {
                acc += wt * img[[c, vv as usize, uu as usize]];
            }
        }
        acc
    }

    #[test]
    fn the_grid_reads_each_crop_block_where_the_crop_drew_it() {
        // Agents heading four ways; the scene raster itself turned by 0.3 rad. Sampling the raster at each block
        // centre gives what the agent's own crop holds there: the block's rows 1 and 2 of column 1 (the columns
        // centred on the agent's 15: centres 1.5, 5.5, .., 29.5).
        let (f, s) = gradient_frame(&[0.0, FRAC_PI_2, 2.5, -1.0]);
        let spec = crop(false);
        let crops = rasterize(&f, &s, &spec).unwrap();
        let scene_pose = AgentPose::new([101.0, 99.0], FRAC_PI_2 + 0.3);
        let scene = scene_raster(&f, &s, &spec, 128, scene_pose).unwrap();
        let poses: Vec<AgentPose> = s.iter().map(TrafficState::pose).collect();
        let grid = crop_grid(&poses, &spec, 4, 128, &scene_pose).unwrap();
        assert_eq!(grid.dim(), (4, 8, 8, 2));
        let mut checked = 0;
        for i in 0..4 {
            for bi in 0..8 {
                for bj in 0..8 {
                    let (r, c) = (bi * 4 + 1, bj * 4 + 1);
                    for ch in 0..2 {
                        let want = (crops[[i, ch, r, c]] + crops[[i, ch, r + 1, c]]) / 2.0;
                        let got = sample(&scene, ch, grid[[i, bi, bj, 0]], grid[[i, bi, bj, 1]]);
                        assert!((got - want).abs() < 0.02, "agent {i} block ({bi}, {bj}) ch {ch}: {got} vs {want}");
                        checked += 1;
                    }
                }
            }
        }
        assert_eq!(checked, 4 * 8 * 8 * 2);
    }

    #[test]
    fn a_mirrored_agent_reads_the_mirrored_columns() {
        // Two agents mirrored about the north-up scene raster's middle column, x = 100 (an odd size: the origin's
        // pixel is the middle one; headings θ and π − θ): one's grid is the other's with its columns reversed and
        // x negated.
        let a = AgentPose::new([97.0, 104.0], 0.7);
        let b = AgentPose::new([103.0, 104.0], std::f64::consts::PI - 0.7);
        let scene_pose = AgentPose::new([100.0, 100.0], FRAC_PI_2);
        let g = crop_grid(&[a, b], &crop(false), 4, 95, &scene_pose).unwrap();
        for bi in 0..8 {
            for bj in 0..8 {
                assert!((g[[0, bi, bj, 0]] + g[[1, bi, 7 - bj, 0]]).abs() < 1e-5);
                assert!((g[[0, bi, bj, 1]] - g[[1, bi, 7 - bj, 1]]).abs() < 1e-5);
            }
        }
    }

    #[test]
    fn a_north_up_raster_centred_on_an_agent_puts_it_at_the_centre() {
        let (f, s) = gradient_frame(&[FRAC_PI_2]);
        let spec = crop(true);
        let pose = AgentPose::new(s[0].position, FRAC_PI_2);
        let scene = scene_raster(&f, &s, &spec, 64, pose).unwrap();
        // The 0.5 × 0.5 m pedestrian's box covers the centre pixel (32, 32), drawn blue over the map.
        assert!(scene[[2, 32, 32]] > 0.99 && scene[[0, 32, 32]] < 0.01, "{:?}", scene.slice(ndarray::s![.., 32, 32]));
        // A one-block grid of a one-pixel crop at the agent: the raster's centre, (0, 0) plus half a pixel.
        let one = MapSpec { height_px: 1, width_px: 1, agent_row: 0, agent_col: 0, ..spec };
        let g = crop_grid(&[s[0].pose()], &one, 1, 64, &pose).unwrap();
        assert!((g[[0, 0, 0, 0]] - 1.0 / 64.0).abs() < 1e-6 && (g[[0, 0, 0, 1]] - 1.0 / 64.0).abs() < 1e-6, "{g:?}");
    }

    #[test]
    fn a_frame_s_raster_grows_to_hold_every_crop() {
        let spec = crop(false);
        let scene = SceneSpec { min_px: 64, stride: 4, ..Default::default() };
        let (f, s) = gradient_frame(&[0.0, 1.0]);
        let (raster, grid, slot) = scene_inputs(&f, &s, &spec, scene).unwrap();
        assert_eq!(raster.dim(), (1, 3, 64, 64));
        assert_eq!(grid.dim(), (1, 2, 8, 8, 2));
        assert_eq!(slot.to_vec(), vec![0, 1]);
        assert!(raster.iter().any(|&v| v > 0.0));
        // Three agents heading east, the first two 10 m apart (their crops meet), the third 60 m on: two groups, two
        // rasters of one side; the first group's crops span 26 m (4 m behind the first to 12 m ahead of the
        // second), 52 px at 0.5 m, so the least side, 64; every block of every crop inside its group's raster.
        let xs = [20.0, 30.0, 90.0];
        let p = Array3::from_shape_fn((3, 2, 2), |(i, t, d)| [xs[i] + t as f64, 20.0][d]);
        let far = Frame::new(p, None, vec![AgentClass::Pedestrian; 3]).unwrap();
        let states = traffic_states(&far, 1.0);
        let (raster, grid, slot) = scene_inputs(&far, &states, &spec, scene).unwrap();
        assert_eq!((raster.dim(), grid.dim()), ((2, 3, 64, 64), (2, 2, 8, 8, 2)));
        assert_eq!(slot.to_vec(), vec![0, 1, 2]);
        assert!(grid.slice(ndarray::s![.., ..1, .., .., ..]).iter().all(|v| v.abs() < 1.0), "{grid:?}");
        assert!(grid.slice(ndarray::s![0, 1, .., .., ..]).iter().all(|v| v.abs() < 1.0), "{grid:?}");
        // Groups farther apart than the most a raster holds: a larger side for the group that needs it.
        let wide = Array3::from_shape_fn((2, 2, 2), |(i, t, d)| [20.0 + 16.0 * i as f64 + t as f64, 20.0][d]);
        let wide = Frame::new(wide, None, vec![AgentClass::Pedestrian; 2]).unwrap();
        let (raster, _, _) = scene_inputs(&wide, &traffic_states(&wide, 1.0), &spec, scene).unwrap();
        assert_eq!(raster.dim(), (1, 3, 96, 96)); // boxes touching at x = 33: 32 m, 64 + 2 px
                                                  // No map: blank rasters; no agents: one least raster and an empty grid.
        assert!(raster.iter().all(|&v| v == 0.0));
        let none = Frame::new(Array3::zeros((0, 2, 2)), None, vec![]).unwrap();
        let (raster, grid, slot) = scene_inputs(&none, &[], &spec, scene).unwrap();
        assert_eq!((raster.dim(), grid.dim(), slot.len()), ((1, 3, 64, 64), (1, 0, 8, 8, 2), 0));
    }

    #[test]
    fn bad_geometry_is_a_typed_error() {
        let (f, s) = gradient_frame(&[0.0]);
        let spec = crop(false);
        let pose = AgentPose::new([0.0, 0.0], 0.0);
        for size in [0, MAX_SCENE_PX + 1] {
            assert!(matches!(scene_raster(&f, &s, &spec, size, pose), Err(DganError::InvalidSpec(_))));
            assert!(matches!(crop_grid(&[pose], &spec, 4, size, &pose), Err(DganError::InvalidSpec(_))));
        }
        for stride in [0, 33] {
            assert!(matches!(crop_grid(&[pose], &spec, stride, 64, &pose), Err(DganError::InvalidSpec(_))));
        }
        assert!(matches!(scene_raster(&f, &[], &spec, 64, pose), Err(DganError::InvalidFrame(_))));
        // No agents: an empty grid.
        assert_eq!(crop_grid(&[], &spec, 4, 64, &pose).unwrap().dim(), (0, 8, 8, 2));
    }
}
