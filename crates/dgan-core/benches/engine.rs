//! Latency of the engine's parts: `cargo bench -p dgan-core`.
//!
//! - `graph/rtree/{1000,10000}` vs `graph/brute_force/{1000,10000}`: the attention-zone graph at constant density
//!   (one agent per 100 m², a mix of pedestrian and vehicle radii), so 10× the agents means ~10× the edges.
//! - `raster/vector_map/32` and `raster/raster_map/32`: 32 agent crops of 64×64 px.
//! - `decode/{100,4096}` and `decode/4096/2_threads`: 100 and 4,096 agents, K = 60 anchors, T_f = 12, on one thread
//!   and shared out over two.
//! - `predict/contract_map/32`: one whole predict (preprocess, raster, ONNX Runtime, decode) with the map fixture;
//!   needs `ORT_DYLIB_PATH`.
//! - `hdmap_waymo/raster` and `hdmap_waymo/predict`: a real Waymo Open Motion frame (45 agents, its whole vector map
//!   of 148 elements; `tests/fixtures/waymo_frame.json`) with the bundled `hdmap` model: the rasterisation of every
//!   agent's crop at the model's map spec (from the map's tiles, kept after the first iteration; `raster_per_agent`:
//!   each crop drawn from the elements; `raster_first_call`: a fresh map, its tiles drawn), and the whole predict it
//!   is part of, split into preprocessing, network and decoding; needs `ORT_DYLIB_PATH`.
//! - `tracker/zara1_excerpt` and `tracker/crowd_10hz/200`: the streaming tracker's cost per tick (update plus the
//!   frame at the tick; throughput in ticks): the bundled real zara1 excerpt replayed tick by tick (20 ticks, up to
//!   22 pedestrians), and 200 agents at 10 Hz resampled to a 0.4 s model (100 ticks).

use criterion::{criterion_group, criterion_main, BenchmarkId, Criterion};
use dgan_core::decode::{decode, decode_on, Anchors, Calibration, DecodeParams, NetworkOutputs};
use dgan_core::graph::{attention_zone_edges, attention_zone_edges_brute_force};
use dgan_core::preprocess::preprocess;
use dgan_core::raster::rasterize;
use dgan_core::state::traffic_states;
use dgan_core::transform::AgentPose;
use dgan_core::{
    AgentClass, Detection, Frame, MapElement, MapElementKind, MapSpec, Predictor, RasterMap, SceneMap, TimeBase,
    Tracker, VectorMap,
};
use ndarray::{Array2, Array3, Array4};
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;
use std::hint::black_box;
use std::path::PathBuf;
use std::sync::Arc;

/// The crate's folder: `CARGO_MANIFEST_DIR` as cargo sets it when it runs this (the compile-time value as a fallback),
/// so that a binary reused from a checkout elsewhere still finds the repository.
fn manifest_dir() -> PathBuf {
    std::env::var_os("CARGO_MANIFEST_DIR").map_or_else(|| env!("CARGO_MANIFEST_DIR").into(), Into::into)
}

fn scene(n: usize) -> (Vec<[f64; 2]>, Vec<f64>) {
    let mut rng = ChaCha8Rng::seed_from_u64(n as u64);
    let side = (n as f64 * 100.0).sqrt();
    let c = (0..n).map(|_| [rng.random_range(0.0..side), rng.random_range(0.0..side)]).collect();
    let r = (0..n).map(|i| if i % 5 == 0 { rng.random_range(5.0..20.0) } else { rng.random_range(0.5..6.0) }).collect();
    (c, r)
}

fn bench_graph(c: &mut Criterion) {
    let mut g = c.benchmark_group("graph");
    for n in [1_000usize, 10_000] {
        let (centres, radii) = scene(n);
        g.bench_with_input(BenchmarkId::new("rtree", n), &n, |b, _| {
            b.iter(|| attention_zone_edges(black_box(&centres), black_box(&radii)))
        });
        g.bench_with_input(BenchmarkId::new("brute_force", n), &n, |b, _| {
            b.iter(|| attention_zone_edges_brute_force(black_box(&centres), black_box(&radii)))
        });
    }
    g.finish();
}

/// 32 agents driving along a straight 4-lane road with lane lines, edges, a crosswalk and a median.
fn road_frame(map: SceneMap) -> Frame {
    let n = 32;
    let p = Array3::from_shape_fn((n, 8, 2), |(i, t, d)| {
        if d == 0 {
            (i as f64) * 6.0 + t as f64 * 1.6
        } else {
            ((i % 4) as f64 - 1.5) * 3.5
        }
    });
    Frame::new(p, None, vec![AgentClass::Vehicle; n]).expect("valid frame").with_map(Arc::new(map))
}

fn vector_map() -> SceneMap {
    let mut el = vec![];
    let line = |k, y: f64| MapElement::new(k, (0..=60).map(|i| [i as f64 * 5.0 - 50.0, y]).collect());
    for lane in 0..4 {
        let y = (lane as f64 - 1.5) * 3.5;
        el.push(line(MapElementKind::LaneCenterline, y));
        el.push(line(MapElementKind::LaneLineDashed, y + 1.75));
    }
    el.push(line(MapElementKind::RoadEdge, -7.0));
    el.push(line(MapElementKind::RoadEdge, 7.0));
    for x in (0..250).step_by(50) {
        let x = x as f64;
        el.push(MapElement::new(MapElementKind::Crosswalk, vec![[x, -7.0], [x + 4.0, -7.0], [x + 4.0, 7.0], [x, 7.0]]));
    }
    el.push(MapElement::new(MapElementKind::Obstacle, vec![[-50.0, -0.2], [250.0, -0.2], [250.0, 0.2], [-50.0, 0.2]]));
    SceneMap::Vector(VectorMap::new(el.into_iter().collect::<Result<_, _>>().expect("valid map")))
}

fn bench_raster(c: &mut Criterion) {
    let spec = MapSpec {
        height_px: 64,
        width_px: 64,
        resolution_m: 0.5,
        agent_row: 48,
        agent_col: 32,
        draw_agents: true,
        optional: false,
        render: dgan_core::MapRender::Agent,
        classes: vec![],
        scene: None,
    };
    let mut g = c.benchmark_group("raster");
    let frame = road_frame(vector_map());
    let states = traffic_states(&frame, 0.2);
    g.bench_function("vector_map/32", |b| b.iter(|| rasterize(black_box(&frame), &states, &spec)));
    let image = Array3::from_shape_fn((576, 720, 3), |(r, c, ch)| ((r * 7 + c * 3 + ch * 50) % 256) as u8);
    let raster = RasterMap::new(image, [[2.0, 0.0, 100.0], [0.0, 2.0, 300.0], [0.0, 0.0, 1.0]]).expect("valid map");
    let frame = road_frame(SceneMap::Raster(raster));
    g.bench_function("raster_map/32", |b| b.iter(|| rasterize(black_box(&frame), &states, &spec)));
    g.finish();
}

fn bench_decode(c: &mut Criterion) {
    let t_f = 12;
    let sets = (0..3).map(|c| Array3::from_shape_fn((20, t_f, 2), |(k, t, d)| (c * k * t + d) as f64 * 0.1)).collect();
    let anchors = Anchors::new(AgentClass::ALL.to_vec(), sets).expect("valid anchors");
    let mut g = c.benchmark_group("decode");
    for (n, threads) in [(100, 1), (4096, 1), (4096, 2)] {
        let mut rng = ChaCha8Rng::seed_from_u64(3);
        let cl = Array2::from_shape_fn((n, 3), |_| rng.random_range(-2.0f32..2.0));
        let al = Array2::from_shape_fn((n, 60), |_| rng.random_range(-2.0f32..2.0));
        let off = Array4::from_shape_fn((n, 60, t_f, 2), |_| rng.random_range(-0.5f32..0.5));
        let prior = Array3::from_shape_fn((n, t_f, 2), |(i, t, d)| (i * t + d) as f32 * 0.05);
        let poses: Vec<AgentPose> = (0..n).map(|i| AgentPose::new([i as f64, 0.0], i as f64 * 0.1)).collect();
        let out = NetworkOutputs { class_logits: cl.view(), anchor_logits: al.view(), offsets: off.view() };
        let calibration = Calibration { temperature: 1.3, speed_exponent: 0.5, class_temperature: 2.0 };
        let params = DecodeParams::new(&anchors, Some(prior.view()), calibration, 0.5);
        let id = if threads == 1 { format!("{n}") } else { format!("{n}/{threads}_threads") };
        g.bench_function(id, |b| b.iter(|| decode_on(out, params, &poses, 60, threads)));
    }
    g.finish();
}

/// The model at `path` (relative to the repository root), or None with a note when ONNX Runtime is not configured.
fn load_model(bench: &str, path: &str) -> Option<Predictor> {
    if std::env::var_os("ORT_DYLIB_PATH").is_none() {
        eprintln!("{bench} bench skipped: set ORT_DYLIB_PATH to the onnxruntime wheel's libonnxruntime.so.*");
        return None;
    }
    let model = manifest_dir().join("../..").join(path);
    Some(Predictor::load(&model).unwrap_or_else(|e| panic!("{} does not load: {e}", model.display())))
}

fn bench_predict(c: &mut Criterion) {
    let Some(predictor) = load_model("predict", "tests/fixtures/contract_map.onnx") else { return };
    let mut frame = road_frame(vector_map());
    // The fixture's crop is 16×16 at 1 m; the scene is the same road.
    frame = frame.with_ids((0..32).collect()).expect("unique ids");
    c.bench_function("predict/contract_map/32", |b| b.iter(|| predictor.predict(black_box(&frame))));
}

/// The real Waymo frame of `tests/fixtures/waymo_frame.json` (written by `make_waymo_frame.py`).
fn waymo_frame() -> Frame {
    let path = manifest_dir().join("../../tests/fixtures/waymo_frame.json");
    let text = std::fs::read_to_string(&path).expect("waymo_frame.json is readable");
    let v: serde_json::Value = serde_json::from_str(&text).expect("valid JSON");
    let floats = |key: &str| -> Vec<f64> {
        v[key].as_array().expect("an array").iter().map(|x| x.as_f64().expect("a number")).collect()
    };
    let pos = v["positions"].as_array().expect("positions");
    let (n, t) = (pos.len(), pos[0].as_array().expect("steps").len());
    let p = Array3::from_shape_fn((n, t, 2), |(i, k, d)| pos[i][k][d].as_f64().expect("a number"));
    let mask = Array2::from_shape_fn((n, t), |(i, k)| v["mask"][i][k].as_bool().expect("a bool"));
    let classes: Vec<AgentClass> = v["classes"]
        .as_array()
        .expect("classes")
        .iter()
        .map(|c| c.as_str().expect("a name").parse().expect("a class"))
        .collect();
    let elements = v["map"]
        .as_array()
        .expect("map")
        .iter()
        .map(|e| {
            let kind: MapElementKind = e["kind"].as_str().expect("a kind").parse().expect("a known kind");
            let pts = e["points"].as_array().expect("points");
            let pts = pts.iter().map(|q| [q[0].as_f64().expect("x"), q[1].as_f64().expect("y")]).collect();
            MapElement::new(kind, pts).expect("a valid element")
        })
        .collect();
    let ids = v["ids"].as_array().expect("ids").iter().map(|x| x.as_i64().expect("an id")).collect();
    Frame::new(p, Some(mask), classes)
        .and_then(|f| f.with_ids(ids))
        .and_then(|f| f.with_headings(&floats("headings")))
        .and_then(|f| f.with_lengths(&floats("lengths")))
        .and_then(|f| f.with_widths(&floats("widths")))
        .expect("a valid frame")
        .with_map(Arc::new(SceneMap::Vector(VectorMap::new(elements))))
}

fn bench_hdmap(c: &mut Criterion) {
    let Some(predictor) = load_model("hdmap_waymo", "python/dgan/models/hdmap.onnx") else { return };
    let spec = predictor.contract().input.clone();
    let map_spec = spec.map.clone().expect("hdmap has a map branch");
    let frame = waymo_frame();
    let states = traffic_states(&frame, spec.dt_s);
    let mut g = c.benchmark_group("hdmap_waymo");
    g.bench_function("raster", |b| b.iter(|| rasterize(black_box(&frame), &states, &map_spec)));
    // The same crops drawn per agent (map.render = "agent", as before contract 7).
    let per_agent = MapSpec { render: dgan_core::MapRender::Agent, ..map_spec.clone() };
    g.bench_function("raster_per_agent", |b| b.iter(|| rasterize(black_box(&frame), &states, &per_agent)));
    // Map preparation: the first call on a map, which draws the tiles its crops need (a fresh copy of the map each
    // iteration), crops included.
    let Some(SceneMap::Vector(map)) = frame.map() else { unreachable!("the Waymo frame has a vector map") };
    let fresh = || frame.clone().with_map(Arc::new(SceneMap::Vector(VectorMap::new(map.elements().to_vec()))));
    g.bench_function("raster_first_call", |b| {
        b.iter_batched(fresh, |f| rasterize(&f, &states, &map_spec), criterion::BatchSize::SmallInput)
    });
    g.bench_function("predict", |b| b.iter(|| predictor.predict(black_box(&frame))));
    // predict split into its three parts: preprocessing, the network, decoding.
    g.bench_function("preprocess", |b| b.iter(|| preprocess(black_box(&frame), &spec)));
    let pre = preprocess(&frame, &spec).expect("the frame preprocesses");
    g.bench_function("network", |b| b.iter(|| predictor.run(black_box(pre.inputs.clone()))));
    let (cl, al, off) = predictor.run(pre.inputs.clone()).expect("the network runs");
    let out = NetworkOutputs { class_logits: cl.view(), anchor_logits: al.view(), offsets: off.view() };
    let anchors = predictor.anchors();
    let contract = predictor.contract();
    let top_scale = contract.top_scales().expect("the contract's top-mode scale");
    let top_mean = contract.top_mean_powers().expect("the contract's top-mean power");
    let params = DecodeParams {
        top_scale: &top_scale,
        top_mean: &top_mean,
        ..DecodeParams::new(anchors, Some(pre.prior.view()), contract.calibration(), spec.dt_s)
    };
    g.bench_function("decode", |b| b.iter(|| decode(out, params, &pre.poses, anchors.total())));
    g.finish();
}

fn replay(base: TimeBase, ticks: &[(f64, Vec<(i64, Detection)>)]) -> usize {
    let mut tracker = Tracker::new(base, AgentClass::Pedestrian);
    let mut agents = 0;
    for (t, dets) in ticks {
        tracker.update(*t, dets.clone()).expect("valid tick");
        agents += tracker.frame().expect("frame").len();
    }
    agents
}

fn bench_tracker(c: &mut Criterion) {
    let mut g = c.benchmark_group("tracker");
    let path = manifest_dir().join("../../python/dgan/data/zara1/frames_5430_5620.txt");
    let text = std::fs::read_to_string(path).expect("the bundled zara1 excerpt");
    let mut by_tick: std::collections::BTreeMap<i64, Vec<(i64, Detection)>> = Default::default();
    for line in text.lines() {
        let v: Vec<f64> = line.split_whitespace().map(|x| x.parse().expect("number")).collect();
        by_tick.entry(v[0] as i64).or_default().push((v[1] as i64, Detection::at(v[0] * 0.04, v[2], v[3])));
    }
    let ticks: Vec<(f64, Vec<(i64, Detection)>)> = by_tick.into_iter().map(|(f, d)| (f as f64 * 0.04, d)).collect();
    let base = TimeBase::new(8, 0.4).expect("time base");
    g.throughput(criterion::Throughput::Elements(ticks.len() as u64));
    g.bench_function("zara1_excerpt", |b| b.iter(|| replay(base, black_box(&ticks))));
    let mut rng = ChaCha8Rng::seed_from_u64(7);
    let n = 200;
    let start: Vec<[f64; 4]> = (0..n)
        .map(|_| {
            let (x, y) = (rng.random_range(0.0..100.0), rng.random_range(0.0..100.0));
            [x, y, rng.random_range(-2.0..2.0), rng.random_range(-2.0..2.0)]
        })
        .collect();
    let crowd: Vec<(f64, Vec<(i64, Detection)>)> = (0..100)
        .map(|k| {
            let t = f64::from(k) * 0.1;
            let d =
                start.iter().enumerate().map(|(i, s)| (i as i64, Detection::at(t, s[0] + s[2] * t, s[1] + s[3] * t)));
            (t, d.collect())
        })
        .collect();
    g.throughput(criterion::Throughput::Elements(crowd.len() as u64));
    g.bench_with_input(BenchmarkId::new("crowd_10hz", n), &n, |b, _| b.iter(|| replay(base, black_box(&crowd))));
    g.finish();
}

criterion_group!(benches, bench_graph, bench_raster, bench_decode, bench_predict, bench_hdmap, bench_tracker);
criterion_main!(benches);
