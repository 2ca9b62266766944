//! The attention-zone graph equals the O(N²) definition on random scenes up to 10,000 agents.

use dgan_core::graph::{attention_zone_edges, attention_zone_edges_brute_force, attention_zone_edges_on};
use proptest::prelude::*;
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;

/// A scene of `n` agents at a density of about one per `area_per_agent` m², with pedestrian-to-vehicle radii and a
/// few very large ones.
fn scene(n: usize, seed: u64, area_per_agent: f64) -> (Vec<[f64; 2]>, Vec<f64>) {
    let mut rng = ChaCha8Rng::seed_from_u64(seed);
    let side = (n as f64 * area_per_agent).sqrt().max(1.0);
    let centres = (0..n).map(|_| [rng.random_range(0.0..side), rng.random_range(0.0..side)]).collect();
    let radii = (0..n)
        .map(|_| match rng.random_range(0..100) {
            0 => rng.random_range(20.0..80.0),
            1..=30 => rng.random_range(5.0..15.0),
            _ => rng.random_range(0.0..4.0),
        })
        .collect();
    (centres, radii)
}

#[test]
fn ten_thousand_agents_match_brute_force() {
    for (seed, density) in [(1, 400.0), (2, 100.0), (3, 2500.0)] {
        let (c, r) = scene(10_000, seed, density);
        let fast = attention_zone_edges(&c, &r).unwrap();
        let slow = attention_zone_edges_brute_force(&c, &r).unwrap();
        assert!(!fast.is_empty());
        assert_eq!(fast, slow, "seed {seed}");
    }
}

#[test]
fn the_edges_are_the_same_whatever_the_threads() {
    let (c, r) = scene(6_000, 4, 300.0);
    let slow = attention_zone_edges_brute_force(&c, &r).unwrap();
    for threads in [1, 2, 3, 16] {
        assert_eq!(attention_zone_edges_on(&c, &r, usize::MAX, threads).unwrap(), slow, "{threads} threads");
    }
    // The edge budget holds on threads too.
    let err = attention_zone_edges_on(&vec![[0.0, 0.0]; 3000], &vec![1.0; 3000], 50_000, 4).unwrap_err();
    assert!(err.to_string().contains("more than 50000 edges"), "{err}");
}

#[test]
fn clustered_and_degenerate_scenes_match() {
    // Everyone at one point, zero radii: all pairs touch.
    let c = vec![[3.0, 4.0]; 50];
    let r = vec![0.0; 50];
    assert_eq!(attention_zone_edges(&c, &r).unwrap().len(), 50 * 49 / 2);
    // Agents on a line exactly touching their neighbours.
    let c: Vec<[f64; 2]> = (0..100).map(|i| [i as f64 * 2.0, 0.0]).collect();
    let r = vec![1.0; 100];
    assert_eq!(attention_zone_edges(&c, &r).unwrap(), attention_zone_edges_brute_force(&c, &r).unwrap());
    assert_eq!(attention_zone_edges(&c, &r).unwrap().len(), 99);
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(24))]
    #[test]
    fn random_scenes_match(n in 0usize..10_000, seed in any::<u64>(), density in 10.0..3000.0f64) {
        let (c, r) = scene(n, seed, density);
        prop_assert_eq!(attention_zone_edges(&c, &r).unwrap(), attention_zone_edges_brute_force(&c, &r).unwrap());
    }
}
