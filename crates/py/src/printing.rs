//! The printing kernels: `diffuse_layer`, one printer layer of 3D vector error diffusion
//! (`inkopt_core::kernels::diffuse`); `diffuse_counts_layer`, one optimisation layer of the error diffusion of ink
//! counts between optimisation voxels (`inkopt_core::kernels::counts`); `mark_smooth`, the voxels that take the
//! ordered dither's counts instead (`inkopt_core::kernels::adaptive`); `sort_blocks` and `place_blocks`, each
//! block's printer voxels in threshold order and their labels (`inkopt_core::kernels::blocks`); and
//! `feature_plane`, one plane of the exact Euclidean feature transform the extrusion baseline takes its nearest
//! texels from (`inkopt_core::kernels::feature`).

use numpy::{PyReadonlyArray1, PyReadonlyArray2, PyReadonlyArray3, PyUntypedArrayMethods};
use pyo3::prelude::*;

use crate::arrays::{c_slice, check_shape, err};

/// diffuse_layer(mixture (N, Y, X) f32, inside (Y, X) u8, inside_next (Y, X) u8, error (2, Y, X, N) f32, z, out
/// (Y, X) u8): 3D vector error diffusion of printer layer z (inkopt_core::kernels::diffuse). error[z % 2] holds
/// the error carried into layer z and is zeroed on return; error[(z + 1) % 2] accumulates the next layer's.
/// Writes the labels (ink index, 255 outside) into `out`. The GIL is released.
#[pyfunction]
pub(crate) fn diffuse_layer(
    py: Python<'_>,
    mixture: PyReadonlyArray3<f32>,
    inside: PyReadonlyArray2<u8>,
    inside_next: PyReadonlyArray2<u8>,
    mut error: numpy::PyReadwriteArray4<f32>,
    z: usize,
    mut out: numpy::PyReadwriteArray2<u8>,
) -> PyResult<()> {
    let (n, ny, nx) = (mixture.shape()[0], mixture.shape()[1], mixture.shape()[2]);
    check_shape(inside.shape(), &[ny, nx], "inside")?;
    check_shape(inside_next.shape(), &[ny, nx], "inside_next")?;
    check_shape(error.shape(), &[2, ny, nx, n], "error")?;
    check_shape(out.shape(), &[ny, nx], "out")?;
    if !error.is_c_contiguous() || !out.is_c_contiguous() {
        return Err(err("error and out must be C-contiguous"));
    }
    let (m, i, i_next) =
        (c_slice(&mixture, "mixture")?, c_slice(&inside, "inside")?, c_slice(&inside_next, "inside_next")?);
    let e = error.as_slice_mut().map_err(|_| err("error must be C-contiguous"))?;
    let o = out.as_slice_mut().map_err(|_| err("out must be C-contiguous"))?;
    let (e0, e1) = e.split_at_mut(n * ny * nx);
    let (cur, next) = if z.is_multiple_of(2) { (e0, e1) } else { (e1, e0) };
    let shape = inkopt_core::kernels::diffuse::LayerShape { n, ny, nx };
    py.detach(|| inkopt_core::kernels::diffuse::diffuse_layer(shape, z, m, i, i_next, cur, next, o)).map_err(err)
}

/// diffuse_counts_layer(share (N, y, x) f64, block (y, x) u32, inside (y, x) u8, inside_next (y, x) u8, error
/// (2, y, x, N) f64, z, down, counts (y, x, N) u32, thresholds=None) -> float: the ink counts of optimisation layer
/// z by vector error diffusion between optimisation voxels (inkopt_core::kernels::counts), a fraction `down` of
/// each residual to layer z + 1. error[z % 2] holds the error carried into layer z and is zeroed on return;
/// error[(z + 1) % 2] accumulates the next layer's. thresholds: None for the nearest counts, or (y, x, T) f64 each
/// block's ordered-dither thresholds in increasing order (the first `block` used) to round by. Writes `counts`;
/// returns the layer's largest |residual component|. The GIL is released.
#[pyfunction]
#[pyo3(signature = (share, block, inside, inside_next, error, z, down, counts, thresholds=None))]
#[allow(clippy::too_many_arguments)]
pub(crate) fn diffuse_counts_layer(
    py: Python<'_>,
    share: PyReadonlyArray3<f64>,
    block: PyReadonlyArray2<u32>,
    inside: PyReadonlyArray2<u8>,
    inside_next: PyReadonlyArray2<u8>,
    mut error: numpy::PyReadwriteArray4<f64>,
    z: usize,
    down: f64,
    mut counts: numpy::PyReadwriteArray3<u32>,
    thresholds: Option<PyReadonlyArray3<f64>>,
) -> PyResult<f64> {
    use inkopt_core::kernels::counts::{diffuse_counts_layer, CountLayer, CountShape};
    let (n, ny, nx) = (share.shape()[0], share.shape()[1], share.shape()[2]);
    check_shape(block.shape(), &[ny, nx], "block")?;
    check_shape(inside.shape(), &[ny, nx], "inside")?;
    check_shape(inside_next.shape(), &[ny, nx], "inside_next")?;
    check_shape(error.shape(), &[2, ny, nx, n], "error")?;
    check_shape(counts.shape(), &[ny, nx, n], "counts")?;
    if let Some(t) = &thresholds {
        check_shape(&t.shape()[..2], &[ny, nx], "thresholds")?;
    }
    let layer = CountLayer {
        z,
        share: c_slice(&share, "share")?,
        block: c_slice(&block, "block")?,
        inside: c_slice(&inside, "inside")?,
        inside_next: c_slice(&inside_next, "inside_next")?,
        thresholds: thresholds.as_ref().map(|t| c_slice(t, "thresholds")).transpose()?,
    };
    let e = error.as_slice_mut().map_err(|_| err("error must be C-contiguous"))?;
    let c = counts.as_slice_mut().map_err(|_| err("counts must be C-contiguous"))?;
    let (e0, e1) = e.split_at_mut(n * ny * nx);
    let (cur, next) = if z.is_multiple_of(2) { (e0, e1) } else { (e1, e0) };
    py.detach(|| diffuse_counts_layer(CountShape { n, ny, nx }, &layer, down, cur, next, c)).map_err(err)
}

/// feature_plane(z, site_z (Y, X) i32, sampling (z, y, x) f64, out (3, Y, X) i32): plane z of the exact Euclidean
/// feature transform of a (Z, Y, X) grid, as scipy.ndimage.distance_transform_edt(return_indices=True) gives it
/// (ties included). site_z: the z of each column's nearest feature to plane z (ties to the lower z; -1: none);
/// out receives each voxel's nearest feature's z, y and x (inkopt_core::kernels::feature). The GIL is released.
#[pyfunction]
pub(crate) fn feature_plane(
    py: Python<'_>,
    z: i64,
    site_z: PyReadonlyArray2<i32>,
    sampling: (f64, f64, f64),
    mut out: numpy::PyReadwriteArray3<i32>,
) -> PyResult<()> {
    let (ny, nx) = (site_z.shape()[0], site_z.shape()[1]);
    check_shape(out.shape(), &[3, ny, nx], "out")?;
    let sites = c_slice(&site_z, "site_z")?;
    let o = out.as_slice_mut().map_err(|_| err("out must be C-contiguous"))?;
    let shape = inkopt_core::kernels::feature::PlaneShape { ny, nx, sampling: [sampling.0, sampling.1, sampling.2] };
    py.detach(|| inkopt_core::kernels::feature::feature_plane(z, sites, shape, o)).map_err(err)
}

/// mark_smooth(share (N, y, x) f64, classes (y, x) u8, smooth, below=None, below_inside=None): sets
/// `DITHER_CLASS` (255) in `classes` (each voxel's class, 0 outside) at every inside voxel whose RMS share distance
/// to its inside neighbours (four in the layer; one in `below` (N, y, x) f64 where `below_inside` (y, x) u8 is
/// nonzero) is below `smooth` (inkopt_core::kernels::adaptive). The GIL is released.
#[pyfunction]
#[pyo3(signature = (share, classes, smooth, below=None, below_inside=None))]
pub(crate) fn mark_smooth(
    py: Python<'_>,
    share: PyReadonlyArray3<f64>,
    mut classes: numpy::PyReadwriteArray2<u8>,
    smooth: f64,
    below: Option<PyReadonlyArray3<f64>>,
    below_inside: Option<PyReadonlyArray2<u8>>,
) -> PyResult<()> {
    use inkopt_core::kernels::adaptive::{mark_smooth, Below};
    use inkopt_core::kernels::counts::CountShape;
    let (n, ny, nx) = (share.shape()[0], share.shape()[1], share.shape()[2]);
    check_shape(classes.shape(), &[ny, nx], "classes")?;
    let b = match (&below, &below_inside) {
        (Some(s), Some(i)) => {
            check_shape(s.shape(), &[n, ny, nx], "below")?;
            check_shape(i.shape(), &[ny, nx], "below_inside")?;
            Some(Below { share: c_slice(s, "below")?, inside: c_slice(i, "below_inside")? })
        }
        (None, None) => None,
        _ => return Err(err("below and below_inside go together")),
    };
    let sh = c_slice(&share, "share")?;
    let c = classes.as_slice_mut().map_err(|_| err("classes must be C-contiguous"))?;
    py.detach(|| mark_smooth(CountShape { n, ny, nx }, sh, b, smooth, c)).map_err(err)
}

/// sort_blocks(t (k, Y, X) f32, ry (ny + 1) u32, rx (nx + 1) u32, order (ny, nx, W) u32, sorted (ny, nx, W) f64):
/// each block's printer voxels (rows ry[y]..ry[y + 1], columns rx[x]..rx[x + 1], all k layers) in increasing
/// threshold, ties to the lower flat index: their flat (k, Y, X) indices into `order` and thresholds into `sorted`
/// (unused slots u32::MAX and 2.0; inkopt_core::kernels::blocks). The GIL is released.
#[pyfunction]
pub(crate) fn sort_blocks(
    py: Python<'_>,
    t: PyReadonlyArray3<f32>,
    ry: PyReadonlyArray1<u32>,
    rx: PyReadonlyArray1<u32>,
    mut order: numpy::PyReadwriteArray3<u32>,
    mut sorted: numpy::PyReadwriteArray3<f64>,
) -> PyResult<()> {
    use inkopt_core::kernels::blocks::{sort_blocks, Blocks};
    let width = order.shape()[2];
    check_shape(sorted.shape(), order.shape(), "sorted")?;
    let b = Blocks { k: t.shape()[0], ry: c_slice(&ry, "ry")?, rx: c_slice(&rx, "rx")?, width };
    let tt = c_slice(&t, "t")?;
    let o = order.as_slice_mut().map_err(|_| err("order must be C-contiguous"))?;
    let s = sorted.as_slice_mut().map_err(|_| err("sorted must be C-contiguous"))?;
    py.detach(|| sort_blocks(b, tt, o, s)).map_err(err)
}

/// place_blocks(order (ny, nx, W) u32, counts (ny, nx, N) u32, ry (ny + 1) u32, rx (nx + 1) u32, labels (k, Y, X)
/// u8): every block's voxels in `order` (sort_blocks) take its counts' bands in turn, band indices into `labels`
/// (inkopt_core::kernels::blocks). The GIL is released.
#[pyfunction]
pub(crate) fn place_blocks(
    py: Python<'_>,
    order: PyReadonlyArray3<u32>,
    counts: PyReadonlyArray3<u32>,
    ry: PyReadonlyArray1<u32>,
    rx: PyReadonlyArray1<u32>,
    mut labels: numpy::PyReadwriteArray3<u8>,
) -> PyResult<()> {
    use inkopt_core::kernels::blocks::{place_blocks, Blocks};
    let n = counts.shape()[2];
    let b = Blocks { k: labels.shape()[0], ry: c_slice(&ry, "ry")?, rx: c_slice(&rx, "rx")?, width: order.shape()[2] };
    let (o, c) = (c_slice(&order, "order")?, c_slice(&counts, "counts")?);
    let l = labels.as_slice_mut().map_err(|_| err("labels must be C-contiguous"))?;
    py.detach(|| place_blocks(b, o, c, n, l)).map_err(err)
}
