//! Several frames as one graph: their network inputs stacked along the agent axis, edge indices shifted by the
//! agents before them. The frames' graphs stay disjoint (no edge joins two frames), so the network gives every agent
//! the same outputs as it would in its own frame, in one call.

use crate::error::{DganError, Result};
use crate::preprocess::{Neighbors, NetworkInputs};
use ndarray::{concatenate, Array2, ArrayView, Axis, Dimension, RemoveAxis};

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
    let map = if same_presence(parts, |p| p.map.as_ref(), "map")? {
        Some(stack("map", parts.iter().filter_map(|p| p.map.as_ref().map(|m| m.view())).collect())?)
    } else {
        None
    };
    let map_present = if same_presence(parts, |p| p.map_present.as_ref(), "map_present")? {
        Some(stack("map_present", parts.iter().filter_map(|p| p.map_present.as_ref().map(|m| m.view())).collect())?)
    } else {
        None
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
        neighbors,
    };
    Ok(Joined { inputs, agent_ptr })
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
    fn rejects_mixed_inputs_and_nothing() {
        let a = inputs(1, array![[0, 0]], true);
        let b = inputs(1, array![[0, 0]], false);
        assert!(join(&[a, b]).is_err());
        assert!(join(&[]).is_err());
    }
}
