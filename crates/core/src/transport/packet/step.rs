//! The packet step: one tentative collision (delta tracking) in each of eight lanes, in vector arithmetic.
//!
//! Every step draws five uniforms per lane (`STEP_DRAWS`: free flight, accept test, roulette or Fresnel, two for
//! the phase function) whether it uses them or not, so a lane's draw index is a pure function of its history.
//! A lane whose tentative collision is real scatters (Henyey-Greenstein, `hg8`) with implicit absorption and
//! Russian roulette (`flight::survive`'s rule, vectorised) and starts a new flight; a lane whose flight reaches
//! its `t_exit` (the grid's face, or the edge of its safe ball in a masked volume) is reported in
//! `StepEvents`, as are paths that end, for the per-lane code in `packet/mod.rs`.

use bytemuck::cast;
use wide::{f32x8, i32x8, u32x8, CmpGe, CmpLt};

use super::{Packet, STEP_DRAWS, W};
use crate::transport::grid::{grid_exit8, locate8, safe_radius8};
use crate::transport::path::{MAX_EVENTS, MAX_STEPS, RR_THRESHOLD};
use crate::transport::rng::uniform8;
use crate::transport::scene::{Geometry, Medium};

/// What a step left for per-lane handling (bit l = lane l).
pub(super) struct StepEvents {
    /// Flights that reached t_exit without a collision.
    pub exits: i32,
    /// Paths that ended (absorbed by the roulette, or cut).
    pub ended: i32,
    /// Lanes that scattered into a voxel next to the object's surface (masked volumes): the general walk.
    pub shallow: i32,
    /// Real collisions (scattered or absorbed), at distance `t` along the flight, in voxel `j`.
    pub collided: i32,
    pub t: [f32; W],
    pub j: [i32; W],
    /// The third uniform of the step (the Fresnel decision of a lane that reached the grid's face).
    pub u_fresnel: [f32; W],
}

#[inline(always)]
fn select_i32(mask: f32x8, t: i32x8, f: i32x8) -> i32x8 {
    cast::<f32x8, i32x8>(mask).blend(t, f)
}

/// New directions after Henyey-Greenstein scattering of d (as `sampling::hg_sample`, vectorised).
#[inline(always)]
pub(crate) fn hg8(d: [f32x8; 3], g: f32, u1: f32x8, u2: f32x8) -> [f32x8; 3] {
    let one = f32x8::ONE;
    let c = if g.abs() < 1e-3 {
        one - u1 * f32x8::splat(2.0)
    } else {
        let sq = f32x8::splat(1.0 - g * g) / (f32x8::splat(1.0 - g) + u1 * f32x8::splat(2.0 * g));
        ((f32x8::splat(1.0 + g * g) - sq * sq) * f32x8::splat(0.5 / g)).max(-one).min(one)
    };
    let s = (one - c * c).max(f32x8::ZERO).sqrt();
    let sign = d[2].cmp_ge(f32x8::ZERO).blend(one, -one);
    let a = -one / (sign + d[2]);
    let b = d[0] * d[1] * a;
    let b1 = [one + sign * d[0] * d[0] * a, sign * b, -(sign * d[0])];
    let b2 = [b, sign + d[1] * d[1] * a, -d[1]];
    let (sp, cp) = (u2 * f32x8::splat(std::f32::consts::TAU)).sin_cos();
    let (x, y) = (s * cp, s * sp);
    let w = [b1[0] * x + b2[0] * y + d[0] * c, b1[1] * x + b2[1] * y + d[1] * c, b1[2] * x + b2[2] * y + d[2] * c];
    let k = f32x8::splat(0.5) * (f32x8::splat(3.0) - (w[0] * w[0] + w[1] * w[1] + w[2] * w[2]));
    [w[0] * k, w[1] * k, w[2] * k]
}

impl Packet {
    /// One tentative collision in every live lane; real collisions scatter (vectorised).
    #[inline(always)]
    pub(super) fn step<M: Medium>(&mut self, geo: &Geometry, med: &M) -> StepEvents {
        let masked = geo.masked();
        let live = self.live_mask();
        let (k_lo, k_hi) = (u32x8::from(self.k_lo), u32x8::from(self.k_hi));
        let i = u32x8::from(self.draw);
        let u = |k: u32| uniform8(k_lo, k_hi, i + u32x8::splat(k));
        let (u_flight, u_accept, u_third, u_phase1, u_phase2) = (u(0), u(1), u(2), u(3), u(4));
        self.draw = (i + u32x8::splat(STEP_DRAWS)).into();

        let one = f32x8::ONE;
        let t = f32x8::from(self.t) - (one - u_flight).ln() * f32x8::from(self.inv_maj);
        let t_exit = f32x8::from(self.t_exit);
        let exit = t.cmp_ge(t_exit) & live;
        let p = self.p.map(f32x8::from);
        let d = self.d.map(f32x8::from);
        let mut q = [p[0] + d[0] * t, p[1] + d[1] * t, p[2] + d[2] * t];
        let v = locate8(geo, &mut q);
        let j = ((v[2] * i32x8::splat(geo.n[1]) + v[1]) * i32x8::splat(geo.n[0]) + v[0]).to_array();
        let va = v.map(|x| x.to_array());
        let (mut st, mut albedo) = ([0.0f32; W], [0.0f32; W]);
        for l in 0..W {
            (st[l], albedo[l]) = med.coeffs_at(j[l] as usize, [va[0][l], va[1][l], va[2][l]], self.chan[l]);
        }
        let (st, albedo) = (f32x8::from(st), f32x8::from(albedo));
        let maj = f32x8::from(self.maj);
        let accept = live & !exit & (u_accept * maj).cmp_lt(st);

        // Implicit absorption and Russian roulette at real collisions.
        let rr = f32x8::splat(RR_THRESHOLD);
        let w = f32x8::from(self.weight) * albedo;
        let low = w.cmp_lt(rr);
        let dead = accept & low & !(u_third * rr).cmp_lt(w);
        let scatter = accept & !dead;
        self.weight = accept.blend(low.blend(rr, w), f32x8::from(self.weight)).into();
        self.events = (u32x8::from(self.events) - cast::<f32x8, u32x8>(accept)).into();
        self.steps = (u32x8::from(self.steps) + u32x8::splat(1)).into();

        // Scattering lanes: new direction, a new flight from the collision point.
        let nd = hg8(d, geo.g, u_phase1, u_phase2);
        let p2 = [scatter.blend(q[0], p[0]), scatter.blend(q[1], p[1]), scatter.blend(q[2], p[2])];
        let d2 = [scatter.blend(nd[0], d[0]), scatter.blend(nd[1], d[1]), scatter.blend(nd[2], d[2])];
        let mut shallow = 0;
        if masked {
            let safe = f32x8::from(geo.safe_distances8(v));
            shallow = (scatter & safe.cmp_lt(f32x8::splat(2.0))).move_mask();
            let radius = safe_radius8(geo, q, v, safe);
            self.t_exit = scatter.blend(radius, t_exit).into();
        } else {
            let (te, ax) = grid_exit8(geo, p2, d2);
            self.t_exit = scatter.blend(te, t_exit).into();
            self.axis = select_i32(scatter, ax, i32x8::from(self.axis)).into();
        }
        self.p = p2.map(<[f32; W]>::from);
        self.d = d2.map(<[f32; W]>::from);
        self.t = scatter.blend(f32x8::ZERO, t).into();

        let too_long = cast::<u32x8, f32x8>(
            u32x8::from(self.events).cmp_gt(u32x8::splat(MAX_EVENTS))
                | u32x8::from(self.steps).cmp_gt(u32x8::splat(MAX_STEPS as u32)),
        );
        StepEvents {
            exits: (exit & !too_long).move_mask(),
            ended: ((dead | too_long) & live).move_mask(),
            shallow: shallow & !too_long.move_mask(),
            collided: accept.move_mask(),
            t: t.into(),
            j,
            u_fresnel: u_third.into(),
        }
    }
}
