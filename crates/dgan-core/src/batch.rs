//! Several frames as one graph: their network inputs stacked along the agent axis, edge indices shifted by the
//! agents before them. The frames' graphs stay disjoint (no edge joins two frames), so the network gives every agent
//! the same outputs as it would in its own frame, in one call.

use crate::error::{DganError, Result};
use crate::preprocess::{Neighbors, NetworkInputs};
use ndarray::{concatenate, Array1, Array2, Array5, ArrayView, Axis, Dimension, RemoveAxis};

/// Joined inputs and where each frame's agents are: frame `f` holds rows `agent_ptr[f]..agent_ptr[f + 1]`.
#[derive(Debug, Clone)]
pub struct Joined {
    /// The stacked network inputs.
    pub inputs: NetworkInputs,
    /// `F + 1` offsets of each frame's agents.
    pub agent_ptr: Vec<usize>,
}

fn stack<A: Clone, D: RemoveAxis>(name: &str, views: Vec<ArrayView<'_, A, D>>) -> Result<ndarray::Array<A, D>> {
    concatenate(Axis(0), &views).map_err(|e| DganError::InvalidSpec(format!("cannot join {name}: {e}")))
}

fn same_presence<T>(parts: &[NetworkInputs], get: impl Fn(&NetworkInputs) -> Option<&T>, name: &str) -> Result<bool> {
    let some = parts.iter().filter(|p| get(p).is_some()).count();
    if some != 0 && some != parts.len() {
        return Err(DganError::InvalidSpec(format!("{name} is given for some frames and not others")));
    }
    Ok(some > 0)
}

/// Stacks the inputs of several frames preprocessed under one specification.
pub fn join(parts: &[NetworkInputs]) -> Result<Joined> {
    if parts.is_empty() {
        return Err(DganError::InvalidSpec("no frames to join".into()));
    }
    let mut agent_ptr = vec![0];
    for p in parts {
        agent_ptr.push(agent_ptr.last().copied().unwrap_or(0) + p.trajectory.dim().0);
    }
    let shifted: Vec<Array2<i64>> =
        parts.iter().zip(&agent_ptr).map(|(p, &offset)| p.edge_index.mapv(|v| v + offset as i64)).collect();
    // A kept-features model's reads (contract 13) join with their tiles' rasters (a tile computed once).
    let (mut kept, mut tiles) = (None, None);
    if same_presence(parts, |p| p.kept.as_ref(), "kept map features")? {
        let pairs: Vec<(&crate::kept::KeptReads, &ndarray::Array4<f32>)> = parts
            .iter()
            .map(|p| p.kept.as_ref().zip(p.map.as_ref()))
            .collect::<Option<_>>()
            .ok_or_else(|| DganError::InvalidSpec("kept map features without their tiles' rasters".into()))?;
        let (reads, rasters) = crate::kept::KeptReads::join(&pairs)?;
        (kept, tiles) = (Some(reads), Some(rasters));
    }
    let map = if tiles.is_some() {
        tiles
    } else if same_presence(parts, |p| p.map.as_ref(), "map")? {
        Some(stack("map", parts.iter().filter_map(|p| p.map.as_ref().map(|m| m.view())).collect())?)
    } else {
        None
    };
    let map_present = if same_presence(parts, |p| p.map_present.as_ref(), "map_present")? {
        Some(stack("map_present", parts.iter().filter_map(|p| p.map_present.as_ref().map(|m| m.view())).collect())?)
    } else {
        None
    };
    // A scene model's rasters (each frame's groups) stack; their grids pad to the largest group, slots follow.
    let (map_grid, map_slot) = if same_presence(parts, |p| p.map_grid.as_ref(), "map_grid")? {
        let grids: Vec<(&Array5<f32>, &Array1<i64>)> = parts
            .iter()
            .map(|p| p.map_grid.as_ref().zip(p.map_slot.as_ref()))
            .collect::<Option<_>>()
            .ok_or_else(|| DganError::InvalidSpec("map_grid without map_slot".into()))?;
        let most = grids.iter().map(|(g, _)| g.dim().1).max().unwrap_or(0);
        let (_, _, gh, gw, _) = grids[0].0.dim();
        let rasters: usize = grids.iter().map(|(g, _)| g.dim().0).sum();
        let mut grid = Array5::<f32>::zeros((rasters, most, gh, gw, 2));
        let mut slot = Vec::with_capacity(agent_ptr.last().copied().unwrap_or(0));
        let mut base = 0;
        for (g, s) in &grids {
            let (c, m, h, w, _) = g.dim();
            if (h, w) != (gh, gw) {
                return Err(DganError::InvalidSpec(format!("cannot join map_grid of shape {:?}", g.dim())));
            }
            grid.slice_mut(ndarray::s![base..base + c, ..m, .., .., ..]).assign(g);
            let m = m.max(1) as i64;
            slot.extend(s.iter().map(|&v| (base as i64 + v / m) * most as i64 + v % m));
            base += c;
        }
        (Some(grid), Some(Array1::from(slot)))
    } else {
        (None, None)
    };
    fn views<'a, A: 'a, D: Dimension + 'a>(
        parts: &'a [NetworkInputs],
        f: impl Fn(&'a NetworkInputs) -> &'a ndarray::Array<A, D>,
    ) -> Vec<ArrayView<'a, A, D>> {
        parts.iter().map(|p| f(p).view()).collect()
    }
    let neighbors = if same_presence(parts, |p| p.neighbors.as_ref(), "neighbors")? {
        let d = parts.iter().filter_map(|p| p.neighbors.as_ref()).map(|nb| nb.index.ncols()).max().unwrap_or(1);
        let n = agent_ptr.last().copied().unwrap_or(0);
        let f = parts.iter().filter_map(|p| p.neighbors.as_ref()).map(|nb| nb.features.dim().2).max().unwrap_or(0);
        let mut index = Array2::from_shape_fn((n, d), |(i, _)| i as i64);
        let mut mask = Array2::<f32>::zeros((n, d));
        let mut features = ndarray::Array3::<f32>::zeros((n, d, f));
        for (p, &offset) in parts.iter().zip(&agent_ptr) {
            if let Some(nb) = &p.neighbors {
                let (rows, cols) = nb.index.dim();
                let r = ndarray::s![offset..offset + rows, ..cols];
                index.slice_mut(r).assign(&nb.index.mapv(|v| v + offset as i64));
                mask.slice_mut(r).assign(&nb.mask);
                features.slice_mut(ndarray::s![offset..offset + rows, ..cols, ..]).assign(&nb.features);
            }
        }
        Some(Neighbors { index, mask, features })
    } else {
        None
    };
    let inputs = NetworkInputs {
        trajectory: stack("trajectory", views(parts, |p| &p.trajectory))?,
        trajectory_mask: stack("trajectory_mask", views(parts, |p| &p.trajectory_mask))?,
        state: stack("state", views(parts, |p| &p.state))?,
        edge_index: stack("edge_index", shifted.iter().map(|e| e.view()).collect())?,
        edge_features: stack("edge_features", views(parts, |p| &p.edge_features))?,
        map,
        map_present,
        map_grid,
        map_slot,
        kept,
        neighbors,
    };
    Ok(Joined { inputs, agent_ptr })
}

/// The inputs of the agents `rows` (in that order) of one frame, their edges re-indexed: `rows` must be closed under
/// the frame's edges (a union of the graph's components), so that every agent keeps all its neighbours and the
/// network gives it the outputs it would give it in the whole frame. The neighbour lists keep their padded width.
pub fn take(inputs: &NetworkInputs, rows: &[usize]) -> Result<NetworkInputs> {
    let n = inputs.trajectory.dim().0;
    let mut new_index = vec![-1i64; n];
    for (k, &r) in rows.iter().enumerate() {
        let slot = new_index.get_mut(r).ok_or_else(|| DganError::InvalidSpec(format!("agent {r} of {n} taken")))?;
        if *slot >= 0 {
            return Err(DganError::InvalidSpec(format!("agent {r} taken twice")));
        }
        *slot = k as i64;
    }
    let inside = |v: i64| usize::try_from(v).ok().and_then(|v| new_index.get(v).copied()).filter(|k| *k >= 0);
    // Agent indices of the taken rows, re-indexed; a neighbour outside the part is refused.
    let remapped = |a: Array2<i64>| -> Result<Array2<i64>> {
        let mut out = a;
        for v in out.iter_mut() {
            *v = inside(*v)
                .ok_or_else(|| DganError::InvalidSpec(format!("agent {v} is a neighbour outside the part taken")))?;
        }
        Ok(out)
    };
    let kept: Vec<usize> =
        (0..inputs.edge_index.nrows()).filter(|&e| inside(inputs.edge_index[[e, 0]]).is_some()).collect();
    // A scene model's part keeps the rasters (and grids) of its agents' groups, in their order, its agents' slots
    // pointing into them: whole groups, as the predictor's parts take them.
    let scene = match (&inputs.map_grid, &inputs.map_slot) {
        (Some(g), Some(s)) => {
            let most = g.dim().1.max(1) as i64;
            let mut groups: Vec<usize> = rows.iter().map(|&r| (s[r] / most) as usize).collect();
            groups.sort_unstable();
            groups.dedup();
            let slots = rows
                .iter()
                .map(|&r| {
                    let k = groups.binary_search(&((s[r] / most) as usize)).unwrap_or(0) as i64;
                    k * most + s[r] % most
                })
                .collect::<Array1<i64>>();
            Some((groups, slots))
        }
        _ => None,
    };
    let edge_index = remapped(inputs.edge_index.select(Axis(0), &kept))?;
    let neighbors = match &inputs.neighbors {
        Some(nb) => {
            let index = remapped(nb.index.select(Axis(0), rows))?;
            Some(Neighbors { index, mask: nb.mask.select(Axis(0), rows), features: nb.features.select(Axis(0), rows) })
        }
        None => None,
    };
    // A kept-features model's part reads the blocks its agents read, and computes the tiles among them.
    let (reads, tiles) = match (&inputs.kept, &inputs.map) {
        (Some(k), Some(m)) => {
            let (reads, tiles) = k.take(m, rows);
            (Some(reads), Some(tiles))
        }
        _ => (None, None),
    };
    Ok(NetworkInputs {
        trajectory: inputs.trajectory.select(Axis(0), rows),
        trajectory_mask: inputs.trajectory_mask.select(Axis(0), rows),
        state: inputs.state.select(Axis(0), rows),
        edge_features: inputs.edge_features.select(Axis(0), &kept),
        edge_index,
        map: match (&scene, &inputs.map) {
            _ if tiles.is_some() => tiles,
            (Some((groups, _)), Some(m)) => Some(m.select(Axis(0), groups)),
            (None, Some(m)) => Some(m.select(Axis(0), rows)),
            (_, None) => None,
        },
        map_present: inputs.map_present.as_ref().map(|m| m.select(Axis(0), rows)),
        map_grid: match (&scene, &inputs.map_grid) {
            (Some((groups, _)), Some(g)) => Some(g.select(Axis(0), groups)),
            _ => None,
        },
        map_slot: scene.map(|(_, slots)| slots),
        kept: reads,
        neighbors,
    })
}

/// The attention graph's components as parts for `parts` concurrent calls: each component whole, the largest first
/// to the part with the fewest agents; each part's rows ascending. Parts may be empty.
pub fn balanced_parts(n: usize, edges: &[[u32; 2]], parts: usize) -> Vec<Vec<usize>> {
    let mut components = crate::graph::components(n, edges.iter().map(|&[a, b]| (a as usize, b as usize)));
    // Largest first; ties in order of their first agent (the sort is stable), so the parts are deterministic.
    components.sort_by_key(|c| std::cmp::Reverse(c.len()));
    let mut out = vec![vec![]; parts.max(1)];
    for c in components {
        if let Some(lightest) = out.iter_mut().min_by_key(|p| p.len()) {
            lightest.extend(c);
        }
    }
    for p in &mut out {
        p.sort_unstable();
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;
    use ndarray::{array, Array1, Array3, Array4};

    fn inputs(n: usize, edges: Array2<i64>, map: bool) -> NetworkInputs {
        let e = edges.nrows();
        NetworkInputs {
            trajectory: Array3::from_elem((n, 2, 2), n as f32),
            trajectory_mask: Array2::ones((n, 2)),
            state: Array2::zeros((n, 8)),
            edge_index: edges,
            edge_features: Array2::zeros((e, 6)),
            map: map.then(|| Array4::zeros((n, 3, 2, 2))),
            map_present: map.then(|| Array1::ones(n)),
            map_grid: None,
            map_slot: None,
            kept: None,
            neighbors: None,
        }
    }

    #[test]
    fn joins_and_shifts_edges() {
        let a = inputs(2, array![[0, 0], [0, 1], [1, 0], [1, 1]], true);
        let b = inputs(1, array![[0, 0]], true);
        let j = join(&[a, b]).unwrap();
        assert_eq!(j.agent_ptr, vec![0, 2, 3]);
        assert_eq!(j.inputs.edge_index.row(4).to_vec(), vec![2, 2]);
        assert_eq!(j.inputs.trajectory[[2, 0, 0]], 1.0);
        assert_eq!(j.inputs.map.unwrap().dim().0, 3);
        assert_eq!(j.inputs.map_present.unwrap().len(), 3);
    }

    /// A scene model's inputs (contract 12): one raster `(1, 3, 4, 4)`, each agent's 1 × 1 grid at `(i, 10 n)`.
    fn scene_inputs(n: usize) -> NetworkInputs {
        let mut x = inputs(n, Array2::from_shape_fn((n, 2), |(i, _)| i as i64), true);
        x.map = Some(Array4::from_elem((1, 3, 4, 4), n as f32));
        x.map_grid =
            Some(ndarray::Array5::from_shape_fn((1, n, 1, 1, 2), |(_, i, _, _, d)| [i as f32, 10.0 * n as f32][d]));
        x.map_slot = Some(Array1::from_iter(0..n as i64));
        x
    }

    #[test]
    fn joins_scene_rasters_and_pads_their_grids() {
        let j = join(&[scene_inputs(2), scene_inputs(3), scene_inputs(1)]).unwrap().inputs;
        let (map, grid, slot) = (j.map.unwrap(), j.map_grid.unwrap(), j.map_slot.unwrap());
        assert_eq!((map.dim(), grid.dim()), ((3, 3, 4, 4), (3, 3, 1, 1, 2)));
        assert_eq!(map[[1, 0, 0, 0]], 3.0);
        assert_eq!(slot.to_vec(), vec![0, 1, 3, 4, 5, 6]);
        // Each agent's slot finds its own grid: frame f's agent i at (i, 10 n_f); padding is zeros.
        let flat = grid.into_shape_with_order((9, 1, 1, 2)).unwrap();
        let read: Vec<[f32; 2]> =
            slot.iter().map(|&s| [flat[[s as usize, 0, 0, 0]], flat[[s as usize, 0, 0, 1]]]).collect();
        assert_eq!(read, vec![[0.0, 20.0], [1.0, 20.0], [0.0, 30.0], [1.0, 30.0], [2.0, 30.0], [0.0, 10.0]]);
        assert_eq!(flat[[2, 0, 0, 1]], 0.0);
        // A part of a scene frame keeps its groups' rasters and grids, its agents' slots pointing into them.
        let part = take(&scene_inputs(3), &[2]).unwrap();
        assert_eq!(part.map.unwrap().dim(), (1, 3, 4, 4));
        assert_eq!(part.map_grid.unwrap().dim(), (1, 3, 1, 1, 2));
        assert_eq!(part.map_slot.unwrap().to_vec(), vec![2]);
        let mut groups = scene_inputs(3);
        groups.map = Some(Array4::from_shape_fn((2, 3, 4, 4), |(g, _, _, _)| g as f32));
        groups.map_grid = Some(ndarray::Array5::from_shape_fn((2, 2, 1, 1, 2), |(g, _, _, _, _)| g as f32));
        groups.map_slot = Some(Array1::from(vec![0, 2, 1]));
        let second = take(&groups, &[1]).unwrap();
        assert_eq!(second.map.unwrap().iter().copied().fold(0.0, f32::max), 1.0);
        assert_eq!(second.map_grid.unwrap().dim(), (1, 2, 1, 1, 2));
        assert_eq!(second.map_slot.unwrap().to_vec(), vec![0]);
        // A frame of two groups (two rasters, slots 0, 2, 1 of M = 2) joined after one of three agents.
        let mut two = scene_inputs(3);
        two.map = Some(Array4::from_elem((2, 3, 4, 4), 7.0));
        two.map_grid = Some(ndarray::Array5::zeros((2, 2, 1, 1, 2)));
        two.map_slot = Some(Array1::from(vec![0, 2, 1]));
        let j = join(&[scene_inputs(3), two]).unwrap().inputs;
        assert_eq!(j.map.unwrap().dim(), (3, 3, 4, 4));
        assert_eq!(j.map_slot.unwrap().to_vec(), vec![0, 1, 2, 3, 6, 4]);
        // Rasters of different sides do not stack: the predictor joins only frames of one side.
        let mut other = scene_inputs(1);
        other.map = Some(Array4::zeros((1, 3, 8, 8)));
        assert!(matches!(join(&[scene_inputs(1), other]), Err(DganError::InvalidSpec(_))));
    }

    #[test]
    fn joins_padded_neighbours_of_different_degrees() {
        let with = |n: usize, edges: Array2<i64>| {
            let mut x = inputs(n, edges.clone(), false);
            x.neighbors = Some(Neighbors::from_edges(n, &edges, &x.edge_features).unwrap());
            x
        };
        let a = with(2, array![[0, 0], [0, 1], [1, 0], [1, 1]]);
        let b = with(1, array![[0, 0]]);
        let nb = join(&[a, b]).unwrap().inputs.neighbors.unwrap();
        assert_eq!(nb.index.dim(), (3, 2));
        assert_eq!(nb.index.row(2).to_vec(), vec![2, 2]);
        assert_eq!(nb.mask.row(2).to_vec(), vec![1.0, 0.0]);
        assert_eq!(nb.index.row(1).to_vec(), vec![0, 1]);
    }

    #[test]
    fn takes_a_part_closed_under_its_edges() {
        let edges = array![[0, 0], [0, 2], [1, 1], [2, 0], [2, 2]];
        let mut x = inputs(3, edges.clone(), true);
        x.trajectory = Array3::from_shape_fn((3, 2, 2), |(i, _, _)| i as f32);
        x.edge_features = Array2::from_shape_fn((5, 6), |(e, _)| e as f32);
        x.neighbors = Some(Neighbors::from_edges(3, &edges, &x.edge_features).unwrap());
        let part = take(&x, &[0, 2]).unwrap();
        assert_eq!(part.trajectory.dim().0, 2);
        assert_eq!(part.trajectory[[1, 0, 0]], 2.0);
        assert_eq!(part.edge_index, array![[0, 0], [0, 1], [1, 0], [1, 1]]);
        assert_eq!(part.edge_features.column(0).to_vec(), vec![0.0, 1.0, 3.0, 4.0]);
        let nb = part.neighbors.unwrap();
        assert_eq!(nb.index, array![[0, 1], [0, 1]]);
        assert_eq!(nb.mask, array![[1.0, 1.0], [1.0, 1.0]]);
        assert_eq!(part.map.unwrap().dim().0, 2);
        let lone = take(&x, &[1]).unwrap();
        assert_eq!(lone.neighbors.unwrap().index, array![[0, 0]]);
        // A part that cuts an edge, an agent twice or out of range: refused.
        assert!(take(&x, &[0]).is_err());
        assert!(take(&x, &[1, 1]).is_err());
        assert!(take(&x, &[5]).is_err());
    }

    #[test]
    fn parts_keep_components_whole_and_balance_them() {
        // Components {0, 1, 2}, {3, 4}, {5}, {6}.
        let parts = balanced_parts(7, &[[0, 1], [1, 2], [3, 4]], 2);
        assert_eq!(parts, vec![vec![0, 1, 2, 6], vec![3, 4, 5]]);
        assert_eq!(balanced_parts(3, &[[0, 1], [1, 2]], 2), vec![vec![0, 1, 2], vec![]]);
        assert_eq!(balanced_parts(0, &[], 2), vec![Vec::<usize>::new(), vec![]]);
        assert_eq!(balanced_parts(2, &[], 1), vec![vec![0, 1]]);
    }

    #[test]
    fn rejects_mixed_inputs_and_nothing() {
        let a = inputs(1, array![[0, 0]], true);
        let b = inputs(1, array![[0, 0]], false);
        assert!(join(&[a, b]).is_err());
        assert!(join(&[]).is_err());
    }
}
