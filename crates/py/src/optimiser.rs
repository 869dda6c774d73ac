//! The optimiser's kernels: `smooth_rows` (the step preconditioner, `inkopt_core::kernels::smooth`),
//! `softmax_rows` / `softmax_backward` (the softmax parameterisation, `inkopt_core::kernels::simplex`) and
//! `momentum_step` / `abs_order_statistics` (the exponentiated-gradient step, `inkopt_core::kernels::step`), each
//! run on a kept thread pool of the caller's size.

use std::sync::{Arc, Mutex};

use numpy::ndarray::Array2;
use numpy::{IntoPyArray, PyArray2, PyReadonlyArray1, PyReadonlyArray2, PyReadwriteArray2, PyUntypedArrayMethods};
use pyo3::prelude::*;

use crate::arrays::{c_slice, check_shape, err};
use inkopt_core::kernels::smooth;

/// Run `f` on `threads` threads: None (or 0) in rayon's global pool (all cores, as a `Scene` without
/// `threads`), else in a pool of that many (threads named `inkopt-p{n}-{i}`), built once per process and count
/// and kept (a process whose callers ask for several counts keeps one idle pool per count). The free functions
/// below run in it, so that a caller's thread count (e.g. an ink-set search's per-run share) holds for them as for
/// its renders, without a new pool per call.
fn run_on<R: Send>(threads: Option<usize>, f: impl FnOnce() -> R + Send) -> PyResult<R> {
    static POOLS: Mutex<Vec<(usize, Arc<rayon::ThreadPool>)>> = Mutex::new(Vec::new());
    let n = match threads {
        None | Some(0) => return Ok(f()),
        Some(n) => n,
    };
    let pool = {
        let mut pools = POOLS.lock().map_err(|e| err(e.to_string()))?;
        match pools.iter().find(|(k, _)| *k == n) {
            Some((_, p)) => p.clone(),
            None => {
                let b = rayon::ThreadPoolBuilder::new().num_threads(n).thread_name(move |i| format!("inkopt-p{n}-{i}"));
                let p = Arc::new(b.build().map_err(|e| err(e.to_string()))?);
                // Wait until every thread runs (and carries its name): the pool is whole when it is first used.
                p.broadcast(|_| ());
                pools.push((n, p.clone()));
                p
            }
        }
    };
    Ok(pool.install(f))
}

/// smooth_rows(shape (Z, Y, X), index (F,) i64, values (F, C) f32, steps, alpha, guide (T, D) f32 or None, tau,
/// threads=None, rows=None, guide_key=None, guide_extra=None) -> None: `steps` explicit diffusion steps of weight
/// `alpha`, in place, of the rows `rows` of the values ((K,) u32, strictly increasing; None: all, K = F) over the
/// 6-neighbourhood of their voxels index[rows] (strictly increasing linear indices into the grid `shape`; row r of
/// the values is voxel index[r]), each neighbour weighted by exp(-|guide_r - guide_q|² / tau²) if a guide is given:
/// row r's guide vector is `guide[guide_key[r]]` ((K,) u32; None: guide[r], T = K) followed by `guide_extra[r]`
/// ((K,) f32) if given. The other rows are unchanged (inkopt_core::kernels::smooth::diffuse_subset: one channel at
/// a time, 37 bytes per row of the subset while it runs). The GIL is released; `threads` as for a `Scene` (default
/// all cores).
#[pyfunction]
#[pyo3(signature = (shape, index, values, steps, alpha, guide=None, tau=1.0, threads=None, rows=None, guide_key=None,
    guide_extra=None))]
#[allow(clippy::too_many_arguments)]
pub(crate) fn smooth_rows(
    py: Python<'_>,
    shape: (usize, usize, usize),
    index: PyReadonlyArray1<i64>,
    mut values: PyReadwriteArray2<f32>,
    steps: usize,
    alpha: f32,
    guide: Option<PyReadonlyArray2<f32>>,
    tau: f32,
    threads: Option<usize>,
    rows: Option<PyReadonlyArray1<u32>>,
    guide_key: Option<PyReadonlyArray1<u32>>,
    guide_extra: Option<PyReadonlyArray1<f32>>,
) -> PyResult<()> {
    let n = [shape.0, shape.1, shape.2];
    let ch = values.shape()[1];
    let idx = c_slice(&index, "index")?;
    let subset = rows.as_ref().map(|r| c_slice(r, "rows")).transpose()?;
    let key = guide_key.as_ref().map(|k| c_slice(k, "guide_key")).transpose()?;
    let extra = guide_extra.as_ref().map(|e| c_slice(e, "guide_extra")).transpose()?;
    if guide.is_none() && (key.is_some() || extra.is_some()) {
        return Err(err("guide_key and guide_extra need a guide"));
    }
    let v = values.as_slice_mut().map_err(|_| err("values must be C-contiguous"))?;
    let g = match &guide {
        Some(a) => {
            let table = c_slice(a, "guide")?;
            Some(inkopt_core::kernels::smooth::Guide { table, dims: a.shape()[1], key, extra, tau })
        }
        None => None,
    };
    py.detach(|| {
        run_on(threads, || smooth::diffuse_subset(n, idx, subset, v, ch, steps, alpha, g, smooth::SLAB_PLANES))
    })?
    .map_err(err)
}

/// softmax_rows(x, threads=None) -> p: the softmax of each row of x (rows, n) float32 (`inkopt_core::kernels::simplex`,
/// parallel on `threads` (default all cores), thread-count independent). The GIL is released.
#[pyfunction]
#[pyo3(signature = (x, threads=None))]
pub(crate) fn softmax_rows<'py>(
    py: Python<'py>,
    x: PyReadonlyArray2<f32>,
    threads: Option<usize>,
) -> PyResult<Bound<'py, PyArray2<f32>>> {
    let (rows, n) = (x.shape()[0], x.shape()[1]);
    let xs = c_slice(&x, "x")?;
    let mut p = vec![0.0f32; rows * n];
    py.detach(|| run_on(threads, || inkopt_core::kernels::simplex::softmax_rows(xs, n, &mut p)))?.map_err(err)?;
    Ok(Array2::from_shape_vec((rows, n), p).map_err(|e| err(e.to_string()))?.into_pyarray(py))
}

/// softmax_backward(x, g, scale, natural, threads=None) -> (rows, n) float32: with p = softmax_rows(x) and
/// c = scale g - <scale g, p> per row, c if natural (the exponentiated-gradient direction) else p c (dE/dx for
/// g = dE/dp). x, g (rows, n) float32, scale (rows,) float32. The GIL is released.
#[pyfunction]
#[pyo3(signature = (x, g, scale, natural, threads=None))]
pub(crate) fn softmax_backward<'py>(
    py: Python<'py>,
    x: PyReadonlyArray2<f32>,
    g: PyReadonlyArray2<f32>,
    scale: PyReadonlyArray1<f32>,
    natural: bool,
    threads: Option<usize>,
) -> PyResult<Bound<'py, PyArray2<f32>>> {
    let (rows, n) = (x.shape()[0], x.shape()[1]);
    check_shape(g.shape(), &[rows, n], "g")?;
    let (xs, gs, ss) = (c_slice(&x, "x")?, c_slice(&g, "g")?, c_slice(&scale, "scale")?);
    let mut out = vec![0.0f32; rows * n];
    py.detach(|| {
        run_on(threads, || inkopt_core::kernels::simplex::softmax_backward(xs, gs, ss, n, natural, &mut out))
    })?
    .map_err(err)?;
    Ok(Array2::from_shape_vec((rows, n), out).map_err(|e| err(e.to_string()))?.into_pyarray(py))
}

/// momentum_step(x, m, g, beta, lr, bias, scale, threads=None) -> (x_new, m_new): the exponentiated-gradient step
/// m' = beta m + (1 - beta) g, x' = x - (lr (m' / bias)) / scale over float32 arrays of one shape (rows, n), in
/// f32 as numpy evaluates that expression (`inkopt_core::kernels::step`). New arrays; the GIL is released.
#[pyfunction]
#[pyo3(signature = (x, m, g, beta, lr, bias, scale, threads=None))]
#[allow(clippy::too_many_arguments, clippy::type_complexity)]
pub(crate) fn momentum_step<'py>(
    py: Python<'py>,
    x: PyReadonlyArray2<f32>,
    m: PyReadonlyArray2<f32>,
    g: PyReadonlyArray2<f32>,
    beta: f64,
    lr: f64,
    bias: f64,
    scale: f32,
    threads: Option<usize>,
) -> PyResult<(Bound<'py, PyArray2<f32>>, Bound<'py, PyArray2<f32>>)> {
    let (rows, n) = (x.shape()[0], x.shape()[1]);
    check_shape(m.shape(), &[rows, n], "m")?;
    check_shape(g.shape(), &[rows, n], "g")?;
    let (xs, ms, gs) = (c_slice(&x, "x")?, c_slice(&m, "m")?, c_slice(&g, "g")?);
    let (mut xo, mut mo) = (vec![0.0f32; rows * n], vec![0.0f32; rows * n]);
    py.detach(|| {
        run_on(threads, || {
            inkopt_core::kernels::step::momentum_step(xs, ms, gs, beta, lr, bias, scale, &mut xo, &mut mo)
        })
    })?
    .map_err(err)?;
    let shape = |v| Array2::from_shape_vec((rows, n), v).map_err(|e| err(e.to_string()));
    Ok((shape(xo)?.into_pyarray(py), shape(mo)?.into_pyarray(py)))
}

/// abs_order_statistics(values, ranks, threads=None) -> list of float: the entries of |values| (float32 (rows, n),
/// C-contiguous, taken flat) at the given 0-based ranks of their increasing order, exactly (NaN if a
/// value is NaN; `inkopt_core::kernels::step`). No copy of the values is made; the GIL is released.
#[pyfunction]
#[pyo3(signature = (values, ranks, threads=None))]
pub(crate) fn abs_order_statistics(
    py: Python<'_>,
    values: PyReadonlyArray2<f32>,
    ranks: Vec<usize>,
    threads: Option<usize>,
) -> PyResult<Vec<f32>> {
    let vs = c_slice(&values, "values")?;
    py.detach(|| run_on(threads, || inkopt_core::kernels::step::abs_order_statistics(vs, &ranks)))?.map_err(err)
}
