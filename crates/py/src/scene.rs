//! The `Scene` class: a voxel scene built once (geometry, medium, light, thread pool) that renders texel lists
//! (`Texels`) and accumulates gradients; its media come as `Medium` objects. `set_medium` swaps the medium and keeps the geometry (safe distances), thread
//! pool and gradient buffers, for optimisers that render a new medium every iteration (`set_voxels` overwrites
//! only some voxels); `set_light` lights it by a uniform light or an environment map. The gradient methods'
//! work is in `gradients`. The GIL is released while rendering.

use inkopt_core::transport::mask::MaskRef;
use inkopt_core::{render, render_hero, Boundary, EnvMap, Geometry, UniformLight};
use numpy::{
    IntoPyArray, PyArray1, PyReadonlyArray1, PyReadonlyArray2, PyReadonlyArray3, PyReadonlyArray4,
    PyUntypedArrayMethods,
};
use pyo3::prelude::*;

use crate::arrays::{c_slice, check_shape, err, options, pack, Packed};
use crate::gradients;
use crate::medium::{with_medium, Inside, Medium, MediumKind};
use crate::state::Scene;
use crate::texels::Texels;

#[pymethods]
impl Scene {
    /// Scene(shape_zyx, voxel_mm_xyz, medium, *, inside=None, normals=None, normal_index=None,
    /// normal_vectors=None, boundary="box", ior=1.5, g=0.4, threads=None). `medium`: a `Medium` of this grid;
    /// `inside`: the object's mask, (Z, Y, X) uint8 or its bits (`np.packbits`, as `Medium.band` takes it), or
    /// "labels": a label medium's voxels other than 255 (a printed volume's own labels; no mask array at all).
    /// Shading normals: dense (`normals` (Z, Y, X, 3) f32) or sparse (`normal_index` (K,) i64 increasing linear
    /// indices, `normal_vectors` (K, 3) f32).
    #[new]
    #[pyo3(signature = (shape, voxel_mm, medium, *, inside=None, normals=None, normal_index=None,
                        normal_vectors=None, boundary="box", ior=1.5, g=0.4, threads=None))]
    fn new(
        py: Python<'_>,
        shape: (usize, usize, usize),
        voxel_mm: (f32, f32, f32),
        medium: PyRef<'_, Medium>,
        inside: Option<Bound<'_, PyAny>>,
        normals: Option<PyReadonlyArray4<f32>>,
        normal_index: Option<PyReadonlyArray1<i64>>,
        normal_vectors: Option<PyReadonlyArray2<f32>>,
        boundary: &str,
        ior: f32,
        g: f32,
        threads: Option<usize>,
    ) -> PyResult<Self> {
        let (nz, ny, nx) = shape;
        let bnd = match boundary {
            "box" => Boundary::Box,
            "periodic-xy" => Boundary::PeriodicXY,
            other => return Err(err(format!("unknown boundary '{other}'; use 'box' or 'periodic-xy'"))),
        };
        let mut geo = Geometry::new([nx, ny, nz], [voxel_mm.0, voxel_mm.1, voxel_mm.2], bnd, ior, g).map_err(err)?;
        let medium = medium.build(py, [nz, ny, nx])?;
        if let Some(m) = inside {
            if m.extract::<&str>().is_ok_and(|s| s == "labels") {
                let MediumKind::Labels(labels) = &medium else {
                    return Err(err("inside='labels' needs a label medium"));
                };
                let mask = MaskRef::Labels(labels.labels());
                geo = py.detach(|| geo.with_inside_mask(mask)).map_err(err)?;
            } else {
                // read in place a slab at a time (a bit mask unpacked a slab at a time), not copied
                geo = Inside::extract(&m)?.with(py, [nz, ny, nx], |m| geo.with_inside_mask(m).map_err(err))?;
            }
        }
        if let Some(nrm) = &normals {
            check_shape(nrm.shape(), &[nz, ny, nx, 3], "normals")?;
            geo = geo.with_normals(c_slice(nrm, "normals")?).map_err(err)?; // kept sparse, not copied
        }
        match (normal_index, normal_vectors) {
            (Some(i), Some(v)) => {
                if normals.is_some() {
                    return Err(err("give the normals dense or sparse, not both"));
                }
                check_shape(v.shape(), &[i.len(), 3], "normal_vectors")?;
                geo = geo
                    .with_sparse_normals(c_slice(&i, "normal_index")?, c_slice(&v, "normal_vectors")?)
                    .map_err(err)?;
            }
            (None, None) => {}
            _ => return Err(err("normal_index and normal_vectors go together")),
        }
        let mut b = rayon::ThreadPoolBuilder::new();
        if let Some(t) = threads {
            b = b.num_threads(t);
        }
        let pool = b.build().map_err(|e| err(e.to_string()))?;
        Ok(Scene { geo, medium, pool, grads: None, sparse: false, shape: [nz, ny, nx] })
    }

    /// set_medium(medium): replace the medium by `medium` (a `Medium` of this grid) and keep the geometry (grid,
    /// boundary, ior, g, inside mask and its safe distances, normals), the thread pool and any gradient buffers.
    /// A dense medium replaced by a dense one, or a sparse one by a sparse one of the same voxels, is overwritten
    /// in place (no second copy at the peak).
    fn set_medium(&mut self, py: Python<'_>, medium: PyRef<'_, Medium>) -> PyResult<()> {
        if !medium.refill(py, &mut self.medium, self.shape)? {
            self.medium = medium.build(py, self.shape)?;
        }
        Ok(())
    }

    /// set_voxels(index, sigma_s, sigma_a): overwrite the coefficients of some voxels of a dense, sparse or band
    /// medium (a sparse one must store them, a band one hold them in its band: the core has one mixture) in place
    /// (the optimiser's free voxels, every iteration) and recompute the majorant. `index` (K,) int64: linear
    /// voxel indices of the (z, y, x) grid (a voxel listed twice takes its last values); `sigma_s`, `sigma_a`
    /// (K, 3) float32, mm^-1. All checked before anything is written. The GIL is released.
    fn set_voxels(
        &mut self,
        py: Python<'_>,
        index: PyReadonlyArray1<i64>,
        sigma_s: PyReadonlyArray2<f32>,
        sigma_a: PyReadonlyArray2<f32>,
    ) -> PyResult<()> {
        let k = index.len();
        check_shape(sigma_s.shape(), &[k, 3], "sigma_s")?;
        check_shape(sigma_a.shape(), &[k, 3], "sigma_a")?;
        let (ix, s, a) = (c_slice(&index, "index")?, c_slice(&sigma_s, "sigma_s")?, c_slice(&sigma_a, "sigma_a")?);
        let pool = &self.pool;
        match &mut self.medium {
            MediumKind::Dense(m) => py.detach(|| pool.install(|| m.set_voxels(ix, s, a))).map_err(err),
            MediumKind::Sparse(m) => py.detach(|| pool.install(|| m.set_voxels(ix, s, a))).map_err(err),
            MediumKind::Band(m) => py.detach(|| pool.install(|| m.set_voxels(ix, s, a))).map_err(err),
            MediumKind::Labels(_) => Err(err("set_voxels needs coefficients (sigma_s, sigma_a), not labels")),
        }
    }

    /// in_band(index) -> (K,) bool: whether each voxel of `index` (K,) int64 (linear (z, y, x) indices) is in a
    /// band medium's band (what its `set_voxels` takes; a core or outside voxel is not). Only for a band medium.
    fn in_band<'py>(&self, py: Python<'py>, index: PyReadonlyArray1<i64>) -> PyResult<Bound<'py, PyArray1<bool>>> {
        let ix = c_slice(&index, "index")?;
        match &self.medium {
            MediumKind::Band(m) => Ok(m.in_band(ix).into_pyarray(py)),
            _ => Err(err("in_band needs a band medium")),
        }
    }

    /// set_light(map=None, rotate_deg=0.0): light the scene by an equirectangular environment map of linear
    /// radiance, (H, 2H, 3) float32 C-contiguous (row 0 looks up along +z, column 0 starts at +x, longitude
    /// grows towards +y; bilinear per channel), turned by `rotate_deg` about z (from +x towards +y); None: the
    /// uniform white light of radiance 1 (the default).
    #[pyo3(signature = (map=None, rotate_deg=0.0))]
    fn set_light(&mut self, map: Option<PyReadonlyArray3<f32>>, rotate_deg: f32) -> PyResult<()> {
        match map {
            None => self.geo.set_light(Box::new(UniformLight([1.0; 3]))),
            Some(m) => {
                let s = m.shape();
                if s[2] != 3 {
                    return Err(err(format!("the light map has shape {s:?}, expected (H, 2H, 3)")));
                }
                let env = EnvMap::new(s[0], s[1], c_slice(&m, "light map")?, rotate_deg).map_err(err)?;
                self.geo.set_light(Box::new(env));
            }
        }
        Ok(())
    }

    #[getter]
    fn threads(&self) -> usize {
        self.pool.current_num_threads()
    }

    /// (bricks, stored_bricks, bytes) of the signed distances of the inside mask, stored by bricks of 8^3 voxels
    /// (`inkopt_core::transport::distance::BrickedDistances`): the grid's bricks, those stored with their bytes (the
    /// others, of one value, cost a table entry), the bytes held; None without an inside mask.
    #[getter]
    fn distance_storage(&self) -> Option<(usize, usize, usize)> {
        self.geo.dist.as_ref().map(|d| (d.bricks(), d.stored_bricks(), d.bytes()))
    }

    /// render(texels, *, spp, seed, first_texel=0, include_specular=True, hero=False) -> (mean (I,3) f32,
    /// var_mean (I,3) f32, stats dict). Random numbers are keyed by (seed, texel index, sample); `first_texel` is
    /// the index of the first of `texels`. `hero`: spp paths per texel each serving the three channels (hero
    /// channel sample mod 3, balance heuristic; `inkopt_core::transport::hero`) instead of spp per channel.
    #[pyo3(signature = (texels, *, spp, seed, first_texel=0, include_specular=true, hero=false))]
    fn render<'py>(
        &self,
        py: Python<'py>,
        texels: PyRef<'_, Texels>,
        spp: u32,
        seed: u64,
        first_texel: u64,
        include_specular: bool,
        hero: bool,
    ) -> PyResult<Packed<'py>> {
        let texels = texels.on(&self.geo)?;
        let opts = options(spp, seed, include_specular)?;
        let (est, stats) = py.detach(|| {
            self.pool.install(|| {
                with_medium!(&self.medium, m => if hero {
                    render_hero(&self.geo, m, texels, first_texel, &opts)
                } else {
                    render(&self.geo, m, texels, first_texel, &opts)
                })
            })
        });
        pack(py, &est, &stats)
    }

    /// Reset the gradient accumulators for a pass whose adjoints are at most `max_abs_adjoint` in magnitude
    /// (sets the fixed-point quantum). `grad_index`: which voxels get gradients, and in which slot; gradients are
    /// then returned per slot, (F, 3). Either (z, y, x) int32, the slot of each voxel or -1 for none, or (F,)
    /// int64, strictly increasing linear indices of the voxels whose slots are 0..F (no map per grid voxel on
    /// either side: the core ranks them per grid row, `inkopt_core::spans`). None: every voxel, (z, y, x, 3).
    /// The buffer of the previous call, if it was not taken (take_grad frees it), is zeroed in place when it was
    /// for the same slots (checked: element by element, or in O(F) for the second form) or both None; otherwise
    /// it is freed before the new one is allocated. The GIL is released.
    #[pyo3(signature = (max_abs_adjoint, grad_index=None))]
    fn zero_grad(
        &mut self,
        py: Python<'_>,
        max_abs_adjoint: f32,
        grad_index: Option<Bound<'_, PyAny>>,
    ) -> PyResult<()> {
        gradients::zero_grad(self, py, max_abs_adjoint, grad_index)
    }

    /// backward(texels, adjoint (I,3) f32, *, spp, seed, first_texel=0, include_specular=True, method="replay",
    /// hero=False) -> (mean, var_mean, stats), as render's: accumulates adjoint . dc/dsigma into the buffers of
    /// zero_grad. `hero`: hero paths as render's (method "replay" only).
    #[pyo3(signature = (texels, adjoint, *, spp, seed, first_texel=0, include_specular=true, method="replay", hero=false))]
    fn backward<'py>(
        &mut self,
        py: Python<'py>,
        texels: PyRef<'_, Texels>,
        adjoint: PyReadonlyArray2<f32>,
        spp: u32,
        seed: u64,
        first_texel: u64,
        include_specular: bool,
        method: &str,
        hero: bool,
    ) -> PyResult<Packed<'py>> {
        let texels = texels.on(&self.geo)?;
        let opts = options(spp, seed, include_specular)?;
        gradients::backward(self, py, texels, first_texel, adjoint, &opts, method, hero)
    }

    /// The accumulated gradients (d e/d sigma_s, d e/d sigma_a): (z, y, x, 3) float32 each, or (F, 3) per slot
    /// when zero_grad was given a grad_index. The buffers are freed (48 bytes per slot: a big object's optimiser
    /// step should not hold them beside its own arrays), a block of slots at a time as they are converted, so the
    /// sums and the arrays are not resident at once; the next zero_grad allocates new ones.
    fn take_grad<'py>(&mut self, py: Python<'py>) -> PyResult<(Bound<'py, PyAny>, Bound<'py, PyAny>)> {
        gradients::take_grad(self, py)
    }

    /// The gradients as take_grad, but as their raw fixed-point sums (int64) and the quantum (float): the float
    /// gradient is float32(float64(sum) * quantum). Sums of shards of one pass (same max_abs_adjoint) add up,
    /// wrapping, to the whole pass's sums, which is how texel shards on several machines combine bit-identically.
    /// (Also frees the buffers, as take_grad does.)
    fn take_grad_fixed<'py>(&mut self, py: Python<'py>) -> PyResult<(Bound<'py, PyAny>, Bound<'py, PyAny>, f64)> {
        gradients::take_grad_fixed(self, py)
    }
}
