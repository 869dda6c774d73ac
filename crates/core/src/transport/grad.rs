//! The gradient pass (path replay, or the biased `L_i = 1` radiative backpropagation variant) into the
//! fixed-point gradient buffers of `sums`. The same drivers as `render`: packets of eight paths for mask-free volumes and
//! masked boxes, the scalar `trace` for masked periodic slabs; gradients are integer sums, so they are
//! bit-identical for any thread count and work split.
use rayon::prelude::*;

use crate::transport::estimate::{estimates, Moments, RenderOptions, Stats, TexelEstimate};
use crate::transport::packet::{self, trace_paths, NoPathTally, PathTally};
use crate::transport::path::{NoTally, Tally};
use crate::transport::render::PACKET_CHUNK;
use crate::transport::rng::PathRng;
use crate::transport::scene::{Geometry, Medium, Texel};
pub(crate) use crate::transport::sums::{fixed, AddQueue};
pub use crate::transport::sums::{GradBuffers, NO_GRADIENT};
use crate::transport::trace::trace;

#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum GradMethod {
    /// Unbiased path replay backpropagation (Vicini et al. 2021) for the analog estimator.
    Replay,
    /// Radiative backpropagation with the incident and outgoing radiance along the adjoint path approximated by
    /// the environment radiance 1 (biased, one pass). Under this approximation the sigma_s derivative
    /// (-L + integral of phase * L_i) vanishes, so only sigma_a receives gradient: -adjoint x track length.
    Li1,
}

struct ReplayTally<'q, 'a, M: Medium> {
    q: &'q mut AddQueue<'a>,
    grads: &'a GradBuffers,
    c: usize,
    /// Weight in quanta.
    w: f32,
    med: &'a M,
}

impl<M: Medium> Tally for ReplayTally<'_, '_, M> {
    #[inline(always)]
    fn segment(&mut self, j: usize, len: f32) {
        // -l for sigma_a, and the same -l for sigma_s, which the difference sums leave out.
        if let Some(k) = self.grads.slot(j) {
            self.q.add((3 + self.c) * self.grads.n + k, -fixed(len, self.w));
        }
    }
    #[inline(always)]
    fn scatter(&mut self, j: usize) {
        let s = self.med.sigma_s(j, self.c);
        if let (Some(k), true) = (self.grads.slot(j), s > 0.0) {
            self.q.add(self.c * self.grads.n + k, fixed(1.0 / s, self.w));
        }
    }
}

struct Li1Tally<'q, 'a> {
    q: &'q mut AddQueue<'a>,
    grads: &'a GradBuffers,
    c: usize,
    w: f32,
}

impl Tally for Li1Tally<'_, '_> {
    #[inline(always)]
    fn segment(&mut self, j: usize, len: f32) {
        // -l for sigma_a, nothing for sigma_s: the difference sums get +l.
        if let Some(k) = self.grads.slot(j) {
            let (n, x) = (self.grads.n, fixed(len, self.w));
            self.q.add((3 + self.c) * n + k, -x);
            self.q.add(self.c * n + k, x);
        }
    }
    #[inline(always)]
    fn scatter(&mut self, _: usize) {}
}

/// Gradient pass: accumulate sum_i adjoint_i . d c_i / d (sigma_s, sigma_a) into `grads` for the given texels,
/// `adjoint[i]` = d e / d c_i (linear RGB), |adjoint| at most the bound given to `GradBuffers::zero`. Returns
/// this pass's own forward estimates and statistics.
pub fn backward<M: Medium>(
    geo: &Geometry,
    med: &M,
    texels: &[Texel],
    first_texel: u64,
    adjoint: &[[f32; 3]],
    opts: &RenderOptions,
    method: GradMethod,
    grads: &GradBuffers,
) -> (Vec<TexelEstimate>, Stats) {
    assert_eq!(texels.len(), adjoint.len());
    assert_eq!(grads.n_voxels, med.len());
    if packet::supported(geo) {
        return backward_packets(geo, med, texels, first_texel, adjoint, opts, method, grads);
    }
    let inv_spp = 1.0 / opts.spp as f32;
    let inv_q = (1.0 / grads.quantum) as f32;
    let results: Vec<(TexelEstimate, Stats)> = texels
        .par_iter()
        .enumerate()
        .map(|(i, tex)| {
            let mut q = AddQueue::new(&grads.buf);
            let mut m = Moments::new();
            let mut st = Stats { paths: 3 * opts.spp as u64, ..Stats::default() };
            let key = first_texel + i as u64;
            for c in 0..3 {
                for s in 0..opts.spp {
                    let adj = adjoint[i][c];
                    let mut rng = PathRng::new(opts.seed, key, s, c as u32);
                    let r = match method {
                        GradMethod::Replay => trace(geo, med, tex, c, &mut rng, opts.include_specular, &mut NoTally),
                        GradMethod::Li1 => {
                            let mut t = Li1Tally { q: &mut q, grads, c, w: adj * inv_spp * inv_q };
                            trace(geo, med, tex, c, &mut rng, opts.include_specular, &mut t)
                        }
                    };
                    m.add(c, r.value);
                    st.events += r.events as u64;
                    if method == GradMethod::Replay && r.value != 0.0 && adj != 0.0 {
                        let mut rng = PathRng::new(opts.seed, key, s, c as u32);
                        let mut t = ReplayTally { q: &mut q, grads, c, w: adj * r.value * inv_spp * inv_q, med };
                        trace(geo, med, tex, c, &mut rng, opts.include_specular, &mut t);
                        st.replayed_paths += 1;
                        st.replayed_events += r.events as u64;
                    }
                }
            }
            q.flush();
            (m.estimate(opts.spp), st)
        })
        .collect();
    let stats = results.iter().fold(Stats::default(), |a, r| Stats::merge(a, r.1));
    (results.into_iter().map(|r| r.0).collect(), stats)
}

/// Per-path weights (in quanta) of a packet gradient pass: path `job` of a chunk adds weight x (its tallies) to
/// the gradient buffer, as `ReplayTally` / `Li1Tally` do for one path. A replay skips paths of weight 0.
struct PacketTally<'a, M: Medium> {
    q: AddQueue<'a>,
    grads: &'a GradBuffers,
    med: &'a M,
    method: GradMethod,
    w: Vec<f32>,
}

impl<M: Medium> PathTally for PacketTally<'_, M> {
    const ACTIVE: bool = true;
    #[inline(always)]
    fn wanted(&self, job: usize) -> bool {
        self.method == GradMethod::Li1 || self.w[job] != 0.0
    }
    #[inline(always)]
    fn segment(&mut self, job: usize, c: usize, j: usize, len: f32) {
        let (q, grads, w) = (&mut self.q, self.grads, self.w[job]);
        match self.method {
            GradMethod::Replay => ReplayTally { q, grads, c, w, med: self.med }.segment(j, len),
            GradMethod::Li1 => Li1Tally { q, grads, c, w }.segment(j, len),
        }
    }
    #[inline(always)]
    fn scatter(&mut self, job: usize, c: usize, j: usize) {
        if self.method == GradMethod::Replay {
            ReplayTally { q: &mut self.q, grads: self.grads, c, w: self.w[job], med: self.med }.scatter(j);
        }
    }
}

/// `backward` with packets (`packet::supported` geometries). Path replay: a forward pass gives every path's
/// value, then the paths with a non-zero value and adjoint are traced again, exactly (each path is a pure
/// function of its key), with their tallies. `L_i = 1`: one pass with tallies.
fn backward_packets<M: Medium>(
    geo: &Geometry,
    med: &M,
    texels: &[Texel],
    first_texel: u64,
    adjoint: &[[f32; 3]],
    opts: &RenderOptions,
    method: GradMethod,
    grads: &GradBuffers,
) -> (Vec<TexelEstimate>, Stats) {
    let spp = opts.spp as usize;
    let scale = 1.0 / opts.spp as f32 * (1.0 / grads.quantum) as f32;
    let chunks: Vec<(Vec<TexelEstimate>, Stats)> = texels
        .par_chunks(PACKET_CHUNK)
        .enumerate()
        .map(|(k, chunk)| {
            let first = k * PACKET_CHUNK;
            let key = first_texel + first as u64;
            let jobs = chunk.len() * 3 * spp;
            let adj = |job: usize| adjoint[first + job / (3 * spp)][job % (3 * spp) / spp];
            let mut values = vec![0.0f32; jobs];
            let mut st = Stats { paths: jobs as u64, ..Stats::default() };
            let mut tally = PacketTally { q: AddQueue::new(&grads.buf), grads, med, method, w: vec![0.0; jobs] };
            match method {
                GradMethod::Li1 => {
                    tally.w = (0..jobs).map(|job| adj(job) * scale).collect();
                    st.events = trace_paths(geo, med, chunk, key, opts, &mut values, &mut tally);
                }
                GradMethod::Replay => {
                    st.events = trace_paths(geo, med, chunk, key, opts, &mut values, &mut NoPathTally);
                    tally.w = (0..jobs).map(|job| adj(job) * values[job] * scale).collect();
                    st.replayed_paths = tally.w.iter().filter(|&&w| w != 0.0).count() as u64;
                    let mut scratch = vec![0.0f32; jobs];
                    st.replayed_events = trace_paths(geo, med, chunk, key, opts, &mut scratch, &mut tally);
                }
            }
            tally.q.flush();
            (estimates(&values, spp), st)
        })
        .collect();
    let stats = chunks.iter().fold(Stats::default(), |a, r| Stats::merge(a, r.1));
    (chunks.into_iter().flat_map(|r| r.0).collect(), stats)
}
