//! Hero paths eight at a time (mask-free grids and masked boxes, as `packet`): delta tracking in SIMD lanes,
//! each lane a hero path carrying the three channels. In masked boxes a lane delta-tracks only inside a safe
//! ball (every voxel within it is inside the object) and runs `hero`'s scalar walk (regular tracking) near the
//! surface and outside the object until it scatters deep inside again; both track the same estimator, so a
//! path switches between them at any flight.
//!
//! Every lane flies at one majorant, the largest of the three channels' (`Medium::majorant`), and a tentative
//! collision at x is real with probability sigma_t,h(x) / majorant (h the lane's hero channel). The channels'
//! samplers then share one path space, the null-collision one (Miller et al. 2019): a path's density under
//! channel k's sampler is prod_real sigma_t,k x prod_null (majorant - sigma_t,k) times factors common to the
//! channels, and its contribution to channel j is prod_real sigma_s,j x prod_null (majorant - sigma_t,j) times
//! the same factors. So, as in `hero`'s walk, a lane carries per channel k a relative density p_k (times
//! sigma_t,k / sigma_t,h at a real collision, (majorant - sigma_t,k) / (majorant - sigma_t,h) at a null one) and
//! an albedo product a_k, and channel j's value is 3 a_j p_j / sum_k p_k (at most 3 a_j). Exact: the
//! contributions, summed over the null collisions, are the channel's f_j, and the balance heuristic over
//! samplers of one space is unbiased. Gradients: a path's track lengths and real collisions (`grid::tally_segments`
//! per flight) give d log f_j as in `trace`, and E[value_j x d log f_j] = d integral f_j (the track-length
//! derivative depends on the real path only, whose f_j is the null collisions' sum).
//!
//! Random numbers: the packets' 32-bit stream keyed by (seed, texel, sample, hero), five uniforms per step
//! (`STEP_DRAWS`); a path's value depends on its key only, so a replay follows it exactly.

use bytemuck::cast;
use wide::{f32x8, i32x8, u32x8, CmpGe, CmpLt};

use crate::transport::estimate::RenderOptions;
use crate::transport::grid::{
    component, facing_normal, grid_exit8, grid_face_point, locate8, locate_box, safe_radius8, span, tally_segments,
    wrap_coord,
};
use crate::transport::hero::{hero_of, put, trace_job, walk_hero, Carried, HeroEnd, JobTally};
use crate::transport::packet::step::hg8;
use crate::transport::packet::PathTally;
use crate::transport::path::{Tally, Walk, MAX_EVENTS, MAX_STEPS, RR_THRESHOLD};
use crate::transport::rng::{path_key, uniform8, LaneRng};
use crate::transport::sampling::{add, scale};
use crate::transport::scene::{Boundary, Geometry, Medium, Texel};
use crate::transport::trace::{camera_ray, interface, Start};

const W: usize = 8;
/// Uniforms drawn by a camera ray; the walk starts after them.
const CAMERA_DRAWS: u32 = 3;
/// Uniforms drawn per lane per step: free flight, accept test, roulette or Fresnel, two for the phase function.
const STEP_DRAWS: u32 = 5;

/// Eight hero paths in flight (structure of arrays): the flight from p along d (t flown, t_exit at the grid's
/// face on `axis`), per channel the relative densities `pr` and albedo products `a`, the random stream.
struct Lanes {
    p: [[f32; W]; 3],
    d: [[f32; W]; 3],
    t: [f32; W],
    t_exit: [f32; W],
    axis: [i32; W],
    pr: [[f32; W]; 3],
    a: [[f32; W]; 3],
    k_lo: [u32; W],
    k_hi: [u32; W],
    draw: [u32; W],
    events: [u32; W],
    steps: [u32; W],
    hero: [usize; W],
    job: [Option<usize>; W],
}

/// What a step left for per-lane handling (bit l = lane l), as `packet::step`'s events.
struct Events {
    exits: i32,
    ended: i32,
    /// Lanes that scattered into a voxel next to the object's surface (masked volumes): the scalar walk.
    shallow: i32,
    collided: i32,
    t: [f32; W],
    j: [i32; W],
    u_fresnel: [f32; W],
}

impl Lanes {
    fn new() -> Self {
        Lanes {
            p: [[0.0; W]; 3],
            d: [[0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 0.0, 0.0]; 3],
            t: [0.0; W],
            t_exit: [0.0; W],
            axis: [2; W],
            pr: [[1.0; W]; 3],
            a: [[0.0; W]; 3],
            k_lo: [0; W],
            k_hi: [0; W],
            draw: [0; W],
            events: [0; W],
            steps: [0; W],
            hero: [0; W],
            job: [None; W],
        }
    }

    /// Begin a flight from p along d in lane l.
    fn start_flight(&mut self, geo: &Geometry, l: usize, p: [f32; 3], d: [f32; 3]) {
        for a in 0..3 {
            (self.p[a][l], self.d[a][l]) = (p[a], d[a]);
        }
        self.t[l] = 0.0;
        if geo.masked() {
            let v = locate_box(geo, p);
            let s = f32x8::splat(geo.safe_distance(v) as f32);
            self.t_exit[l] = safe_radius8(geo, p.map(f32x8::splat), v.map(i32x8::splat), s).to_array()[0];
        } else {
            let (t_exit, axis) = grid_exit8(geo, p.map(f32x8::splat), d.map(f32x8::splat));
            self.t_exit[l] = t_exit.to_array()[0];
            self.axis[l] = axis.to_array()[0];
        }
    }

    /// Continue lane l's path (job `job`) with the scalar walk from p in voxel v: its values if it ended, else
    /// (None) the lane is flying in the deep interior again.
    #[allow(clippy::too_many_arguments)]
    fn walk<M: Medium, P: PathTally>(
        &mut self,
        geo: &Geometry,
        med: &M,
        l: usize,
        job: usize,
        (p, d, v): ([f32; 3], [f32; 3], [i32; 3]),
        in_medium: bool,
        tally: &mut P,
    ) -> Option<[f32; 3]> {
        let mut rng = LaneRng { k_lo: self.k_lo[l], k_hi: self.k_hi[l], draw: self.draw[l] };
        let mut w = Walk { p, d, v, weight: 0.0, in_medium, events: self.events[l], steps: self.steps[l] as u64 };
        let mut car = Carried { p: std::array::from_fn(|c| self.pr[c][l]), a: std::array::from_fn(|c| self.a[c][l]) };
        let mut jt = JobTally { inner: tally, job };
        let end = walk_hero(geo, med, self.hero[l], &mut w, &mut car, &mut rng, &mut jt, true);
        self.draw[l] = rng.draw;
        match end {
            HeroEnd::Done(r) => {
                self.events[l] = r.events;
                Some(r.value)
            }
            HeroEnd::Deep => {
                (self.events[l], self.steps[l]) = (w.events, w.steps.min(u32::MAX as u64) as u32);
                for c in 0..3 {
                    (self.pr[c][l], self.a[c][l]) = (car.p[c], car.a[c]);
                }
                self.start_flight(geo, l, w.p, w.d);
                None
            }
        }
    }

    /// Lane l's channel values: 3 a_j p_j / sum_k p_k.
    fn values(&self, l: usize) -> [f32; 3] {
        let q = (self.pr[0][l] + self.pr[1][l] + self.pr[2][l]) * (1.0 / 3.0);
        std::array::from_fn(|j| {
            if self.a[j][l] == 0.0 || self.pr[j][l] == 0.0 {
                0.0
            } else {
                self.a[j][l] * self.pr[j][l] / q
            }
        })
    }

    /// One tentative collision in every live lane at majorant `maj`; real collisions scatter (vectorised).
    #[inline(always)]
    fn step<M: Medium>(&mut self, geo: &Geometry, med: &M, maj: f32) -> Events {
        let live: f32x8 = cast(i32x8::from(self.job.map(|j| -(j.is_some() as i32))));
        let (k_lo, k_hi, i) = (u32x8::from(self.k_lo), u32x8::from(self.k_hi), u32x8::from(self.draw));
        let u = |k: u32| uniform8(k_lo, k_hi, i + u32x8::splat(k));
        let (u_flight, u_accept, u_third, u_phase1, u_phase2) = (u(0), u(1), u(2), u(3), u(4));
        self.draw = (i + u32x8::splat(STEP_DRAWS)).into();
        let (one, majv) = (f32x8::ONE, f32x8::splat(maj));
        let t = f32x8::from(self.t) - (one - u_flight).ln() * f32x8::splat(1.0 / maj);
        let t_exit = f32x8::from(self.t_exit);
        let exit = t.cmp_ge(t_exit) & live;
        let (p, d) = (self.p.map(f32x8::from), self.d.map(f32x8::from));
        let mut q = [p[0] + d[0] * t, p[1] + d[1] * t, p[2] + d[2] * t];
        let v = locate8(geo, &mut q);
        let j = ((v[2] * i32x8::splat(geo.n[1]) + v[1]) * i32x8::splat(geo.n[0]) + v[0]).to_array();
        let va = v.map(|x| x.to_array());
        let masked = geo.masked();
        let (mut st, mut albedo, mut st_h) = ([[0.0f32; W]; 3], [[0.0f32; W]; 3], [0.0f32; W]);
        for l in 0..W {
            for c in 0..3 {
                (st[c][l], albedo[c][l]) = med.coeffs_at(j[l] as usize, [va[0][l], va[1][l], va[2][l]], c);
            }
            st_h[l] = st[self.hero[l]][l];
        }
        let st_h = f32x8::from(st_h);
        let flying = live & !exit;
        let accept = flying & (u_accept * majv).cmp_lt(st_h);
        self.update(&st, &albedo, st_h, majv, flying, accept);

        // Russian roulette on the largest channel value at real collisions, every channel scaled alike.
        let pr = self.pr.map(f32x8::from);
        let a = self.a.map(f32x8::from);
        let qsum = (pr[0] + pr[1] + pr[2]) * f32x8::splat(1.0 / 3.0);
        let top = (a[0] * pr[0]).max(a[1] * pr[1]).max(a[2] * pr[2]) / qsum;
        let rr = f32x8::splat(RR_THRESHOLD);
        let low = top.cmp_lt(rr);
        let dead = accept & low & !(u_third * rr).cmp_lt(top);
        let boost = (accept & low & !dead).blend(rr / top, one);
        self.a = a.map(|x| (x * boost).into());
        self.events = (u32x8::from(self.events) - cast::<f32x8, u32x8>(accept)).into();
        self.steps = (u32x8::from(self.steps) + u32x8::splat(1)).into();

        let scatter = accept & !dead;
        let nd = hg8(d, geo.g, u_phase1, u_phase2);
        let p2 = [scatter.blend(q[0], p[0]), scatter.blend(q[1], p[1]), scatter.blend(q[2], p[2])];
        let d2 = [scatter.blend(nd[0], d[0]), scatter.blend(nd[1], d[1]), scatter.blend(nd[2], d[2])];
        let mut shallow = 0;
        if masked {
            let safe = f32x8::from(geo.safe_distances8(v));
            shallow = (scatter & safe.cmp_lt(f32x8::splat(2.0))).move_mask();
            self.t_exit = scatter.blend(safe_radius8(geo, q, v, safe), t_exit).into();
        } else {
            let (te, ax) = grid_exit8(geo, p2, d2);
            self.t_exit = scatter.blend(te, t_exit).into();
            self.axis = cast::<f32x8, i32x8>(scatter).blend(ax, i32x8::from(self.axis)).into();
        }
        self.p = p2.map(<[f32; W]>::from);
        self.d = d2.map(<[f32; W]>::from);
        self.t = scatter.blend(f32x8::ZERO, t).into();
        let too_long = cast::<u32x8, f32x8>(
            u32x8::from(self.events).cmp_gt(u32x8::splat(MAX_EVENTS))
                | u32x8::from(self.steps).cmp_gt(u32x8::splat(MAX_STEPS as u32)),
        );
        Events {
            exits: (exit & !too_long).move_mask(),
            ended: ((dead | too_long) & live).move_mask(),
            shallow: shallow & !too_long.move_mask(),
            collided: accept.move_mask(),
            t: t.into(),
            j,
            u_fresnel: u_third.into(),
        }
    }

    /// The tentative collisions' updates of the flying lanes: real (`accept`) p_k *= sigma_t,k / sigma_t,h and
    /// a_k *= albedo_k, null p_k *= (maj - sigma_t,k) / (maj - sigma_t,h); then the densities scaled to a largest
    /// of 1 (the hero's factor is 1, so the largest is positive).
    #[inline(always)]
    fn update(
        &mut self,
        st: &[[f32; W]; 3],
        albedo: &[[f32; W]; 3],
        st_h: f32x8,
        maj: f32x8,
        flying: f32x8,
        accept: f32x8,
    ) {
        let mut pr = self.pr.map(f32x8::from);
        for c in 0..3 {
            let s = f32x8::from(st[c]);
            let factor = accept.blend(s / st_h, (maj - s) / (maj - st_h));
            pr[c] = flying.blend(pr[c] * factor, pr[c]);
            self.a[c] = accept.blend(f32x8::from(self.a[c]) * f32x8::from(albedo[c]), f32x8::from(self.a[c])).into();
        }
        let m = pr[0].max(pr[1]).max(pr[2]);
        let m = flying.blend(m, f32x8::ONE);
        self.pr = pr.map(|x| (x / m).into());
    }
}

/// Trace the hero paths of `texels` (those the tally wants; job = texel x spp + sample) and write their values
/// to `values`, laid out [texel][channel][sample] (3 spp per texel). `first_key`: the texel index of
/// `texels[0]` in the random-number keys. Mask-free grids and masked boxes (`packet::supported`). Returns the
/// number of collisions.
pub(crate) fn trace_hero_lanes<M: Medium, P: PathTally>(
    geo: &Geometry,
    med: &M,
    texels: &[Texel],
    first_key: u64,
    opts: &RenderOptions,
    values: &mut [f32],
    tally: &mut P,
) -> u64 {
    assert!(supported(geo));
    let spp = opts.spp as usize;
    let jobs = texels.len() * spp;
    assert_eq!(values.len(), 3 * jobs);
    let maj = (0..3).map(|c| med.majorant(c)).fold(0.0f32, f32::max);
    if maj <= 0.0 {
        // No medium anywhere: every path is a scalar walk (light through vacuum and interfaces).
        let mut events = 0;
        for job in 0..jobs {
            if tally.wanted(job) {
                events += trace_job(geo, med, texels, first_key, opts, job, values, tally);
            }
        }
        return events;
    }
    let mut ln = Lanes::new();
    let (mut next, mut events) = (0usize, 0u64);
    for l in 0..W {
        refill(geo, med, texels, first_key, opts, &mut ln, l, &mut next, &mut events, values, tally);
    }
    while ln.job.iter().any(|j| j.is_some()) {
        let (p0, d0) = (ln.p, ln.d);
        let ev = ln.step(geo, med, maj);
        if P::ACTIVE {
            let mut bits = ev.collided | ev.exits;
            while bits != 0 {
                let l = bits.trailing_zeros() as usize;
                bits &= bits - 1;
                let job = ln.job[l].expect("a live lane");
                let (p, d) = ([p0[0][l], p0[1][l], p0[2][l]], [d0[0][l], d0[1][l], d0[2][l]]);
                let collided = ev.collided >> l & 1 == 1;
                let len = if collided { ev.t[l] } else { ln.t_exit[l] };
                let mut jt = JobTally { inner: &mut *tally, job };
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
            let job = ln.job[l].expect("a live lane");
            let ended = if ev.ended >> l & 1 == 1 {
                Some([0.0; 3])
            } else if geo.masked() {
                // A shallow collision (the lane is at it), or the edge of the safe ball: the scalar walk from there.
                let d = [ln.d[0][l], ln.d[1][l], ln.d[2][l]];
                let mut p = [ln.p[0][l], ln.p[1][l], ln.p[2][l]];
                if ev.exits >> l & 1 == 1 {
                    p = add(p, scale(d, ln.t_exit[l]));
                    if geo.safe_distance(locate_box(geo, p)) >= 2 {
                        ln.start_flight(geo, l, p, d);
                        continue;
                    }
                }
                ln.walk(geo, med, l, job, (p, d, locate_box(geo, p)), true, tally)
            } else {
                at_face(geo, &mut ln, l, ev.u_fresnel[l])
            };
            if let Some(v) = ended {
                put(values, spp, job, v);
                events += ln.events[l] as u64;
                refill(geo, med, texels, first_key, opts, &mut ln, l, &mut next, &mut events, values, tally);
            }
        }
    }
    events
}

/// Whether `trace_hero_lanes` handles this geometry (mask-free volumes, and masked boxes).
pub(crate) fn supported(geo: &Geometry) -> bool {
    !geo.masked() || geo.boundary == Boundary::Box
}

/// Lane l's flight reached the grid's face: Fresnel reflection (a new flight; None) or out to the light (the
/// channel values).
fn at_face(geo: &Geometry, ln: &mut Lanes, l: usize, u: f32) -> Option<[f32; 3]> {
    let axis = ln.axis[l] as usize;
    let d = [ln.d[0][l], ln.d[1][l], ln.d[2][l]];
    let mut p = grid_face_point(geo, [ln.p[0][l], ln.p[1][l], ln.p[2][l]], d, ln.t_exit[l], axis);
    if geo.boundary == Boundary::PeriodicXY {
        for a in 0..2 {
            p[a] = wrap_coord(p[a], span(geo, a));
        }
    }
    let n_geo = facing_normal(axis, if component(d, axis) > 0.0 { 1 } else { -1 });
    let (nd, transmitted) = interface(d, n_geo, n_geo, geo.ior, u);
    if transmitted {
        let v = ln.values(l);
        return Some(std::array::from_fn(|c| v[c] * geo.light.radiance(nd, c)));
    }
    ln.start_flight(geo, l, p, nd);
    None
}

/// Give lane l the next wanted path that starts flying in the medium; paths that end before (a camera ray
/// that does not refract, or that reflects out of the grid) are written directly.
#[allow(clippy::too_many_arguments)]
fn refill<M: Medium, P: PathTally>(
    geo: &Geometry,
    med: &M,
    texels: &[Texel],
    first_key: u64,
    opts: &RenderOptions,
    ln: &mut Lanes,
    l: usize,
    next: &mut usize,
    events: &mut u64,
    values: &mut [f32],
    tally: &mut P,
) {
    let spp = opts.spp as usize;
    ln.job[l] = None;
    while *next < texels.len() * spp {
        let job = *next;
        *next += 1;
        if !tally.wanted(job) {
            continue;
        }
        let (ti, s) = (job / spp, (job % spp) as u32);
        let h = hero_of(opts.seed, first_key + ti as u64, s, opts.spp);
        let mut rng = LaneRng::new(path_key(opts.seed, first_key + ti as u64, s, h as u32));
        let start = camera_ray(geo, &texels[ti], opts.include_specular, &mut rng);
        (ln.k_lo[l], ln.k_hi[l], ln.draw[l]) = (rng.k_lo, rng.k_hi, CAMERA_DRAWS);
        (ln.events[l], ln.steps[l], ln.hero[l]) = (0, 0, h);
        let weight = match start {
            Start::Medium(.., w) => w,
            _ => 1.0,
        };
        for c in 0..3 {
            (ln.pr[c][l], ln.a[c][l]) = (1.0, weight);
        }
        let ended = match start {
            Start::Done(_) => Some([0.0; 3]),
            Start::Medium(p, d, v, _) if geo.masked() => ln.walk(geo, med, l, job, (p, d, v), true, tally),
            Start::Outside(p, d, v) if geo.masked() => ln.walk(geo, med, l, job, (p, d, v), false, tally),
            Start::Medium(p, d, _, _) => {
                ln.start_flight(geo, l, p, d);
                None
            }
            Start::Outside(_, d, v) if !geo.in_grid(v) => Some(std::array::from_fn(|c| geo.light.radiance(d, c))),
            Start::Outside(..) => {
                *events += trace_job(geo, med, texels, first_key, opts, job, values, tally);
                continue;
            }
        };
        match ended {
            Some(v) => {
                put(values, spp, job, v);
                *events += ln.events[l] as u64;
            }
            None => {
                ln.job[l] = Some(job);
                return;
            }
        }
    }
}
