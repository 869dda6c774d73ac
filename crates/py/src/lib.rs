//! Thin PyO3 bindings of inkopt-core, the module `inkopt._core`: the `Scene` class (render and gradients), its
//! argument classes `Medium` and `Texels`, and the printing and optimiser kernels as functions. Array conventions
//! are the Python package's: (z, y, x[, c]) arrays, texel voxels (z, y, x), normals and voxel sizes (x, y, z).
//! The type stub `python/inkopt/_core.pyi` lists the Python API.
//!
//! Files: `state` (the `Scene` class's fields), `scene` (its Python methods: construction, media, light, render),
//! `medium` (the `Medium` class and the scene's medium built from it), `labels` (the `LabelBricks` class: label
//! planes pushed into bricks), `texels` (the `Texels` class),
//! `gradients` (the gradient methods of `Scene`), `printing` (error diffusion of labels and of counts), `optimiser` (smoothing and softmax
//! kernels on kept thread pools), `arrays` (argument checks and conversions shared by all).

use pyo3::prelude::*;

mod arrays;
mod gradients;
mod labels;
mod medium;
mod optimiser;
mod printing;
mod scene;
mod state;
mod texels;

#[pymodule]
fn _core(m: &Bound<'_, PyModule>) -> PyResult<()> {
    m.add_class::<state::Scene>()?;
    m.add_class::<medium::Medium>()?;
    m.add_class::<labels::LabelBricks>()?;
    m.add_class::<texels::Texels>()?;
    m.add_function(wrap_pyfunction!(printing::diffuse_layer, m)?)?;
    m.add_function(wrap_pyfunction!(printing::diffuse_counts_layer, m)?)?;
    m.add_function(wrap_pyfunction!(printing::mark_smooth, m)?)?;
    m.add_function(wrap_pyfunction!(printing::sort_blocks, m)?)?;
    m.add_function(wrap_pyfunction!(printing::place_blocks, m)?)?;
    m.add_function(wrap_pyfunction!(printing::feature_plane, m)?)?;
    m.add_function(wrap_pyfunction!(optimiser::smooth_rows, m)?)?;
    m.add_function(wrap_pyfunction!(optimiser::softmax_rows, m)?)?;
    m.add_function(wrap_pyfunction!(optimiser::softmax_backward, m)?)?;
    m.add_function(wrap_pyfunction!(optimiser::momentum_step, m)?)?;
    m.add_function(wrap_pyfunction!(optimiser::abs_order_statistics, m)?)?;
    m.add("__version__", env!("CARGO_PKG_VERSION"))?;
    Ok(())
}
