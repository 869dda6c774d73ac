//! The gradient's fixed-point sums: the buffers the gradient passes (`grad`, `hero_pass`) add into, the queue
//! that carries out their adds, and the sums' conversion to float gradients (block by block, each block's memory
//! given back as it is converted, when the buffers are consumed).
use std::sync::atomic::{AtomicI64, Ordering::Relaxed};

use rayon::prelude::*;

use crate::cache::prefetch_write;
use crate::pages::release;
use crate::spans::RowSpans;

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
            SlotMap::Dense(m) => (m[j] != NO_GRADIENT).then_some(m[j] as usize),
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
        self.each_sum(0..self.n, &mut |k, s, a| (grad_s[k], grad_a[k]) = (to_float(s, q), to_float(a, q)));
    }

    /// As `collect`, but the raw fixed-point sums (multiples of `quantum()`): sums of passes over disjoint texels
    /// with the same quantum add up (wrapping i64) to the sum of one pass over all of them, so shards combine
    /// bit-identically when converted as `collect` does: `(sum as f64 * quantum) as f32`.
    pub fn collect_fixed(&self, grad_s: &mut [i64], grad_a: &mut [i64]) {
        self.each_sum(0..self.n, &mut |k, s, a| (grad_s[k], grad_a[k]) = (s, a));
    }

    /// `collect`, consuming the buffers: `RELEASE_BLOCK` slots at a time are converted and their sums' pages given
    /// back (`pages::release`), so the sums (48 B per slot) and the gradients (24 B, in arrays whose pages are
    /// taken as they are first written, as a fresh `vec![0.0; _]`'s are) are not resident at once: the peak is
    /// the sums' own. Each value is converted as `collect` converts it, so the bits are the same.
    pub fn into_collected(self, grad_s: &mut [f32], grad_a: &mut [f32]) {
        let q = self.quantum;
        self.drain(&mut |k, s, a| (grad_s[k], grad_a[k]) = (to_float(s, q), to_float(a, q)));
    }

    /// `collect_fixed`, consuming the buffers a block at a time as `into_collected` does.
    pub fn into_collected_fixed(self, grad_s: &mut [i64], grad_a: &mut [i64]) {
        self.drain(&mut |k, s, a| (grad_s[k], grad_a[k]) = (s, a));
    }

    /// The fixed-point unit of the current pass (set by `zero`).
    pub fn quantum(&self) -> f64 {
        self.quantum
    }

    /// Hand each (interleaved index 3 slot + channel, sigma_s sum, sigma_a sum) of the slots `slots` to `out`. The
    /// sums are integers (wrapping, as the atomic adds), so sigma_s = difference + sigma_a is exactly the sum of
    /// every sigma_s contribution.
    fn each_sum(&self, slots: std::ops::Range<usize>, out: &mut impl FnMut(usize, i64, i64)) {
        let (n, b) = (self.n, &self.buf);
        for c in 0..3 {
            for j in slots.clone() {
                let a = b[(3 + c) * n + j].load(Relaxed);
                out(3 * j + c, b[c * n + j].load(Relaxed).wrapping_add(a), a);
            }
        }
    }

    /// `each_sum` over all slots, `RELEASE_BLOCK` at a time, each block's pages in the six planes given back once
    /// handed out (with the previous block's, so the page a block boundary cuts is given back too).
    fn drain(mut self, out: &mut impl FnMut(usize, i64, i64)) {
        let n = self.n;
        for start in (0..n).step_by(RELEASE_BLOCK) {
            let end = (start + RELEASE_BLOCK).min(n);
            self.each_sum(start..end, out);
            for p in 0..6 {
                release(&mut self.buf[p * n + start.saturating_sub(RELEASE_BLOCK)..p * n + end]);
            }
        }
    }
}

/// Slots converted between two page releases of `GradBuffers::drain` (512 KiB of each plane: whole pages of any
/// page size up to that, and 6 system calls per 3 MiB of sums).
const RELEASE_BLOCK: usize = 1 << 16;

/// A fixed-point sum as a float gradient: float32(float64(sum) * quantum).
#[inline(always)]
fn to_float(sum: i64, quantum: f64) -> f32 {
    (sum as f64 * quantum) as f32
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

#[cfg(test)]
mod tests {
    use super::*;

    /// Consuming the buffers a block at a time gives the same gradients and sums as `collect` and `collect_fixed`,
    /// bit for bit, for slot counts below one block, at a block's edge and over several blocks with a partial last.
    #[test]
    fn into_collected_equals_collect() {
        for n in [1, 1000, RELEASE_BLOCK, 2 * RELEASE_BLOCK + 12345] {
            let mut g = GradBuffers::new(n);
            g.zero(0.37);
            let mut x = 987654321u64;
            for v in g.buf.iter_mut() {
                x = x.wrapping_mul(6364136223846793005).wrapping_add(1442695040888963407);
                *v.get_mut() = (x as i64) >> 20;
            }
            let (mut s, mut a) = (vec![0.0f32; 3 * n], vec![0.0f32; 3 * n]);
            let (mut fs, mut fa) = (vec![0i64; 3 * n], vec![0i64; 3 * n]);
            g.collect(&mut s, &mut a);
            g.collect_fixed(&mut fs, &mut fa);
            let copy = |g: &GradBuffers| GradBuffers {
                n_voxels: g.n_voxels,
                n: g.n,
                map: SlotMap::All,
                quantum: g.quantum,
                buf: g.buf.iter().map(|v| AtomicI64::new(v.load(Relaxed))).collect(),
            };
            let (mut s2, mut a2) = (vec![0.0f32; 3 * n], vec![0.0f32; 3 * n]);
            copy(&g).into_collected(&mut s2, &mut a2);
            let (mut fs2, mut fa2) = (vec![0i64; 3 * n], vec![0i64; 3 * n]);
            g.into_collected_fixed(&mut fs2, &mut fa2);
            let bits = |v: &[f32]| v.iter().map(|x| x.to_bits()).collect::<Vec<_>>();
            assert!(bits(&s) == bits(&s2) && bits(&a) == bits(&a2), "{n} slots: float gradients differ");
            assert!(fs == fs2 && fa == fa2, "{n} slots: fixed-point sums differ");
            assert!(s.iter().any(|&v| v != 0.0), "{n} slots: nothing was compared");
        }
    }

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
