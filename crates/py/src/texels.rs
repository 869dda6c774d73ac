//! The `Texels` class: a list of texels (the sensor elements of a render or gradient pass) converted and checked
//! once, when it is built; a pass then only checks that each texel lies inside its scene's object.

use inkopt_core::{face_normal, Geometry, Texel};
use numpy::{PyReadonlyArray1, PyReadonlyArray2, PyUntypedArrayMethods};
use pyo3::prelude::*;

use crate::arrays::{c_slice, err};

/// Texels for `Scene.render` and `Scene.backward`: voxel (I, 3) int32 (z, y, x), face (I,) uint8 (0..5: -x,
/// +x, -y, +y, -z, +z), normal (I, 3) float32 (x, y, z) outward, made unit here. 28 bytes per texel.
#[pyclass(module = "inkopt._core", frozen)]
pub(crate) struct Texels(Vec<Texel>);

#[pymethods]
impl Texels {
    /// Texels(voxel, face, normal): the texel arrays, copied in the core's form; a ValueError for arrays of
    /// different lengths or layouts, a face id above 5 or a normal that is not a unit vector facing out of its
    /// face.
    #[new]
    fn new(voxel: PyReadonlyArray2<i32>, face: PyReadonlyArray1<u8>, normal: PyReadonlyArray2<f32>) -> PyResult<Self> {
        let i = face.len();
        if voxel.shape() != [i, 3] || normal.shape() != [i, 3] {
            return Err(err(format!(
                "texel arrays must be voxel (I,3), face (I,), normal (I,3); got {:?}, {:?}, {:?}",
                voxel.shape(),
                face.shape(),
                normal.shape()
            )));
        }
        let (v, f, n) = (c_slice(&voxel, "voxel")?, c_slice(&face, "face")?, c_slice(&normal, "normal")?);
        let mut out = Vec::with_capacity(i);
        for k in 0..i {
            if f[k] > 5 {
                return Err(err(format!("texel {k} has face id {} (must be 0..5)", f[k])));
            }
            let nrm = [n[3 * k], n[3 * k + 1], n[3 * k + 2]];
            let len = (nrm[0] * nrm[0] + nrm[1] * nrm[1] + nrm[2] * nrm[2]).sqrt();
            let fnrm = face_normal(f[k]);
            if !(len > 0.5 && len < 2.0) || (nrm[0] * fnrm[0] + nrm[1] * fnrm[1] + nrm[2] * fnrm[2]) <= 0.0 {
                return Err(err(format!("texel {k} normal {nrm:?} is not a unit vector facing out of face {}", f[k])));
            }
            let voxel = [v[3 * k + 2], v[3 * k + 1], v[3 * k]];
            out.push(Texel { voxel, face: f[k], normal: [nrm[0] / len, nrm[1] / len, nrm[2] / len] });
        }
        Ok(Texels(out))
    }

    /// The number of texels.
    fn __len__(&self) -> usize {
        self.0.len()
    }
}

impl Texels {
    /// The texels of a pass on `geo`; a ValueError for a texel on a voxel outside the object.
    pub(crate) fn on(&self, geo: &Geometry) -> PyResult<&[Texel]> {
        if let Some((k, t)) = self.0.iter().enumerate().find(|(_, t)| !geo.is_inside(t.voxel)) {
            let [x, y, z] = t.voxel;
            return Err(err(format!(
                "texel {k} lies on voxel (z,y,x)={:?}, which is not inside the object",
                [z, y, x]
            )));
        }
        Ok(&self.0)
    }
}
