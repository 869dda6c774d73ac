//! The `Medium` class (a scene's medium as the caller's arrays: dense, sparse, band or label form, checked once
//! when it is built), the core medium a scene holds, and the macro that runs a generic core function on whichever form
//! the scene holds.

use inkopt_core::transport::mask::MaskRef;
use inkopt_core::{BandMedium, DenseMedium, LabelMedium, SparseMedium};
use numpy::ndarray::Dimension;
use numpy::{
    Element, PyArray, PyArray1, PyArray2, PyArray3, PyArray4, PyArrayMethods, PyReadonlyArray, PyReadonlyArray1,
    PyUntypedArrayMethods,
};
use pyo3::prelude::*;

use crate::arrays::{c_slice, check_shape, err};
use crate::labels::LabelBricks;

/// The four forms of a scene's medium. A scene holds one, so the size difference between the variants costs
/// nothing worth a box (an extra indirection on every render call).
#[allow(clippy::large_enum_variant)]
pub(crate) enum MediumKind {
    Dense(DenseMedium),
    Sparse(SparseMedium),
    Band(BandMedium),
    Labels(LabelMedium),
}

/// Run `$body` with `$m` bound to the scene's medium, whatever its kind (each kind its own monomorphised walk).
macro_rules! with_medium {
    ($medium:expr, $m:ident => $body:expr) => {
        match $medium {
            $crate::medium::MediumKind::Dense($m) => $body,
            $crate::medium::MediumKind::Sparse($m) => $body,
            $crate::medium::MediumKind::Band($m) => $body,
            $crate::medium::MediumKind::Labels($m) => $body,
        }
    };
}
pub(crate) use with_medium;

/// A medium for `Scene(...)` and `Scene.set_medium`, built by `Medium.dense`, `Medium.sparse`, `Medium.band` or
/// `Medium.labels`.
/// It holds references to the caller's arrays (no copy; the scene copies them into its own form when it takes
/// the medium), their dtypes, shapes and layout checked when it is built; the grid is checked by the scene.
#[pyclass(module = "inkopt._core", frozen)]
pub(crate) struct Medium(Form);

enum Form {
    Dense { sigma_s: Py<PyArray4<f32>>, sigma_a: Py<PyArray4<f32>> },
    Sparse(Sparse),
    Band { inside: Inside, band: Sparse, core_sigma_s: [f32; 3], core_sigma_a: [f32; 3] },
    Labels { labels: Labels, ink_sigma_s: Py<PyArray2<f32>>, ink_sigma_a: Py<PyArray2<f32>> },
}

/// A label grid as the caller gives it: (Z, Y, X) uint8, or its planes already pushed into `LabelBricks`.
enum Labels {
    Dense(Py<PyArray3<u8>>),
    Bricks(Py<LabelBricks>),
}

/// An inside mask as the caller gives it: (Z, Y, X) uint8 (non-zero: inside), or its bits, (ceil(Z Y X / 8),)
/// uint8 (`np.packbits` of the C-order flattening, as `model.mask.PackedMask.bits` holds it).
pub(crate) enum Inside {
    Bytes(Py<PyArray3<u8>>),
    Bits(Py<PyArray1<u8>>),
}

impl Inside {
    /// `obj` as a mask (its dtype, dimensions and layout checked; the grid is checked by `with`).
    pub(crate) fn extract(obj: &Bound<'_, PyAny>) -> PyResult<Self> {
        if let Ok(a) = obj.cast::<PyArray3<u8>>() {
            return Ok(Inside::Bytes(checked(a.clone(), "inside", &[None, None, None])?));
        }
        if let Ok(a) = obj.cast::<PyArray1<u8>>() {
            return Ok(Inside::Bits(checked(a.clone(), "inside", &[None])?));
        }
        Err(err("inside must be a (Z, Y, X) uint8 mask or its bits, (ceil(Z * Y * X / 8),) uint8 (np.packbits)"))
    }

    /// `f` of the mask read in place (no copy) as a `MaskRef` of the grid `shape` (Z, Y, X).
    pub(crate) fn with<R>(
        &self,
        py: Python<'_>,
        shape: [usize; 3],
        f: impl FnOnce(MaskRef<'_>) -> PyResult<R>,
    ) -> PyResult<R> {
        match self {
            Inside::Bytes(a) => {
                let m = view(a, py)?;
                check_shape(m.shape(), &shape, "inside")?;
                f(MaskRef::Bytes(c_slice(&m, "inside")?))
            }
            Inside::Bits(a) => {
                let m = view(a, py)?;
                f(MaskRef::bits(c_slice(&m, "inside")?, shape.iter().product()).map_err(err)?)
            }
        }
    }
}

/// Listed voxels' coefficients: `index` (K,) int64, `sigma_s` and `sigma_a` (K, 3) float32.
struct Sparse {
    index: Py<PyArray1<i64>>,
    sigma_s: Py<PyArray2<f32>>,
    sigma_a: Py<PyArray2<f32>>,
}

impl Sparse {
    fn checked(
        index: Bound<'_, PyArray1<i64>>,
        sigma_s: Bound<'_, PyArray2<f32>>,
        sigma_a: Bound<'_, PyArray2<f32>>,
    ) -> PyResult<Self> {
        let k = Some(index.len());
        let index = checked(index, "index", &[None])?;
        let (sigma_s, sigma_a) =
            (checked(sigma_s, "sigma_s", &[k, Some(3)])?, checked(sigma_a, "sigma_a", &[k, Some(3)])?);
        Ok(Sparse { index, sigma_s, sigma_a })
    }
}

/// The array as a C-ordered reference; a ValueError naming `name` for another layout or a shape that is not
/// `want` (None: any extent on that axis).
fn checked<T: Element, D: Dimension>(
    a: Bound<'_, PyArray<T, D>>,
    name: &str,
    want: &[Option<usize>],
) -> PyResult<Py<PyArray<T, D>>> {
    let dims = a.shape();
    if dims.len() != want.len() || dims.iter().zip(want).any(|(d, w)| w.is_some_and(|w| w != *d)) {
        let want: Vec<String> = want.iter().map(|w| w.map_or("_".into(), |w| w.to_string())).collect();
        return Err(err(format!("{name} has shape {dims:?}, expected ({})", want.join(", "))));
    }
    if !a.is_c_contiguous() {
        return Err(err(format!("{name} must be C-contiguous (np.ascontiguousarray)")));
    }
    Ok(a.unbind())
}

/// A read-only view of a held array.
fn view<'py, T: Element, D: Dimension>(a: &Py<PyArray<T, D>>, py: Python<'py>) -> PyResult<PyReadonlyArray<'py, T, D>> {
    a.bind(py).try_readonly().map_err(|e| err(e.to_string()))
}

#[pymethods]
impl Medium {
    /// Medium.dense(sigma_s, sigma_a): coefficients of every grid voxel, (Z, Y, X, 3) float32 each, mm^-1.
    #[staticmethod]
    fn dense(sigma_s: Bound<'_, PyArray4<f32>>, sigma_a: Bound<'_, PyArray4<f32>>) -> PyResult<Self> {
        let d = sigma_s.shape();
        let want = [Some(d[0]), Some(d[1]), Some(d[2]), Some(3)];
        let sigma_s = checked(sigma_s, "sigma_s", &want)?;
        Ok(Medium(Form::Dense { sigma_s, sigma_a: checked(sigma_a, "sigma_a", &want)? }))
    }

    /// Medium.sparse(index, sigma_s, sigma_a): the coefficients of the voxels `index` (K,) int64 (strictly
    /// increasing linear (z, y, x) indices; every other voxel is vacuum), (K, 3) float32 each, mm^-1: 24 bytes per
    /// voxel of each grid row's span of them.
    #[staticmethod]
    fn sparse(
        index: Bound<'_, PyArray1<i64>>,
        sigma_s: Bound<'_, PyArray2<f32>>,
        sigma_a: Bound<'_, PyArray2<f32>>,
    ) -> PyResult<Self> {
        Ok(Medium(Form::Sparse(Sparse::checked(index, sigma_s, sigma_a)?)))
    }

    /// Medium.band(inside, index, sigma_s, sigma_a, core_sigma_s, core_sigma_a): an object as a band and a core.
    /// `inside` (Z, Y, X) uint8 (non-zero: inside) or its bits ((ceil(Z Y X / 8),) uint8, `np.packbits`; read a
    /// z-plane at a time when a scene takes the medium, not kept); the band's voxels
    /// `index` (K,) int64 (strictly increasing linear (z, y, x) indices of inside voxels) with their coefficients
    /// (K, 3) float32 each; every other inside voxel has the core's `core_sigma_s`, `core_sigma_a` (3,) float32;
    /// outside voxels are vacuum; mm^-1. 24 bytes per band voxel, 12 per run of band or core voxels in a grid
    /// row and 4 per row; renders exactly as the sparse or dense form holding the same coefficients.
    #[staticmethod]
    fn band(
        inside: Bound<'_, PyAny>,
        index: Bound<'_, PyArray1<i64>>,
        sigma_s: Bound<'_, PyArray2<f32>>,
        sigma_a: Bound<'_, PyArray2<f32>>,
        core_sigma_s: PyReadonlyArray1<'_, f32>,
        core_sigma_a: PyReadonlyArray1<'_, f32>,
    ) -> PyResult<Self> {
        let inside = Inside::extract(&inside)?;
        let band = Sparse::checked(index, sigma_s, sigma_a)?;
        let three = |a: &PyReadonlyArray1<'_, f32>, name: &str| -> PyResult<[f32; 3]> {
            let v = a.as_array();
            check_shape(a.shape(), &[3], name)?;
            Ok([v[0], v[1], v[2]])
        };
        let (core_sigma_s, core_sigma_a) =
            (three(&core_sigma_s, "core_sigma_s")?, three(&core_sigma_a, "core_sigma_a")?);
        Ok(Medium(Form::Band { inside, band, core_sigma_s, core_sigma_a }))
    }

    /// Medium.labels(labels, ink_sigma_s, ink_sigma_a): one ink per voxel, (Z, Y, X) uint8 (255: vacuum), or a
    /// `LabelBricks` whose planes are all pushed (the scene built from this medium takes its bricks); and the ink
    /// table, (N, 3) float32 each, mm^-1. The scene stores the labels by bricks either way.
    #[staticmethod]
    fn labels(
        labels: Bound<'_, PyAny>,
        ink_sigma_s: Bound<'_, PyArray2<f32>>,
        ink_sigma_a: Bound<'_, PyArray2<f32>>,
    ) -> PyResult<Self> {
        let n = Some(ink_sigma_s.shape()[0]);
        let labels = if let Ok(b) = labels.cast::<LabelBricks>() {
            Labels::Bricks(b.clone().unbind())
        } else if let Ok(a) = labels.cast::<PyArray3<u8>>() {
            Labels::Dense(checked(a.clone(), "labels", &[None, None, None])?)
        } else {
            return Err(err("labels must be a (Z, Y, X) uint8 array or LabelBricks"));
        };
        let ink_sigma_s = checked(ink_sigma_s, "ink_sigma_s", &[n, Some(3)])?;
        Ok(Medium(Form::Labels {
            labels,
            ink_sigma_s,
            ink_sigma_a: checked(ink_sigma_a, "ink_sigma_a", &[n, Some(3)])?,
        }))
    }

    /// The medium's form: "dense", "sparse", "band" or "labels".
    #[getter]
    fn form(&self) -> &'static str {
        match self.0 {
            Form::Dense { .. } => "dense",
            Form::Sparse(_) => "sparse",
            Form::Band { .. } => "band",
            Form::Labels { .. } => "labels",
        }
    }
}

impl Medium {
    /// The core medium of a (z, y, x) = `shape` grid (a copy of the arrays in the core's form); a ValueError for
    /// arrays of another grid.
    pub(crate) fn build(&self, py: Python<'_>, shape: [usize; 3]) -> PyResult<MediumKind> {
        let [nz, ny, nx] = shape;
        match &self.0 {
            Form::Dense { sigma_s, sigma_a } => {
                let (s, a) = (view(sigma_s, py)?, view(sigma_a, py)?);
                check_shape(s.shape(), &[nz, ny, nx, 3], "sigma_s")?;
                let m = DenseMedium::from_interleaved(c_slice(&s, "sigma_s")?, c_slice(&a, "sigma_a")?);
                Ok(MediumKind::Dense(m.map_err(err)?))
            }
            Form::Sparse(Sparse { index, sigma_s, sigma_a }) => {
                let (ix, s, a) = (view(index, py)?, view(sigma_s, py)?, view(sigma_a, py)?);
                let (ix, s, a) = (c_slice(&ix, "index")?, c_slice(&s, "sigma_s")?, c_slice(&a, "sigma_a")?);
                Ok(MediumKind::Sparse(SparseMedium::new([nx, ny, nz], ix, s, a).map_err(err)?))
            }
            Form::Band { inside, band: Sparse { index, sigma_s, sigma_a }, core_sigma_s, core_sigma_a } => {
                let (ix, s, a) = (view(index, py)?, view(sigma_s, py)?, view(sigma_a, py)?);
                let (ix, s, a) = (c_slice(&ix, "index")?, c_slice(&s, "sigma_s")?, c_slice(&a, "sigma_a")?);
                let core = (*core_sigma_s, *core_sigma_a);
                let m =
                    inside.with(py, [nz, ny, nx], |m| BandMedium::new([nx, ny, nz], m, ix, s, a, core).map_err(err))?;
                Ok(MediumKind::Band(m))
            }
            Form::Labels { labels, ink_sigma_s, ink_sigma_a } => {
                let (is, ia) = (view(ink_sigma_s, py)?, view(ink_sigma_a, py)?);
                let (is, ia) = (c_slice(&is, "ink_sigma_s")?, c_slice(&ia, "ink_sigma_a")?);
                let m = match labels {
                    Labels::Dense(l) => {
                        let l = view(l, py)?;
                        check_shape(l.shape(), &[nz, ny, nx], "labels")?;
                        let l = c_slice(&l, "labels")?;
                        py.detach(|| LabelMedium::new([nx, ny, nz], l, is, ia))
                    }
                    Labels::Bricks(b) => {
                        let mut b = b.try_borrow_mut(py).map_err(|_| err("label bricks in use by another thread"))?;
                        let bricks = b.take(py, shape)?;
                        LabelMedium::from_bricks(bricks, is, ia)
                    }
                };
                Ok(MediumKind::Labels(m.map_err(err)?))
            }
        }
    }

    /// Overwrite `kind` with this medium in place when it has the same form and stores the same voxels (a
    /// dense medium of the `shape` grid, or a sparse one of the same index): no second copy of a big medium at
    /// the peak. Whether it did; a ValueError (nothing written) for bad coefficients or a dense medium of
    /// another grid.
    pub(crate) fn refill(&self, py: Python<'_>, kind: &mut MediumKind, shape: [usize; 3]) -> PyResult<bool> {
        let [nz, ny, nx] = shape;
        match (kind, &self.0) {
            (MediumKind::Dense(m), Form::Dense { sigma_s, sigma_a }) => {
                let (s, a) = (view(sigma_s, py)?, view(sigma_a, py)?);
                check_shape(s.shape(), &[nz, ny, nx, 3], "sigma_s")?;
                m.refill(c_slice(&s, "sigma_s")?, c_slice(&a, "sigma_a")?).map_err(err)?;
            }
            (MediumKind::Sparse(m), Form::Sparse(Sparse { index, sigma_s, sigma_a })) => {
                if !m.stores(c_slice(&view(index, py)?, "index")?) {
                    return Ok(false);
                }
                let (s, a) = (view(sigma_s, py)?, view(sigma_a, py)?);
                m.refill(c_slice(&s, "sigma_s")?, c_slice(&a, "sigma_a")?).map_err(err)?;
            }
            _ => return Ok(false),
        }
        Ok(true)
    }
}
