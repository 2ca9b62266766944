//! The ONNX Runtime session against the contract fixtures (`tests/fixtures/make_fixtures.py`).

mod common;

use common::{fixture, onnxruntime_library};
use dgan_core::{
    AgentClass, DganError, Frame, MapElement, MapElementKind, Predictor, PredictorOptions, SceneMap, VectorMap,
};
use ndarray::Array3;
use std::sync::Arc;

fn load(name: &str) -> dgan_core::Result<Predictor> {
    let options = PredictorOptions { onnxruntime_library: Some(onnxruntime_library()), ..Default::default() };
    Predictor::load_with(fixture(name), &options)
}

fn walkers(n: usize) -> Frame {
    let p = Array3::from_shape_fn((n, 8, 2), |(i, t, d)| {
        if d == 0 {
            i as f64 * 1.5 + t as f64 * 0.5
        } else {
            i as f64 * 0.7 - t as f64 * 0.1
        }
    });
    Frame::new(p, None, (0..n).map(|i| AgentClass::ALL[i % 3]).collect()).expect("valid frame")
}

#[test]
fn predicts_sorted_normalised_modes() {
    let lane = VectorMap::new(vec![
        MapElement::new(MapElementKind::LaneCenterline, vec![[-50.0, 0.0], [50.0, 0.0]]).expect("a valid line")
    ]);
    for name in ["contract_nomap.onnx", "contract_map.onnx"] {
        let p = load(name).unwrap();
        assert_eq!(p.anchors().total(), 7);
        let frame = walkers(5).with_map(Arc::new(SceneMap::Vector(lane.clone())));
        let out = p.predict(&frame).unwrap();
        assert_eq!(out.trajectories.dim(), (5, 7, 12, 2));
        for i in 0..5 {
            let row = out.probabilities.row(i);
            assert!((row.sum() - 1.0).abs() < 1e-9, "{name}: all modes sum to 1");
            assert!(row.windows(2).into_iter().all(|w| w[0] >= w[1]), "{name}: sorted");
            assert!((out.class_probabilities.row(i).sum() - 1.0).abs() < 1e-9);
        }
        let top = p.predict_modes(&frame, 3).unwrap();
        assert_eq!(top.trajectories.dim(), (5, 3, 12, 2));
        assert_eq!(top.trajectories, out.trajectories.slice(ndarray::s![.., ..3, .., ..]).to_owned());
    }
}

#[test]
fn a_required_map_is_a_typed_error() {
    // contract_map.onnx is a contract-1 map model: its map is not optional.
    let p = load("contract_map.onnx").unwrap();
    assert!(matches!(p.predict(&walkers(3)), Err(DganError::MapRequired(_))));
}

#[test]
fn empty_scene_gives_an_empty_prediction() {
    let p = load("contract_map.onnx").unwrap();
    let out = p.predict(&Frame::new(Array3::zeros((0, 8, 2)), None, vec![]).unwrap()).unwrap();
    assert_eq!(out.trajectories.dim(), (0, 7, 12, 2));
    assert_eq!(out.edges.dim(), (0, 2));
}

#[test]
fn bad_models_fail_at_load_with_a_reason() {
    let cases: [(&str, &str); 8] = [
        ("bad_no_metadata.onnx", "no \"dgan_contract\" metadata"),
        ("bad_contract_version.onnx", "contract_version 99"),
        ("bad_metadata_json.onnx", "not a valid contract"),
        ("bad_fixed_agent_axis.onnx", "must be dynamic"),
        ("bad_anchor_count.onnx", "anchor_logits"),
        ("bad_missing_input.onnx", "missing input \"edge_features\""),
        ("bad_map_without_input.onnx", "missing input \"map\""),
        ("bad_truncated.onnx", "cannot load model"),
    ];
    for (name, needle) in cases {
        let err = load(name).unwrap_err();
        let msg = err.to_string();
        assert!(msg.contains(needle), "{name}: {msg:?} should mention {needle:?}");
        let kind_ok = match name {
            "bad_truncated.onnx" => matches!(err, DganError::ModelLoad { .. }),
            _ => matches!(err, DganError::Contract(_)),
        };
        assert!(kind_ok, "{name}: wrong error kind {err:?}");
    }
    assert!(matches!(load("does_not_exist.onnx"), Err(DganError::ModelNotFound(_))));
}

#[test]
fn bad_frames_are_typed_errors() {
    let p = load("contract_nomap.onnx").unwrap();
    let short = Frame::new(Array3::zeros((2, 5, 2)), None, vec![AgentClass::Vehicle; 2]).unwrap();
    assert!(matches!(p.predict(&short), Err(DganError::InvalidFrame(_))));
    assert!(matches!(p.predict_modes(&walkers(2), 0), Err(DganError::InvalidSpec(_))));
}

#[test]
fn predict_batch_equals_predict_per_frame() {
    let p = load("contract_nomap.onnx").unwrap();
    let frames = [walkers(3), Frame::new(Array3::zeros((0, 8, 2)), None, vec![]).unwrap(), walkers(5)];
    let batch = p.predict_batch(&frames, 4).unwrap();
    assert_eq!(batch.len(), 3);
    for (frame, got) in frames.iter().zip(&batch) {
        let want = p.predict_modes(frame, 4).unwrap();
        assert_eq!(got.agent_ids, want.agent_ids);
        assert_eq!(got.edges, want.edges);
        let worst = got.trajectories.iter().zip(&want.trajectories).map(|(a, b)| (a - b).abs()).fold(0.0, f64::max);
        assert!(worst < 1e-5, "batch and single predictions differ by {worst}");
    }
    assert!(p.predict_batch(&[], 4).unwrap().is_empty());
    assert!(matches!(p.predict_batch(&frames, 0), Err(DganError::InvalidSpec(_))));
}

/// Two groups of walkers 500 m apart: two components of the attention graph, `n` agents each.
fn two_groups(n: usize) -> Frame {
    let p = Array3::from_shape_fn((2 * n, 8, 2), |(i, t, d)| {
        let far = if i % 2 == 1 && d == 0 { 500.0 } else { 0.0 };
        let i = i / 2;
        far + if d == 0 { i as f64 * 1.5 + t as f64 * 0.5 } else { i as f64 * 0.7 - t as f64 * 0.1 }
    });
    Frame::new(p, None, (0..2 * n).map(|i| AgentClass::ALL[(i / 2) % 3]).collect()).expect("valid frame")
}

fn with_threads(name: &str, threads: usize) -> Predictor {
    let options = PredictorOptions {
        onnxruntime_library: Some(onnxruntime_library()),
        intra_threads: threads,
        ..Default::default()
    };
    Predictor::load_with(fixture(name), &options).expect("the fixture loads")
}

#[test]
fn a_frame_split_across_lanes_equals_one_call() {
    if dgan_core::limits::cores() < 2 {
        return; // threads = 2 is refused on one core (thread_counts_are_bounded_by_the_cores)
    }
    let (one, two) = (with_threads("contract_nomap.onnx", 1), with_threads("contract_nomap.onnx", 2));
    assert_eq!((one.lanes(), two.lanes()), (0, 2));
    // Interleaved rows, so that each part's rows are scattered through the frame and must be put back in order.
    let frame = two_groups(6);
    let want = one.predict_modes(&frame, 4).unwrap();
    let parts = dgan_core::batch::balanced_parts(
        12,
        &want.edges.rows().into_iter().map(|r| [r[0] as u32, r[1] as u32]).collect::<Vec<_>>(),
        2,
    );
    assert_eq!(parts, vec![vec![0, 2, 4, 6, 8, 10], vec![1, 3, 5, 7, 9, 11]], "the frame splits in two");
    for frame in [frame, walkers(12), walkers(4)] {
        let want = one.predict_modes(&frame, 4).unwrap();
        let got = two.predict_modes(&frame, 4).unwrap();
        assert_eq!(got.agent_ids, want.agent_ids);
        assert_eq!(got.edges, want.edges);
        assert_eq!(got.mode_classes, want.mode_classes);
        let worst = got.trajectories.iter().zip(&want.trajectories).map(|(a, b)| (a - b).abs()).fold(0.0, f64::max);
        assert!(worst < 1e-5, "split and single predictions differ by {worst}");
        let worst = got.probabilities.iter().zip(&want.probabilities).map(|(a, b)| (a - b).abs()).fold(0.0, f64::max);
        assert!(worst < 1e-6, "split and single probabilities differ by {worst}");
    }
}

#[test]
fn predict_batch_on_lanes_equals_predict_per_frame() {
    if dgan_core::limits::cores() < 2 {
        return;
    }
    let (one, two) = (with_threads("contract_nomap.onnx", 1), with_threads("contract_nomap.onnx", 2));
    let empty = Frame::new(Array3::zeros((0, 8, 2)), None, vec![]).unwrap();
    let frames = [walkers(3), empty, walkers(5), two_groups(5), walkers(1), walkers(7)];
    let batch = two.predict_batch(&frames, 3).unwrap();
    assert_eq!(batch.len(), frames.len());
    for (frame, got) in frames.iter().zip(&batch) {
        let want = one.predict_modes(frame, 3).unwrap();
        assert_eq!(got.agent_ids, want.agent_ids);
        assert_eq!(got.edges, want.edges);
        let worst = got.trajectories.iter().zip(&want.trajectories).map(|(a, b)| (a - b).abs()).fold(0.0, f64::max);
        assert!(worst < 1e-5, "batch on lanes and single predictions differ by {worst}");
    }
    // A bad frame is named by its index, whichever lane it fell to.
    let short = Frame::new(Array3::zeros((2, 5, 2)), None, vec![AgentClass::Vehicle; 2]).unwrap();
    let mut frames = frames.to_vec();
    frames.insert(4, short);
    let err = two.predict_batch(&frames, 3).unwrap_err();
    assert!(matches!(err, DganError::InvalidFrame(_)), "{err}");
    assert!(err.to_string().contains("frame 4 of the batch"), "{err}");
}

#[test]
fn each_predict_is_timed_by_phase() {
    let lane = VectorMap::new(vec![
        MapElement::new(MapElementKind::LaneCenterline, vec![[-50.0, 0.0], [50.0, 0.0]]).expect("a valid line")
    ]);
    for (name, map) in [("contract_nomap.onnx", false), ("contract_map.onnx", true)] {
        let p = load(name).unwrap();
        assert_eq!(p.last_times(), None, "no call yet");
        let frame = walkers(5).with_map(Arc::new(SceneMap::Vector(lane.clone())));
        p.predict_batch(std::slice::from_ref(&frame), 7).unwrap();
        assert_eq!(p.last_times(), None, "predict_batch is not timed");
        p.predict(&frame).unwrap();
        let t = p.last_times().expect("the call's times");
        let phases = t.preprocess + t.crops + t.network + t.decode + t.parts;
        assert!(phases <= t.total && t.network > std::time::Duration::ZERO, "{t:?}");
        assert_eq!(t.crops > std::time::Duration::ZERO, map, "{t:?}");
        assert_eq!(t.parts, std::time::Duration::ZERO, "{t:?}");
    }
}
