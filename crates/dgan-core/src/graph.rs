//! The dynamic attention-zone graph: each agent has a circle of radius r_i = speed_i · T_f + λ · length_i around
//! its position at t_obs, and two agents are joined when their circles intersect (touching counts).
//!
//! [`attention_zone_edges`] gives exactly the edges of the O(N²) definition ([`attention_zone_edges_brute_force`])
//! from an R-tree of the circles' bounding boxes: O(N log N + E).

use crate::error::{DganError, Result};
use rstar::primitives::{GeomWithData, Rectangle};
use rstar::{RTree, AABB};

/// The attention radius r = speed · horizon + λ · length, in metres.
pub fn attention_radius(speed_mps: f64, horizon_s: f64, lambda: f64, length_m: f64) -> f64 {
    speed_mps * horizon_s + lambda * length_m
}

fn check(centres: &[[f64; 2]], radii: &[f64]) -> Result<()> {
    if centres.len() != radii.len() {
        return Err(DganError::InvalidFrame(format!("{} centres but {} radii", centres.len(), radii.len())));
    }
    if centres.len() > u32::MAX as usize {
        return Err(DganError::InvalidFrame("too many agents for a u32 graph index".into()));
    }
    if let Some(i) = radii.iter().position(|r| !(r.is_finite() && *r >= 0.0)) {
        return Err(DganError::InvalidFrame(format!("attention radius of agent {i} is {}", radii[i])));
    }
    if let Some(i) = centres.iter().position(|c| !(c[0].is_finite() && c[1].is_finite())) {
        return Err(DganError::InvalidFrame(format!("position of agent {i} is not finite")));
    }
    Ok(())
}

#[inline]
fn intersects(a: [f64; 2], ra: f64, b: [f64; 2], rb: f64) -> bool {
    let (dx, dy) = (a[0] - b[0], a[1] - b[1]);
    let r = ra + rb;
    dx * dx + dy * dy <= r * r
}

/// Undirected edges `[i, j]` with `i < j`, sorted, between agents whose attention circles intersect.
pub fn attention_zone_edges(centres: &[[f64; 2]], radii: &[f64]) -> Result<Vec<[u32; 2]>> {
    attention_zone_edges_within(centres, radii, usize::MAX)
}

/// [`attention_zone_edges`], refused with [`DganError::SceneTooLarge`] as soon as more than `max_edges` edges are
/// found: the work stays bounded by about `max_edges + N` whatever the scene (1,000 agents on one point would make
/// 499,500 edges).
pub fn attention_zone_edges_within(centres: &[[f64; 2]], radii: &[f64], max_edges: usize) -> Result<Vec<[u32; 2]>> {
    attention_zone_edges_on(centres, radii, max_edges, crate::limits::cores())
}

/// [`attention_zone_edges_within`] with the queries of a frame of [`PARALLEL_FROM_AGENTS`] or more shared out over up
/// to `threads` threads ([`crate::limits::share_jobs`]), in jobs of [`AGENTS_PER_JOB`] agents. The same edges
/// whatever the threads.
pub fn attention_zone_edges_on(
    centres: &[[f64; 2]],
    radii: &[f64],
    max_edges: usize,
    threads: usize,
) -> Result<Vec<[u32; 2]>> {
    use std::sync::atomic::{AtomicUsize, Ordering};
    check(centres, radii)?;
    let boxes: Vec<GeomWithData<Rectangle<[f64; 2]>, u32>> = centres
        .iter()
        .zip(radii)
        .enumerate()
        .map(|(i, (c, r))| {
            GeomWithData::new(Rectangle::from_corners([c[0] - r, c[1] - r], [c[0] + r, c[1] + r]), i as u32)
        })
        .collect();
    let tree = RTree::bulk_load(boxes);
    let found = AtomicUsize::new(0);
    let edges_of = |i: usize| {
        if found.load(Ordering::Relaxed) > max_edges {
            return vec![];
        }
        let (c, r) = (centres[i], radii[i]);
        let envelope = AABB::from_corners([c[0] - r, c[1] - r], [c[0] + r, c[1] + r]);
        let mut out: Vec<[u32; 2]> = tree
            .locate_in_envelope_intersecting(&envelope)
            .map(|g| g.data)
            .filter(|&j| (j as usize) > i && intersects(c, r, centres[j as usize], radii[j as usize]))
            .map(|j| [i as u32, j])
            .collect();
        out.sort_unstable();
        found.fetch_add(out.len(), Ordering::Relaxed);
        out
    };
    // Below a few thousand agents the queries take well under a millisecond: one thread.
    let mut per_agent: Vec<Vec<[u32; 2]>> = vec![Vec::new(); centres.len()];
    if centres.len() < PARALLEL_FROM_AGENTS || threads <= 1 {
        per_agent.iter_mut().enumerate().for_each(|(i, slot)| *slot = edges_of(i));
    } else {
        let jobs: Vec<(usize, &mut [Vec<[u32; 2]>])> =
            per_agent.chunks_mut(AGENTS_PER_JOB).enumerate().map(|(k, slots)| (k * AGENTS_PER_JOB, slots)).collect();
        let one = |(first, slots): (usize, &mut [Vec<[u32; 2]>])| {
            slots.iter_mut().enumerate().for_each(|(k, slot)| *slot = edges_of(first + k));
            Ok(())
        };
        let panicked = || DganError::InvalidFrame("an attention-graph thread panicked".into());
        crate::limits::share_jobs(jobs, threads, one, panicked)?;
    }
    let total = found.into_inner();
    if total > max_edges {
        return Err(DganError::SceneTooLarge(format!(
            "the attention graph has more than {max_edges} edges (at least {total}, among {} agents): the agents' \
             attention zones overlap too much for the network's memory and time; raise the limit \
             (max_edges of the Predictor) or predict fewer agents at once",
            centres.len()
        )));
    }
    Ok(per_agent.concat())
}

/// From this many agents on, the attention graph's queries are shared out over the threads a call may use.
pub const PARALLEL_FROM_AGENTS: usize = 2000;
/// Agents a thread queries at a time.
const AGENTS_PER_JOB: usize = 256;

/// The O(N²) definition, for tests and benchmarks.
pub fn attention_zone_edges_brute_force(centres: &[[f64; 2]], radii: &[f64]) -> Result<Vec<[u32; 2]>> {
    check(centres, radii)?;
    let mut out = Vec::new();
    for i in 0..centres.len() {
        for j in i + 1..centres.len() {
            if intersects(centres[i], radii[i], centres[j], radii[j]) {
                out.push([i as u32, j as u32]);
            }
        }
    }
    Ok(out)
}

/// The connected components of `n` nodes joined by `pairs` (pairs naming a node `>= n` are ignored): each
/// component's nodes ascending, the components in the order of their lowest node.
pub fn components(n: usize, pairs: impl IntoIterator<Item = (usize, usize)>) -> Vec<Vec<usize>> {
    let mut parent: Vec<usize> = (0..n).collect();
    fn root(parent: &mut [usize], mut x: usize) -> usize {
        while parent[x] != x {
            parent[x] = parent[parent[x]];
            x = parent[x];
        }
        x
    }
    for (a, b) in pairs {
        if a < n && b < n {
            let (ra, rb) = (root(&mut parent, a), root(&mut parent, b));
            parent[ra.max(rb)] = ra.min(rb);
        }
    }
    let mut index = vec![usize::MAX; n];
    let mut out: Vec<Vec<usize>> = vec![];
    for i in 0..n {
        let r = root(&mut parent, i);
        if index[r] == usize::MAX {
            index[r] = out.len();
            out.push(vec![]);
        }
        out[index[r]].push(i);
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn components_follow_every_chain_and_ignore_pairs_out_of_range() {
        let got = components(6, [(4, 3), (0, 2), (2, 5), (9, 1)]);
        assert_eq!(got, vec![vec![0, 2, 5], vec![1], vec![3, 4]]);
        assert!(components(0, []).is_empty());
    }

    #[test]
    fn touching_circles_are_joined() {
        let c = [[0.0, 0.0], [3.0, 0.0], [10.0, 0.0]];
        let r = [1.0, 2.0, 1.0];
        assert_eq!(attention_zone_edges(&c, &r).unwrap(), vec![[0, 1]]);
        assert_eq!(attention_zone_edges_brute_force(&c, &r).unwrap(), vec![[0, 1]]);
    }

    #[test]
    fn radius_follows_the_paper() {
        // 1.5 m/s over 4.8 s plus 0.5 × 0.5 m.
        assert!((attention_radius(1.5, 4.8, 0.5, 0.5) - 7.45).abs() < 1e-12);
    }

    #[test]
    fn bad_radii_are_errors() {
        assert!(attention_zone_edges(&[[0.0, 0.0]], &[f64::NAN]).is_err());
        assert!(attention_zone_edges(&[[0.0, 0.0]], &[-1.0]).is_err());
        assert!(attention_zone_edges(&[[0.0, 0.0]], &[]).is_err());
        assert!(attention_zone_edges(&[], &[]).unwrap().is_empty());
    }

    #[test]
    fn the_edge_budget_stops_early() {
        // 2,000 agents on one point would make 1,999,000 edges: refused fast, past the budget.
        let c = vec![[5.0, 5.0]; 2000];
        let r = vec![1.0; 2000];
        let started = std::time::Instant::now();
        let err = attention_zone_edges_within(&c, &r, 10_000).unwrap_err();
        assert!(matches!(err, DganError::SceneTooLarge(_)), "{err}");
        assert!(err.to_string().contains("more than 10000 edges"), "{err}");
        assert!(started.elapsed().as_secs_f64() < 1.0);
        assert_eq!(attention_zone_edges_within(&c[..100], &r[..100], 4950).unwrap().len(), 4950);
    }
}
