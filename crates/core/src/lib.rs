//! inkopt-core: Monte Carlo volumetric light transport through voxel ink volumes, with path-replay gradients,
//! and the printing and optimiser kernels that run beside it.
//!
//! Conventions (see `docs/conventions.md` in the repository): voxel (x, y, z) has linear index
//! `(z * ny + y) * nx + x` (C order of a (z, y, x) array); lengths in mm, coefficients in mm^-1; geometric
//! vectors are (x, y, z); radiance is linear RGB, each channel traced as its own monochromatic problem.
//!
//! Layout:
//! - [`transport`]: light transport. The scene (grid geometry, media, shading normals, lights, texels), grid
//!   traversal, free-flight sampling, the scalar walk, eight-path packets, the render and gradient drivers,
//!   random numbers and sampling routines.
//! - [`kernels`]: the printing kernel (`diffuse`: error diffusion of ink mixtures to one ink per printer voxel)
//!   and the optimiser's kernels (`smooth`: the step preconditioner; `simplex`: the softmax of its variables).
//! - [`spans`]: voxel sets stored per grid row, the storage both share (sparse media, gradient slots, the
//!   smoothing's neighbour lookup).
//! - [`cache`]: software prefetch (the gradient replay's queued adds).
//! - [`pages`]: giving a held buffer's pages back to the system (the gradient sums, as they are converted).
//!
//! Layering: `cache`, `pages` and `spans` use nothing in the crate; `transport` uses them; `kernels` use `spans` and
//! `transport::medium::EMPTY` (the label of an empty voxel, which `diffuse` writes); nothing uses `kernels`.
//! Inside `transport` each module uses only the modules listed before it in `transport`'s documentation. The
//! test `tests/layering.rs` checks this order on the source, so the module graph has no circles.

pub mod cache;
pub mod kernels;
pub mod pages;
pub mod spans;
pub mod transport;

pub use transport::band::BandMedium;
pub use transport::estimate::{RenderOptions, Stats, TexelEstimate};
pub use transport::grad::{backward, GradBuffers, GradMethod, NO_GRADIENT};
pub use transport::hero_pass::{backward_hero, render_hero};
pub use transport::light::EnvMap;
pub use transport::render::render;
pub use transport::scene::{
    face_normal, Boundary, DenseMedium, Geometry, LabelMedium, Light, Medium, SparseMedium, Texel, UniformLight, EMPTY,
};

#[cfg(test)]
mod tests;
