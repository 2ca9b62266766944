//! Rotating and translating the whole scene (agents, headings, velocities, map) leaves every agent-centric
//! network input unchanged.

use dgan_core::preprocess::preprocess;
use dgan_core::{
    AgentClass, Frame, GraphLayout, HeadingSource, InputSpec, MapElement, MapElementKind, MapSpec, PriorSpec, SceneMap,
    VectorMap,
};
use ndarray::{Array2, Array3};
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;
use std::sync::Arc;

fn rigid(p: [f64; 2], angle: f64, shift: [f64; 2]) -> [f64; 2] {
    let (s, c) = angle.sin_cos();
    [c * p[0] - s * p[1] + shift[0], s * p[0] + c * p[1] + shift[1]]
}

fn map(angle: f64, shift: [f64; 2]) -> SceneMap {
    let t = |pts: &[[f64; 2]]| pts.iter().map(|p| rigid(*p, angle, shift)).collect::<Vec<_>>();
    let el = |k, pts: &[[f64; 2]]| MapElement::new(k, t(pts)).expect("valid element");
    SceneMap::Vector(VectorMap::new(vec![
        el(MapElementKind::LaneCenterline, &[[-50.0, 1.75], [50.0, 1.75]]),
        el(MapElementKind::LaneLineDashed, &[[-50.0, 3.5], [50.0, 3.5]]),
        el(MapElementKind::RoadEdge, &[[-50.0, 7.0], [50.0, 7.0]]),
        el(MapElementKind::Crosswalk, &[[5.0, -7.0], [9.0, -7.0], [9.0, 7.0], [5.0, 7.0]]),
        el(MapElementKind::Obstacle, &[[-20.0, -1.0], [-10.0, -1.0], [-10.0, 0.0], [-20.0, 0.0]]),
    ]))
}

fn frame(angle: f64, shift: [f64; 2]) -> Frame {
    let mut rng = ChaCha8Rng::seed_from_u64(7);
    let n = 30;
    let mut p = Array3::zeros((n, 8, 2));
    let mut mask = Array2::from_elem((n, 8), true);
    let mut headings = vec![f64::NAN; n];
    let mut vel = Array2::from_elem((n, 2), f64::NAN);
    let mut classes = vec![];
    for i in 0..n {
        let start = [rng.random_range(-30.0..30.0), rng.random_range(-6.0..6.0)];
        let v = [rng.random_range(-3.0..12.0), rng.random_range(-1.0..1.0)];
        let a = [rng.random_range(-1.0..1.0), rng.random_range(-0.5..0.5)];
        for t in 0..8 {
            let tt = t as f64 * 0.2;
            // Every fifth agent tracked with jitter, which the spec's denoising smooths out.
            let jitter = if i % 5 == 2 { 0.15 * ((t * 7 % 5) as f64 - 2.0) } else { 0.0 };
            let q = [
                start[0] + v[0] * tt + 0.5 * a[0] * tt * tt + jitter,
                start[1] + v[1] * tt + 0.5 * a[1] * tt * tt - jitter,
            ];
            let w = rigid(q, angle, shift);
            p[[i, t, 0]] = w[0];
            p[[i, t, 1]] = w[1];
        }
        if i % 4 == 1 {
            for t in 0..3 {
                mask[[i, t]] = false;
            }
        }
        if i % 3 == 0 {
            headings[i] = 0.3 + angle;
            let rv = rigid(v, angle, [0.0, 0.0]);
            vel[[i, 0]] = rv[0];
            vel[[i, 1]] = rv[1];
        }
        classes.push(AgentClass::ALL[i % 3]);
    }
    Frame::new(p, Some(mask), classes)
        .expect("valid frame")
        .with_headings(&headings)
        .expect("valid headings")
        .with_velocities(vel.view())
        .expect("valid velocities")
        .with_map(Arc::new(map(angle, shift)))
}

fn close(a: &[f32], b: &[f32], tol: f32, what: &str) {
    assert_eq!(a.len(), b.len());
    let worst = a.iter().zip(b).map(|(x, y)| (x - y).abs()).fold(0.0f32, f32::max);
    assert!(worst <= tol, "{what}: max difference {worst} > {tol}");
}

#[test]
fn agent_centric_inputs_are_invariant_to_rigid_motions() {
    let spec = InputSpec {
        dt_s: 0.2,
        t_obs: 8,
        t_f: 15,
        classes: AgentClass::ALL.to_vec(),
        attention_lambda: 0.5,
        map: Some(MapSpec {
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
        }),
        prior: PriorSpec::constant_velocity(0.8),
        graph: GraphLayout::Padded,
        heading: HeadingSource::Measured,
        denoise_gate_m: 0.05,
    };
    let base = preprocess(&frame(0.0, [0.0, 0.0]), &spec).unwrap();
    for (angle, shift) in [(1.0, [100.0, -50.0]), (-2.5, [3000.0, 4000.0]), (std::f64::consts::PI, [0.0, 0.0])] {
        let moved = preprocess(&frame(angle, shift), &spec).unwrap();
        let (a, b) = (&base.inputs, &moved.inputs);
        close(a.trajectory.as_slice().unwrap(), b.trajectory.as_slice().unwrap(), 1e-3, "trajectory");
        assert_eq!(a.trajectory_mask, b.trajectory_mask);
        close(a.state.as_slice().unwrap(), b.state.as_slice().unwrap(), 1e-3, "state");
        assert_eq!(a.edge_index, b.edge_index, "edges");
        close(a.edge_features.as_slice().unwrap(), b.edge_features.as_slice().unwrap(), 1e-3, "edge features");
        close(base.prior.as_slice().unwrap(), moved.prior.as_slice().unwrap(), 1e-3, "kinematic prior");
        let (na, nb) = (a.neighbors.as_ref().unwrap(), b.neighbors.as_ref().unwrap());
        assert_eq!(na.index, nb.index, "padded neighbours");
        close(na.features.as_slice().unwrap(), nb.features.as_slice().unwrap(), 1e-3, "neighbour features");
        // Anti-aliased drawing of the same geometry differs only by rounding at a few edge pixels.
        let (ma, mb) = (a.map.as_ref().unwrap(), b.map.as_ref().unwrap());
        let diff: Vec<f32> = ma.iter().zip(mb.iter()).map(|(x, y)| (x - y).abs()).collect();
        let mean = diff.iter().sum::<f32>() / diff.len() as f32;
        let big = diff.iter().filter(|d| **d > 0.1).count() as f32 / diff.len() as f32;
        assert!(mean < 2e-3 && big < 2e-3, "map: mean diff {mean}, share of pixels off by > 0.1: {big}");
        assert!(ma.iter().any(|v| *v > 0.5), "the crops must not be empty");
    }
}
