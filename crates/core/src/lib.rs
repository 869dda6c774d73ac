//! inkopt-core: Monte Carlo volumetric light transport through voxel ink volumes, with path-replay gradients.
//!
//! Conventions (see docs/conventions.md in the repository): voxel (x, y, z) has linear index
//! `(z * ny + y) * nx + x` (C order of a (z, y, x) array); lengths in mm, coefficients in mm^-1; geometric
//! vectors are (x, y, z); radiance is linear RGB, each channel traced as its own monochromatic problem.
//!
//! Modules: `scene` (geometry, texels), `medium` (dense, sparse and label media), `spans` (voxel sets stored per grid row), `normals` (sparse shading normals), `light` (the `Light` trait:
//! uniform light, environment maps), `grid` (locating points, voxel traversal, exit distances, periodic wrap),
//! `flight` (the free-flight samplers), `trace` (the scalar walk), `packet` (eight paths per core in SIMD
//! lanes), `render` (parallel drivers of the forward render), `grad` (the gradient pass and its fixed-point
//! buffers), `rng` (counter-based random numbers), `sampling` (phase function, Fresnel), `diffuse` (3D vector
//! error diffusion of ink mixtures to one ink per printer voxel), `smooth` (diffusion of per-voxel values over a
//! sparse voxel set: the optimiser's step preconditioner), `simplex` (row-wise softmax of the optimiser's variables and
//! its backward map).

pub mod diffuse;
mod flight;
pub mod grad;
mod grid;
pub mod light;
pub mod medium;
pub mod normals;
pub(crate) mod packet;
pub mod render;
pub mod rng;
pub mod sampling;
pub mod scene;
pub mod simplex;
pub mod smooth;
pub mod spans;
pub mod trace;

pub use grad::{backward, GradBuffers, GradMethod, NO_GRADIENT};
pub use render::{render, RenderOptions, Stats, TexelEstimate};
pub use light::EnvMap;
pub use scene::{face_normal, Boundary, DenseMedium, Geometry, LabelMedium, Light, Medium, SparseMedium, Texel,
                UniformLight, EMPTY};

#[cfg(test)]
mod tests;
