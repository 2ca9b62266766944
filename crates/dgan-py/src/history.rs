//! Time bases: `frames_from_rows` (behind `dgan.Frame.from_records` and `dgan.evaluate`) and the streaming `Tracker`.

use crate::error::{invalid_frame, IntoPyResult};
use crate::frame::{parse_classes, PyFrame};
use dgan_core::{frame_and_future_at, tracks_from_rows_with, AgentClass, Detection, Duplicates, TimeBase, Tracker};
use ndarray::Array2;
use numpy::{IntoPyArray, PyArray1, PyArray2, PyArray3, PyReadonlyArray1, PyReadonlyArray2};
use pyo3::prelude::*;
use pyo3::types::PyDict;

/// Per-row columns as given from Python: a dict with `ids` (int64), `xs`, `ys` (float64) and optionally `classes`
/// (a list), `headings`, `lengths`, `widths`, `vxs`, `vys` (float64, may be missing or None).
struct Columns<'py> {
    ids: PyReadonlyArray1<'py, i64>,
    xs: PyReadonlyArray1<'py, f64>,
    ys: PyReadonlyArray1<'py, f64>,
    classes: Option<Bound<'py, PyAny>>,
    headings: Option<PyReadonlyArray1<'py, f64>>,
    lengths: Option<PyReadonlyArray1<'py, f64>>,
    widths: Option<PyReadonlyArray1<'py, f64>>,
    vxs: Option<PyReadonlyArray1<'py, f64>>,
    vys: Option<PyReadonlyArray1<'py, f64>>,
}

/// An optional column of a dict: missing and None are both absent.
fn item<'py>(d: &Bound<'py, PyDict>, k: &str) -> PyResult<Option<Bound<'py, PyAny>>> {
    Ok(d.get_item(k)?.filter(|v| !v.is_none()))
}

/// An optional float64 column of a dict.
fn floats<'py>(d: &Bound<'py, PyDict>, k: &str) -> PyResult<Option<PyReadonlyArray1<'py, f64>>> {
    item(d, k)?.map(|v| v.extract().map_err(|_| invalid_frame(format!("{k} must be a 1-D float64 array")))).transpose()
}

/// A required float64 column of a dict.
fn required_floats<'py>(d: &Bound<'py, PyDict>, k: &str) -> PyResult<PyReadonlyArray1<'py, f64>> {
    floats(d, k)?.ok_or_else(|| invalid_frame(format!("the column {k} is required")))
}

impl<'py> Columns<'py> {
    fn from_dict(d: &Bound<'py, PyDict>) -> PyResult<Self> {
        let ids = item(d, "ids")?.ok_or_else(|| invalid_frame("the column ids is required"))?;
        Ok(Self {
            ids: ids.extract().map_err(|_| invalid_frame("ids must be a 1-D int64 array"))?,
            xs: required_floats(d, "xs")?,
            ys: required_floats(d, "ys")?,
            classes: item(d, "classes")?,
            headings: floats(d, "headings")?,
            lengths: floats(d, "lengths")?,
            widths: floats(d, "widths")?,
            vxs: floats(d, "vxs")?,
            vys: floats(d, "vys")?,
        })
    }
}

impl Columns<'_> {
    /// One detection per row, at `times` (seconds).
    fn detections(&self, times: &[f64]) -> PyResult<Vec<(i64, Detection)>> {
        let ids = self.ids.as_slice()?;
        let n = ids.len();
        let column = |name: &str, a: Option<&PyReadonlyArray1<'_, f64>>| -> PyResult<Vec<f64>> {
            match a {
                Some(a) => {
                    let v = a.as_slice()?.to_vec();
                    if v.len() != n {
                        return Err(invalid_frame(format!("column {name} has {} rows, the ids {n}", v.len())));
                    }
                    Ok(v)
                }
                None => Ok(vec![f64::NAN; n]),
            }
        };
        let (xs, ys) = (column("x", Some(&self.xs))?, column("y", Some(&self.ys))?);
        let (hs, ls) = (column("heading", self.headings.as_ref())?, column("length", self.lengths.as_ref())?);
        let ws = column("width", self.widths.as_ref())?;
        let (vx, vy) = (column("vx", self.vxs.as_ref())?, column("vy", self.vys.as_ref())?);
        if times.len() != n {
            return Err(invalid_frame(format!("{} times given for {n} rows", times.len())));
        }
        let classes: Vec<Option<AgentClass>> = match &self.classes {
            Some(c) => {
                let parsed = parse_classes(c)?;
                if parsed.len() != n {
                    return Err(invalid_frame(format!("{} classes given for {n} rows", parsed.len())));
                }
                parsed.into_iter().map(Some).collect()
            }
            None => vec![None; n],
        };
        Ok((0..n)
            .map(|i| {
                let d = Detection {
                    time_s: times[i],
                    position: [xs[i], ys[i]],
                    class: classes[i],
                    heading: hs[i],
                    length: ls[i],
                    width: ws[i],
                    velocity: [vx[i], vy[i]],
                };
                (ids[i], d)
            })
            .collect())
    }
}

fn parse_default_class(class: &Bound<'_, PyAny>) -> PyResult<AgentClass> {
    let list = pyo3::types::PyList::new(class.py(), [class])?;
    Ok(parse_classes(list.as_any())?[0])
}

/// What one frame of [`frames_from_rows`] holds: the frame, the data's median spacing, whether it was upsampled,
/// and with `t_f` > 0 its agents' future positions `(N, t_f, 2)` with their mask `(N, t_f)`.
type RowsFrame<'py> =
    (PyFrame, Option<f64>, bool, Option<Bound<'py, PyArray3<f64>>>, Option<Bound<'py, PyArray2<bool>>>);

/// The frames at each of `nows` (seconds) of a long table's rows (`columns` as [`Columns`], plus `times`, float64
/// seconds), the table grouped once: by id (repeated times resolved by `duplicates`), resampled to `t_obs` steps
/// `dt` apart (data up to 2.5× sparser interpolated with `upsample`). With `t_f` > 0 each frame comes with what its
/// agents did over the next `t_f` steps (`dgan_core::frame_and_future_at`), the ground truth of an evaluation.
#[pyfunction]
#[pyo3(signature = (columns, nows, t_obs, dt, max_gap, default_class, duplicates="error", upsample=false, t_f=0))]
#[allow(clippy::too_many_arguments)]
pub fn frames_from_rows<'py>(
    py: Python<'py>,
    columns: &Bound<'py, PyDict>,
    nows: Vec<f64>,
    t_obs: usize,
    dt: f64,
    max_gap: Option<f64>,
    default_class: Bound<'py, PyAny>,
    duplicates: &str,
    upsample: bool,
    t_f: usize,
) -> PyResult<Vec<RowsFrame<'py>>> {
    let default_class = parse_default_class(&default_class)?;
    let duplicates: Duplicates = duplicates.parse().py()?;
    let base = time_base(t_obs, dt, max_gap)?;
    let times = required_floats(columns, "times")?;
    let rows = Columns::from_dict(columns)?.detections(times.as_slice()?)?;
    let out = py
        .detach(|| {
            let tracks = tracks_from_rows_with(rows, duplicates)?;
            let views: Vec<(i64, &[Detection])> = tracks.iter().map(|(i, t)| (*i, t.as_slice())).collect();
            nows.iter()
                .map(|&now| frame_and_future_at(&views, now, &base, default_class, upsample, t_f))
                .collect::<dgan_core::Result<Vec<_>>>()
        })
        .py()?;
    Ok(out
        .into_iter()
        .map(|(r, future)| {
            let (positions, mask) = if t_f > 0 {
                (Some(future.positions.into_pyarray(py)), Some(future.mask.into_pyarray(py)))
            } else {
                (None, None)
            };
            (PyFrame { inner: r.frame }, r.spacing_s, r.upsampled, positions, mask)
        })
        .collect())
}

/// One track's positions `xy (N, 2)` at `times (N,)` seconds sampled at `at (M,)` seconds on a grid `dt` apart
/// (`dgan_core::sample_track`: gaps wider than `max_gap`, by default the grid's, not bridged); `(M, 2)` float64, NaN
/// where nothing is sampled.
#[pyfunction]
#[pyo3(signature = (times, xy, at, dt, max_gap=None))]
pub fn sample_track<'py>(
    py: Python<'py>,
    times: PyReadonlyArray1<'py, f64>,
    xy: PyReadonlyArray2<'py, f64>,
    at: PyReadonlyArray1<'py, f64>,
    dt: f64,
    max_gap: Option<f64>,
) -> PyResult<Bound<'py, PyArray2<f64>>> {
    let base = time_base(1, dt, max_gap)?;
    let xy = xy.as_array();
    if xy.ncols() != 2 {
        return Err(invalid_frame(format!("xy must have shape (N, 2), got {:?}", xy.shape())));
    }
    let positions: Vec<[f64; 2]> = xy.rows().into_iter().map(|r| [r[0], r[1]]).collect();
    let (times, at) = (times.as_array().to_vec(), at.as_array().to_vec());
    let sampled = py.detach(|| dgan_core::sample_track(&times, &positions, &at, &base)).py()?;
    let mut out = Array2::<f64>::from_elem((sampled.len(), 2), f64::NAN);
    for (mut row, p) in out.rows_mut().into_iter().zip(&sampled) {
        if let Some(p) = p {
            row[0] = p[0];
            row[1] = p[1];
        }
    }
    Ok(out.into_pyarray(py))
}

fn time_base(t_obs: usize, dt: f64, max_gap: Option<f64>) -> PyResult<TimeBase> {
    match max_gap {
        Some(g) => TimeBase::with_max_gap(t_obs, dt, g),
        None => TimeBase::new(t_obs, dt),
    }
    .py()
}

/// One number of a detection, a column of [`PyTracker::state`].
type DetectionValue = fn(&Detection) -> f64;

/// A streaming tracker (see `dgan.Tracker`).
#[derive(Debug)]
#[pyclass(name = "Tracker", module = "dgan._dgan")]
pub struct PyTracker {
    inner: Tracker,
}

#[pymethods]
impl PyTracker {
    #[new]
    #[pyo3(signature = (t_obs, dt, max_gap, default_class))]
    fn new(t_obs: usize, dt: f64, max_gap: Option<f64>, default_class: Bound<'_, PyAny>) -> PyResult<Self> {
        Ok(Self { inner: Tracker::new(time_base(t_obs, dt, max_gap)?, parse_default_class(&default_class)?) })
    }

    /// Adds the detections of one tick at `time` seconds (`columns` as [`Columns`]).
    fn update(&mut self, time: f64, columns: &Bound<'_, PyDict>) -> PyResult<()> {
        let cols = Columns::from_dict(columns)?;
        let n = cols.ids.len()?;
        let rows = cols.detections(&vec![time; n])?;
        self.inner.update(time, rows).py()
    }

    /// The frame at the latest tick.
    fn frame(&self) -> PyResult<PyFrame> {
        Ok(PyFrame { inner: self.inner.frame().py()? })
    }

    /// The latest tick's time, if any.
    #[getter]
    fn now(&self) -> Option<f64> {
        self.inner.now_s()
    }

    /// Agents remembered.
    fn __len__(&self) -> usize {
        self.inner.len()
    }

    /// The ids of the agents remembered, increasing.
    fn ids<'py>(&self, py: Python<'py>) -> Bound<'py, PyArray1<i64>> {
        PyArray1::from_iter(py, self.inner.ids())
    }

    /// What it remembers, one row per detection: `ids`, `times`, `xs`, `ys`, `classes` (codes, -1 for the default
    /// class), `headings`, `lengths`, `widths`, `vxs`, `vys`, and `now`; [`PyTracker::restore`] takes it back.
    fn state<'py>(&self, py: Python<'py>) -> PyResult<Bound<'py, PyDict>> {
        let rows: Vec<(i64, &Detection)> =
            self.inner.tracks().iter().flat_map(|(id, track)| track.iter().map(move |d| (*id, d))).collect();
        let out = PyDict::new(py);
        out.set_item("ids", PyArray1::from_iter(py, rows.iter().map(|r| r.0)))?;
        let class = |d: &Detection| d.class.map_or(-1, |c| i64::from(c.code()));
        out.set_item("classes", PyArray1::from_iter(py, rows.iter().map(|r| class(r.1))))?;
        let columns: [(&str, DetectionValue); 8] = [
            ("times", |d| d.time_s),
            ("xs", |d| d.position[0]),
            ("ys", |d| d.position[1]),
            ("headings", |d| d.heading),
            ("lengths", |d| d.length),
            ("widths", |d| d.width),
            ("vxs", |d| d.velocity[0]),
            ("vys", |d| d.velocity[1]),
        ];
        for (name, value) in columns {
            out.set_item(name, PyArray1::from_iter(py, rows.iter().map(|r| value(r.1))))?;
        }
        out.set_item("now", self.inner.now_s())?;
        Ok(out)
    }

    /// A tracker on the time base given that remembers `state` (as [`PyTracker::state`] gives it).
    #[staticmethod]
    #[pyo3(signature = (t_obs, dt, max_gap, default_class, state))]
    fn restore(
        t_obs: usize,
        dt: f64,
        max_gap: Option<f64>,
        default_class: Bound<'_, PyAny>,
        state: &Bound<'_, PyDict>,
    ) -> PyResult<Self> {
        let cols = Columns::from_dict(state)?;
        let times: PyReadonlyArray1<'_, f64> = required_floats(state, "times")?;
        let mut rows = Columns { classes: None, ..cols }.detections(times.as_slice()?)?;
        let codes: PyReadonlyArray1<'_, i64> = item(state, "classes")?
            .ok_or_else(|| invalid_frame("the column classes is required"))?
            .extract()
            .map_err(|_| invalid_frame("classes must be a 1-D int64 array"))?;
        let codes = codes.as_slice()?;
        if codes.len() != rows.len() {
            return Err(invalid_frame(format!("{} classes given for {} rows", codes.len(), rows.len())));
        }
        for ((_, d), code) in rows.iter_mut().zip(codes) {
            d.class = if *code < 0 { None } else { Some(AgentClass::from_code(*code).py()?) };
        }
        let mut tracks: std::collections::BTreeMap<i64, Vec<Detection>> = std::collections::BTreeMap::new();
        for (id, d) in rows {
            tracks.entry(id).or_default().push(d);
        }
        let now: Option<f64> = item(state, "now")?.map(|v| v.extract()).transpose()?;
        let base = time_base(t_obs, dt, max_gap)?;
        Ok(Self { inner: Tracker::restore(base, parse_default_class(&default_class)?, tracks, now).py()? })
    }
}
