//! Light transport: Monte Carlo random walks of monochromatic paths through a voxel medium, their forward
//! render and their gradients (path replay).
//!
//! Modules, each using only those listed before it (and `crate::spans`, `crate::cache`, `crate::pages`):
//! - `bricks`: bricks of 8^3 voxels (their constants, a slab of planes cut into bricks).
//! - `label_bricks`: a grid's ink labels stored by bricks, built from planes pushed in order.
//! - `mask`: an inside mask as bytes, bits or a label grid's non-empty voxels (`MaskRef`), read by the builds a row
//!   or a slab at a time.
//! - `sampling`: vectors, the Henyey-Greenstein phase function, Fresnel, reflection and refraction.
//! - `rng`: counter-based random numbers (a path's numbers are a pure function of its key).
//! - `light`: the `Light` trait (uniform light, environment maps).
//! - `normals`: sparse shading normals.
//! - `medium`: the `Medium` trait and its dense, sparse and label forms.
//! - `band`: the band medium (a band near the surface stored per voxel, one homogeneous core).
//! - `distance`: safe and empty distances of an inside mask (erosions) and their signed byte stored by bricks.
//! - `scene`: the grid geometry (size, boundary, inside mask, safe and empty distances), texels.
//! - `path`: a path's walk state, its value, the `Tally` that receives its segments, the walk's limits.
//! - `grid`: locating points, voxel traversal (DDA), exit distances, the periodic wrap, empty jumps.
//! - `flight`: the free-flight samplers (regular and delta tracking) and the roulette.
//! - `trace`: the camera ray, the surface interface and the one scalar walk.
//! - `estimate`: render options, per-texel estimates, statistics and their fixed-order sums.
//! - `packet`: eight paths per core in SIMD lanes (`packet::step` is its vector step and uses `packet`).
//! - `render`: parallel drivers of the forward render.
//! - `sums`: the gradient's fixed-point sums (buffers, queued adds, their conversion to float gradients).
//! - `grad`: the gradient pass.
//! - `hero`: hero-channel paths (one path serves the three channels; the spectral band groups): the estimator
//!   and its scalar walk.
//! - `hero_lanes`: hero paths eight at a time in mask-free grids (null-collision delta tracking in SIMD lanes).
//! - `hero_pass`: the hero paths' render and gradient drivers.

pub mod band;
pub mod bricks;
pub mod distance;
pub mod estimate;
pub(crate) mod flight;
pub mod grad;
pub(crate) mod grid;
pub mod hero;
pub(crate) mod hero_lanes;
pub mod hero_pass;
pub mod label_bricks;
pub mod light;
pub mod mask;
pub mod medium;
pub mod normals;
pub(crate) mod packet;
pub mod path;
pub mod render;
pub mod rng;
pub mod sampling;
pub mod scene;
pub mod sums;
pub mod trace;
