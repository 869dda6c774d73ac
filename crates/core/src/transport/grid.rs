//! Grid helpers, written once for every walk: locating a point's voxel, the periodic wrap of x and y, distances
//! to a voxel's or the grid's faces, the incremental voxel traversal (DDA) and the per-voxel segments of a
//! straight flight (what gradient tallies receive), and the safe ball of the masked packet walk.
//!
//! Scalar helpers serve the scalar walks (`trace`, `flight`) and the per-lane code of `packet`; the `*8`
//! helpers are their eight-lane forms for the packet step. The two forms are not always the same arithmetic
//! (the lanes divide where the scalar code multiplies by a reciprocal); each keeps its own, since unifying them
//! would change the bits of one renderer's results; the comments say which is which.

use std::ops::Range;

use bytemuck::cast;
use wide::{f32x8, i32x8, CmpEq, CmpGe, CmpGt, CmpLt};

use crate::transport::path::Tally;
use crate::transport::sampling::{add, scale, V3};
use crate::transport::scene::{Boundary, Geometry, BRICK};

/// The grid's extent along axis a (n * size): its period on a periodic axis.
#[inline(always)]
pub(crate) fn span(geo: &Geometry, a: usize) -> f32 {
    geo.n[a] as f32 * geo.size[a]
}

/// Whether axis a wraps around (x and y of a periodic slab).
#[inline(always)]
pub(crate) fn wraps(geo: &Geometry, a: usize) -> bool {
    geo.boundary == Boundary::PeriodicXY && a < 2
}

/// x shifted by whole periods into [0, span] (span itself only by rounding: `locate` checks for it).
#[inline(always)]
pub(crate) fn wrap_coord(x: f32, span: f32) -> f32 {
    x - (x / span).floor() * span
}

/// The voxel containing p, clamped to the grid (no periodic wrap).
#[inline(always)]
pub(crate) fn locate_box(geo: &Geometry, p: V3) -> [i32; 3] {
    let mut v = [0i32; 3];
    for a in 0..3 {
        v[a] = ((p[a] * geo.inv_size[a]) as i32).max(0).min(geo.n[a] - 1);
    }
    v
}

/// The voxel containing p, not clamped: outside the grid when p is (a flight leaving the grid).
#[inline(always)]
pub(crate) fn voxel_of(geo: &Geometry, p: V3) -> [i32; 3] {
    std::array::from_fn(|a| (p[a] * geo.inv_size[a]).floor() as i32)
}

/// Radius of a ball around p that reaches no cell beyond those within s - 1 steps (26 directions) of p's cell
/// `c` (cells of edge `h`): per axis, s - 1 cells plus p's distance to its own cell's nearer face, shrunk by
/// 1e-4 relative against rounding.
#[inline(always)]
fn ball_radius(p: V3, c: [i32; 3], h: [f32; 3], s: u8) -> f32 {
    let mut r = f32::INFINITY;
    for a in 0..3 {
        let lo = (p[a] - c[a] as f32 * h[a]).max(0.0);
        let own = lo.min((h[a] - lo).max(0.0));
        r = r.min((s - 1) as f32 * h[a] + own);
    }
    r * (1.0 - 1e-4)
}

/// A flight outside the object at p in (in-grid, outside) voxel v, along d: where it is after crossing, at once,
/// a ball around p that holds no voxel of the object (no random numbers are drawn in vacuum, so only its position
/// changes): the ball from the brick level (`Geometry::brick_empty`) or else the voxel level
/// (`Geometry::empty_distance`). Returns the new position and its voxel (possibly beyond the grid); None where
/// neither level guarantees more than p's own voxel (next to the object, or without empty distances): the flight
/// then goes on voxel by voxel. The voxel is located from the new position but kept within the block of empty
/// voxels the ball was taken from: far from the origin the rounding of p + r d and of its voxel's index exceeds
/// the ball's margin and could otherwise name a voxel of the object.
#[inline(always)]
pub(crate) fn empty_jump(geo: &Geometry, p: V3, d: V3, v: [i32; 3]) -> Option<(V3, [i32; 3])> {
    let bricks = geo.brick_empty.as_ref()?;
    let k = BRICK as i32;
    let b: [i32; 3] = std::array::from_fn(|a| v[a] / k);
    let e = bricks[((b[2] * geo.bricks[1] + b[1]) * geo.bricks[0] + b[0]) as usize];
    let (r, lo, hi) = if e >= 2 {
        let m = e as i32 - 1;
        let r = ball_radius(p, b, std::array::from_fn(|a| geo.size[a] * k as f32), e);
        (r, b.map(|c| (c - m) * k), b.map(|c| (c + m + 1) * k - 1))
    } else {
        let e = geo.empty_distance(v);
        if e < 2 {
            return None;
        }
        let m = e as i32 - 1;
        (ball_radius(p, v, geo.size, e), v.map(|c| c - m), v.map(|c| c + m))
    };
    let q = add(p, scale(d, r));
    let w = voxel_of(geo, q);
    Some((q, std::array::from_fn(|a| w[a].clamp(lo[a], hi[a]))))
}

/// The voxel containing p (clamped to the grid); on periodic axes p is first wrapped into [0, span).
#[inline(always)]
pub(crate) fn locate(geo: &Geometry, p: &mut V3) -> [i32; 3] {
    for a in 0..2 {
        if wraps(geo, a) {
            let s = span(geo, a);
            if p[a] < 0.0 || p[a] >= s {
                p[a] = wrap_coord(p[a], s);
                if p[a] >= s {
                    p[a] = 0.0;
                }
            }
        }
    }
    locate_box(geo, *p)
}

/// A voxel step along `axis` (direction `step`) to coordinate k: on a periodic axis a k outside the grid wraps
/// to the other side and the position frame `p` shifts by one period; returns the wrapped coordinate then.
#[inline(always)]
pub(crate) fn wrap_step(geo: &Geometry, axis: usize, k: i32, step: i32, p: &mut V3) -> Option<i32> {
    if (k as u32) >= geo.n[axis] as u32 && wraps(geo, axis) {
        p[axis] -= step as f32 * span(geo, axis);
        Some(k - step * geo.n[axis])
    } else {
        None
    }
}

#[inline(always)]
pub(crate) fn inv(d: V3) -> V3 {
    [1.0 / d[0], 1.0 / d[1], 1.0 / d[2]]
}

/// Distance along d from p to the nearest plane `plane(a)` of the axes `axes` that d moves towards (axes with
/// d[a] = 0 never reach theirs), clamped at 0, and its axis (`axes.start` if none).
#[inline(always)]
fn nearest_plane(p: V3, d: V3, axes: Range<usize>, plane: impl Fn(usize) -> f32) -> (f32, usize) {
    let inv_d = inv(d);
    let mut t = f32::INFINITY;
    let mut axis = axes.start;
    for a in axes {
        // Selects, not branches (the direction is random).
        let ta = if d[a] != 0.0 { ((plane(a) - p[a]) * inv_d[a]).max(0.0) } else { f32::INFINITY };
        let nearer = ta < t;
        t = if nearer { ta } else { t };
        axis = std::hint::select_unpredictable(nearer, a, axis);
    }
    (t, axis)
}

/// Distance along d from p to the boundary of voxel v, and the axis crossed there.
#[inline(always)]
pub(crate) fn voxel_exit(geo: &Geometry, p: V3, d: V3, v: [i32; 3]) -> (f32, usize) {
    nearest_plane(p, d, 0..3, |a| if d[a] > 0.0 { (v[a] + 1) as f32 } else { v[a] as f32 } * geo.size[a])
}

/// Distance along d from p to the grid's boundary (periodic: only z bounds it), and the axis reached there.
#[inline(always)]
pub(crate) fn grid_exit(geo: &Geometry, p: V3, d: V3) -> (f32, usize) {
    let axes = if geo.boundary == Boundary::PeriodicXY { 2..3 } else { 0..3 };
    nearest_plane(p, d, axes, |a| if d[a] > 0.0 { span(geo, a) } else { 0.0 })
}

/// v[axis], as a select over the three components: indexing a local array by a run-time axis puts the array in
/// memory (in the packet loop, scalar stores then a wider reload: a stalled store-to-load forward per exit).
#[inline(always)]
pub(crate) fn component(v: V3, axis: usize) -> f32 {
    debug_assert!(axis < 3);
    if axis == 0 {
        v[0]
    } else if axis == 1 {
        v[1]
    } else {
        v[2]
    }
}

/// The point at distance t along d from p, put exactly onto the grid face it reaches on `axis`
/// (`p + d * t` on the other axes; written per component, without indexing by `axis`, see `component`).
#[inline(always)]
pub(crate) fn grid_face_point(geo: &Geometry, p: V3, d: V3, t: f32, axis: usize) -> V3 {
    let face = if component(d, axis) > 0.0 { span(geo, axis) } else { 0.0 };
    std::array::from_fn(|a| if a == axis { face } else { p[a] + d[a] * t })
}

/// The outward normal of the face on `axis` that a flight going `step` (+-1) along it crosses, seen from the
/// side it comes from: pointing back at the flight.
#[inline(always)]
pub(crate) fn facing_normal(axis: usize, step: i32) -> V3 {
    debug_assert!(axis < 3);
    std::array::from_fn(|a| if a == axis { -step as f32 } else { 0.0 })
}

/// Incremental (Amanatides-Woo) voxel traversal along one straight flight: the distances to the next voxel
/// boundary on each axis advance without divisions.
#[derive(Clone, Copy)]
pub(crate) struct Dda {
    pub t_max: [f32; 3],
    pub t_delta: [f32; 3],
    pub step: [i32; 3],
    /// Change of the linear voxel index for a step along each axis.
    pub dj: [isize; 3],
}

impl Dda {
    #[inline(always)]
    pub fn new(geo: &Geometry, p: V3, d: V3, v: [i32; 3]) -> Self {
        // Without branches on the direction's signs: after a scattering they are random, and three mispredicted
        // branches per flight cost more than computing every case and selecting.
        let inv_d = inv(d);
        let mut dda = Dda { t_max: [f32::INFINITY; 3], t_delta: [f32::INFINITY; 3], step: [0; 3], dj: [0; 3] };
        for a in 0..3 {
            let s = geo.size[a];
            let (up, down) = (d[a] > 0.0, d[a] < 0.0);
            let face = (v[a] + up as i32) as f32 * s;
            let moving = up | down;
            dda.step[a] = up as i32 - down as i32;
            dda.t_max[a] = if moving { ((face - p[a]) * inv_d[a]).max(0.0) } else { f32::INFINITY };
            dda.t_delta[a] = if moving { (s * inv_d[a]).abs() } else { f32::INFINITY };
            dda.dj[a] = dda.step[a] as isize * geo.stride[a];
        }
        dda
    }

    /// The axis of the next voxel boundary.
    #[inline(always)]
    pub fn next_axis(&self) -> usize {
        // Selects, not branches: which boundary comes next is as random as the flight's direction.
        let m = &self.t_max;
        let first = m[0] < m[1];
        let (i, mi) = (if first { 0 } else { 1 }, if first { m[0] } else { m[1] });
        std::hint::select_unpredictable(mi < m[2], i, 2)
    }

    /// Cross the boundary on `axis`: its distance moves on by one voxel.
    #[inline(always)]
    pub fn advance(&mut self, axis: usize) {
        self.t_max[axis] += self.t_delta[axis];
    }
}

/// Move p by t along d onto the face of voxel v on `axis`, return the neighbour across it (wrapped if periodic).
#[inline(always)]
pub(crate) fn cross(geo: &Geometry, p: &mut V3, d: V3, t: f32, axis: usize, v: [i32; 3]) -> ([i32; 3], i32) {
    *p = add(*p, scale(d, t));
    let step = if d[axis] > 0.0 { 1 } else { -1 };
    p[axis] = (if step > 0 { v[axis] + 1 } else { v[axis] }) as f32 * geo.size[axis];
    let mut nb = v;
    nb[axis] += step;
    if let Some(k) = wrap_step(geo, axis, nb[axis], step, p) {
        nb[axis] = k;
    }
    (nb, step)
}

/// Emit the per-voxel segments of the straight flight from p (in voxel v) along d for `length` (a DDA).
pub(crate) fn tally_segments<T: Tally>(geo: &Geometry, p: V3, d: V3, mut v: [i32; 3], length: f32, tally: &mut T) {
    let mut dda = Dda::new(geo, p, d, v);
    let mut t = 0.0f32;
    loop {
        let axis = dda.next_axis();
        let t_next = dda.t_max[axis].min(length);
        tally.segment(geo.index(v), t_next - t);
        if t_next >= length {
            return;
        }
        t = t_next;
        dda.advance(axis);
        v[axis] += dda.step[axis];
        if (v[axis] as u32) >= geo.n[axis] as u32 {
            if !wraps(geo, axis) {
                return; // rounding at the exit face: the remaining length is below float precision
            }
            v[axis] -= dda.step[axis] * geo.n[axis];
        }
    }
}

#[inline(always)]
fn select_i32(mask: f32x8, t: i32x8, f: i32x8) -> i32x8 {
    cast::<f32x8, i32x8>(mask).blend(t, f)
}

/// `grid_exit` in eight lanes (the packet's flights): the same comparisons in the same order, but dividing by
/// d where `grid_exit` multiplies by its reciprocal.
#[inline(always)]
pub(crate) fn grid_exit8(geo: &Geometry, p: [f32x8; 3], d: [f32x8; 3]) -> (f32x8, i32x8) {
    let zero = f32x8::ZERO;
    let mut t = f32x8::splat(f32::INFINITY);
    let mut axis = i32x8::splat(2);
    let first = if geo.boundary == Boundary::PeriodicXY { 2 } else { 0 };
    for a in first..3 {
        let far = f32x8::splat(span(geo, a));
        let b = d[a].cmp_gt(zero).blend(far, zero);
        let ta = ((b - p[a]) / d[a]).max(zero);
        let ta = d[a].cmp_eq(zero).blend(f32x8::splat(f32::INFINITY), ta);
        let nearer = ta.cmp_lt(t);
        t = nearer.blend(ta, t);
        axis = select_i32(nearer, i32x8::splat(a as i32), axis);
    }
    (t, axis)
}

/// `locate` in eight lanes: wraps q (periodic axes: by the reciprocal of the period, every lane) and returns
/// the voxels, clamped to the grid.
#[inline(always)]
pub(crate) fn locate8(geo: &Geometry, q: &mut [f32x8; 3]) -> [i32x8; 3] {
    let mut v = [i32x8::ZERO; 3];
    for a in 0..3 {
        if wraps(geo, a) {
            let s = span(geo, a);
            let w = q[a] - (q[a] * f32x8::splat(1.0 / s)).floor() * f32x8::splat(s);
            q[a] = w.cmp_ge(f32x8::splat(s)).blend(f32x8::ZERO, w);
        }
        v[a] = (q[a] * f32x8::splat(geo.inv_size[a])).trunc_int().max(i32x8::ZERO).min(i32x8::splat(geo.n[a] - 1));
    }
    v
}

/// Radius of a ball around p (in voxel v, safe distance s) that lies inside the object: every voxel within s - 1
/// steps of v is inside, so the ball may reach (s - 1) voxels beyond p's own voxel along each axis. Shrunk by
/// 1e-4 relative so that rounding never puts the ball's edge into an outside voxel (any smaller ball is exact too).
#[inline(always)]
pub(crate) fn safe_radius8(geo: &Geometry, p: [f32x8; 3], v: [i32x8; 3], s: f32x8) -> f32x8 {
    let mut r = f32x8::splat(f32::INFINITY);
    for a in 0..3 {
        let h = f32x8::splat(geo.size[a]);
        let lo = (p[a] - v[a].round_float() * h).max(f32x8::ZERO);
        let own = lo.min((h - lo).max(f32x8::ZERO));
        r = r.min((s - f32x8::ONE) * h + own);
    }
    r * f32x8::splat(1.0 - 1e-4)
}
