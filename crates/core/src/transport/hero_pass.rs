//! Drivers of the hero-path render and gradient pass (`hero`: the scalar walk and the estimator; `hero_lanes`:
//! eight paths at a time). Mask-free grids and masked boxes run the lanes, `PACKET_CHUNK` texels per work item;
//! masked periodic slabs the scalar walk, one texel per work item. Each texel's path values are summed in sample order and gradients in
//! fixed point (`grad::GradBuffers`), so results are bit-identical for any thread count and work split.

use rayon::prelude::*;

use crate::transport::estimate::{estimates, Moments, RenderOptions, Stats, TexelEstimate};
use crate::transport::grad::{fixed, AddQueue, GradBuffers};
use crate::transport::hero::{hero_of, trace_hero, HeroValue};
use crate::transport::hero_lanes::{supported, trace_hero_lanes};
use crate::transport::packet::{NoPathTally, PathTally};
use crate::transport::path::{NoTally, Tally};
use crate::transport::render::PACKET_CHUNK;
use crate::transport::rng::PathRng;
use crate::transport::scene::{Geometry, Medium, Texel};

/// Forward render with hero paths: `opts.spp` paths per texel, each serving the three channels (the per-channel
/// estimates of `render`, from spp paths per texel instead of 3 spp).
pub fn render_hero<M: Medium>(
    geo: &Geometry,
    med: &M,
    texels: &[Texel],
    first_texel: u64,
    opts: &RenderOptions,
) -> (Vec<TexelEstimate>, Stats) {
    if supported(geo) {
        return lanes_pass(geo, med, texels, first_texel, opts, None);
    }
    let results: Vec<(TexelEstimate, Stats)> = texels
        .par_iter()
        .enumerate()
        .map(|(i, tex)| {
            let mut m = Moments::new();
            let mut st = Stats { paths: opts.spp as u64, ..Stats::default() };
            let key = first_texel + i as u64;
            for s in 0..opts.spp {
                scalar_sample(geo, med, tex, key, s, opts, &mut m, &mut st);
            }
            (m.estimate(opts.spp), st)
        })
        .collect();
    let stats = results.iter().fold(Stats::default(), |a, r| Stats::merge(a, r.1));
    (results.into_iter().map(|r| r.0).collect(), stats)
}

/// One sample `s` of texel `key` by the scalar hero walk, added to the texel's moments and stats: (its hero, its
/// value); a replay restarts the same random numbers from (seed, key, s, hero).
#[allow(clippy::too_many_arguments)]
#[inline(always)]
fn scalar_sample<M: Medium>(
    geo: &Geometry,
    med: &M,
    tex: &Texel,
    key: u64,
    s: u32,
    opts: &RenderOptions,
    m: &mut Moments,
    st: &mut Stats,
) -> (usize, HeroValue) {
    let h = hero_of(opts.seed, key, s, opts.spp);
    let mut rng = PathRng::new(opts.seed, key, s, h as u32);
    let r = trace_hero(geo, med, tex, h, &mut rng, opts.include_specular, &mut NoTally);
    (0..3).for_each(|c| m.add(c, r.value[c]));
    st.events += r.events as u64;
    (h, r)
}

/// A replayed hero path's gradient adds: weight `w[c]` (in quanta) for channel c, as `grad`'s replay tally
/// (sigma_a sums get -l per segment, the sigma_s - sigma_a differences 1 / sigma_s per collision).
struct HeroReplay<'q, 'a, M: Medium> {
    q: &'q mut AddQueue<'a>,
    grads: &'a GradBuffers,
    w: [f32; 3],
    med: &'a M,
}

impl<M: Medium> Tally for HeroReplay<'_, '_, M> {
    #[inline(always)]
    fn segment(&mut self, j: usize, len: f32) {
        if let Some(k) = self.grads.slot(j) {
            for c in 0..3 {
                if self.w[c] != 0.0 {
                    self.q.add((3 + c) * self.grads.n + k, -fixed(len, self.w[c]));
                }
            }
        }
    }
    #[inline(always)]
    fn scatter(&mut self, j: usize) {
        if let Some(k) = self.grads.slot(j) {
            for c in 0..3 {
                let s = self.med.sigma_s(j, c);
                if self.w[c] != 0.0 && s > 0.0 {
                    self.q.add(c * self.grads.n + k, fixed(1.0 / s, self.w[c]));
                }
            }
        }
    }
}

/// The lanes' replay tally: job `job` (texel x spp + sample) adds with its three weights `w[job]`.
struct LanesReplay<'a, M: Medium> {
    q: AddQueue<'a>,
    grads: &'a GradBuffers,
    med: &'a M,
    w: Vec<[f32; 3]>,
}

impl<M: Medium> PathTally for LanesReplay<'_, M> {
    const ACTIVE: bool = true;
    #[inline(always)]
    fn wanted(&self, job: usize) -> bool {
        self.w[job] != [0.0; 3]
    }
    #[inline(always)]
    fn segment(&mut self, job: usize, _: usize, j: usize, len: f32) {
        HeroReplay { q: &mut self.q, grads: self.grads, w: self.w[job], med: self.med }.segment(j, len);
    }
    #[inline(always)]
    fn scatter(&mut self, job: usize, _: usize, j: usize) {
        HeroReplay { q: &mut self.q, grads: self.grads, w: self.w[job], med: self.med }.scatter(j);
    }
}

/// A pass of the lanes over chunks of texels: forward only, or with `grad` (adjoints, buffers) a forward pass
/// then the replay of every path whose value and adjoint give it a non-zero weight.
fn lanes_pass<M: Medium>(
    geo: &Geometry,
    med: &M,
    texels: &[Texel],
    first_texel: u64,
    opts: &RenderOptions,
    grad: Option<(&[[f32; 3]], &GradBuffers)>,
) -> (Vec<TexelEstimate>, Stats) {
    let spp = opts.spp as usize;
    let chunks: Vec<(Vec<TexelEstimate>, Stats)> = texels
        .par_chunks(PACKET_CHUNK)
        .enumerate()
        .map(|(k, chunk)| {
            let first = k * PACKET_CHUNK;
            let key = first_texel + first as u64;
            let mut values = vec![0.0f32; chunk.len() * 3 * spp];
            let mut st = Stats { paths: (chunk.len() * spp) as u64, ..Stats::default() };
            st.events = trace_hero_lanes(geo, med, chunk, key, opts, &mut values, &mut NoPathTally);
            if let Some((adjoint, grads)) = grad {
                let scale = 1.0 / opts.spp as f32 * (1.0 / grads.quantum) as f32;
                let w: Vec<[f32; 3]> = (0..chunk.len() * spp)
                    .map(|job| {
                        let (ti, s) = (job / spp, job % spp);
                        std::array::from_fn(|c| adjoint[first + ti][c] * values[(3 * ti + c) * spp + s] * scale)
                    })
                    .collect();
                st.replayed_paths = w.iter().filter(|x| **x != [0.0; 3]).count() as u64;
                let mut tally = LanesReplay { q: AddQueue::new(&grads.buf), grads, med, w };
                let mut scratch = vec![0.0f32; values.len()];
                st.replayed_events = trace_hero_lanes(geo, med, chunk, key, opts, &mut scratch, &mut tally);
                tally.q.flush();
            }
            (estimates(&values, spp), st)
        })
        .collect();
    let stats = chunks.iter().fold(Stats::default(), |a, r| Stats::merge(a, r.1));
    (chunks.into_iter().flat_map(|r| r.0).collect(), stats)
}

/// Gradient pass with hero paths (path replay): as `grad::backward` with `GradMethod::Replay`, each path's
/// value per channel times that channel's adjoint weighting its replay. `adjoint[i]` = d e / d c_i (linear
/// RGB), at most the bound given to `GradBuffers::zero`. Returns the pass's own estimates and statistics.
pub fn backward_hero<M: Medium>(
    geo: &Geometry,
    med: &M,
    texels: &[Texel],
    first_texel: u64,
    adjoint: &[[f32; 3]],
    opts: &RenderOptions,
    grads: &GradBuffers,
) -> (Vec<TexelEstimate>, Stats) {
    assert_eq!(texels.len(), adjoint.len());
    assert_eq!(grads.n_voxels, med.len());
    if supported(geo) {
        return lanes_pass(geo, med, texels, first_texel, opts, Some((adjoint, grads)));
    }
    let scale = 1.0 / opts.spp as f32 * (1.0 / grads.quantum) as f32;
    let results: Vec<(TexelEstimate, Stats)> = texels
        .par_iter()
        .enumerate()
        .map(|(i, tex)| {
            let mut q = AddQueue::new(&grads.buf);
            let mut m = Moments::new();
            let mut st = Stats { paths: opts.spp as u64, ..Stats::default() };
            let key = first_texel + i as u64;
            for s in 0..opts.spp {
                let (h, r) = scalar_sample(geo, med, tex, key, s, opts, &mut m, &mut st);
                let w: [f32; 3] = std::array::from_fn(|c| adjoint[i][c] * r.value[c] * scale);
                if w != [0.0; 3] {
                    let mut rng = PathRng::new(opts.seed, key, s, h as u32);
                    let mut t = HeroReplay { q: &mut q, grads, w, med };
                    trace_hero(geo, med, tex, h, &mut rng, opts.include_specular, &mut t);
                    st.replayed_paths += 1;
                    st.replayed_events += r.events as u64;
                }
            }
            q.flush();
            (m.estimate(opts.spp), st)
        })
        .collect();
    let stats = results.iter().fold(Stats::default(), |a, r| Stats::merge(a, r.1));
    (results.into_iter().map(|r| r.0).collect(), stats)
}
