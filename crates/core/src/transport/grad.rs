//! The gradient pass (path replay, or the biased `L_i = 1` radiative backpropagation variant) and its
//! fixed-point gradient buffers. The same drivers as `render`: packets of eight paths for mask-free volumes and
//! masked boxes, the scalar `trace` for masked periodic slabs; gradients are integer sums, so they are
//! bit-identical for any thread count and work split.
use std::sync::atomic::{AtomicI64, Ordering::Relaxed};

use rayon::prelude::*;

use crate::cache::prefetch_write;
use crate::spans::RowSpans;
use crate::transport::estimate::{estimates, Moments, RenderOptions, Stats, TexelEstimate};
use crate::transport::packet::{self, trace_paths, NoPathTally, PathTally};
use crate::transport::path::{NoTally, Tally};
use crate::transport::render::PACKET_CHUNK;
use crate::transport::rng::PathRng;
use crate::transport::scene::{Geometry, Medium, Texel};
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

/// Gradient accumulators: one buffer shared by all worker threads, holding d e / d sigma_s - d e / d sigma_a, then
/// d e / d sigma_a, planar by channel ([s-a R | s-a G | s-a B | a R | a G | a B], n voxels each): the path-space
/// derivatives are k/sigma_s - l (sigma_s) and -l (sigma_a), so a replayed segment adds to the sigma_a sums only and
/// a collision to the difference only, one atomic add each (`collect` forms the sigma_s sum; the `L_i = 1` pass,
/// whose sigma_s derivative is 0, adds a segment to both). In fixed point: every contribution is
/// rounded to a multiple of `quantum` and added to an `AtomicI64` (relaxed `fetch_add`: the sums are only read
/// after the pass). Integer sums do not depend on their order, so the gradient is bit-identical for any thread
/// count and work split (float sums are not). One shared buffer rather than one per thread: half the memory
/// with 2 threads (48 bytes per slot; its speed against per-thread buffers: docs/experiments.md, "Speed and
/// memory"). The quantum is set per pass from the largest adjoint, 2^-32 of it: far below f32 resolution for any
/// realistic voxel total, with +-2^31 adjoint-units of headroom per voxel.
///
/// An optional index map restricts gradients to some voxels (e.g. the free voxels of a shell): `map[j]` is the
/// slot of voxel j, or `NO_GRADIENT`; the buffers then hold only the mapped voxels. `with_voxels` gives the slots
/// of a list of voxels (slot = entry) without a map per grid voxel (`RowSpans`: a few MB for any object).
pub struct GradBuffers {
    /// Voxels in the grid.
    pub(crate) n_voxels: usize,
    /// Gradient slots (= n_voxels without a map).
    pub(crate) n: usize,
    map: SlotMap,
    pub(crate) quantum: f64,
    pub(crate) buf: Vec<AtomicI64>,
}

enum SlotMap {
    All,
    Dense(Vec<u32>),
    Ranks(RowSpans),
}

pub const NO_GRADIENT: u32 = u32::MAX;

impl GradBuffers {
    pub fn new(n_voxels: usize) -> Self {
        Self::with_map(n_voxels, None).unwrap()
    }

    /// Buffers for the voxels of `map` (slot per voxel or NO_GRADIENT; slots must be < the number of mapped
    /// voxels' maximum + 1).
    pub fn with_map(n_voxels: usize, map: Option<Vec<u32>>) -> Result<Self, String> {
        let (n, map) = match map {
            None => (n_voxels, SlotMap::All),
            Some(m) => {
                if m.len() != n_voxels {
                    return Err(format!("gradient index has {} entries, the grid {}", m.len(), n_voxels));
                }
                (m.iter().filter(|&&k| k != NO_GRADIENT).map(|&k| k as usize + 1).max().unwrap_or(0), SlotMap::Dense(m))
            }
        };
        Ok(Self::allocate(n_voxels, n, map))
    }

    /// Buffers for the voxels `index` (strictly increasing linear indices of an (nx, ny, nz) grid): voxel
    /// `index[e]` has slot e.
    pub fn with_voxels(n_xyz: [usize; 3], index: &[i64]) -> Result<Self, String> {
        let ranks = RowSpans::new(n_xyz, index)?;
        Ok(Self::allocate(ranks.grid(), index.len(), SlotMap::Ranks(ranks)))
    }

    fn allocate(n_voxels: usize, n: usize, map: SlotMap) -> Self {
        let buf = (0..6 * n).map(|_| AtomicI64::new(0)).collect();
        GradBuffers { n_voxels, n, map, quantum: 1.0, buf }
    }

    /// Whether the buffers cover only the voxels of an index map or list.
    pub fn is_mapped(&self) -> bool {
        !matches!(self.map, SlotMap::All)
    }

    /// The index map (slot per voxel or NO_GRADIENT), if the buffers were made with one: a caller whose next pass
    /// has the same map reuses these buffers (`zero`) instead of allocating new ones.
    pub fn map(&self) -> Option<&[u32]> {
        match &self.map {
            SlotMap::Dense(m) => Some(m),
            _ => None,
        }
    }

    /// Whether the buffers were made `with_voxels(.., index)` for exactly these voxels. O(len).
    pub fn lists(&self, index: &[i64]) -> bool {
        matches!(&self.map, SlotMap::Ranks(r) if r.lists(index))
    }

    /// Number of gradient slots.
    pub fn slots(&self) -> usize {
        self.n
    }

    #[inline(always)]
    pub(crate) fn slot(&self, j: usize) -> Option<usize> {
        match &self.map {
            SlotMap::All => Some(j),
            SlotMap::Dense(m) => {
                let k = m[j];
                if k == NO_GRADIENT {
                    None
                } else {
                    Some(k as usize)
                }
            }
            SlotMap::Ranks(r) => r.rank(j),
        }
    }

    /// Clear the buffer, in place and in parallel, for a pass whose adjoints are at most `max_abs_adjoint` in
    /// magnitude.
    pub fn zero(&mut self, max_abs_adjoint: f32) {
        let m = if max_abs_adjoint > 0.0 && max_abs_adjoint.is_finite() { max_abs_adjoint as f64 } else { 1.0 };
        self.quantum = m / 4_294_967_296.0;
        self.buf.par_chunks_mut(1 << 16).for_each(|c| c.iter_mut().for_each(|x| *x.get_mut() = 0));
    }

    /// The gradient as interleaved (slot, channel) arrays: (d e / d sigma_s, d e / d sigma_a).
    pub fn collect(&self, grad_s: &mut [f32], grad_a: &mut [f32]) {
        let q = self.quantum;
        self.each_sum(|k, s, a| {
            grad_s[k] = (s as f64 * q) as f32;
            grad_a[k] = (a as f64 * q) as f32;
        });
    }

    /// As `collect`, but the raw fixed-point sums (multiples of `quantum()`): sums of passes over disjoint texels
    /// with the same quantum add up (wrapping i64) to the sum of one pass over all of them, so shards combine
    /// bit-identically when converted as `collect` does: `(sum as f64 * quantum) as f32`.
    pub fn collect_fixed(&self, grad_s: &mut [i64], grad_a: &mut [i64]) {
        self.each_sum(|k, s, a| {
            grad_s[k] = s;
            grad_a[k] = a;
        });
    }

    /// The fixed-point unit of the current pass (set by `zero`).
    pub fn quantum(&self) -> f64 {
        self.quantum
    }

    /// Hand each (interleaved index 3 slot + channel, sigma_s sum, sigma_a sum) of the buffer to `out`. The sums are
    /// integers (wrapping, as the atomic adds), so sigma_s = difference + sigma_a is exactly the sum of every
    /// sigma_s contribution.
    fn each_sum(&self, mut out: impl FnMut(usize, i64, i64)) {
        let n = self.n;
        let b = &self.buf;
        for c in 0..3 {
            for j in 0..n {
                let a = b[(3 + c) * n + j].load(Relaxed);
                out(3 * j + c, b[c * n + j].load(Relaxed).wrapping_add(a), a);
            }
        }
    }
}

#[inline(always)]
pub(crate) fn fixed(x: f32, inv_quantum: f32) -> i64 {
    (x * inv_quantum).round() as i64
}

/// How many adds `AddQueue` keeps in flight.
const ADD_QUEUE: usize = 16;

/// Adds into the shared gradient buffer, each carried out `ADD_QUEUE` adds after it is queued, its cache line
/// fetched meanwhile. A replay adds once per voxel segment, at scattered places of a buffer of hundreds of MB,
/// and a locked add waits for its line before anything after it may load: one add after the other, each add
/// was a cache miss in series. Queued, the misses overlap. The sums are integers, so the order of the adds
/// changes no bit of them. `flush` before the buffer is read.
pub(crate) struct AddQueue<'a> {
    buf: &'a [AtomicI64],
    at: [usize; ADD_QUEUE],
    value: [i64; ADD_QUEUE],
    /// Queued adds, and the ring position of the next one (the oldest once the ring is full).
    len: usize,
    next: usize,
}

impl<'a> AddQueue<'a> {
    pub(crate) fn new(buf: &'a [AtomicI64]) -> Self {
        AddQueue { buf, at: [0; ADD_QUEUE], value: [0; ADD_QUEUE], len: 0, next: 0 }
    }

    #[inline(always)]
    pub(crate) fn add(&mut self, at: usize, value: i64) {
        prefetch_write(&self.buf[at]);
        let k = self.next;
        if self.len == ADD_QUEUE {
            self.buf[self.at[k]].fetch_add(self.value[k], Relaxed);
        } else {
            self.len += 1;
        }
        (self.at[k], self.value[k]) = (at, value);
        self.next = (k + 1) % ADD_QUEUE;
    }

    pub(crate) fn flush(&mut self) {
        for k in 0..self.len {
            self.buf[self.at[k]].fetch_add(self.value[k], Relaxed);
        }
        (self.len, self.next) = (0, 0);
    }
}

impl Drop for AddQueue<'_> {
    fn drop(&mut self) {
        debug_assert!(self.len == 0 || std::thread::panicking(), "gradient adds queued but never flushed");
    }
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

#[cfg(test)]
mod tests {
    use super::*;

    /// Queued adds leave every slot with the sum of what was added to it, whether fewer or more adds than the
    /// queue holds were made, over and over the same slots or not, and the queue is empty after `flush`.
    #[test]
    fn queued_adds_sum_as_direct_adds() {
        for n_adds in [0, 1, ADD_QUEUE - 1, ADD_QUEUE, ADD_QUEUE + 1, 10 * ADD_QUEUE + 3] {
            let buf: Vec<AtomicI64> = (0..37).map(|_| AtomicI64::new(0)).collect();
            let mut want = [0i64; 37];
            let mut q = AddQueue::new(&buf);
            let mut x = 12345u64;
            for _ in 0..n_adds {
                x = x.wrapping_mul(6364136223846793005).wrapping_add(1442695040888963407);
                let (at, v) = ((x >> 33) as usize % 37, (x >> 20) as i64 % 1000 - 500);
                want[at] += v;
                q.add(at, v);
            }
            q.flush();
            assert_eq!(q.len, 0);
            let got: Vec<i64> = buf.iter().map(|a| a.load(Relaxed)).collect();
            assert_eq!(got, want, "{n_adds} adds");
        }
    }
}
