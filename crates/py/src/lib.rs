//! Thin PyO3 bindings of inkopt-core: a `Scene` (geometry + medium, built once) that renders texel lists and
//! accumulates gradients. Array conventions are the Python package's: (z, y, x[, c]) arrays, texel voxels
//! (z, y, x), normals and voxel sizes (x, y, z). The GIL is released while rendering. `set_medium` swaps the
//! medium of a scene and keeps its geometry (safe distances), thread pool and gradient buffers, for optimisers
//! that render a new medium every iteration (`set_voxels` overwrites only some voxels of a dense medium);
//! `set_light` lights it by a uniform light or an environment map.

use inkopt_core::{backward, render, Boundary, DenseMedium, EnvMap, Geometry, GradBuffers, GradMethod, LabelMedium,
                  RenderOptions, SparseMedium, Stats, Texel, TexelEstimate, UniformLight, NO_GRADIENT};
use numpy::ndarray::{Array2, Array4, Dimension};
use numpy::{Element, IntoPyArray, PyArray2, PyReadonlyArray, PyReadonlyArray1, PyReadonlyArray2, PyReadonlyArray3,
            PyReadonlyArray4, PyReadonlyArrayDyn, PyUntypedArrayMethods};
use pyo3::exceptions::PyValueError;
use pyo3::prelude::*;
use pyo3::types::PyDict;
use std::sync::{Arc, Mutex};

enum MediumKind {
    Dense(DenseMedium),
    Sparse(SparseMedium),
    Labels(LabelMedium),
}

/// Run `$body` with `$m` bound to the scene's medium, whatever its kind (each kind its own monomorphised walk).
macro_rules! with_medium {
    ($medium:expr, $m:ident => $body:expr) => {
        match $medium {
            MediumKind::Dense($m) => $body,
            MediumKind::Sparse($m) => $body,
            MediumKind::Labels($m) => $body,
        }
    };
}

#[pyclass(module = "inkopt._core")]
struct Scene {
    geo: Geometry,
    medium: MediumKind,
    pool: rayon::ThreadPool,
    grads: Option<GradBuffers>,
    /// Whether the gradient buffers are per slot of a grad_index (else per voxel).
    sparse: bool,
    shape: [usize; 3],
}

fn grad_index_given(g: &Option<GradBuffers>) -> bool {
    g.as_ref().map(|g| g.is_mapped()).unwrap_or(false)
}

fn err(msg: impl Into<String>) -> PyErr {
    PyValueError::new_err(msg.into())
}

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
                pools.push((n, p.clone()));
                p
            }
        }
    };
    Ok(pool.install(f))
}

#[pymethods]
impl Scene {
    /// Scene(shape_zyx, voxel_mm_xyz, *, sigma_s=None, sigma_a=None, medium_index=None, labels=None,
    /// ink_sigma_s=None, ink_sigma_a=None, inside=None, normals=None, normal_index=None, normal_vectors=None,
    /// boundary="box", ior=1.5, g=0.4, threads=None). Medium: dense (`sigma_s`, `sigma_a` (Z, Y, X, 3) f32),
    /// sparse (`medium_index` (K,) i64 strictly increasing linear indices of the voxels that are not vacuum, with
    /// `sigma_s`, `sigma_a` (K, 3) f32: 24 bytes per voxel of each row's span of them), or labels. Shading normals:
    /// dense (`normals` (Z, Y, X, 3) f32) or sparse (`normal_index` (K,) i64 increasing linear indices,
    /// `normal_vectors` (K, 3) f32).
    #[new]
    #[pyo3(signature = (shape, voxel_mm, *, sigma_s=None, sigma_a=None, medium_index=None, labels=None,
                        ink_sigma_s=None, ink_sigma_a=None, inside=None, normals=None, normal_index=None,
                        normal_vectors=None, boundary="box", ior=1.5, g=0.4, threads=None))]
    #[allow(clippy::too_many_arguments)]
    fn new(
        shape: (usize, usize, usize),
        voxel_mm: (f32, f32, f32),
        sigma_s: Option<PyReadonlyArrayDyn<f32>>,
        sigma_a: Option<PyReadonlyArrayDyn<f32>>,
        medium_index: Option<PyReadonlyArray1<i64>>,
        labels: Option<PyReadonlyArray3<u8>>,
        ink_sigma_s: Option<PyReadonlyArray2<f32>>,
        ink_sigma_a: Option<PyReadonlyArray2<f32>>,
        inside: Option<PyReadonlyArray3<u8>>,
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
        let medium = medium_from([nz, ny, nx], sigma_s, sigma_a, medium_index, labels, ink_sigma_s, ink_sigma_a)?;
        if let Some(m) = inside {
            check_shape(m.shape(), &[nz, ny, nx], "inside")?;
            geo = geo.with_inside(c_slice(&m, "inside")?.to_vec()).map_err(err)?;
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
                geo = geo.with_sparse_normals(c_slice(&i, "normal_index")?, c_slice(&v, "normal_vectors")?)
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

    /// set_medium(*, sigma_s=None, sigma_a=None, medium_index=None, labels=None, ink_sigma_s=None,
    /// ink_sigma_a=None): replace the medium (the same arguments as the constructor's) and keep the geometry
    /// (grid, boundary, ior, g, inside mask and its safe distances, normals), the thread pool and any gradient
    /// buffers. A dense medium replaced by a dense one, or a sparse one by a sparse one of the same voxels, is
    /// overwritten in place (no second copy at the peak).
    #[pyo3(signature = (*, sigma_s=None, sigma_a=None, medium_index=None, labels=None, ink_sigma_s=None,
                        ink_sigma_a=None))]
    fn set_medium(
        &mut self,
        sigma_s: Option<PyReadonlyArrayDyn<f32>>,
        sigma_a: Option<PyReadonlyArrayDyn<f32>>,
        medium_index: Option<PyReadonlyArray1<i64>>,
        labels: Option<PyReadonlyArray3<u8>>,
        ink_sigma_s: Option<PyReadonlyArray2<f32>>,
        ink_sigma_a: Option<PyReadonlyArray2<f32>>,
    ) -> PyResult<()> {
        let [nz, ny, nx] = self.shape;
        match (&mut self.medium, &sigma_s, &sigma_a, &medium_index, &labels) {
            (MediumKind::Dense(m), Some(s), Some(a), None, None) => {
                check_shape(s.shape(), &[nz, ny, nx, 3], "sigma_s")?;
                check_shape(a.shape(), &[nz, ny, nx, 3], "sigma_a")?;
                return m.refill(c_slice(s, "sigma_s")?, c_slice(a, "sigma_a")?).map_err(err);
            }
            (MediumKind::Sparse(m), Some(s), Some(a), Some(ix), None) if m.stores(c_slice(ix, "medium_index")?) => {
                check_shape(s.shape(), &[ix.len(), 3], "sigma_s")?;
                check_shape(a.shape(), &[ix.len(), 3], "sigma_a")?;
                return m.refill(c_slice(s, "sigma_s")?, c_slice(a, "sigma_a")?).map_err(err);
            }
            _ => {}
        }
        self.medium = medium_from(self.shape, sigma_s, sigma_a, medium_index, labels, ink_sigma_s, ink_sigma_a)?;
        Ok(())
    }

    /// set_voxels(index, sigma_s, sigma_a): overwrite the coefficients of some voxels of a dense or sparse
    /// medium (a sparse one must store them) in place
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
            MediumKind::Labels(_) => Err(err("set_voxels needs coefficients (sigma_s, sigma_a), not labels")),
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

    /// render(texel_voxel (I,3) int32 zyx, texel_face (I,) uint8, texel_normal (I,3) float32 xyz, *, spp, seed,
    /// first_texel=0, include_specular=True) -> (mean (I,3) f32, var_mean (I,3) f32, stats dict)
    #[pyo3(signature = (texel_voxel, texel_face, texel_normal, *, spp, seed, first_texel=0, include_specular=true))]
    #[allow(clippy::too_many_arguments)]
    fn render<'py>(
        &self,
        py: Python<'py>,
        texel_voxel: PyReadonlyArray2<i32>,
        texel_face: PyReadonlyArray1<u8>,
        texel_normal: PyReadonlyArray2<f32>,
        spp: u32,
        seed: u64,
        first_texel: u64,
        include_specular: bool,
    ) -> PyResult<(Bound<'py, PyArray2<f32>>, Bound<'py, PyArray2<f32>>, Bound<'py, PyDict>)> {
        let texels = self.texels(&texel_voxel, &texel_face, &texel_normal)?;
        let opts = options(spp, seed, include_specular)?;
        let (est, stats) = py.detach(|| {
            self.pool.install(|| with_medium!(&self.medium, m => render(&self.geo, m, &texels, first_texel, &opts)))
        });
        pack(py, &est, &stats)
    }

    /// Reset the gradient accumulators for a pass whose adjoints are at most `max_abs_adjoint` in magnitude
    /// (sets the fixed-point quantum). `grad_index`: which voxels get gradients, and in which slot; gradients are
    /// then returned per slot, (F, 3). Either (z, y, x) int32, the slot of each voxel or -1 for none, or (F,)
    /// int64, strictly increasing linear indices of the voxels whose slots are 0..F (no map per grid voxel on
    /// either side: the core ranks them per grid row, `inkopt_core::spans`). None: every voxel, (z, y, x, 3). The buffer of the previous call, if it was
    /// not taken (take_grad frees it), is zeroed in place when it was for the same slots (checked: element by element, or in O(F) for the second form) or both
    /// None; otherwise it is freed before the new one is allocated. The GIL is released.
    #[pyo3(signature = (max_abs_adjoint, grad_index=None))]
    fn zero_grad(&mut self, py: Python<'_>, max_abs_adjoint: f32, grad_index: Option<Bound<'_, PyAny>>)
                 -> PyResult<()> {
        let n = self.geo.voxel_count();
        let dense_ix: Option<PyReadonlyArray3<i32>>;
        let voxels_ix: Option<PyReadonlyArray1<i64>>;
        match &grad_index {
            None => (dense_ix, voxels_ix) = (None, None),
            Some(a) => {
                if let Ok(d) = a.extract::<PyReadonlyArray3<i32>>() {
                    check_shape(d.shape(), &self.shape, "grad_index")?;
                    (dense_ix, voxels_ix) = (Some(d), None);
                } else if let Ok(v) = a.extract::<PyReadonlyArray1<i64>>() {
                    (dense_ix, voxels_ix) = (None, Some(v));
                } else {
                    return Err(err("grad_index must be a (z, y, x) int32 slot map or (F,) int64 voxel indices"));
                }
            }
        }
        let dense = match &dense_ix { Some(d) => Some(c_slice(d, "grad_index")?), None => None };
        let voxels = match &voxels_ix { Some(v) => Some(c_slice(v, "grad_index")?), None => None };
        let slot = |k: i32| if k < 0 { NO_GRADIENT } else { k as u32 };
        let [nz, ny, nx] = self.shape;
        let (pool, grads) = (&self.pool, &mut self.grads);
        let done = py.detach(|| pool.install(|| {
            use rayon::prelude::*;
            let same = grads.as_ref().is_some_and(|g| match (g.map(), dense, voxels) {
                (None, None, None) => !g.is_mapped(),
                (Some(m), Some(ix), None) => m.len() == ix.len() && m.par_iter().zip(ix).all(|(&m, &k)| m == slot(k)),
                (None, None, Some(v)) => g.lists(v),
                _ => false,
            });
            if !same {
                *grads = None; // free the old buffers first: two sets of them would be the peak of a big object
                *grads = Some(match (dense, voxels) {
                    (Some(ix), _) => GradBuffers::with_map(n, Some(ix.par_iter().map(|&k| slot(k)).collect()))?,
                    (None, Some(v)) => GradBuffers::with_voxels([nx, ny, nz], v)?,
                    (None, None) => GradBuffers::with_map(n, None)?,
                });
            }
            grads.as_mut().unwrap().zero(max_abs_adjoint);
            Ok::<(), String>(())
        }));
        self.sparse = grad_index_given(&self.grads);
        done.map_err(err)
    }

    /// backward(texel_voxel, texel_face, texel_normal, adjoint (I,3) f32, *, spp, seed, first_texel=0,
    /// include_specular=True, method="replay") -> (mean, var_mean, stats): accumulates adjoint . dc/dsigma.
    #[pyo3(signature = (texel_voxel, texel_face, texel_normal, adjoint, *, spp, seed, first_texel=0,
                        include_specular=true, method="replay"))]
    #[allow(clippy::too_many_arguments)]
    fn backward<'py>(
        &mut self,
        py: Python<'py>,
        texel_voxel: PyReadonlyArray2<i32>,
        texel_face: PyReadonlyArray1<u8>,
        texel_normal: PyReadonlyArray2<f32>,
        adjoint: PyReadonlyArray2<f32>,
        spp: u32,
        seed: u64,
        first_texel: u64,
        include_specular: bool,
        method: &str,
    ) -> PyResult<(Bound<'py, PyArray2<f32>>, Bound<'py, PyArray2<f32>>, Bound<'py, PyDict>)> {
        let texels = self.texels(&texel_voxel, &texel_face, &texel_normal)?;
        let opts = options(spp, seed, include_specular)?;
        let method = match method {
            "replay" => GradMethod::Replay,
            "li1" => GradMethod::Li1,
            other => return Err(err(format!("unknown gradient method '{other}'; use 'replay' or 'li1'"))),
        };
        if adjoint.shape() != [texels.len(), 3] {
            return Err(err(format!("adjoint has shape {:?}, expected ({}, 3)", adjoint.shape(), texels.len())));
        }
        let adj: Vec<[f32; 3]> = c_slice(&adjoint, "adjoint")?.chunks_exact(3).map(|c| [c[0], c[1], c[2]]).collect();
        if adj.iter().any(|a| a.iter().any(|x| !x.is_finite())) {
            return Err(err("adjoint contains NaN or infinite values"));
        }
        if self.grads.is_none() {
            return Err(err("call zero_grad before backward"));
        }
        let grads = self.grads.as_ref().unwrap();
        let (est, stats) = py.detach(|| {
            self.pool.install(|| with_medium!(&self.medium, m =>
                backward(&self.geo, m, &texels, first_texel, &adj, &opts, method, grads)))
        });
        pack(py, &est, &stats)
    }

    /// The accumulated gradients (d e/d sigma_s, d e/d sigma_a): (z, y, x, 3) float32 each, or (F, 3) per slot
    /// when zero_grad was given a grad_index. The buffers are freed (48 bytes per slot: a big object's optimiser
    /// step should not hold them beside its own arrays); the next zero_grad allocates new ones.
    fn take_grad<'py>(&mut self, py: Python<'py>) -> PyResult<(Bound<'py, PyAny>, Bound<'py, PyAny>)> {
        let g = self.grads.take().ok_or_else(|| err("no gradient: call zero_grad and backward first"))?;
        let n = g.slots();
        let mut gs = vec![0.0f32; 3 * n];
        let mut ga = vec![0.0f32; 3 * n];
        py.detach(|| g.collect(&mut gs, &mut ga));
        drop(g);
        Ok((self.grad_array(py, gs)?, self.grad_array(py, ga)?))
    }

    /// The gradients as take_grad, but as their raw fixed-point sums (int64) and the quantum (float): the float
    /// gradient is float32(float64(sum) * quantum). Sums of shards of one pass (same max_abs_adjoint) add up,
    /// wrapping, to the whole pass's sums, which is how texel shards on several machines combine bit-identically.
    /// (Also frees the buffers, as take_grad does.)
    fn take_grad_fixed<'py>(&mut self, py: Python<'py>) -> PyResult<(Bound<'py, PyAny>, Bound<'py, PyAny>, f64)> {
        let g = self.grads.take().ok_or_else(|| err("no gradient: call zero_grad and backward first"))?;
        let n = g.slots();
        let mut gs = vec![0i64; 3 * n];
        let mut ga = vec![0i64; 3 * n];
        py.detach(|| g.collect_fixed(&mut gs, &mut ga));
        let quantum = g.quantum();
        drop(g);
        Ok((self.grad_array(py, gs)?, self.grad_array(py, ga)?, quantum))
    }
}

impl Scene {
    /// A gradient buffer as an array: (F, 3) per slot after a grad_index, else (z, y, x, 3).
    fn grad_array<'py, T: Element>(&self, py: Python<'py>, v: Vec<T>) -> PyResult<Bound<'py, PyAny>> {
        let [nz, ny, nx] = self.shape;
        if self.sparse {
            let n = v.len() / 3;
            return Ok(Array2::from_shape_vec((n, 3), v).map_err(|e| err(e.to_string()))?.into_pyarray(py).into_any());
        }
        Ok(Array4::from_shape_vec((nz, ny, nx, 3), v).map_err(|e| err(e.to_string()))?.into_pyarray(py).into_any())
    }

    fn texels(&self, voxel: &PyReadonlyArray2<i32>, face: &PyReadonlyArray1<u8>, normal: &PyReadonlyArray2<f32>)
              -> PyResult<Vec<Texel>> {
        let i = face.len();
        if voxel.shape() != [i, 3] || normal.shape() != [i, 3] {
            return Err(err("texel arrays must be voxel (I,3), face (I,), normal (I,3)"));
        }
        let (v, f, n) = (c_slice(voxel, "texel_voxel")?, c_slice(face, "texel_face")?, c_slice(normal, "texel_normal")?);
        let mut out = Vec::with_capacity(i);
        for k in 0..i {
            let vox = [v[3 * k + 2], v[3 * k + 1], v[3 * k]];
            if f[k] > 5 {
                return Err(err(format!("texel {k} has face id {} (must be 0..5)", f[k])));
            }
            if !self.geo.is_inside(vox) {
                return Err(err(format!("texel {k} lies on voxel (z,y,x)={:?}, which is not inside the object",
                                       [v[3 * k], v[3 * k + 1], v[3 * k + 2]])));
            }
            let nrm = [n[3 * k], n[3 * k + 1], n[3 * k + 2]];
            let len = (nrm[0] * nrm[0] + nrm[1] * nrm[1] + nrm[2] * nrm[2]).sqrt();
            let fnrm = inkopt_core::face_normal(f[k]);
            if !(len > 0.5 && len < 2.0) || (nrm[0] * fnrm[0] + nrm[1] * fnrm[1] + nrm[2] * fnrm[2]) <= 0.0 {
                return Err(err(format!("texel {k} normal {nrm:?} is not a unit vector facing out of face {}", f[k])));
            }
            out.push(Texel { voxel: vox, face: f[k], normal: [nrm[0] / len, nrm[1] / len, nrm[2] / len] });
        }
        Ok(out)
    }
}

/// The array's data in C order; a ValueError for other layouts (a Fortran-ordered array is contiguous too, but
/// its memory is not in the (z, y, x[, c]) order the core reads).
fn c_slice<'a, T: Element, D: Dimension>(a: &'a PyReadonlyArray<'_, T, D>, name: &str) -> PyResult<&'a [T]> {
    if !a.is_c_contiguous() {
        return Err(err(format!("{name} must be C-contiguous (np.ascontiguousarray)")));
    }
    a.as_slice().map_err(|_| err(format!("{name} must be C-contiguous (np.ascontiguousarray)")))
}

fn check_shape(dims: &[usize], want: &[usize], name: &str) -> PyResult<()> {
    if dims != want {
        return Err(err(format!("{name} has shape {dims:?}, expected {want:?}")));
    }
    Ok(())
}

/// The medium of a (z, y, x) = `shape` grid: dense sigma_s and sigma_a (z, y, x, 3) float32; sparse: those of
/// the voxels `medium_index` only, (K, 3) each; or labels (z, y, x) uint8 with an ink table ink_sigma_s,
/// ink_sigma_a (N, 3) float32.
fn medium_from(
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
            Ok(MediumKind::Labels(LabelMedium::new(l, c_slice(&is, "ink_sigma_s")?, c_slice(&ia, "ink_sigma_a")?).map_err(err)?))
        }
        _ => Err(err("give either sigma_s and sigma_a, or labels with an ink table")),
    }
}

fn options(spp: u32, seed: u64, include_specular: bool) -> PyResult<RenderOptions> {
    if spp == 0 {
        return Err(err("spp must be at least 1"));
    }
    Ok(RenderOptions { spp, seed, include_specular })
}

type Packed<'py> = (Bound<'py, PyArray2<f32>>, Bound<'py, PyArray2<f32>>, Bound<'py, PyDict>);

fn pack<'py>(py: Python<'py>, est: &[TexelEstimate], stats: &Stats) -> PyResult<Packed<'py>> {
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

/// diffuse_layer(mixture (N, Y, X) f32, inside (Y, X) u8, inside_next (Y, X) u8, error (2, Y, X, N) f32, z, out
/// (Y, X) u8): 3D vector error diffusion of printer layer z (inkopt_core::diffuse). error[z % 2] holds the error
/// carried into layer z and is zeroed on return; error[(z + 1) % 2] accumulates the next layer's. Writes the
/// labels (ink index, 255 outside) into `out`. The GIL is released.
#[pyfunction]
fn diffuse_layer(
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
    let (m, i, i_next) = (c_slice(&mixture, "mixture")?, c_slice(&inside, "inside")?, c_slice(&inside_next, "inside_next")?);
    let e = error.as_slice_mut().map_err(|_| err("error must be C-contiguous"))?;
    let o = out.as_slice_mut().map_err(|_| err("out must be C-contiguous"))?;
    let (e0, e1) = e.split_at_mut(n * ny * nx);
    let (cur, next) = if z.is_multiple_of(2) { (e0, e1) } else { (e1, e0) };
    let shape = inkopt_core::kernels::diffuse::LayerShape { n, ny, nx };
    py.detach(|| inkopt_core::kernels::diffuse::diffuse_layer(shape, z, m, i, i_next, cur, next, o)).map_err(err)
}

/// smooth_rows(shape (Z, Y, X), index (F,) i64, values (F, C) f32, steps, alpha, guide (F, D) f32 or None, tau,
/// threads=None) -> (F, C) f32: `steps` explicit diffusion steps of weight `alpha` over the 6-neighbourhood of the
/// voxels `index` (strictly increasing linear indices into the grid `shape`; row r of the values is voxel index[r]),
/// each neighbour weighted by exp(-|guide_r - guide_q|² / tau²) if a guide is given (inkopt_core::smooth). The
/// GIL is released; `threads` as for a `Scene` (default all cores).
#[pyfunction]
#[pyo3(signature = (shape, index, values, steps, alpha, guide=None, tau=1.0, threads=None))]
#[allow(clippy::too_many_arguments)]
fn smooth_rows<'py>(
    py: Python<'py>,
    shape: (usize, usize, usize),
    index: PyReadonlyArray1<i64>,
    values: PyReadonlyArray2<f32>,
    steps: usize,
    alpha: f32,
    guide: Option<PyReadonlyArray2<f32>>,
    tau: f32,
    threads: Option<usize>,
) -> PyResult<Bound<'py, PyArray2<f32>>> {
    let n = [shape.0, shape.1, shape.2];
    let (rows, ch) = (values.shape()[0], values.shape()[1]);
    let idx = c_slice(&index, "index")?;
    let mut v = c_slice(&values, "values")?.to_vec();
    let g = match &guide {
        Some(a) => Some(inkopt_core::kernels::smooth::Guide { values: c_slice(a, "guide")?, dims: a.shape()[1], tau }),
        None => None,
    };
    py.detach(|| run_on(threads, || inkopt_core::kernels::smooth::diffuse_rows(n, idx, &mut v, ch, steps, alpha, g)))?
        .map_err(err)?;
    Ok(Array2::from_shape_vec((rows, ch), v).map_err(|e| err(e.to_string()))?.into_pyarray(py))
}

/// softmax_rows(x, threads=None) -> p: the softmax of each row of x (rows, n) float32 (``inkopt_core::simplex``,
/// parallel on `threads` (default all cores), thread-count independent). The GIL is released.
#[pyfunction]
#[pyo3(signature = (x, threads=None))]
fn softmax_rows<'py>(py: Python<'py>, x: PyReadonlyArray2<f32>, threads: Option<usize>)
                     -> PyResult<Bound<'py, PyArray2<f32>>> {
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
fn softmax_backward<'py>(py: Python<'py>, x: PyReadonlyArray2<f32>, g: PyReadonlyArray2<f32>,
                         scale: PyReadonlyArray1<f32>, natural: bool, threads: Option<usize>)
                         -> PyResult<Bound<'py, PyArray2<f32>>> {
    let (rows, n) = (x.shape()[0], x.shape()[1]);
    check_shape(g.shape(), &[rows, n], "g")?;
    let (xs, gs, ss) = (c_slice(&x, "x")?, c_slice(&g, "g")?, c_slice(&scale, "scale")?);
    let mut out = vec![0.0f32; rows * n];
    py.detach(|| run_on(threads, || inkopt_core::kernels::simplex::softmax_backward(xs, gs, ss, n, natural, &mut out)))?
        .map_err(err)?;
    Ok(Array2::from_shape_vec((rows, n), out).map_err(|e| err(e.to_string()))?.into_pyarray(py))
}

#[pymodule]
fn _core(m: &Bound<'_, PyModule>) -> PyResult<()> {
    m.add_class::<Scene>()?;
    m.add_function(wrap_pyfunction!(diffuse_layer, m)?)?;
    m.add_function(wrap_pyfunction!(smooth_rows, m)?)?;
    m.add_function(wrap_pyfunction!(softmax_rows, m)?)?;
    m.add_function(wrap_pyfunction!(softmax_backward, m)?)?;
    m.add("__version__", env!("CARGO_PKG_VERSION"))?;
    Ok(())
}
