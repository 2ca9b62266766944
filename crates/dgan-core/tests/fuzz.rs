//! A stable-toolchain fuzzer of the engine's doors: random and mutated frames, maps, contracts, sealed model bytes and
//! detection streams, each run to completion under `catch_unwind`. Every input must give `Ok` or a typed error: a
//! panic fails the run. How long inputs take is printed (the slowest one with its seed), never asserted: the work an
//! input may cause is bounded by `Limits`, which the engine's own tests check, and a wall-clock bound inside a test
//! measures the machine as much as the code.
//!
//! `cargo test -p dgan-core --test fuzz` runs a quick round (`DGAN_FUZZ_ITERS`, default 2,000 an area); the long
//! run is `./dev fuzz [ITERS]` (release build), which prints the executions per area.

use dgan_core::contract::ModelContract;
use dgan_core::history::{frame_at, tracks_from_rows, Detection, TimeBase, Tracker};
use dgan_core::integrity::{digest_offset, file_digest};
use dgan_core::preprocess::{preprocess_within, Limits};
use dgan_core::raster::rasterize;
use dgan_core::state::traffic_states;
use dgan_core::{
    AgentClass, Frame, HeadingSource, InputSpec, MapElement, MapElementKind, MapSpec, SceneMap, VectorMap,
};
use ndarray::{Array2, Array3};
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;
use std::panic::{catch_unwind, AssertUnwindSafe};
use std::sync::Arc;
use std::time::{Duration, Instant};

/// A number drawn to hit edges: zeros, tiny, huge, negative, non-finite, and ordinary values.
fn number(rng: &mut ChaCha8Rng) -> f64 {
    match rng.random_range(0..16) {
        0 => f64::NAN,
        1 => f64::INFINITY,
        2 => f64::NEG_INFINITY,
        3 => 0.0,
        4 => -0.0,
        5 => f64::MIN_POSITIVE,
        6 => 10f64.powi(rng.random_range(-30..40)) * if rng.random() { 1.0 } else { -1.0 },
        7 => f64::MAX,
        8 => 1e9 * rng.random::<f64>(),
        _ => rng.random_range(-200.0..200.0),
    }
}

fn class(rng: &mut ChaCha8Rng) -> AgentClass {
    [AgentClass::Vehicle, AgentClass::Cyclist, AgentClass::Pedestrian][rng.random_range(0..3)]
}

fn spec(rng: &mut ChaCha8Rng, t_obs: usize) -> InputSpec {
    let h = rng.random_range(1..40);
    let w = rng.random_range(1..40);
    let map = rng.random::<bool>().then(|| MapSpec {
        height_px: h,
        width_px: w,
        resolution_m: [0.05, 0.5, 1.0, 7.0][rng.random_range(0..4)],
        agent_row: rng.random_range(0..h),
        agent_col: rng.random_range(0..w),
        draw_agents: rng.random(),
        optional: true,
        render: if rng.random() { dgan_core::MapRender::Tiles } else { dgan_core::MapRender::Agent },
        classes: vec![],
        scene: None,
    });
    InputSpec {
        dt_s: [0.1, 0.4, 1.0][rng.random_range(0..3)],
        t_obs,
        t_f: rng.random_range(1..20),
        classes: vec![AgentClass::Vehicle, AgentClass::Cyclist, AgentClass::Pedestrian],
        attention_lambda: 0.5,
        map,
        prior: Default::default(),
        graph: if rng.random() { dgan_core::GraphLayout::Padded } else { dgan_core::GraphLayout::EdgeList },
        heading: [HeadingSource::Measured, HeadingSource::MotionWhenMoving, HeadingSource::Motion]
            [rng.random_range(0..3)],
        denoise_gate_m: [0.0, 0.0, 0.1, 1.0][rng.random_range(0..4)],
    }
}

fn vector_map(rng: &mut ChaCha8Rng) -> Option<Arc<SceneMap>> {
    let mut els = vec![];
    for _ in 0..rng.random_range(0..6) {
        let kind = MapElementKind::ALL[rng.random_range(0..MapElementKind::ALL.len())];
        let scale = 10f64.powi(rng.random_range(0..10));
        let n = if rng.random_range(0..20) == 0 { rng.random_range(0..3000) } else { rng.random_range(0..12) };
        let pts: Vec<[f64; 2]> = (0..n)
            .map(|_| {
                if rng.random_range(0..30) == 0 {
                    [number(rng), number(rng)]
                } else {
                    [rng.random_range(-1.0..1.0) * scale, rng.random_range(-1.0..1.0) * scale]
                }
            })
            .collect();
        if let Ok(e) = MapElement::new(kind, pts) {
            els.push(e);
        }
    }
    rng.random::<bool>().then(|| Arc::new(SceneMap::Vector(VectorMap::new(els))))
}

/// A random frame (often invalid) run through preprocessing, maps and all.
fn fuzz_frame(rng: &mut ChaCha8Rng) -> bool {
    let (n, t) = (rng.random_range(0..12), rng.random_range(1..10));
    let mut pos = Array3::from_shape_fn((n, t, 2), |_| rng.random_range(-30.0..30.0));
    for _ in 0..rng.random_range(0..3) {
        if n > 0 {
            pos[[rng.random_range(0..n), rng.random_range(0..t), rng.random_range(0..2)]] = number(rng);
        }
    }
    let mask = rng.random::<bool>().then(|| Array2::from_shape_fn((n, t), |_| rng.random_range(0..5) > 0));
    let classes = (0..n).map(|_| class(rng)).collect();
    let Ok(mut frame) = Frame::new(pos, mask, classes) else { return false };
    let values = |rng: &mut ChaCha8Rng| -> Vec<f64> {
        (0..n).map(|_| if rng.random() { f64::NAN } else { number(rng) }).collect()
    };
    if rng.random() {
        frame = match frame.with_headings(&values(rng)) {
            Ok(f) => f,
            Err(_) => return false,
        };
    }
    if rng.random() {
        let v = Array2::from_shape_fn((n, 2), |_| if rng.random() { f64::NAN } else { number(rng) });
        frame = match frame.with_velocities(v.view()) {
            Ok(f) => f,
            Err(_) => return false,
        };
    }
    if rng.random() {
        frame = match frame.with_lengths(&values(rng)) {
            Ok(f) => f,
            Err(_) => return false,
        };
    }
    if let Some(map) = vector_map(rng) {
        frame = frame.with_map(map);
    }
    let spec = spec(rng, t);
    let limits = Limits { max_edges: 10_000, max_input_bytes: 64 << 20 };
    preprocess_within(&frame, &spec, &limits).is_ok()
}

/// Random geometry rasterised around random agents (the hangs of issue 13 came from here).
fn fuzz_map(rng: &mut ChaCha8Rng) -> bool {
    let Some(map) = vector_map(rng) else { return false };
    let n = rng.random_range(1..4);
    let pos = Array3::from_shape_fn((n, 2, 2), |(_, k, _)| rng.random_range(-50.0..50.0) + k as f64);
    let Ok(frame) = Frame::new(pos, None, (0..n).map(|_| class(rng)).collect()) else { return false };
    let frame = frame.with_map(map);
    let s = spec(rng, 2);
    s.map.as_ref().is_some_and(|m| rasterize(&frame, &traffic_states(&frame, 0.4), m).is_ok())
}

const CONTRACT: &str = r#"{"contract_version": 3, "units": "m", "dt_s": 0.4, "t_obs": 8, "t_f": 2,
 "classes": ["pedestrian"], "attention_lambda": 0.5, "map": {"height_px": 8, "width_px": 8, "resolution_m": 0.5,
 "agent_row": 4, "agent_col": 4, "draw_agents": true, "optional": true},
 "prior": {"kind": "constant_velocity", "window_s": 0.0}, "graph": "padded",
 "anchors": {"pedestrian": [[[1.0, 0.0], [2.0, 0.0]], [[0.5, 0.5], [1.0, 1.0]]]}, "temperature": 1.2,
 "name": "fuzz", "description": ""}"#;

/// The contract JSON with bytes flipped, inserted, deleted or a value replaced.
fn fuzz_contract(rng: &mut ChaCha8Rng) -> bool {
    let mut bytes = CONTRACT.as_bytes().to_vec();
    for _ in 0..rng.random_range(1..6) {
        let at = rng.random_range(0..bytes.len());
        match rng.random_range(0..4) {
            0 => bytes[at] ^= 1 << rng.random_range(0..8),
            1 => bytes.insert(at, b"0123456789-.,:{}[]\"e"[rng.random_range(0..20)]),
            2 => {
                bytes.remove(at);
            }
            _ => {
                let v = format!("{}", number(rng) as i64);
                bytes.splice(at..(at + 1).min(bytes.len()), v.bytes());
            }
        }
        if bytes.is_empty() {
            break;
        }
    }
    let text = String::from_utf8_lossy(&bytes);
    match ModelContract::from_json(&text) {
        Ok(c) => c.anchors().is_ok() && c.expected_outputs().is_ok(),
        Err(e) => {
            assert!(!e.to_string().contains(" at line "), "unclear: {e}");
            false
        }
    }
}

/// Sealed-file bytes, mutated: finding and checking the digest never panics.
fn fuzz_model_bytes(rng: &mut ChaCha8Rng) -> bool {
    let mut bytes: Vec<u8> = (0..rng.random_range(0..400)).map(|_| rng.random()).collect();
    if rng.random() {
        let key = format!("\"weights_sha256\":{}\"{}\"", " ".repeat(rng.random_range(0..3)), "0".repeat(64));
        let at = rng.random_range(0..=bytes.len());
        bytes.splice(at..at, key.bytes());
        for _ in 0..rng.random_range(0..3) {
            let i = rng.random_range(0..bytes.len());
            bytes[i] ^= 1 << rng.random_range(0..8);
        }
    }
    if let Ok(Some(offset)) = digest_offset(&bytes) {
        assert_eq!(file_digest(&bytes, offset).len(), 64);
        return true;
    }
    false
}

/// Random detection streams: the table path and the tracker.
fn fuzz_history(rng: &mut ChaCha8Rng) -> bool {
    let dt = [0.1, 0.4, 0.5][rng.random_range(0..3)];
    let Ok(base) = TimeBase::with_max_gap(rng.random_range(1..12), dt, number(rng).abs().min(10.0)) else {
        return false;
    };
    let rows: Vec<(i64, Detection)> = (0..rng.random_range(0..60))
        .map(|_| {
            let t = if rng.random_range(0..20) == 0 { number(rng) } else { f64::from(rng.random_range(0..30)) * 0.1 };
            (rng.random_range(0..6), Detection::at(t, number(rng), rng.random_range(-5.0..5.0)))
        })
        .collect();
    let now = if rows.is_empty() { 0.0 } else { rows[rng.random_range(0..rows.len())].1.time_s };
    let mut deep = false;
    if let Ok(tracks) = tracks_from_rows(rows.clone()) {
        let views: Vec<(i64, &[Detection])> = tracks.iter().map(|(i, t)| (*i, t.as_slice())).collect();
        deep = frame_at(&views, now, &base, AgentClass::Pedestrian).is_ok_and(|f| !f.is_empty());
    }
    let mut tracker = Tracker::new(base, AgentClass::Pedestrian);
    let mut t = 0.0;
    for chunk in rows.chunks(4) {
        t += rng.random_range(0.0..0.3);
        let mut dets = chunk.to_vec();
        dets.dedup_by_key(|d| d.0);
        if tracker.update(t, dets).is_ok() {
            let _ = tracker.frame();
        }
    }
    deep
}

/// A fuzz target: runs one input; true when it got past validation into the work (counted as "deep").
type Target = (&'static str, fn(&mut ChaCha8Rng) -> bool);

const TARGETS: [Target; 5] = [
    ("frame", fuzz_frame),
    ("map", fuzz_map),
    ("contract", fuzz_contract),
    ("model_bytes", fuzz_model_bytes),
    ("history", fuzz_history),
];

#[test]
fn fuzz_every_door() {
    let iters: u64 = std::env::var("DGAN_FUZZ_ITERS").ok().and_then(|s| s.parse().ok()).unwrap_or(2_000);
    let seed: u64 = std::env::var("DGAN_FUZZ_SEED").ok().and_then(|s| s.parse().ok()).unwrap_or(0x6467616e);
    std::panic::set_hook(Box::new(|_| {})); // panics are counted below, with the seed that makes them
    let mut failures = vec![];
    let mut total = 0u64;
    let started = Instant::now();
    for (k, (name, target)) in TARGETS.iter().enumerate() {
        let t0 = Instant::now();
        let mut deep = 0u64;
        let mut slowest = (Duration::ZERO, 0u64);
        for i in 0..iters {
            let case_seed = seed ^ ((k as u64) << 56) ^ i;
            let mut rng = ChaCha8Rng::seed_from_u64(case_seed);
            let t = Instant::now();
            let outcome = catch_unwind(AssertUnwindSafe(|| target(&mut rng)));
            match outcome {
                Ok(true) => deep += 1,
                Ok(false) => {}
                Err(_) => failures.push(format!("{name}: panic with seed {case_seed}")),
            }
            slowest = slowest.max((t.elapsed(), case_seed));
        }
        total += iters;
        println!(
            "fuzz {name:<12} {iters} executions ({deep} past validation) in {:.1} s; slowest {:.1} ms (seed {})",
            t0.elapsed().as_secs_f64(),
            slowest.0.as_secs_f64() * 1e3,
            slowest.1
        );
    }
    let _ = std::panic::take_hook();
    println!(
        "fuzz total       {total} executions in {:.1} s, {} failures",
        started.elapsed().as_secs_f64(),
        failures.len()
    );
    assert!(failures.is_empty(), "{failures:#?}");
}
