//! Renders and gradient passes eight paths at a time: mask-free volumes (boxes, periodic slabs) and masked boxes
//! (voxelized meshes).
//!
//! One path's walk is a long chain of dependent operations (random number, logarithm, voxel lookup,
//! coefficient load, accept test, phase sampling) that leaves most of a core idle. Here eight independent paths
//! advance in SIMD lanes (`wide::f32x8`, AVX2 with `target-cpu=native`): `step.rs` draws a tentative collision
//! (delta tracking) for each lane, and the lanes whose collision is real scatter, all in vector arithmetic.
//! The rarer events are handled per lane here, with the scalar code the scalar tracer uses: camera rays
//! (`trace::camera_ray`), a flight reaching the grid's face (Fresnel reflection, or out to the light), a path
//! ending and its lane taking the next path. In masked volumes a lane delta-tracks only inside a safe ball
//! (every voxel within it is inside the object, `Geometry::safe`); near the surface and outside the object it
//! runs the scalar walk (`trace::walk` with regular tracking) until it scatters deep inside again.
//!
//! The estimator is `trace`'s (implicit absorption, Russian roulette); only the random numbers differ: each path
//! keys the packets' 32-bit counter-based stream (`rng::uniform8`, `rng::LaneRng`). A path's value depends
//! only on its key, never on its lane or thread, so renders are bit-identical for any thread count, and a
//! gradient pass replays exactly the paths of its forward pass: `trace_paths` with an active `PathTally`
//! reports every flight's per-voxel segments (`grid::tally_segments`) and collisions.

pub(crate) mod step;

use crate::transport::estimate::RenderOptions;
use crate::transport::flight::Regular;
use crate::transport::grid::{
    component, facing_normal, grid_exit8, grid_face_point, locate_box, safe_radius8, span, tally_segments, wrap_coord,
};
use crate::transport::path::{PathValue, Tally, Walk};
use crate::transport::rng::{path_key, LaneRng, PathRng};
use crate::transport::sampling::{add, scale, V3};
use crate::transport::scene::{Boundary, Geometry, Medium, Texel};
use crate::transport::trace::{camera_ray, interface, trace, walk, Start, WalkEnd};
use bytemuck::cast;
use wide::{f32x8, i32x8};

const W: usize = 8;
/// Uniforms drawn by a camera ray (2 for the point on the face, 1 for the Fresnel event); the walk starts after.
const CAMERA_DRAWS: u32 = 3;
/// Uniforms drawn per lane per step: free flight, accept test, roulette or Fresnel, two for the phase function.
const STEP_DRAWS: u32 = 5;

/// Gradient tallies of the paths `trace_paths` traces, per path (`job`) and channel `c`: the segments (voxel,
/// length) of every flight and the voxel of every scattering, as `path::Tally` for one path.
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
        if geo.masked() {
            let v = locate_box(geo, p);
            let (pv, vv) = (p.map(f32x8::splat), v.map(i32x8::splat));
            let s = f32x8::splat(geo.safe_distance(v) as f32);
            self.t_exit[l] = safe_radius8(geo, pv, vv, s).to_array()[0];
        } else {
            let (t_exit, axis) = grid_exit8(geo, p.map(f32x8::splat), d.map(f32x8::splat));
            self.t_exit[l] = t_exit.to_array()[0];
            self.axis[l] = axis.to_array()[0];
        }
    }

    /// Continue lane l's path with the general walk (masked volumes: near the surface and outside the object)
    /// from p in voxel v; returns the path's value if it ended, else the lane is flying in the deep interior.
    fn walk<M: Medium, P: PathTally>(
        &mut self,
        geo: &Geometry,
        med: &M,
        l: usize,
        job: usize,
        p: V3,
        d: V3,
        v: [i32; 3],
        in_medium: bool,
        tally: &mut P,
    ) -> Option<PathValue> {
        let mut rng = self.rng(l);
        let mut w =
            Walk { p, d, v, weight: self.weight[l], in_medium, events: self.events[l], steps: self.steps[l] as u64 };
        let mut jt = JobTally { inner: tally, job, c: self.chan[l] };
        let end = walk(geo, med, self.chan[l], &mut w, &mut Regular::new(), &mut rng, &mut jt, true);
        self.draw[l] = rng.draw;
        match end {
            WalkEnd::Done(r) => Some(r),
            WalkEnd::Deep => {
                (self.weight[l], self.events[l], self.steps[l]) =
                    (w.weight, w.events, w.steps.min(u32::MAX as u64) as u32);
                self.start_flight(geo, l, w.p, w.d);
                None
            }
        }
    }
}

/// Whether `trace_paths` handles this geometry (mask-free volumes, and masked boxes).
pub(crate) fn supported(geo: &Geometry) -> bool {
    !geo.masked() || geo.boundary == Boundary::Box
}

/// Trace the paths of `texels` (those the tally wants) and write their values to `values`, laid out
/// [texel][channel][sample] (3 * spp per texel; entries of paths not traced are left alone). `first_key` is the
/// random-number key of `texels[0]`. Every path is a pure function of its key, so a replay with an active tally
/// follows exactly the paths of an earlier pass. Returns the number of collisions.
pub(crate) fn trace_paths<M: Medium, P: PathTally>(
    geo: &Geometry,
    med: &M,
    texels: &[Texel],
    first_key: u64,
    opts: &RenderOptions,
    values: &mut [f32],
    tally: &mut P,
) -> u64 {
    assert!(supported(geo));
    let masked = geo.masked();
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
            let mut rng = LaneRng::new(key);
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
                Start::Outside(_, d, v) if !geo.in_grid(v) => {
                    Some(PathValue { value: geo.light.radiance(d, c), events: 0 })
                }
                Start::Outside(..) => {
                    // A texel inside a mask-free grid (not one of our texel lists): the scalar tracer.
                    let mut rng = PathRng::new(seed, first_key + ti as u64, s, c as u32);
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
                    let s = geo.safe_distance(locate_box(geo, p));
                    if s >= 2 {
                        pk.start_flight(geo, l, p, d);
                        continue;
                    }
                }
                pk.walk(geo, med, l, job, p, d, locate_box(geo, p), true, tally)
            } else {
                // The flight reached the grid's face: Fresnel reflection or out to the light.
                let axis = pk.axis[l] as usize;
                let d = [pk.d[0][l], pk.d[1][l], pk.d[2][l]];
                let mut p = grid_face_point(geo, [pk.p[0][l], pk.p[1][l], pk.p[2][l]], d, pk.t_exit[l], axis);
                if geo.boundary == Boundary::PeriodicXY {
                    for a in 0..2 {
                        p[a] = wrap_coord(p[a], span(geo, a));
                    }
                }
                let n_geo = facing_normal(axis, if component(d, axis) > 0.0 { 1 } else { -1 });
                let (nd, transmitted) = interface(d, n_geo, n_geo, geo.ior, ev.u_fresnel[l]);
                if transmitted {
                    Some(PathValue { value: pk.weight[l] * geo.light.radiance(nd, c), events: pk.events[l] })
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
