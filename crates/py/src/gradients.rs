//! The gradient methods of `Scene` (`zero_grad`, `backward`, `take_grad`, `take_grad_fixed`; their Python
//! signatures and docstrings are in `scene`): fixed-point gradient buffers per voxel or per slot of a
//! `grad_index`, filled by path replay (or the `L_i = 1` pass) and returned as numpy arrays.

use inkopt_core::{
    backward as core_backward, backward_hero, GradBuffers, GradMethod, RenderOptions, Texel, NO_GRADIENT,
};
use numpy::ndarray::{Array2, Array4};
use numpy::{Element, IntoPyArray, PyReadonlyArray1, PyReadonlyArray2, PyReadonlyArray3, PyUntypedArrayMethods};
use pyo3::prelude::*;

use crate::arrays::{c_slice, check_shape, err, pack, Packed};
use crate::medium::with_medium;
use crate::state::Scene;

/// Whether the buffers are per slot of a grad_index (else per voxel).
fn grad_index_given(g: &Option<GradBuffers>) -> bool {
    g.as_ref().map(|g| g.is_mapped()).unwrap_or(false)
}

/// `Scene.zero_grad`.
pub(crate) fn zero_grad(
    scene: &mut Scene,
    py: Python<'_>,
    max_abs_adjoint: f32,
    grad_index: Option<Bound<'_, PyAny>>,
) -> PyResult<()> {
    let n = scene.geo.voxel_count();
    let dense_ix: Option<PyReadonlyArray3<i32>>;
    let voxels_ix: Option<PyReadonlyArray1<i64>>;
    match &grad_index {
        None => (dense_ix, voxels_ix) = (None, None),
        Some(a) => {
            if let Ok(d) = a.extract::<PyReadonlyArray3<i32>>() {
                check_shape(d.shape(), &scene.shape, "grad_index")?;
                (dense_ix, voxels_ix) = (Some(d), None);
            } else if let Ok(v) = a.extract::<PyReadonlyArray1<i64>>() {
                (dense_ix, voxels_ix) = (None, Some(v));
            } else {
                return Err(err("grad_index must be a (z, y, x) int32 slot map or (F,) int64 voxel indices"));
            }
        }
    }
    let dense = match &dense_ix {
        Some(d) => Some(c_slice(d, "grad_index")?),
        None => None,
    };
    let voxels = match &voxels_ix {
        Some(v) => Some(c_slice(v, "grad_index")?),
        None => None,
    };
    let slot = |k: i32| if k < 0 { NO_GRADIENT } else { k as u32 };
    let [nz, ny, nx] = scene.shape;
    let (pool, grads) = (&scene.pool, &mut scene.grads);
    let done = py.detach(|| {
        pool.install(|| {
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
        })
    });
    scene.sparse = grad_index_given(&scene.grads);
    done.map_err(err)
}

/// `Scene.backward` on checked texels, the first with index `first_texel`; `hero`: hero paths (replay only).
#[allow(clippy::too_many_arguments)]
pub(crate) fn backward<'py>(
    scene: &Scene,
    py: Python<'py>,
    texels: &[Texel],
    first_texel: u64,
    adjoint: PyReadonlyArray2<f32>,
    opts: &RenderOptions,
    method: &str,
    hero: bool,
) -> PyResult<Packed<'py>> {
    let method = match method {
        "replay" => GradMethod::Replay,
        "li1" => GradMethod::Li1,
        other => return Err(err(format!("unknown gradient method '{other}'; use 'replay' or 'li1'"))),
    };
    if hero && method != GradMethod::Replay {
        return Err(err("hero paths have the 'replay' gradient method only"));
    }
    if adjoint.shape() != [texels.len(), 3] {
        return Err(err(format!("adjoint has shape {:?}, expected ({}, 3)", adjoint.shape(), texels.len())));
    }
    let adj: Vec<[f32; 3]> = c_slice(&adjoint, "adjoint")?.chunks_exact(3).map(|c| [c[0], c[1], c[2]]).collect();
    if adj.iter().any(|a| a.iter().any(|x| !x.is_finite())) {
        return Err(err("adjoint contains NaN or infinite values"));
    }
    if scene.grads.is_none() {
        return Err(err("call zero_grad before backward"));
    }
    let grads = scene.grads.as_ref().unwrap();
    let (est, stats) = py.detach(|| {
        scene.pool.install(|| {
            with_medium!(&scene.medium, m => if hero {
                backward_hero(&scene.geo, m, texels, first_texel, &adj, opts, grads)
            } else {
                core_backward(&scene.geo, m, texels, first_texel, &adj, opts, method, grads)
            })
        })
    });
    pack(py, &est, &stats)
}

/// `Scene.take_grad`.
pub(crate) fn take_grad<'py>(scene: &mut Scene, py: Python<'py>) -> PyResult<(Bound<'py, PyAny>, Bound<'py, PyAny>)> {
    let g = scene.grads.take().ok_or_else(|| err("no gradient: call zero_grad and backward first"))?;
    let n = g.slots();
    // Zeroed allocations (calloc: fresh pages, taken as they are written) filled as the sums are given back.
    let mut gs = vec![0.0f32; 3 * n];
    let mut ga = vec![0.0f32; 3 * n];
    py.detach(|| g.into_collected(&mut gs, &mut ga));
    Ok((grad_array(scene, py, gs)?, grad_array(scene, py, ga)?))
}

/// `Scene.take_grad_fixed`.
pub(crate) fn take_grad_fixed<'py>(
    scene: &mut Scene,
    py: Python<'py>,
) -> PyResult<(Bound<'py, PyAny>, Bound<'py, PyAny>, f64)> {
    let g = scene.grads.take().ok_or_else(|| err("no gradient: call zero_grad and backward first"))?;
    let n = g.slots();
    let quantum = g.quantum();
    let mut gs = vec![0i64; 3 * n];
    let mut ga = vec![0i64; 3 * n];
    py.detach(|| g.into_collected_fixed(&mut gs, &mut ga));
    Ok((grad_array(scene, py, gs)?, grad_array(scene, py, ga)?, quantum))
}

/// A gradient buffer as an array: (F, 3) per slot after a grad_index, else (z, y, x, 3).
fn grad_array<'py, T: Element>(scene: &Scene, py: Python<'py>, v: Vec<T>) -> PyResult<Bound<'py, PyAny>> {
    let [nz, ny, nx] = scene.shape;
    if scene.sparse {
        let n = v.len() / 3;
        return Ok(Array2::from_shape_vec((n, 3), v).map_err(|e| err(e.to_string()))?.into_pyarray(py).into_any());
    }
    Ok(Array4::from_shape_vec((nz, ny, nx, 3), v).map_err(|e| err(e.to_string()))?.into_pyarray(py).into_any())
}
