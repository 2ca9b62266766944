//! Agent-centric, heading-aligned RGB crops of the scene map, one per agent, in the paper's colours.
//!
//! A vector map is drawn with anti-aliasing (tiny-skia): regions first (white bike lanes, grey crosswalks, pink
//! obstacles), then yellow road edges, solid and dashed white lane lines and green centre lines. A raster map is
//! resampled bilinearly through its homography. The agents themselves are drawn on top as blue boxes.

use crate::canvas::{world_bounds, Canvas};
use crate::error::{DganError, Result};
use crate::frame::Frame;
use crate::limits::share_jobs;
use crate::map::SceneMap;
use crate::spec::{MapRender, MapSpec};
use crate::state::TrafficState;
use crate::tiles::{resample_chw, tile, Overlay};
use ndarray::Array4;
use rstar::primitives::GeomWithData;
use rstar::{RTree, AABB};
use std::sync::atomic::{AtomicUsize, Ordering};

pub use crate::canvas::{colour, AGENT};
pub use crate::map::Rgb;

/// The version of the rasteriser (colours, widths, drawing order, anti-aliasing, agent boxes). Bump it with any
/// change to what a crop holds: exporters write it into each model's contract (`raster_version`), a model exported
/// with another is refused, and the training window cache is keyed by it.
pub const RASTER_VERSION: u32 = 1;

/// Crops a rasterising thread takes at a time.
const CROPS_PER_JOB: usize = 4;

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

/// `threads` shared with the other predictions in flight in this process: at least one.
pub(crate) fn threads_in_flight(threads: usize) -> usize {
    (threads / IN_FLIGHT.load(Ordering::SeqCst).max(1)).max(1)
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
    rasterize_into(frame, states, spec, threads, Vec::new())
}

/// The crops of the agents `rows` only (in that order), each as [`rasterize_on`] draws it: the boxes of every agent
/// of the frame, not of `rows` alone. For the parts of a frame that run as separate network calls.
pub fn rasterize_rows(
    frame: &Frame,
    states: &[TrafficState],
    spec: &MapSpec,
    rows: &[usize],
    threads: usize,
) -> Result<Array4<f32>> {
    rasterize_rows_into(frame, states, spec, rows, threads, Vec::new())
}

/// [`rasterize_on`] drawn into `buffer`'s memory (any length; grown or cut to the crops' size, every value then
/// overwritten): a caller that keeps the buffer of one call for the next (`Array4::into_raw_vec_and_offset`) spares
/// the operating system's page faults of a fresh allocation, most of the cost of large crops beyond drawing them.
pub fn rasterize_into(
    frame: &Frame,
    states: &[TrafficState],
    spec: &MapSpec,
    threads: usize,
    buffer: Vec<f32>,
) -> Result<Array4<f32>> {
    let every: Vec<usize> = (0..frame.len()).collect();
    rasterize_rows_into(frame, states, spec, &every, threads, buffer)
}

fn rasterize_rows_into(
    frame: &Frame,
    states: &[TrafficState],
    spec: &MapSpec,
    rows: &[usize],
    threads: usize,
    mut buffer: Vec<f32>,
) -> Result<Array4<f32>> {
    spec.validate()?;
    if states.len() != frame.len() {
        return Err(DganError::InvalidFrame(format!("{} states for {} agents", states.len(), frame.len())));
    }
    let n = states.len();
    // Each row's state, or None where its class does not read the map (`spec.classes`): that crop stays blank.
    let mine: Vec<Option<&TrafficState>> = rows
        .iter()
        .map(|&i| match (states.get(i), frame.classes().get(i)) {
            (Some(s), Some(&c)) => Ok(spec.reads(c).then_some(s)),
            _ => Err(DganError::InvalidSpec(format!("crop of agent {i} of {n}"))),
        })
        .collect::<Result<_>>()?;
    let (h, w) = (spec.height_px, spec.width_px);
    // Every crop writes all of its 3 × h × w values (`Canvas::write_chw`): what the buffer held is overwritten.
    let len = rows.len() * 3 * h * w;
    buffer.truncate(len);
    buffer.resize(len, 0.0);
    let mut out = Array4::from_shape_vec((rows.len(), 3, h, w), buffer)
        .map_err(|e| DganError::InvalidSpec(format!("raster buffer: {e}")))?;
    let flat = out.as_slice_mut().ok_or_else(|| DganError::InvalidSpec("raster buffer is not contiguous".into()))?;
    let threads = threads_in_flight(threads).min(rows.len() / 8).max(1);
    let crops = Crops::new(frame, states, spec, &mine, threads)?;
    // Scoped threads that end with the call, rather than a pool whose idle workers keep spinning on the cores that
    // ONNX Runtime runs on next (on two cores that cost as much as the parallel drawing saved).
    let per = 3 * h * w;
    if threads == 1 {
        for (crop, s) in flat.chunks_mut(per).zip(&mine) {
            crops.draw(crop, *s)?;
        }
    } else {
        // Jobs of a few crops, taken by each thread as it finishes one: crops of a map's busy part cost many times
        // blank ones, and contiguous shares left them on one thread (a tiled zara1 frame of 4,096 agents: 86 ms of
        // crops on one thread, 83 on two, 32 on sixteen).
        let jobs: Vec<_> = flat.chunks_mut(per * CROPS_PER_JOB).zip(mine.chunks(CROPS_PER_JOB)).collect();
        let one = |(part, agents): (&mut [f32], &[Option<&TrafficState>])| {
            part.chunks_mut(per).zip(agents).try_for_each(|(crop, s)| crops.draw(crop, *s))
        };
        share_jobs(jobs, threads, one, || DganError::InvalidSpec("a rasterising thread panicked".into()))?;
    }
    Ok(out)
}

/// What one call's crops are drawn from: the frame's map, its agents' boxes (found through an R-tree) and, for a
/// vector map drawn from tiles with the agents' boxes, the tiles the crops read with the boxes drawn on
/// ([`Overlay`]).
struct Crops<'a> {
    frame: &'a Frame,
    states: &'a [TrafficState],
    spec: &'a MapSpec,
    agents: RTree<GeomWithData<[f64; 2], usize>>,
    /// Half the largest box diagonal: how far beyond its centre an agent's box can reach.
    max_half_diag: f64,
    overlay: Option<Overlay>,
}

impl<'a> Crops<'a> {
    /// The drawer of `frame`'s crops of the agents `mine` (None: a crop left blank), its overlay built on up to
    /// `threads` threads.
    fn new(
        frame: &'a Frame,
        states: &'a [TrafficState],
        spec: &'a MapSpec,
        mine: &[Option<&TrafficState>],
        threads: usize,
    ) -> Result<Self> {
        let agents =
            RTree::bulk_load(states.iter().enumerate().map(|(i, s)| GeomWithData::new(s.position, i)).collect());
        let max_half_diag = states.iter().map(|s| s.length.hypot(s.width) / 2.0).fold(0.0, f64::max);
        let mut crops = Self { frame, states, spec, agents, max_half_diag, overlay: None };
        // From tiles, the boxes are drawn once on the tiles the crops read instead of once on each crop.
        if let Some(SceneMap::Vector(m)) = frame.map() {
            if spec.render == MapRender::Tiles && spec.draw_agents {
                let views: Vec<[f64; 4]> = mine.iter().flatten().map(|s| world_bounds(spec, &s.pose())).collect();
                crops.overlay = Some(Overlay::new(m, spec, &views, |v| crops.boxes_near(v), threads)?);
            }
        }
        Ok(crops)
    }

    /// Every agent whose box can reach into world bounds `v`.
    fn boxes_near(&self, v: [f64; 4]) -> Vec<&'a TrafficState> {
        let d = self.max_half_diag;
        let near = AABB::from_corners([v[0] - d, v[1] - d], [v[2] + d, v[3] + d]);
        let states = self.states;
        self.agents.locate_in_envelope(&near).map(|o| &states[o.data]).collect()
    }

    /// The crop of agent `s` (blank for None), written into `crop` as `3 × h × w` values.
    fn draw(&self, crop: &mut [f32], s: Option<&TrafficState>) -> Result<()> {
        let Some(s) = s else {
            crop.fill(0.0);
            return Ok(());
        };
        let spec = self.spec;
        // From tiles, straight into the crop: the boxes, if drawn, are on the overlay's tiles already.
        match (self.frame.map(), &self.overlay) {
            (Some(SceneMap::Vector(m)), Some(o)) => {
                o.resample_chw(m, spec, &s.pose(), crop);
                return Ok(());
            }
            (Some(SceneMap::Vector(m)), None) if spec.render == MapRender::Tiles => {
                resample_chw(spec, &s.pose(), |i, j| tile(m, spec, i, j), crop);
                return Ok(());
            }
            _ => {}
        }
        let mut canvas = Canvas::new(spec, s.pose()).ok_or_else(|| {
            DganError::InvalidSpec(format!("cannot allocate a {}×{} crop", spec.width_px, spec.height_px))
        })?;
        let view = canvas.view;
        match self.frame.map() {
            Some(SceneMap::Vector(m)) => canvas.draw_vector(m),
            Some(SceneMap::Raster(m)) => canvas.draw_raster(m),
            None => {}
        }
        if spec.draw_agents {
            canvas.draw_boxes(self.boxes_near(view).into_iter());
        }
        canvas.write_chw(crop);
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::canvas::round_u8;
    use crate::class::AgentClass;
    use crate::map::{MapElement, MapElementKind, RasterMap, VectorMap};
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
            render: MapRender::Agent,
            classes: vec![],
            scene: None,
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

    /// 40 vehicles along a road with lines and regions (the scene of `crops_do_not_depend_on_the_threads`).
    fn road(render: MapRender) -> (Frame, Vec<TrafficState>, MapSpec) {
        let p =
            Array3::from_shape_fn((40, 2, 2), |(i, t, d)| if d == 0 { 90.0 + i as f64 * 0.7 } else { 49.0 + t as f64 });
        let line = MapElement::new(MapElementKind::LaneLineDashed, vec![[80.0, 0.0], [130.0, 100.0]]).unwrap();
        let edge = MapElement::new(MapElementKind::RoadEdge, vec![[70.0, 0.0], [120.0, 100.0]]).unwrap();
        let region =
            MapElement::new(MapElementKind::Crosswalk, vec![[95.0, 50.0], [99.0, 50.0], [99.0, 54.0]]).unwrap();
        let map = Arc::new(SceneMap::Vector(VectorMap::new(vec![line, edge, region])));
        let f = Frame::new(p, None, vec![AgentClass::Vehicle; 40]).unwrap().with_map(map);
        let s = traffic_states(&f, 1.0);
        (f, s, MapSpec { render, ..spec(true) })
    }

    #[test]
    fn tiled_crops_resemble_drawn_ones_whatever_the_order_threads_or_calls() {
        let (f, s, agent) = road(MapRender::Agent);
        let tiles = MapSpec { render: MapRender::Tiles, ..agent.clone() };
        let drawn = rasterize_on(&f, &s, &agent, 1).unwrap();
        let first = rasterize_on(&f, &s, &tiles, 1).unwrap();
        let Some(SceneMap::Vector(m)) = f.map() else { unreachable!() };
        let kept = m.tiles().len();
        assert!((1..=16).contains(&kept), "{kept} tiles");
        // Close to the crops drawn per agent: the same lines and regions, resampled.
        let diff = (&drawn - &first).mapv(f32::abs);
        assert!(diff.mean().unwrap() < 0.02, "{}", diff.mean().unwrap());
        assert!((drawn.sum() - first.sum()).abs() / drawn.sum() < 0.05, "{} vs {}", drawn.sum(), first.sum());
        // Again from the kept tiles, on several threads, and from a copy of the map drawing its own tiles.
        assert_eq!(rasterize_on(&f, &s, &tiles, 1).unwrap(), first);
        assert_eq!(m.tiles().len(), kept, "a second call draws no tile");
        for threads in [2, 3] {
            assert_eq!(rasterize_on(&f, &s, &tiles, threads).unwrap(), first, "{threads} threads");
        }
        let copy = Frame::new(f.positions().clone(), None, vec![AgentClass::Vehicle; 40])
            .unwrap()
            .with_map(Arc::new(SceneMap::Vector(m.clone())));
        assert_eq!(rasterize_on(&copy, &s, &tiles, 1).unwrap(), first);
        // The agents in the other order (the tiles drawn for another crop first): each agent's crop is the same.
        let rev: Vec<usize> = (0..40).rev().collect();
        let p = f.positions().select(ndarray::Axis(0), &rev);
        let back = Frame::new(p, None, vec![AgentClass::Vehicle; 40])
            .unwrap()
            .with_map(Arc::new(SceneMap::Vector(VectorMap::new(m.elements().to_vec()))));
        let s_back = traffic_states(&back, 1.0);
        let reversed = rasterize_on(&back, &s_back, &tiles, 1).unwrap();
        assert_eq!(reversed.select(ndarray::Axis(0), &rev), first);
    }

    #[test]
    fn only_the_classes_that_read_the_map_get_drawn_crops() {
        // `map.classes` (contract 11): a pedestrian's crop is the one drawn for every agent; a vehicle's stays blank.
        let (f, _, _) = road(MapRender::Agent);
        let classes: Vec<_> =
            (0..40).map(|i| if i % 3 == 0 { AgentClass::Pedestrian } else { AgentClass::Vehicle }).collect();
        let f = Frame::new(f.positions().clone(), None, classes.clone())
            .unwrap()
            .with_map(Arc::new(f.map().unwrap().clone()));
        let s = traffic_states(&f, 1.0);
        for render in [MapRender::Agent, MapRender::Tiles] {
            let every = MapSpec { render, ..road(render).2 };
            let readers = MapSpec { classes: vec![AgentClass::Pedestrian], ..every.clone() };
            let all = rasterize_on(&f, &s, &every, 1).unwrap();
            for threads in [1, 3] {
                let some = rasterize_on(&f, &s, &readers, threads).unwrap();
                for (i, c) in classes.iter().enumerate() {
                    let (got, want) = (some.index_axis(ndarray::Axis(0), i), all.index_axis(ndarray::Axis(0), i));
                    match c {
                        AgentClass::Pedestrian => assert_eq!(got, want, "{render:?}, agent {i}"),
                        _ => assert!(got.iter().all(|v| *v == 0.0) && want.iter().any(|v| *v > 0.0), "{i}"),
                    }
                }
                let rows = [3, 4, 0];
                assert_eq!(
                    rasterize_rows(&f, &s, &readers, &rows, threads).unwrap(),
                    some.select(ndarray::Axis(0), &rows)
                );
            }
        }
    }

    #[test]
    fn tiled_crops_carry_the_agents_boxes_drawn_once_on_the_tiles() {
        // The blue the boxes add to every crop, drawn on each crop (`Agent`) or once on the tiles (`Tiles`).
        let blue = |render: MapRender, draw_agents: bool| {
            let (f, s, spec) = road(render);
            let img = rasterize_on(&f, &s, &MapSpec { draw_agents, ..spec }, 2).unwrap();
            img.index_axis(ndarray::Axis(1), 2).sum()
        };
        let per_crop = blue(MapRender::Agent, true) - blue(MapRender::Agent, false);
        let tiled = blue(MapRender::Tiles, true) - blue(MapRender::Tiles, false);
        assert!(per_crop > 100.0, "{per_crop}");
        assert!((tiled - per_crop).abs() < 0.1 * per_crop, "{tiled} against {per_crop}");
        // The map's kept tiles hold no box: a frame of other agents on the same map draws its own.
        let (f, s, spec) = road(MapRender::Tiles);
        let with_boxes = rasterize_on(&f, &s, &spec, 1).unwrap();
        let Some(SceneMap::Vector(m)) = f.map() else { unreachable!() };
        let bare = Frame::new(f.positions().clone(), None, vec![AgentClass::Vehicle; 40])
            .unwrap()
            .with_map(Arc::new(SceneMap::Vector(m.clone())));
        let plain = rasterize_on(&bare, &s, &MapSpec { draw_agents: false, ..spec }, 1).unwrap();
        assert_ne!(with_boxes, plain);
        assert_eq!(
            rasterize_on(&f, &s, &MapSpec { draw_agents: false, ..road(MapRender::Tiles).2 }, 1).unwrap(),
            plain
        );
    }

    #[test]
    fn crops_read_from_the_mosaic_equal_those_from_their_own_patches() {
        // The road's 40 agents read their tiles from one mosaic; with a 41st agent 5 km away the tiles spread too far
        // for one, and each crop copies its own patch: the 40 crops are the same either way, on 1 or 3 threads.
        let (f, s, spec) = road(MapRender::Tiles);
        let Some(SceneMap::Vector(m)) = f.map() else { unreachable!() };
        let views = |states: &[TrafficState]| -> Vec<[f64; 4]> {
            states.iter().map(|s| world_bounds(&spec, &s.pose())).collect()
        };
        let near: Vec<&TrafficState> = vec![];
        assert!(Overlay::new(m, &spec, &views(&s), |_| near.clone(), 1).unwrap().has_mosaic());
        let mut p = Array3::zeros((41, 2, 2));
        p.slice_mut(ndarray::s![..40, .., ..]).assign(f.positions());
        p.slice_mut(ndarray::s![40, .., ..]).assign(&ndarray::array![[5000.0, 49.0], [5000.0, 50.0]]);
        let far =
            Frame::new(p, None, vec![AgentClass::Vehicle; 41]).unwrap().with_map(Arc::new(f.map().unwrap().clone()));
        let s_far = traffic_states(&far, 1.0);
        assert!(!Overlay::new(m, &spec, &views(&s_far), |_| near.clone(), 1).unwrap().has_mosaic());
        for threads in [1, 3] {
            let from_mosaic = rasterize_on(&f, &s, &spec, threads).unwrap();
            let from_patches = rasterize_on(&far, &s_far, &spec, threads).unwrap();
            assert_eq!(from_patches.slice(ndarray::s![..40, .., .., ..]), from_mosaic, "{threads} threads");
            assert!(from_mosaic.iter().any(|v| *v > 0.5));
        }
    }

    #[test]
    fn tiles_serve_crops_up_to_their_bound() {
        let big = MapSpec { height_px: 300, agent_row: 150, render: MapRender::Tiles, ..spec(true) };
        let err = big.validate().unwrap_err().to_string();
        assert!(err.contains("at most 256 pixels a side"), "{err}");
        assert!(MapSpec { render: MapRender::Agent, ..big }.validate().is_ok());
    }

    #[test]
    fn a_map_keeps_a_bounded_number_of_tiles_the_least_recently_used_leaving_first() {
        let m = VectorMap::default();
        let cap = crate::tile_store::TileStore::CAPACITY as i64;
        let key = |i: i64| crate::tile_store::TileKey { resolution_bits: 1, i, j: 0 };
        for i in 0..cap {
            m.tiles().insert(key(i), vec![0u8; 3].into());
        }
        assert!(m.tiles().get(&key(0)).is_some()); // tile 0 used again: tile 1 is now the oldest
        for i in cap..cap + 5 {
            m.tiles().insert(key(i), vec![0u8; 3].into());
            assert_eq!(m.tiles().len(), cap as usize);
        }
        assert!(m.tiles().contains(&key(0)));
        assert!((1..6).all(|i| !m.tiles().contains(&key(i))));
        assert!(m.tiles().contains(&key(6)) && m.tiles().contains(&key(cap + 4)));
    }

    #[test]
    fn the_unit_table_is_the_division() {
        for v in 0..=255u8 {
            let divided = f32::from(std::hint::black_box(v)) / std::hint::black_box(255.0f32);
            assert_eq!(crate::canvas::UNIT[usize::from(v)].to_bits(), divided.to_bits(), "{v}");
        }
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
