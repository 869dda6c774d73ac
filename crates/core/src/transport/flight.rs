//! The free-flight sampler: where a path inside the medium next collides, or reaches the object's surface.
//!
//! Two exact samplers of the same collision density sigma_t(x) exp(-tau) in the piecewise-constant medium:
//! - `Regular` tracking: one exponential optical depth per flight, used up voxel by voxel along a DDA; it finds
//!   every crossing of the object's boundary (an `inside` mask), so it serves masked volumes, the paths near a
//!   surface, and mask-free grids' paths whose camera ray stays outside the object at first.
//! - `Delta` tracking: tentative collisions at the channel's majorant, each accepted with probability
//!   sigma_t(x) / majorant; no voxel crossings, for grids that are entirely inside the object.
//!
//! Both implement `Tracker`, which the one scalar walk (`trace::walk`) drives: it is the scalar reference
//! tracer, the per-lane walk of the packets near surfaces, and (through its `Tally`) the gradient replay. The
//! packets' SIMD step (`packet::step`) is `Delta` in eight lanes with its own random-number layout and
//! vector arithmetic (`wide`'s logarithm, divisions): sharing code with it would change its bits or slow its
//! hot loop, so it shares this module's per-lane logic instead (`survive`'s rule, the grid face events, the
//! segment tallies of `grid::tally_segments`).
//!
//! Both samplers also report the exact per-voxel lengths of every flight and each collision's voxel to a
//! `Tally` (see `trace` for the path-space derivatives they feed).

use crate::transport::grid::{
    facing_normal, grid_exit, grid_face_point, locate, locate_box, tally_segments, wrap_step, Dda,
};
use crate::transport::path::{Tally, Walk, MAX_STEPS, RR_THRESHOLD};
use crate::transport::rng::Uniforms;
use crate::transport::sampling::{add, scale, V3};
use crate::transport::scene::{Boundary, Geometry, Medium};

/// An exponential sample with mean 1 (an optical depth) from uniform u in [0, 1).
#[inline(always)]
pub(crate) fn exp_depth(u: f32) -> f32 {
    -(1.0 - u).ln()
}

/// Multiply the weight by the albedo; Russian roulette below the threshold (one uniform then). False: the path
/// ends (value 0).
#[inline(always)]
pub(crate) fn survive<U: Uniforms>(weight: &mut f32, albedo: f32, rng: &mut U) -> bool {
    *weight *= albedo;
    if *weight >= RR_THRESHOLD {
        return true;
    }
    if rng.next_f32() * RR_THRESHOLD < *weight {
        *weight = RR_THRESHOLD;
        true
    } else {
        false
    }
}

/// What ended a flight.
pub(crate) enum Event {
    /// A real collision in voxel index j (the walk's p and v are at it) with the given albedo.
    Collision(usize, f32),
    /// The flight reached the object's surface through the face of the walk's voxel on `axis`, going `step`;
    /// p is on that face. `nb`: the voxel beyond (wrapped if periodic); `n_sh`: the shading normal on the
    /// incident (inner) side.
    Surface { axis: usize, step: i32, nb: [i32; 3], n_sh: V3 },
    /// The walk took more than `MAX_STEPS` steps: it is cut (value 0).
    Cut,
}

/// A free-flight sampler inside the object. The walk calls `start` for every new flight (after entering the
/// medium or scattering), `redirect` after a reflection at the surface (regular tracking keeps the optical
/// depth left), and `next` for the flight's end.
pub(crate) trait Tracker {
    fn start<U: Uniforms>(&mut self, geo: &Geometry, w: &Walk, rng: &mut U);
    fn redirect(&mut self, geo: &Geometry, w: &Walk);
    fn next<M: Medium, T: Tally, U: Uniforms>(
        &mut self,
        geo: &Geometry,
        med: &M,
        c: usize,
        w: &mut Walk,
        rng: &mut U,
        tally: &mut T,
    ) -> Event;
}

/// Regular tracking: the optical depth left, and the flight from p0 (t flown so far) through voxel index j.
pub(crate) struct Regular {
    tau: f32,
    p0: V3,
    t: f32,
    dda: Dda,
    j: usize,
}

impl Regular {
    pub fn new() -> Self {
        Regular {
            tau: 0.0,
            p0: [0.0; 3],
            t: 0.0,
            dda: Dda { t_max: [0.0; 3], t_delta: [0.0; 3], step: [0; 3], dj: [0; 3] },
            j: 0,
        }
    }
}

impl Tracker for Regular {
    #[inline(always)]
    fn start<U: Uniforms>(&mut self, geo: &Geometry, w: &Walk, rng: &mut U) {
        self.tau = exp_depth(rng.next_f32());
        self.redirect(geo, w);
    }

    #[inline(always)]
    fn redirect(&mut self, geo: &Geometry, w: &Walk) {
        self.p0 = w.p;
        self.dda = Dda::new(geo, w.p, w.d, w.v);
        self.t = 0.0;
        self.j = geo.index(w.v);
    }

    #[inline(always)]
    fn next<M: Medium, T: Tally, U: Uniforms>(
        &mut self,
        geo: &Geometry,
        med: &M,
        c: usize,
        w: &mut Walk,
        _: &mut U,
        tally: &mut T,
    ) -> Event {
        loop {
            w.steps += 1;
            if w.steps > MAX_STEPS {
                return Event::Cut;
            }
            let (st, albedo) = med.coeffs_at(self.j, w.v, c);
            let axis = self.dda.next_axis();
            let t_next = self.dda.t_max[axis];
            let seg = t_next - self.t;
            if st * seg > self.tau {
                let s = self.tau / st;
                tally.segment(self.j, s);
                w.p = add(self.p0, scale(w.d, self.t + s));
                return Event::Collision(self.j, albedo);
            }
            self.tau -= st * seg;
            tally.segment(self.j, seg);
            self.t = t_next;
            self.dda.advance(axis);
            let step = self.dda.step[axis];
            let mut k = w.v[axis] + step;
            let mut dj = self.dda.dj[axis];
            if let Some(kw) = wrap_step(geo, axis, k, step, &mut self.p0) {
                // Around the period: the position frame shifted by one period.
                k = kw;
                dj -= step as isize * geo.n[axis] as isize * geo.stride[axis];
            }
            let mut nb = w.v;
            nb[axis] = k;
            if (k as u32) < geo.n[axis] as u32 && geo.mask_inside(nb) {
                w.v = nb;
                self.j = (self.j as isize + dj) as usize;
                continue;
            }
            // Leaving the object through the face of v on `axis`: the incident side is inside.
            w.p = add(self.p0, scale(w.d, self.t));
            w.p[axis] = (if step > 0 { w.v[axis] + 1 } else { w.v[axis] }) as f32 * geo.size[axis];
            let n_geo = facing_normal(axis, step);
            let n_sh = geo.shading_normal(w.v).map(|n| scale(n, -1.0)).unwrap_or(n_geo);
            return Event::Surface { axis, step, nb, n_sh };
        }
    }
}

/// Delta tracking against the channel's majorant, in a grid that is entirely inside the object (no mask).
pub(crate) struct Delta {
    maj: f32,
}

impl Delta {
    pub fn new(maj: f32) -> Self {
        Delta { maj }
    }
}

impl Tracker for Delta {
    #[inline(always)]
    fn start<U: Uniforms>(&mut self, _: &Geometry, _: &Walk, _: &mut U) {}

    #[inline(always)]
    fn redirect(&mut self, _: &Geometry, _: &Walk) {}

    /// One flight from p: tentative collisions (two uniforms each) until a real one or the grid's face. Moves p
    /// (wrapped into the periodic frame) and v; tallies the exact per-voxel lengths when the tally is active.
    #[inline(always)]
    fn next<M: Medium, T: Tally, U: Uniforms>(
        &mut self,
        geo: &Geometry,
        med: &M,
        c: usize,
        w: &mut Walk,
        rng: &mut U,
        tally: &mut T,
    ) -> Event {
        w.steps += 1;
        if w.steps > MAX_STEPS {
            return Event::Cut;
        }
        let (maj, d) = (self.maj, w.d);
        let periodic = geo.boundary == Boundary::PeriodicXY;
        let (t_exit, axis) = grid_exit(geo, w.p, d);
        let (p_start, v_start) = (w.p, w.v);
        let inv_maj = if maj > 0.0 { 1.0 / maj } else { f32::INFINITY };
        let mut t = 0.0f32;
        loop {
            let (u_flight, u_accept) = rng.next_f32_pair();
            t += exp_depth(u_flight) * inv_maj;
            if t >= t_exit {
                let step = if d[axis] > 0.0 { 1 } else { -1 };
                if T::ACTIVE {
                    tally_segments(geo, p_start, d, v_start, t_exit, tally);
                }
                w.p = grid_face_point(geo, p_start, d, t_exit, axis);
                w.v = locate(geo, &mut w.p);
                w.v[axis] = if step > 0 { geo.n[axis] - 1 } else { 0 };
                let mut nb = w.v;
                nb[axis] += step;
                return Event::Surface { axis, step, nb, n_sh: facing_normal(axis, step) };
            }
            let mut q = add(p_start, scale(d, t));
            let v = if periodic { locate(geo, &mut q) } else { locate_box(geo, q) };
            let j = geo.index(v);
            let (st, albedo) = med.coeffs_at(j, v, c);
            if u_accept * maj < st {
                if T::ACTIVE {
                    tally_segments(geo, p_start, d, v_start, t, tally);
                }
                (w.p, w.v) = (q, v);
                return Event::Collision(j, albedo);
            }
        }
    }
}
