//! Forward rendering of mask-free volumes (boxes and periodic slabs) eight paths at a time.
//!
//! One path's delta-tracking walk is a long chain of dependent operations (random number, logarithm, voxel
//! lookup, coefficient load, accept test, phase sampling) that leaves most of a core idle. Here eight
//! independent paths advance in SIMD lanes (`wide::f32x8`, AVX2 with `target-cpu=native`): every step draws
//! a tentative collision for each lane, and the lanes whose collision is real scatter, all in vector arithmetic.
//! The rarer events (a flight reaching the grid's face, a path ending and its lane taking the next path) are
//! handled per lane. The walk is `trace`'s delta tracking with implicit absorption and Russian roulette, the
//! same estimator; only the random numbers differ: each path keys a 32-bit counter-based hash (draw i of path
//! key k is lowbias32(lowbias32(i ^ k_hi) + k_lo), 24 bits per uniform), which vectorises, where `PathRng`'s
//! 64-bit multiplies do not. A path's value depends only on its key, never on its lane or thread, so renders
//! stay bit-identical for any thread count. The gradient pass keeps the scalar `trace` (its replay needs the
//! tallies), which is an independent estimate of the same quantity.

use bytemuck::cast;
use wide::{f32x8, i32x8, u32x8, CmpEq, CmpGe, CmpGt, CmpLt};

use crate::render::RenderOptions;
use crate::rng::{path_key, Uniforms};
use crate::sampling::{add, scale, V3};
use crate::scene::{Boundary, Geometry, Medium, Texel};
use crate::trace::PathValue;
use crate::trace::{camera_ray, interface, tally_segments, trace, walk_masked, Start, Tally, Walk, WalkEnd,
                   MAX_EVENTS, MAX_STEPS, RR_THRESHOLD};

const W: usize = 8;
/// Uniforms drawn by a camera ray (2 for the point on the face, 1 for the Fresnel event); the walk starts after.
const CAMERA_DRAWS: u32 = 3;
/// Uniforms drawn per lane per step: free flight, accept test, roulette or Fresnel, two for the phase function.
const STEP_DRAWS: u32 = 5;

#[inline(always)]
fn lowbias32(mut x: u32) -> u32 {
    x ^= x >> 16;
    x = x.wrapping_mul(0x7FEB_352D);
    x ^= x >> 15;
    x = x.wrapping_mul(0x846C_A68B);
    x ^ (x >> 16)
}

#[inline(always)]
fn lowbias32x8(mut x: u32x8) -> u32x8 {
    x = x ^ (x >> 16u32);
    x = x * u32x8::splat(0x7FEB_352D);
    x = x ^ (x >> 15u32);
    x = x * u32x8::splat(0x846C_A68B);
    x ^ (x >> 16u32)
}

/// Uniform in [0, 1) with 24 random bits: draw `i` of the stream keyed (k_lo, k_hi).
#[inline(always)]
pub(crate) fn uniform(k_lo: u32, k_hi: u32, i: u32) -> f32 {
    (lowbias32(lowbias32(i ^ k_hi).wrapping_add(k_lo)) >> 8) as f32 * (1.0 / 16_777_216.0)
}

/// A lane's stream as scalar uniforms (camera rays and the walk near the surface).
struct LaneRng {
    k_lo: u32,
    k_hi: u32,
    draw: u32,
}

impl Uniforms for LaneRng {
    #[inline(always)]
    fn next_f32(&mut self) -> f32 {
        self.draw += 1;
        uniform(self.k_lo, self.k_hi, self.draw - 1)
    }
    #[inline(always)]
    fn next_f32_pair(&mut self) -> (f32, f32) {
        (self.next_f32(), self.next_f32())
    }
}

#[inline(always)]
fn uniform8(k_lo: u32x8, k_hi: u32x8, i: u32x8) -> f32x8 {
    let h = lowbias32x8(lowbias32x8(i ^ k_hi) + k_lo) >> 8u32;
    cast::<u32x8, i32x8>(h).round_float() * f32x8::splat(1.0 / 16_777_216.0)
}

#[inline(always)]
fn select_i32(mask: f32x8, t: i32x8, f: i32x8) -> i32x8 {
    cast::<f32x8, i32x8>(mask).blend(t, f)
}

/// Distance along d from p to the grid's boundary (periodic: only z bounds it) and the axis reached there;
/// the same comparisons in the same order as `trace`'s delta tracking.
#[inline(always)]
fn exit8(geo: &Geometry, p: [f32x8; 3], d: [f32x8; 3]) -> (f32x8, i32x8) {
    let zero = f32x8::ZERO;
    let mut t = f32x8::splat(f32::INFINITY);
    let mut axis = i32x8::splat(2);
    let first = if geo.boundary == Boundary::PeriodicXY { 2 } else { 0 };
    for a in first..3 {
        let far = f32x8::splat(geo.n[a] as f32 * geo.size[a]);
        let b = d[a].cmp_gt(zero).blend(far, zero);
        let ta = ((b - p[a]) / d[a]).max(zero);
        let ta = d[a].cmp_eq(zero).blend(f32x8::splat(f32::INFINITY), ta);
        let nearer = ta.cmp_lt(t);
        t = nearer.blend(ta, t);
        axis = select_i32(nearer, i32x8::splat(a as i32), axis);
    }
    (t, axis)
}

/// New directions after Henyey-Greenstein scattering of d (as `sampling::hg_sample`, vectorised).
#[inline(always)]
fn hg8(d: [f32x8; 3], g: f32, u1: f32x8, u2: f32x8) -> [f32x8; 3] {
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

/// Gradient tallies of the paths `trace_paths` traces, per path (`job`) and channel `c`: the segments (voxel,
/// length) of every flight and the voxel of every scattering, as `trace::Tally` for one path.
pub(crate) trait PathTally {
    const ACTIVE: bool;
    /// Whether to trace path `job` at all (a replay skips the paths that carry no gradient).
    fn wanted(&self, _job: usize) -> bool {
        true
    }
    fn segment(&mut self, job: usize, c: usize, j: usize, len: f32);
    fn scatter(&mut self, job: usize, c: usize, j: usize);
}

pub(crate) struct NoPathTally;

impl PathTally for NoPathTally {
    const ACTIVE: bool = false;
    #[inline(always)]
    fn segment(&mut self, _: usize, _: usize, _: usize, _: f32) {}
    #[inline(always)]
    fn scatter(&mut self, _: usize, _: usize, _: usize) {}
}

/// One path's view of a `PathTally` (for the scalar walk and `tally_segments`).
struct JobTally<'a, P: PathTally> {
    inner: &'a mut P,
    job: usize,
    c: usize,
}

impl<P: PathTally> Tally for JobTally<'_, P> {
    const ACTIVE: bool = P::ACTIVE;
    #[inline(always)]
    fn segment(&mut self, j: usize, len: f32) {
        self.inner.segment(self.job, self.c, j, len);
    }
    #[inline(always)]
    fn scatter(&mut self, j: usize) {
        self.inner.scatter(self.job, self.c, j);
    }
}

/// Eight paths in flight: per-lane state, structure of arrays.
struct Packet {
    /// Start of the current straight flight (wrapped into the periodic frame), direction, distance flown.
    p: [[f32; W]; 3],
    d: [[f32; W]; 3],
    t: [f32; W],
    /// Where the flight stops without a collision: the grid's face (mask-free), or the edge of the ball around
    /// the flight's start that is certainly inside the object (with a mask; see `Geometry::safe`).
    t_exit: [f32; W],
    axis: [i32; W],
    weight: [f32; W],
    maj: [f32; W],
    inv_maj: [f32; W],
    k_lo: [u32; W],
    k_hi: [u32; W],
    draw: [u32; W],
    events: [u32; W],
    steps: [u32; W],
    chan: [usize; W],
    /// The path (index into the output) each lane carries; `None`: idle.
    job: [Option<usize>; W],
}

/// What a step left for per-lane handling (bit l = lane l).
struct StepEvents {
    /// Flights that reached t_exit without a collision.
    exits: i32,
    /// Paths that ended (absorbed by the roulette, or cut).
    ended: i32,
    /// Lanes that scattered into a voxel next to the object's surface (masked volumes): the general walk.
    shallow: i32,
    /// Real collisions (scattered or absorbed), at distance `t` along the flight, in voxel `j`.
    collided: i32,
    t: [f32; W],
    j: [i32; W],
    /// The third uniform of the step (the Fresnel decision of a lane that reached the grid's face).
    u_fresnel: [f32; W],
}

impl Packet {
    fn new() -> Self {
        Packet {
            p: [[0.0; W]; 3],
            d: [[0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 0.0, 0.0]; 3],
            t: [0.0; W],
            t_exit: [0.0; W],
            axis: [2; W],
            weight: [0.0; W],
            maj: [0.0; W],
            inv_maj: [0.0; W],
            k_lo: [0; W],
            k_hi: [0; W],
            draw: [0; W],
            events: [0; W],
            steps: [0; W],
            chan: [0; W],
            job: [None; W],
        }
    }

    fn live_mask(&self) -> f32x8 {
        cast(i32x8::from(self.job.map(|j| -(j.is_some() as i32))))
    }

    fn rng(&self, l: usize) -> LaneRng {
        LaneRng { k_lo: self.k_lo[l], k_hi: self.k_hi[l], draw: self.draw[l] }
    }

    /// Begin a flight from p along d in lane l (scalar: after a camera ray, a reflection or the general walk).
    fn start_flight(&mut self, geo: &Geometry, l: usize, p: V3, d: V3) {
        for a in 0..3 {
            self.p[a][l] = p[a];
            self.d[a][l] = d[a];
        }
        self.t[l] = 0.0;
        if geo.inside.is_some() {
            let v = locate_box(geo, p);
            let (pv, vv) = (p.map(f32x8::splat), v.map(i32x8::splat));
            let s = f32x8::splat(geo.safe_distance(geo.index(v)) as f32);
            self.t_exit[l] = safe_radius8(geo, pv, vv, s).to_array()[0];
        } else {
            let (t_exit, axis) = exit8(geo, p.map(f32x8::splat), d.map(f32x8::splat));
            self.t_exit[l] = t_exit.to_array()[0];
            self.axis[l] = axis.to_array()[0];
        }
    }

    /// One tentative collision in every live lane; real collisions scatter (vectorised).
    #[inline(always)]
    fn step<M: Medium>(&mut self, geo: &Geometry, med: &M) -> StepEvents {
        let masked = geo.inside.is_some();
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
        let mut v = [i32x8::ZERO; 3];
        for a in 0..3 {
            if a < 2 && geo.boundary == Boundary::PeriodicXY {
                let span = geo.n[a] as f32 * geo.size[a];
                let w = q[a] - (q[a] * f32x8::splat(1.0 / span)).floor() * f32x8::splat(span);
                q[a] = w.cmp_ge(f32x8::splat(span)).blend(f32x8::ZERO, w);
            }
            v[a] = (q[a] * f32x8::splat(geo.inv_size[a])).trunc_int().max(i32x8::ZERO).min(i32x8::splat(geo.n[a] - 1));
        }
        let j = ((v[2] * i32x8::splat(geo.n[1]) + v[1]) * i32x8::splat(geo.n[0]) + v[0]).to_array();
        let (mut st, mut albedo, mut safe) = ([0.0f32; W], [0.0f32; W], [0.0f32; W]);
        for l in 0..W {
            (st[l], albedo[l]) = med.coeffs(j[l] as usize, self.chan[l]);
            if masked {
                safe[l] = geo.safe_distance(j[l] as usize) as f32;
            }
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
            let safe = f32x8::from(safe);
            shallow = (scatter & safe.cmp_lt(f32x8::splat(2.0))).move_mask();
            let radius = safe_radius8(geo, q, v, safe);
            self.t_exit = scatter.blend(radius, t_exit).into();
        } else {
            let (te, ax) = exit8(geo, p2, d2);
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

    /// Continue lane l's path with the general walk (masked volumes: near the surface and outside the object)
    /// from p in voxel v; returns the path's value if it ended, else the lane is flying in the deep interior.
    #[allow(clippy::too_many_arguments)]
    fn walk<M: Medium, P: PathTally>(&mut self, geo: &Geometry, med: &M, l: usize, job: usize, p: V3, d: V3,
                                     v: [i32; 3], in_medium: bool, tally: &mut P) -> Option<PathValue> {
        let mut rng = self.rng(l);
        let mut w = Walk { p, d, v, weight: self.weight[l], in_medium, events: self.events[l], steps: self.steps[l] as u64 };
        let mut jt = JobTally { inner: tally, job, c: self.chan[l] };
        let end = walk_masked(geo, med, self.chan[l], &mut w, &mut rng, &mut jt, true);
        self.draw[l] = rng.draw;
        match end {
            WalkEnd::Done(r) => Some(r),
            WalkEnd::Deep => {
                (self.weight[l], self.events[l], self.steps[l]) = (w.weight, w.events, w.steps.min(u32::MAX as u64) as u32);
                self.start_flight(geo, l, w.p, w.d);
                None
            }
        }
    }
}

/// Radius of a ball around p (in voxel v, safe distance s) that lies inside the object: every voxel within s - 1
/// steps of v is inside, so the ball may reach (s - 1) voxels beyond p's own voxel along each axis. Shrunk by
/// 1e-4 relative so that rounding never puts the ball's edge into an outside voxel (any smaller ball is exact too).
#[inline(always)]
fn safe_radius8(geo: &Geometry, p: [f32x8; 3], v: [i32x8; 3], s: f32x8) -> f32x8 {
    let mut r = f32x8::splat(f32::INFINITY);
    for a in 0..3 {
        let h = f32x8::splat(geo.size[a]);
        let lo = (p[a] - v[a].round_float() * h).max(f32x8::ZERO);
        let own = lo.min((h - lo).max(f32x8::ZERO));
        r = r.min((s - f32x8::ONE) * h + own);
    }
    r * f32x8::splat(1.0 - 1e-4)
}

/// The voxel containing p, clamped to the grid.
#[inline(always)]
fn locate_box(geo: &Geometry, p: V3) -> [i32; 3] {
    let mut v = [0i32; 3];
    for a in 0..3 {
        v[a] = ((p[a] * geo.inv_size[a]) as i32).max(0).min(geo.n[a] - 1);
    }
    v
}

/// Whether `trace_paths` handles this geometry (mask-free volumes, and masked boxes).
pub(crate) fn supported(geo: &Geometry) -> bool {
    geo.inside.is_none() || geo.boundary == Boundary::Box
}

/// Trace the paths of `texels` (those the tally wants) and write their values to `values`, laid out
/// [texel][channel][sample] (3 * spp per texel; entries of paths not traced are left alone). `first_key` is the
/// random-number key of `texels[0]`. Every path is a pure function of its key, so a replay with an active tally
/// follows exactly the paths of an earlier pass. Returns the number of collisions.
pub(crate) fn trace_paths<M: Medium, P: PathTally>(geo: &Geometry, med: &M, texels: &[Texel], first_key: u64,
                                                   opts: &RenderOptions, values: &mut [f32], tally: &mut P) -> u64 {
    assert!(supported(geo));
    let masked = geo.inside.is_some();
    let (spp, seed, include_specular) = (opts.spp as usize, opts.seed, opts.include_specular);
    let per_texel = 3 * spp;
    let jobs = texels.len() * per_texel;
    assert_eq!(values.len(), jobs);
    let mut pk = Packet::new();
    let mut next = 0usize;
    let mut events = 0u64;
    // Give lane l the next path that reaches the (deep) interior; paths that end before are written directly.
    let refill = |pk: &mut Packet, l: usize, next: &mut usize, events: &mut u64, values: &mut [f32], tally: &mut P| {
        pk.job[l] = None;
        while *next < jobs {
            let job = *next;
            *next += 1;
            if !tally.wanted(job) {
                continue;
            }
            let (ti, r) = (job / per_texel, job % per_texel);
            let (c, s) = (r / spp, (r % spp) as u32);
            let key = path_key(seed, first_key + ti as u64, s, c as u32);
            let mut rng = LaneRng { k_lo: key as u32, k_hi: (key >> 32) as u32, draw: 0 };
            let start = camera_ray(geo, &texels[ti], include_specular, &mut rng);
            let maj = med.majorant(c);
            pk.maj[l] = maj;
            pk.inv_maj[l] = if maj > 0.0 { 1.0 / maj } else { f32::INFINITY };
            (pk.k_lo[l], pk.k_hi[l], pk.draw[l]) = (rng.k_lo, rng.k_hi, CAMERA_DRAWS);
            (pk.events[l], pk.steps[l], pk.chan[l]) = (0, 0, c);
            let ended = match start {
                Start::Done(r) => Some(r),
                Start::Medium(p, d, v, w) if masked => {
                    pk.weight[l] = w;
                    pk.walk(geo, med, l, job, p, d, v, true, tally)
                }
                Start::Outside(p, d, v) if masked => {
                    pk.weight[l] = 1.0;
                    pk.walk(geo, med, l, job, p, d, v, false, tally)
                }
                Start::Medium(p, d, _, w) => {
                    pk.weight[l] = w;
                    pk.start_flight(geo, l, p, d);
                    None
                }
                Start::Outside(_, d, v) if !geo.in_grid(v) => Some(PathValue { value: geo.env.eval(d, c), events: 0 }),
                Start::Outside(..) => {
                    // A texel inside a mask-free grid (not one of our texel lists): the scalar tracer.
                    let mut rng = crate::rng::PathRng::new(seed, first_key + ti as u64, s, c as u32);
                    let mut jt = JobTally { inner: &mut *tally, job, c };
                    Some(trace(geo, med, &texels[ti], c, &mut rng, include_specular, &mut jt))
                }
            };
            match ended {
                Some(r) => {
                    values[job] = r.value;
                    *events += r.events as u64;
                }
                None => {
                    pk.job[l] = Some(job);
                    return;
                }
            }
        }
    };
    for l in 0..W {
        refill(&mut pk, l, &mut next, &mut events, values, tally);
    }
    while pk.job.iter().any(|j| j.is_some()) {
        let (p0, d0) = (pk.p, pk.d);
        let ev = pk.step(geo, med);
        if P::ACTIVE {
            // The flights that ended in this step: a collision at t, or t_exit (grid face or safe-ball edge).
            let mut bits = ev.collided | ev.exits;
            while bits != 0 {
                let l = bits.trailing_zeros() as usize;
                bits &= bits - 1;
                let (job, c) = (pk.job[l].expect("a live lane"), pk.chan[l]);
                let (p, d) = ([p0[0][l], p0[1][l], p0[2][l]], [d0[0][l], d0[1][l], d0[2][l]]);
                let collided = ev.collided >> l & 1 == 1;
                let len = if collided { ev.t[l] } else { pk.t_exit[l] };
                let mut jt = JobTally { inner: &mut *tally, job, c };
                tally_segments(geo, p, d, locate_box(geo, p), len, &mut jt);
                if collided && ev.ended >> l & 1 == 0 {
                    jt.scatter(ev.j[l] as usize);
                }
            }
        }
        let mut bits = ev.ended | ev.exits | ev.shallow;
        while bits != 0 {
            let l = bits.trailing_zeros() as usize;
            bits &= bits - 1;
            let job = pk.job[l].expect("a live lane");
            let c = pk.chan[l];
            let ended = if ev.ended >> l & 1 == 1 {
                Some(PathValue { value: 0.0, events: pk.events[l] })
            } else if masked {
                // A shallow collision (the lane is at it), or the edge of the safe ball: the general walk from there.
                let d = [pk.d[0][l], pk.d[1][l], pk.d[2][l]];
                let mut p = [pk.p[0][l], pk.p[1][l], pk.p[2][l]];
                if ev.exits >> l & 1 == 1 {
                    p = add(p, scale(d, pk.t_exit[l]));
                    let s = geo.safe_distance(geo.index(locate_box(geo, p)));
                    if s >= 2 {
                        pk.start_flight(geo, l, p, d);
                        continue;
                    }
                }
                pk.walk(geo, med, l, job, p, d, locate_box(geo, p), true, tally)
            } else {
                // The flight reached the grid's face: Fresnel reflection or out into the environment.
                let axis = pk.axis[l] as usize;
                let d = [pk.d[0][l], pk.d[1][l], pk.d[2][l]];
                let mut p = add([pk.p[0][l], pk.p[1][l], pk.p[2][l]], scale(d, pk.t_exit[l]));
                let out = d[axis] > 0.0;
                p[axis] = if out { geo.n[axis] as f32 * geo.size[axis] } else { 0.0 };
                if geo.boundary == Boundary::PeriodicXY {
                    for pa in p.iter_mut().take(2).zip(0..2) {
                        let span = geo.n[pa.1] as f32 * geo.size[pa.1];
                        *pa.0 -= (*pa.0 / span).floor() * span;
                    }
                }
                let mut n_geo = [0.0f32; 3];
                n_geo[axis] = if out { -1.0 } else { 1.0 };
                let (nd, transmitted) = interface(d, n_geo, n_geo, geo.ior, ev.u_fresnel[l]);
                if transmitted {
                    Some(PathValue { value: pk.weight[l] * geo.env.eval(nd, c), events: pk.events[l] })
                } else {
                    pk.start_flight(geo, l, p, nd);
                    None
                }
            };
            if let Some(r) = ended {
                values[job] = r.value;
                events += r.events as u64;
                refill(&mut pk, l, &mut next, &mut events, values, tally);
            }
        }
    }
    events
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn vector_and_scalar_uniforms_agree_and_are_uniform() {
        let (k_lo, k_hi) = (0x1234_5678u32, 0x9ABC_DEF0u32);
        let v = uniform8(u32x8::splat(k_lo), u32x8::splat(k_hi), u32x8::from([0, 1, 2, 3, 4, 5, 6, 7])).to_array();
        for (i, x) in v.iter().enumerate() {
            assert_eq!(*x, uniform(k_lo, k_hi, i as u32));
        }
        // Mean and variance over many keys and draws: n = 1e6, standard error of the mean 2.9e-4, test at 5 sigma.
        let n = 1_000_000u32;
        let (mut s, mut s2) = (0.0f64, 0.0f64);
        for t in 0..n {
            let key = path_key(3, t as u64 / 8, 0, 0);
            let x = uniform(key as u32, (key >> 32) as u32, t % 8) as f64;
            assert!((0.0..1.0).contains(&x));
            s += x;
            s2 += x * x;
        }
        let mean = s / n as f64;
        assert!((mean - 0.5).abs() < 5.0 * (1.0f64 / 12.0 / n as f64).sqrt());
        assert!((s2 / n as f64 - mean * mean - 1.0 / 12.0).abs() < 1e-3);
    }

    #[test]
    fn safe_balls_stay_inside_the_object() {
        // Random points in the voxels of a random blob (anisotropic voxels): no voxel that the ball of radius
        // safe_radius8 around the point reaches (box-to-point distance below the radius) is outside.
        let n = [14usize, 12, 13];
        let size = [0.05f32, 0.08, 0.03];
        let mut inside = vec![0u8; n.iter().product()];
        for z in 0..n[2] {
            for y in 0..n[1] {
                for x in 0..n[0] {
                    let r2 = ((x as f32 - 6.5) / 6.0).powi(2) + ((y as f32 - 5.5) / 5.0).powi(2) + ((z as f32 - 6.0) / 5.5).powi(2);
                    inside[(z * n[1] + y) * n[0] + x] = (r2 < 1.0 && (x + 2 * y) % 11 != 3) as u8;
                }
            }
        }
        let geo = Geometry::new(n, size, Boundary::Box, 1.5, 0.4).unwrap().with_inside(inside.clone()).unwrap();
        let mut rng = crate::rng::PathRng::new(9, 0, 0, 0);
        let mut checked = 0;
        for j in 0..inside.len() {
            let s = geo.safe_distance(j);
            if s < 2 {
                continue;
            }
            let v = [(j % n[0]) as i32, ((j / n[0]) % n[1]) as i32, (j / (n[0] * n[1])) as i32];
            for _ in 0..20 {
                let p: V3 = std::array::from_fn(|a| (v[a] as f32 + rng.next_f32()) * size[a]);
                let r = safe_radius8(&geo, p.map(f32x8::splat), v.map(i32x8::splat), f32x8::splat(s as f32)).to_array()[0];
                assert!(r >= (s as f32 - 1.0) * 0.03 * (1.0 - 1e-4) - 1e-6);
                for k in 0..inside.len() {
                    let w = [(k % n[0]) as i32, ((k / n[0]) % n[1]) as i32, (k / (n[0] * n[1])) as i32];
                    let d2: f32 = (0..3)
                        .map(|a| {
                            let (lo, hi) = (w[a] as f32 * size[a], (w[a] + 1) as f32 * size[a]);
                            (lo - p[a]).max(p[a] - hi).max(0.0).powi(2)
                        })
                        .sum();
                    if d2 < r * r * (1.0 - 1e-5) {
                        assert_eq!(inside[k], 1, "point {p:?} in voxel {v:?} (safe {s}) radius {r} reaches {w:?}");
                    }
                }
                checked += 1;
            }
        }
        assert!(checked > 500, "{checked}");
    }

    #[test]
    fn hg8_matches_the_scalar_sampler() {
        let d = crate::sampling::normalize([0.3, -0.5, 0.81]);
        let u1 = f32x8::from([0.01, 0.2, 0.35, 0.5, 0.61, 0.77, 0.9, 0.999]);
        let u2 = f32x8::from([0.9, 0.1, 0.33, 0.5, 0.7, 0.25, 0.05, 0.6]);
        let w = hg8(d.map(f32x8::splat), 0.4, u1, u2);
        let (a, b) = (u1.to_array(), u2.to_array());
        for l in 0..W {
            let s = crate::sampling::hg_sample(d, 0.4, a[l], b[l]);
            for k in 0..3 {
                assert!((w[k].to_array()[l] - s[k]).abs() < 2e-5, "lane {l}: {:?} vs {s:?}", w.map(|x| x.to_array()[l]));
            }
        }
    }
}
