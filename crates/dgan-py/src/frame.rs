//! `Frame`, `RasterMap` and `VectorMap`: owned, validated copies of the caller's arrays.

use crate::error::{invalid_frame, to_py, IntoPyResult};
use dgan_core::{AgentClass, DganError, Frame, MapElement, MapElementKind, RasterMap, SceneMap, VectorMap};
use ndarray::{Array2, Array3, Ix2, Ix3};
use numpy::{IntoPyArray, PyArray1, PyArray2, PyArray3, PyReadonlyArrayDyn};
use pyo3::prelude::*;
use pyo3::types::PyList;
use std::sync::Arc;

fn dims<T: numpy::Element + Clone, D: ndarray::Dimension>(
    name: &str,
    shape_hint: &str,
    a: &PyReadonlyArrayDyn<'_, T>,
) -> PyResult<ndarray::Array<T, D>> {
    let view = a.as_array();
    let shape = view.shape().to_vec();
    view.to_owned()
        .into_dimensionality::<D>()
        .map_err(|_| invalid_frame(format!("{name} must have shape {shape_hint}, got {shape:?}")))
}

/// Classes given as names or canonical integer codes.
pub(crate) fn parse_classes(classes: &Bound<'_, PyAny>) -> PyResult<Vec<AgentClass>> {
    let list = classes.cast::<PyList>().map_err(|_| invalid_frame("classes must be a list of names or integers"))?;
    list.iter()
        .map(|item| {
            if let Ok(s) = item.extract::<String>() {
                s.parse::<AgentClass>().py()
            } else if let Ok(i) = item.extract::<i64>() {
                AgentClass::from_code(i).py()
            } else {
                Err(to_py(DganError::UnknownClass(format!("{item}: classes are names or integer codes"))))
            }
        })
        .collect()
}

fn scene_map(map: &Bound<'_, PyAny>) -> PyResult<Arc<SceneMap>> {
    if let Ok(r) = map.cast::<PyRasterMap>() {
        Ok(r.get().inner.clone())
    } else if let Ok(v) = map.cast::<PyVectorMap>() {
        Ok(v.get().inner.clone())
    } else {
        Err(to_py(DganError::InvalidMap("map must be a dgan.RasterMap or dgan.VectorMap".into())))
    }
}

/// A validated scene at t_obs (see `dgan.Frame`).
#[derive(Debug)]
#[pyclass(name = "Frame", module = "dgan._dgan", frozen)]
pub struct PyFrame {
    pub(crate) inner: Frame,
}

#[pymethods]
impl PyFrame {
    #[new]
    #[pyo3(signature = (positions, mask, classes, ids, headings, velocities, lengths, widths, map, dt = None))]
    #[allow(clippy::too_many_arguments)]
    fn new(
        positions: PyReadonlyArrayDyn<'_, f64>,
        mask: Option<PyReadonlyArrayDyn<'_, bool>>,
        classes: &Bound<'_, PyAny>,
        ids: Option<PyReadonlyArrayDyn<'_, i64>>,
        headings: Option<PyReadonlyArrayDyn<'_, f64>>,
        velocities: Option<PyReadonlyArrayDyn<'_, f64>>,
        lengths: Option<PyReadonlyArrayDyn<'_, f64>>,
        widths: Option<PyReadonlyArrayDyn<'_, f64>>,
        map: Option<&Bound<'_, PyAny>>,
        dt: Option<f64>,
    ) -> PyResult<Self> {
        let positions: Array3<f64> = dims::<f64, Ix3>("positions", "(N, T, 2)", &positions)?;
        let mask: Option<Array2<bool>> = mask.map(|m| dims::<bool, Ix2>("mask", "(N, T)", &m)).transpose()?;
        let classes = parse_classes(classes)?;
        let mut frame = Frame::new(positions, mask, classes).py()?;
        let vec1 = |name: &str, a: Option<PyReadonlyArrayDyn<'_, f64>>| -> PyResult<Option<Vec<f64>>> {
            a.map(|a| dims::<f64, ndarray::Ix1>(name, "(N,)", &a).map(|v| v.to_vec())).transpose()
        };
        if let Some(ids) = ids {
            frame = frame.with_ids(dims::<i64, ndarray::Ix1>("ids", "(N,)", &ids)?.to_vec()).py()?;
        }
        if let Some(h) = vec1("headings", headings)? {
            frame = frame.with_headings(&h).py()?;
        }
        if let Some(v) = velocities {
            frame = frame.with_velocities(dims::<f64, Ix2>("velocities", "(N, 2)", &v)?.view()).py()?;
        }
        if let Some(l) = vec1("lengths", lengths)? {
            frame = frame.with_lengths(&l).py()?;
        }
        if let Some(w) = vec1("widths", widths)? {
            frame = frame.with_widths(&w).py()?;
        }
        if let Some(map) = map {
            frame = frame.with_map(scene_map(map)?);
        }
        if let Some(dt) = dt {
            frame = frame.with_dt(dt).py()?;
        }
        Ok(Self { inner: frame })
    }

    fn __len__(&self) -> usize {
        self.inner.len()
    }

    /// The same agents without a map.
    fn without_map(&self) -> Self {
        Self { inner: self.inner.without_map() }
    }

    /// The same frame with noisy tracks replaced by their least-squares parabola (`dgan_core::Frame::denoised`), and
    /// how many were.
    fn denoised(&self, gate_m: f64) -> PyResult<(Self, usize)> {
        let (inner, smoothed) = self.inner.denoised(gate_m).py()?;
        Ok((Self { inner }, smoothed))
    }

    /// The same agents with another map.
    fn with_map(&self, map: &Bound<'_, PyAny>) -> PyResult<Self> {
        Ok(Self { inner: self.inner.clone().with_map(scene_map(map)?) })
    }

    #[getter]
    fn positions<'py>(&self, py: Python<'py>) -> Bound<'py, PyArray3<f64>> {
        self.inner.positions().clone().into_pyarray(py)
    }

    #[getter]
    fn mask<'py>(&self, py: Python<'py>) -> Bound<'py, PyArray2<bool>> {
        self.inner.mask().clone().into_pyarray(py)
    }

    #[getter]
    fn ids<'py>(&self, py: Python<'py>) -> Bound<'py, PyArray1<i64>> {
        self.inner.ids().to_vec().into_pyarray(py)
    }

    #[getter]
    fn classes(&self) -> Vec<&'static str> {
        self.inner.classes().iter().map(|c| c.name()).collect()
    }

    #[getter]
    fn lengths<'py>(&self, py: Python<'py>) -> Bound<'py, PyArray1<f64>> {
        self.inner.lengths().to_vec().into_pyarray(py)
    }

    #[getter]
    fn widths<'py>(&self, py: Python<'py>) -> Bound<'py, PyArray1<f64>> {
        self.inner.widths().to_vec().into_pyarray(py)
    }

    /// Given headings in world radians, NaN where unknown.
    #[getter]
    fn headings<'py>(&self, py: Python<'py>) -> Bound<'py, PyArray1<f64>> {
        self.inner.headings().iter().map(|h| h.unwrap_or(f64::NAN)).collect::<Vec<_>>().into_pyarray(py)
    }

    /// Given velocities `(N, 2)` in world m/s, NaN where unknown.
    #[getter]
    fn velocities<'py>(&self, py: Python<'py>) -> Bound<'py, PyArray2<f64>> {
        let v = self.inner.velocities();
        ndarray::Array2::from_shape_fn((v.len(), 2), |(i, k)| v[i].map_or(f64::NAN, |x| x[k])).into_pyarray(py)
    }

    /// Seconds between steps, if known.
    #[getter]
    fn dt(&self) -> Option<f64> {
        self.inner.dt_s()
    }

    #[getter]
    fn has_map(&self) -> bool {
        self.inner.map().is_some()
    }
}

fn homography(h: PyReadonlyArrayDyn<'_, f64>) -> PyResult<[[f64; 3]; 3]> {
    let view = h.as_array();
    if view.shape() != [3, 3] {
        return Err(to_py(DganError::InvalidMap(format!(
            "world_to_pixel must be a 3×3 matrix, got shape {:?}",
            view.shape()
        ))));
    }
    Ok(std::array::from_fn(|r| std::array::from_fn(|c| view[[r, c]])))
}

/// An RGB image and its world→pixel homography (see `dgan.RasterMap`).
#[derive(Debug)]
#[pyclass(name = "RasterMap", module = "dgan._dgan", frozen)]
pub struct PyRasterMap {
    pub(crate) inner: Arc<SceneMap>,
}

#[pymethods]
impl PyRasterMap {
    #[new]
    fn new(
        py: Python<'_>,
        image: PyReadonlyArrayDyn<'_, u8>,
        world_to_pixel: PyReadonlyArrayDyn<'_, f64>,
    ) -> PyResult<Self> {
        let shape = image.as_array().shape().to_vec();
        let image = image
            .as_array()
            .to_owned()
            .into_dimensionality::<Ix3>()
            .map_err(|_| to_py(DganError::InvalidMap(format!("image must have shape (H, W, 3), got {shape:?}"))))?;
        let h = homography(world_to_pixel)?;
        let map = py.detach(|| RasterMap::new(image, h)).py()?;
        Ok(Self { inner: Arc::new(SceneMap::Raster(map)) })
    }

    #[staticmethod]
    fn from_file(
        py: Python<'_>,
        path: std::path::PathBuf,
        world_to_pixel: PyReadonlyArrayDyn<'_, f64>,
    ) -> PyResult<Self> {
        let h = homography(world_to_pixel)?;
        let map = py.detach(|| RasterMap::from_file(&path, h)).py()?;
        Ok(Self { inner: Arc::new(SceneMap::Raster(map)) })
    }

    #[getter]
    fn image<'py>(&self, py: Python<'py>) -> Option<Bound<'py, PyArray3<u8>>> {
        match self.inner.as_ref() {
            SceneMap::Raster(r) => Some(r.image().clone().into_pyarray(py)),
            SceneMap::Vector(_) => None,
        }
    }

    #[getter]
    fn world_to_pixel<'py>(&self, py: Python<'py>) -> Option<Bound<'py, PyArray2<f64>>> {
        match self.inner.as_ref() {
            SceneMap::Raster(r) => {
                let m = r.world_to_pixel();
                Some(Array2::from_shape_fn((3, 3), |(i, j)| m[(i, j)]).into_pyarray(py))
            }
            SceneMap::Vector(_) => None,
        }
    }

    /// How many tiles of scene models' features are kept with the map (contract 13).
    #[getter]
    fn features_kept(&self) -> usize {
        self.inner.features().len()
    }
}

/// Typed polylines and polygons in world metres (see `dgan.VectorMap`).
#[derive(Debug)]
#[pyclass(name = "VectorMap", module = "dgan._dgan", frozen)]
pub struct PyVectorMap {
    pub(crate) inner: Arc<SceneMap>,
}

#[pymethods]
impl PyVectorMap {
    #[new]
    fn new(py: Python<'_>, elements: Vec<(String, PyReadonlyArrayDyn<'_, f64>)>) -> PyResult<Self> {
        let mut raw = Vec::with_capacity(elements.len());
        for (k, (kind, pts)) in elements.into_iter().enumerate() {
            let kind: MapElementKind = kind.parse().py()?;
            let view = pts.as_array();
            if view.ndim() != 2 || view.shape()[1] != 2 {
                return Err(to_py(DganError::InvalidMap(format!(
                    "element {k} ({kind}): points must have shape (P, 2), got {:?}",
                    view.shape()
                ))));
            }
            raw.push((kind, view.rows().into_iter().map(|r| [r[0], r[1]]).collect::<Vec<_>>()));
        }
        // Checking and simplifying the geometry runs without the GIL.
        let out = py.detach(|| {
            raw.into_iter()
                .enumerate()
                .map(|(k, (kind, points))| {
                    MapElement::new(kind, points).map_err(|e| match e {
                        DganError::InvalidMap(m) => DganError::InvalidMap(format!("element {k}: {m}")),
                        other => other,
                    })
                })
                .collect::<dgan_core::Result<Vec<_>>>()
        });
        Ok(Self { inner: Arc::new(SceneMap::Vector(VectorMap::new(out.py()?))) })
    }

    fn __len__(&self) -> usize {
        match self.inner.as_ref() {
            SceneMap::Vector(v) => v.elements().len(),
            SceneMap::Raster(_) => 0,
        }
    }

    /// How many tiles of scene models' features are kept with the map (contract 13).
    #[getter]
    fn features_kept(&self) -> usize {
        self.inner.features().len()
    }

    /// How many tiles of the map are kept for `map.render = "tiles"` crops.
    #[getter]
    fn tiles_kept(&self) -> usize {
        match self.inner.as_ref() {
            SceneMap::Vector(v) => v.tiles().len(),
            SceneMap::Raster(_) => 0,
        }
    }

    /// The elements as `(kind, points)` pairs, in drawing order.
    fn elements<'py>(&self, py: Python<'py>) -> Vec<(&'static str, Bound<'py, PyArray2<f64>>)> {
        match self.inner.as_ref() {
            SceneMap::Vector(v) => v
                .elements()
                .iter()
                .map(|e| {
                    let p = e.points();
                    let a = Array2::from_shape_fn((p.len(), 2), |(i, d)| p[i][d]);
                    (e.kind().name(), a.into_pyarray(py))
                })
                .collect(),
            SceneMap::Raster(_) => vec![],
        }
    }
}
