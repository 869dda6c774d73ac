//! Hero-channel transport: one path serves all three channels of the medium (a spectral table's band group).
//!
//! Each sample of a texel has a hero channel h (`hero_of`: stratified, 0, 1, 2 in each full triple of samples,
//! uniformly random for the samples after the last triple, so every sample's hero is each channel with
//! probability 1/3): its distances are sampled with channel h's extinction (regular tracking, `flight::Regular`),
//! its directions and interface events as every channel's (they do not depend on the channel). Each channel j's
//! value is the one-sample balance heuristic over the three channels' samplers, f_j(x) / ((1/3) sum_k p_k(x)),
//! unbiased per sample and per triple of samples. Along a path, with implicit absorption,
//! f_j = p_j x prod albedo_j(x_i) and p_k = prod sigma_t,k(x_i) exp(-tau_k) (common factors dropped), so a path
//! carries, per channel, its albedos' product a_j and its density relative to the others, p_k, updated by
//! sigma_t,k / sigma_t,h at a collision and exp(-(tau_k - tau_h)) over a flight (the optical depths from the
//! segments the tracker reports); channel j's value is 3 a_j p_j / sum_k p_k, at most 3 a_j: the
//! weight cannot explode where the channels' extinctions differ. Russian roulette plays on the largest channel
//! value and scales every channel by the same factor, so each stays unbiased.
//!
//! The lanes (`hero_lanes`) run this walk near surfaces (`walk_hero` with `stop_deep`) and for paths that start
//! inside the grid (`trace_job`).
//!
//! Gradients by path replay: E[d f_j / mix] = d integral f_j, and d log f_j is k_v / sigma_s,j - l_v (sigma_s of
//! voxel v) and -l_v (sigma_a), channel j's own coefficients only; a replayed path adds to the three channels'
//! slots with weights adjoint_j x value_j. Random numbers are keyed by (seed, texel, sample, hero), values
//! summed per texel in sample order, gradients in fixed point: bit-identical for any thread count.

use crate::transport::estimate::RenderOptions;
use crate::transport::flight::{Event, Regular, Tracker};
use crate::transport::grid::facing_normal;
use crate::transport::packet::PathTally;
use crate::transport::path::{Tally, Walk, MAX_EVENTS, RR_THRESHOLD};
use crate::transport::rng::{PathRng, Uniforms};
use crate::transport::sampling::hg_sample;
use crate::transport::scene::{Geometry, Medium, Texel};
use crate::transport::trace::{camera_ray, interface, outside, Outside, Start};

/// The hero channel of sample `sample` of `spp` for `texel`: `sample` mod 3 in the full triples of samples,
/// after them a uniform choice keyed by (seed, texel, sample) (a stream no path uses: channel key 3).
#[inline(always)]
pub fn hero_of(seed: u64, texel: u64, sample: u32, spp: u32) -> usize {
    if sample < spp - spp % 3 {
        return (sample % 3) as usize;
    }
    (PathRng::new(seed, texel, sample, 3).next_u64() % 3) as usize
}

/// One hero path's values (radiance reaching the texel per channel) and its number of collisions.
#[derive(Clone, Copy, Debug, Default)]
pub struct HeroValue {
    pub value: [f32; 3],
    pub events: u32,
}

/// What a hero path carries per channel k: `p[k]`, the path's density under channel k's sampler up to a factor
/// common to the channels, and `a[k]`, the product of its albedos and the roulette's factors.
#[derive(Clone, Copy)]
pub(crate) struct Carried {
    pub p: [f32; 3],
    pub a: [f32; 3],
}

impl Carried {
    /// Channel values so far: a_j p_j / ((1/3) sum_k p_k).
    #[inline(always)]
    pub(crate) fn values(&self) -> [f32; 3] {
        let q = (self.p[0] + self.p[1] + self.p[2]) * (1.0 / 3.0);
        std::array::from_fn(|j| if self.a[j] == 0.0 || self.p[j] == 0.0 { 0.0 } else { self.a[j] * self.p[j] / q })
    }

    /// A flight's transmittances relative to the hero's: p_k *= exp(-dtau_k); dtau is reset.
    #[inline(always)]
    fn fly(&mut self, dtau: &mut [f32; 3]) {
        for k in 0..3 {
            self.p[k] *= (-dtau[k]).exp();
            dtau[k] = 0.0;
        }
        self.normalise();
    }

    /// A collision in voxel j: p_k *= sigma_t,k / sigma_t,h, a_k *= albedo_k.
    #[inline(always)]
    fn collide<M: Medium>(&mut self, med: &M, j: usize, h: usize) {
        let st_h = med.coeffs(j, h).0;
        for k in 0..3 {
            let (st, albedo) = med.coeffs(j, k);
            self.p[k] *= st / st_h;
            self.a[k] *= albedo;
        }
        self.normalise();
    }

    /// Scale the densities so their largest is 1 (the values do not change; no under- or overflow).
    #[inline(always)]
    fn normalise(&mut self) {
        let m = self.p[0].max(self.p[1]).max(self.p[2]);
        if m > 0.0 && m.is_finite() {
            self.p = self.p.map(|x| x / m);
        }
    }

    /// Russian roulette on the largest channel value: below `RR_THRESHOLD` the path survives with probability
    /// value / threshold (one uniform) and every channel's weight is divided by it. False: the path ends.
    #[inline(always)]
    fn survive<U: Uniforms>(&mut self, rng: &mut U) -> bool {
        let v = self.values();
        let top = v[0].max(v[1]).max(v[2]);
        if top >= RR_THRESHOLD {
            return true;
        }
        if rng.next_f32() * RR_THRESHOLD < top {
            let f = RR_THRESHOLD / top;
            self.a = self.a.map(|x| x * f);
            true
        } else {
            false
        }
    }
}

/// Sums the channels' optical depths minus the hero's over the segments the tracker reports, and passes the
/// segments and collisions on to `inner` (a gradient replay's tally).
struct HeroTally<'t, 'm, M: Medium, T: Tally> {
    med: &'m M,
    h: usize,
    dtau: [f32; 3],
    inner: &'t mut T,
}

impl<M: Medium, T: Tally> Tally for HeroTally<'_, '_, M, T> {
    #[inline(always)]
    fn segment(&mut self, j: usize, len: f32) {
        let th = self.med.coeffs(j, self.h).0;
        for k in 0..3 {
            if k != self.h {
                self.dtau[k] += (self.med.coeffs(j, k).0 - th) * len;
            }
        }
        self.inner.segment(j, len);
    }
    #[inline(always)]
    fn scatter(&mut self, j: usize) {
        self.inner.scatter(j);
    }
}

/// How a walk inside the object ended.
enum Inside {
    /// It left the object (the walk is outside).
    Left,
    /// The path ends with value 0 (roulette, or cut).
    Ended,
    /// It scattered in a voxel at least 2 voxels from the surface (only when asked: `stop_deep`).
    Deep,
}

/// How a hero walk ended.
pub(crate) enum HeroEnd {
    /// The path ended with these values.
    Done(HeroValue),
    /// It scattered (state updated) in a voxel at least 2 voxels from the object's surface, where the lanes'
    /// delta tracking takes over (only when `stop_deep`).
    Deep,
}

/// Trace one hero path of hero channel `h` for `texel`. `tally` receives its segments and collisions (a
/// replay's).
pub fn trace_hero<M: Medium, T: Tally>(
    geo: &Geometry,
    med: &M,
    texel: &Texel,
    h: usize,
    rng: &mut PathRng,
    include_specular: bool,
    tally: &mut T,
) -> HeroValue {
    let (mut s, weight) = match camera_ray(geo, texel, include_specular, rng) {
        Start::Medium(p, d, v, weight) => (Walk { p, d, v, weight, in_medium: true, events: 0, steps: 0 }, weight),
        Start::Outside(p, d, v) => (Walk { p, d, v, weight: 1.0, in_medium: false, events: 0, steps: 0 }, 1.0),
        Start::Done(_) => return HeroValue::default(),
    };
    let mut car = Carried { p: [1.0; 3], a: [weight; 3] };
    match walk_hero(geo, med, h, &mut s, &mut car, rng, tally, false) {
        HeroEnd::Done(r) => r,
        HeroEnd::Deep => unreachable!("the walk stops at deep voxels only when asked"),
    }
}

/// The walk of hero path (state `s`, carried `car`, hero channel `h`) until it ends, or with `stop_deep` until
/// it scatters in a voxel at least 2 voxels from the surface (`HeroEnd::Deep`; `s` and `car` updated).
#[allow(clippy::too_many_arguments)]
#[inline(always)]
pub(crate) fn walk_hero<M: Medium, T: Tally, U: Uniforms>(
    geo: &Geometry,
    med: &M,
    h: usize,
    s: &mut Walk,
    car: &mut Carried,
    rng: &mut U,
    tally: &mut T,
    stop_deep: bool,
) -> HeroEnd {
    let mut ht = HeroTally { med, h, dtau: [0.0; 3], inner: tally };
    let mut tracker = Regular::new();
    let cut = |events| HeroEnd::Done(HeroValue { value: [0.0; 3], events });
    loop {
        if s.in_medium {
            match through_medium(geo, med, s, car, &mut tracker, rng, &mut ht, stop_deep) {
                Inside::Left => {}
                Inside::Ended => return cut(s.events),
                Inside::Deep => return HeroEnd::Deep,
            }
            continue;
        }
        match outside(geo, s, rng) {
            Outside::Entered => {}
            Outside::Cut => return cut(s.events),
            Outside::Escaped => {
                let v = car.values();
                let value = std::array::from_fn(|c| v[c] * geo.light.radiance(s.d, c));
                return HeroEnd::Done(HeroValue { value, events: s.events });
            }
        }
    }
}

/// The walk inside the object from state `s` until it leaves, ends, or (`stop_deep`) scatters deep inside.
#[allow(clippy::too_many_arguments)]
#[inline(always)]
fn through_medium<M: Medium, T: Tally, U: Uniforms>(
    geo: &Geometry,
    med: &M,
    s: &mut Walk,
    car: &mut Carried,
    tracker: &mut Regular,
    rng: &mut U,
    ht: &mut HeroTally<'_, '_, M, T>,
    stop_deep: bool,
) -> Inside {
    let h = ht.h;
    tracker.start(geo, s, rng);
    loop {
        match tracker.next(geo, med, h, s, rng, ht) {
            Event::Cut => return Inside::Ended,
            Event::Collision(j, _) => {
                car.fly(&mut ht.dtau);
                s.events += 1;
                car.collide(med, j, h);
                if !car.survive(rng) || s.events > MAX_EVENTS {
                    return Inside::Ended;
                }
                ht.inner.scatter(j);
                let (u1, u2) = rng.next_f32_pair();
                s.d = hg_sample(s.d, geo.g, u1, u2);
                if stop_deep && geo.safe_distance(s.v) >= 2 {
                    return Inside::Deep;
                }
                tracker.start(geo, s, rng);
            }
            Event::Surface { axis, step, nb, n_sh } => {
                car.fly(&mut ht.dtau);
                let (nd, transmitted) = interface(s.d, facing_normal(axis, step), n_sh, geo.ior, rng.next_f32());
                s.d = nd;
                if transmitted {
                    s.v = nb;
                    s.in_medium = false;
                    return Inside::Left;
                }
                tracker.redirect(geo, s);
            }
        }
    }
}

/// One hero path's view of a `PathTally` (segments and collisions of job `job`; the channel is unused).
pub(crate) struct JobTally<'a, P: PathTally> {
    pub inner: &'a mut P,
    pub job: usize,
}

impl<P: PathTally> Tally for JobTally<'_, P> {
    const ACTIVE: bool = P::ACTIVE;
    #[inline(always)]
    fn segment(&mut self, j: usize, len: f32) {
        self.inner.segment(self.job, 0, j, len);
    }
    #[inline(always)]
    fn scatter(&mut self, j: usize) {
        self.inner.scatter(self.job, 0, j);
    }
}

/// Write job `job`'s channel values into the [texel][channel][sample] layout.
#[inline(always)]
pub(crate) fn put(values: &mut [f32], spp: usize, job: usize, v: [f32; 3]) {
    let (ti, s) = (job / spp, job % spp);
    for c in 0..3 {
        values[(3 * ti + c) * spp + s] = v[c];
    }
}

/// Job `job` (texel x spp + sample) of a `PathTally` pass by the scalar hero walk (`trace_hero`, keyed as the
/// scalar renderer keys it), its values written into `values` ([texel][channel][sample]); its collisions.
#[allow(clippy::too_many_arguments)]
pub(crate) fn trace_job<M: Medium, P: PathTally>(
    geo: &Geometry,
    med: &M,
    texels: &[Texel],
    first_key: u64,
    opts: &RenderOptions,
    job: usize,
    values: &mut [f32],
    tally: &mut P,
) -> u64 {
    let spp = opts.spp as usize;
    let (ti, s) = (job / spp, (job % spp) as u32);
    let key = first_key + ti as u64;
    let h = hero_of(opts.seed, key, s, opts.spp);
    let mut rng = PathRng::new(opts.seed, key, s, h as u32);
    let mut jt = JobTally { inner: tally, job };
    let r = trace_hero(geo, med, &texels[ti], h, &mut rng, opts.include_specular, &mut jt);
    put(values, spp, job, r.value);
    r.events as u64
}
