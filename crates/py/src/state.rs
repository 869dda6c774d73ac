//! The state of the `Scene` class (geometry, medium, thread pool, gradient buffers), below its methods: `scene`
//! (the Python methods) uses `gradients` (the gradient methods' work), and both use this type.

use inkopt_core::{Geometry, GradBuffers};
use pyo3::prelude::*;

use crate::medium::MediumKind;

/// A voxel scene (geometry, medium, light) with its thread pool and gradient buffers; the Python class
/// `inkopt._core.Scene`.
#[pyclass(module = "inkopt._core")]
pub(crate) struct Scene {
    pub(crate) geo: Geometry,
    pub(crate) medium: MediumKind,
    pub(crate) pool: rayon::ThreadPool,
    pub(crate) grads: Option<GradBuffers>,
    /// Whether the gradient buffers are per slot of a grad_index (else per voxel).
    pub(crate) sparse: bool,
    pub(crate) shape: [usize; 3],
}
