//! A path's state and what it reports, shared by every walk (`flight`'s samplers, `trace`'s scalar walk, the
//! packets): the `Walk` state, a path's `PathValue`, the `Tally` that receives its segments and collisions (for
//! gradients), and the limits that end a walk (collisions, steps, the roulette's threshold).

use crate::transport::sampling::V3;

/// Receives the events of a path (for gradients). The forward pass uses `NoTally`.
pub trait Tally {
    /// Whether the tally uses segments at all (delta tracking then skips measuring them).
    const ACTIVE: bool = true;
    fn segment(&mut self, idx: usize, len: f32);
    fn scatter(&mut self, idx: usize);
}

pub struct NoTally;

impl Tally for NoTally {
    const ACTIVE: bool = false;
    #[inline(always)]
    fn segment(&mut self, _: usize, _: f32) {}
    #[inline(always)]
    fn scatter(&mut self, _: usize) {}
}

/// Paths that are still going after this many collisions are cut (value 0). At albedo 0.9997 the chance to
/// survive 2e6 collisions is exp(-600): the cut never biases a physical medium.
pub(crate) const MAX_EVENTS: u32 = 2_000_000;
/// Weights below this play Russian roulette. 1.0 would be analog absorption; 0.5 walks longer paths for less
/// variance per path, a gain in efficiency that grows on dark colours (docs/experiments.md, "Speed and memory").
pub(crate) const RR_THRESHOLD: f32 = 0.5;
/// Steps (flights and voxel crossings) after which a walk is cut (value 0): a guard that ends every walk.
pub(crate) const MAX_STEPS: u64 = 50_000_000;

/// Result of one path: its value (radiance reaching the texel) and its number of collisions.
#[derive(Clone, Copy, Debug)]
pub struct PathValue {
    pub value: f32,
    pub events: u32,
}

/// A path's state in the walk: position, direction, voxel, weight, whether it is inside the object, its
/// collisions and steps so far.
#[derive(Clone, Copy)]
pub(crate) struct Walk {
    pub p: V3,
    pub d: V3,
    pub v: [i32; 3],
    pub weight: f32,
    pub in_medium: bool,
    pub events: u32,
    pub steps: u64,
}
