//! The medium of a `Scene` from the Python arrays: dense, sparse or label form, and the macro that runs a
//! generic core function on whichever form the scene holds.

use inkopt_core::{DenseMedium, LabelMedium, SparseMedium};
use numpy::{PyReadonlyArray1, PyReadonlyArray2, PyReadonlyArray3, PyReadonlyArrayDyn, PyUntypedArrayMethods};
use pyo3::prelude::*;

use crate::arrays::{c_slice, check_shape, err};

/// The three forms of a scene's medium. A scene holds one, so the size difference between the variants costs
/// nothing worth a box (an extra indirection on every render call).
#[allow(clippy::large_enum_variant)]
pub(crate) enum MediumKind {
    Dense(DenseMedium),
    Sparse(SparseMedium),
    Labels(LabelMedium),
}

/// Run `$body` with `$m` bound to the scene's medium, whatever its kind (each kind its own monomorphised walk).
macro_rules! with_medium {
    ($medium:expr, $m:ident => $body:expr) => {
        match $medium {
            $crate::medium::MediumKind::Dense($m) => $body,
            $crate::medium::MediumKind::Sparse($m) => $body,
            $crate::medium::MediumKind::Labels($m) => $body,
        }
    };
}
pub(crate) use with_medium;

/// The medium of a (z, y, x) = `shape` grid: dense sigma_s and sigma_a (z, y, x, 3) float32; sparse: those of
/// the voxels `medium_index` only, (K, 3) each; or labels (z, y, x) uint8 with an ink table ink_sigma_s,
/// ink_sigma_a (N, 3) float32.
pub(crate) fn medium_from(
    shape: [usize; 3],
    sigma_s: Option<PyReadonlyArrayDyn<f32>>,
    sigma_a: Option<PyReadonlyArrayDyn<f32>>,
    medium_index: Option<PyReadonlyArray1<i64>>,
    labels: Option<PyReadonlyArray3<u8>>,
    ink_sigma_s: Option<PyReadonlyArray2<f32>>,
    ink_sigma_a: Option<PyReadonlyArray2<f32>>,
) -> PyResult<MediumKind> {
    let [nz, ny, nx] = shape;
    match (sigma_s, sigma_a, labels) {
        (Some(s), Some(a), None) => {
            let (s_, a_) = (c_slice(&s, "sigma_s")?, c_slice(&a, "sigma_a")?);
            match medium_index {
                None => {
                    check_shape(s.shape(), &[nz, ny, nx, 3], "sigma_s")?;
                    check_shape(a.shape(), &[nz, ny, nx, 3], "sigma_a")?;
                    Ok(MediumKind::Dense(DenseMedium::from_interleaved(s_, a_).map_err(err)?))
                }
                Some(ix) => {
                    check_shape(s.shape(), &[ix.len(), 3], "sigma_s")?;
                    check_shape(a.shape(), &[ix.len(), 3], "sigma_a")?;
                    let ix = c_slice(&ix, "medium_index")?;
                    Ok(MediumKind::Sparse(SparseMedium::new([nx, ny, nz], ix, s_, a_).map_err(err)?))
                }
            }
        }
        (None, None, Some(l)) => {
            if medium_index.is_some() {
                return Err(err("medium_index goes with sigma_s and sigma_a, not labels"));
            }
            check_shape(l.shape(), &[nz, ny, nx], "labels")?;
            let (is, ia) = match (ink_sigma_s, ink_sigma_a) {
                (Some(is), Some(ia)) => (is, ia),
                _ => return Err(err("a label volume needs ink_sigma_s and ink_sigma_a")),
            };
            for (t, name) in [(&is, "ink_sigma_s"), (&ia, "ink_sigma_a")] {
                if t.shape().len() != 2 || t.shape()[1] != 3 {
                    return Err(err(format!("{name} has shape {:?}, expected (n_inks, 3)", t.shape())));
                }
            }
            let l = c_slice(&l, "labels")?.to_vec();
            Ok(MediumKind::Labels(
                LabelMedium::new(l, c_slice(&is, "ink_sigma_s")?, c_slice(&ia, "ink_sigma_a")?).map_err(err)?,
            ))
        }
        _ => Err(err("give either sigma_s and sigma_a, or labels with an ink table")),
    }
}
