//! Shared argument handling of the bindings: the ValueError of bad input, C-order slices of numpy arrays, shape
//! checks, render options, and the (mean, var_mean, stats) triple a render or gradient pass
//! returns.

use inkopt_core::{RenderOptions, Stats, TexelEstimate};
use numpy::ndarray::{Array2, Dimension};
use numpy::{Element, IntoPyArray, PyArray2, PyReadonlyArray, PyUntypedArrayMethods};
use pyo3::exceptions::PyValueError;
use pyo3::prelude::*;
use pyo3::types::PyDict;

/// A ValueError with this message (every bad argument of the bindings).
pub(crate) fn err(msg: impl Into<String>) -> PyErr {
    PyValueError::new_err(msg.into())
}

/// The array's data in C order; a ValueError for other layouts (a Fortran-ordered array is contiguous too, but
/// its memory is not in the (z, y, x[, c]) order the core reads).
pub(crate) fn c_slice<'a, T: Element, D: Dimension>(a: &'a PyReadonlyArray<'_, T, D>, name: &str) -> PyResult<&'a [T]> {
    if !a.is_c_contiguous() {
        return Err(err(format!("{name} must be C-contiguous (np.ascontiguousarray)")));
    }
    a.as_slice().map_err(|_| err(format!("{name} must be C-contiguous (np.ascontiguousarray)")))
}

/// A ValueError naming `name` unless its shape `dims` is `want`.
pub(crate) fn check_shape(dims: &[usize], want: &[usize], name: &str) -> PyResult<()> {
    if dims != want {
        return Err(err(format!("{name} has shape {dims:?}, expected {want:?}")));
    }
    Ok(())
}

/// The options of a render or gradient pass; a ValueError for spp = 0.
pub(crate) fn options(spp: u32, seed: u64, include_specular: bool) -> PyResult<RenderOptions> {
    if spp == 0 {
        return Err(err("spp must be at least 1"));
    }
    Ok(RenderOptions { spp, seed, include_specular })
}

/// (mean (I, 3) float32, var_mean (I, 3) float32, stats dict): what `render` and `backward` return.
pub(crate) type Packed<'py> = (Bound<'py, PyArray2<f32>>, Bound<'py, PyArray2<f32>>, Bound<'py, PyDict>);

/// The estimates and statistics of a pass as `Packed`; the stats dict has the keys paths, events,
/// replayed_paths, replayed_events.
pub(crate) fn pack<'py>(py: Python<'py>, est: &[TexelEstimate], stats: &Stats) -> PyResult<Packed<'py>> {
    let n = est.len();
    let mean: Vec<f32> = est.iter().flat_map(|e| e.mean).collect();
    let var: Vec<f32> = est.iter().flat_map(|e| e.var_mean).collect();
    let d = PyDict::new(py);
    d.set_item("paths", stats.paths)?;
    d.set_item("events", stats.events)?;
    d.set_item("replayed_paths", stats.replayed_paths)?;
    d.set_item("replayed_events", stats.replayed_events)?;
    let to = |v: Vec<f32>| Array2::from_shape_vec((n, 3), v).map_err(|e| err(e.to_string()));
    Ok((to(mean)?.into_pyarray(py), to(var)?.into_pyarray(py), d))
}
