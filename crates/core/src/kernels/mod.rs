//! The printing and optimiser kernels: array code that runs beside the light transport and shares none of it.
//!
//! - `diffuse` (printing): 3D vector error diffusion of per-voxel ink mixtures to one ink label per printer
//!   voxel, layer by layer.
//! - `counts` (printing): vector error diffusion of whole ink counts between optimisation voxels (each voxel's
//!   block of printer voxels), one optimisation layer at a time.
//! - `adaptive` (printing): which optimisation voxels of a layer are smooth enough to take the ordered dither's
//!   own counts instead (count-adaptive dithering).
//! - `smooth` (optimiser): explicit diffusion of per-voxel values over a sparse voxel set, the step
//!   preconditioner.
//! - `simplex` (optimiser): the row-wise softmax of the optimiser's variables and its backward map.
//! - `feature` (baselines): the exact Euclidean feature transform of a grid one z plane at a time, scipy's answers
//!   without a grid-sized index array.
//! - `step` (optimiser): the exponentiated-gradient step over every variable and the order statistics of |g| that
//!   set its scale.
//!
//! Each is a fixed-order computation per row, voxel or element (or exact counts), so results do not depend on the
//! thread count. They use `crate::spans` (voxel sets by grid row) and, for `diffuse`, the empty-voxel label
//! `transport::medium::EMPTY`.

pub mod adaptive;
pub mod blocks;
pub mod counts;
pub mod diffuse;
pub mod feature;
pub mod simplex;
pub mod smooth;
pub mod step;
