//! Explicit diffusion of per-voxel values over a sparse set of grid voxels (the optimiser's step
//! preconditioner, `python/inkopt/optim/smooth.py`, which says why).
//!
//! The set is given by `index`, the strictly increasing linear (C-order, (z, y, x)) indices of its voxels; row r
//! of the values belongs to voxel `index[r]`. Values are `rows × channels` f32. One step:
//!
//! ```text
//!   v'[r] = v[r] + alpha * sum over the 6 face neighbours q of r that are in the set of (v[q] - v[r])
//! ```
//!
//! so nothing flows across the set's boundary (the sum of each channel is conserved) and a constant is a fixed
//! point; with alpha <= 1/6 no value leaves the range of its neighbourhood. With a `Guide` (a vector per row,
//! e.g. the target colour the voxel shows and its depth) each term is weighted by w = exp(-|guide[r] - guide[q]|² / tau²),
//! symmetric in r and q, so the flux between rows that should look different fades (an edge-stopping
//! diffusion, as in Perona and Malik's) and the properties above still hold. Each output row is a fixed-order
//! sum of its own inputs, so the result does not depend on the thread count. A neighbour's row is found through
//! a `RowSpans` of the set (16 bytes per grid row and a bit per stored voxel), not a map over the grid, once per
//! slab of z-planes (with the guide's weights); work per step: the rows in parallel blocks; memory beside the
//! values: per row of a slab and its halo, 29 bytes of neighbours and weights and two copies of one channel (8
//! bytes), the channels diffused one at a time, and the slab's result until the next slab has read its halo.

use rayon::prelude::*;

use crate::spans::RowSpans;

/// Per-row vectors that weight the diffusion between two rows by exp(-|a - b|² / tau²). Row r's vector is the
/// `dims` values of entry `key[r]` of `table` (entry r without a key), followed by `extra[r]` if given: so rows
/// that share a vector's first components (voxels under one texel: its target colour) hold a 4-byte key into a
/// shared table, not the components themselves.
#[derive(Clone, Copy)]
pub struct Guide<'a> {
    /// entries × `dims` values
    pub table: &'a [f32],
    pub dims: usize,
    /// per row, its entry of `table` (None: row r's entry is r)
    pub key: Option<&'a [u32]>,
    /// per row, one more component after the table's (None: no more)
    pub extra: Option<&'a [f32]>,
    pub tau: f32,
}

impl<'a> Guide<'a> {
    /// A vector of `dims` values per row: `values` is rows × `dims`.
    pub fn rows(values: &'a [f32], dims: usize, tau: f32) -> Guide<'a> {
        Guide { table: values, dims, key: None, extra: None, tau }
    }

    /// Checks the sizes against `rows` rows and `tau`.
    fn check(&self, rows: usize) -> Result<(), String> {
        let entries = self.table.len().checked_div(self.dims).unwrap_or(0);
        let shape_ok = self.dims > 0 && self.table.len() == entries * self.dims;
        let key_ok = match self.key {
            Some(k) => k.len() == rows && k.iter().all(|&e| (e as usize) < entries),
            None => entries == rows,
        };
        let extra_ok = self.extra.is_none_or(|e| e.len() == rows);
        // `!(tau > 0)` rejects NaN too.
        #[allow(clippy::neg_cmp_op_on_partial_ord)]
        if !shape_ok || !key_ok || !extra_ok || !(self.tau > 0.0) {
            return Err(format!(
                "guide: a table of {} values in {} dims, {} keys and {} extra values for {rows} rows, tau {}",
                self.table.len(),
                self.dims,
                self.key.map_or(0, |k| k.len()),
                self.extra.map_or(0, |e| e.len()),
                self.tau
            ));
        }
        Ok(())
    }

    /// exp(-|guide[a] - guide[b]|² / tau²) times `alpha`: the squared differences summed in the vector's order
    /// from 0.
    fn weight(&self, a: usize, b: usize, alpha: f32) -> f32 {
        let entry = |r: usize| self.key.map_or(r, |k| k[r] as usize) * self.dims;
        let (ea, eb) = (entry(a), entry(b));
        let mut d2 = 0.0f32;
        for i in 0..self.dims {
            let d = self.table[ea + i] - self.table[eb + i];
            d2 += d * d;
        }
        if let Some(e) = self.extra {
            let d = e[a] - e[b];
            d2 += d * d;
        }
        alpha * (-d2 / (self.tau * self.tau)).exp()
    }
}

/// Rows per parallel block of a step.
const BLOCK: usize = 4096;

/// Diffuse `values` (rows × `channels`, row r for voxel `index[r]`) `steps` times with weight `alpha` (and
/// `guide`'s weights if given). `n` = (nz, ny, nx) of the grid. Errors if `index` is not strictly increasing
/// within the grid, or if the sizes disagree.
pub fn diffuse_rows(
    n: [usize; 3],
    index: &[i64],
    values: &mut [f32],
    channels: usize,
    steps: usize,
    alpha: f32,
    guide: Option<Guide>,
) -> Result<(), String> {
    diffuse_subset(n, index, None, values, channels, steps, alpha, guide, SLAB_PLANES)
}

/// z-planes of the set a call of `diffuse_rows` diffuses at a time (besides the halo).
pub const SLAB_PLANES: usize = 64;

/// `diffuse_rows` on the rows `subset` of `values` (strictly increasing row numbers; None: every row), over
/// their voxels `index[subset[r]]`, in place; the other rows are neither changed nor neighbours. `guide` has a
/// vector per row of the subset. The set is diffused `slab` z-planes at a time (at least `steps`; `SLAB_PLANES`),
/// each slab with `steps` planes either side (a value after `steps` steps depends only on the rows within `steps`
/// planes), and each channel on its own (the same bits as all at once, and as any slab thickness), so the call
/// holds a slab's stencil and copies, not the set's.
#[allow(clippy::too_many_arguments)]
pub fn diffuse_subset(
    n: [usize; 3],
    index: &[i64],
    subset: Option<&[u32]>,
    values: &mut [f32],
    channels: usize,
    steps: usize,
    alpha: f32,
    guide: Option<Guide>,
    slab: usize,
) -> Result<(), String> {
    let [nz, ny, nx] = n;
    if nz * ny * nx == 0 {
        return Err(format!("the grid {nz} x {ny} x {nx} has no voxels"));
    }
    if channels == 0 || !values.len().is_multiple_of(channels) {
        return Err(format!("values ({}) are not a whole number of rows of {channels} channels", values.len()));
    }
    let all = values.len() / channels;
    if index.len() != all {
        return Err(format!("index has {} voxels, values have {all} rows", index.len()));
    }
    if let Some(s) = subset {
        if s.iter().any(|&r| r as u64 >= all as u64) || (1..s.len()).any(|e| s[e] <= s[e - 1]) {
            return Err(format!("the subset must be strictly increasing rows of the {all}"));
        }
    }
    let row_of = |r: usize| subset.map_or(r, |s| s[r] as usize);
    let rows = subset.map_or(all, |s| s.len());
    let voxel = |r: usize| index[row_of(r)];
    let set = RowSpans::of([nx, ny, nz], rows, voxel)?;
    if let Some(g) = guide {
        g.check(rows)?;
    }
    if rows >= NONE as usize {
        return Err(format!("{rows} rows: at most {} can be diffused", NONE - 1));
    }
    if steps == 0 || rows == 0 {
        return Ok(());
    }
    let (plane, slab) = (ny * nx, slab.max(steps).max(1));
    // the set's first row in z-plane z or after it (rows are in grid order)
    let first_row = |z: usize| partition_point(rows, |r| (voxel(r) as usize) < z * plane);
    let (z_first, z_end) = (voxel(0) as usize / plane, voxel(rows - 1) as usize / plane + 1);
    // A slab's result is written once the next slab has read its halo, which reaches back into this slab only.
    let mut pending: Option<(usize, Vec<f32>)> = None;
    for z0 in (z_first..z_end).step_by(slab) {
        let z1 = (z0 + slab).min(z_end);
        let (r0, r1) = (first_row(z0), first_row(z1));
        if r0 == r1 {
            continue;
        }
        let window = first_row(z0.saturating_sub(steps))..first_row(z1 + steps);
        let stencil = Stencil::new(n, voxel, window.clone(), &set, alpha, guide);
        let out = stencil.diffuse(values, row_of, channels, steps, r0..r1);
        if let Some((p0, done)) = pending.replace((r0, out)) {
            write_rows(values, row_of, channels, p0, &done);
        }
    }
    if let Some((p0, done)) = pending {
        write_rows(values, row_of, channels, p0, &done);
    }
    Ok(())
}

/// The first r in 0..rows where `before(r)` is false (`before` true then false over the rows).
fn partition_point(rows: usize, before: impl Fn(usize) -> bool) -> usize {
    let (mut lo, mut hi) = (0, rows);
    while lo < hi {
        let mid = lo + (hi - lo) / 2;
        if before(mid) {
            lo = mid + 1;
        } else {
            hi = mid;
        }
    }
    lo
}

/// Write `done` (rows × `channels`, the set's rows from `first`) into `values` at those rows.
fn write_rows(values: &mut [f32], row_of: impl Fn(usize) -> usize, channels: usize, first: usize, done: &[f32]) {
    for (k, row) in done.chunks_exact(channels).enumerate() {
        let at = row_of(first + k) * channels;
        values[at..at + channels].copy_from_slice(row);
    }
}

/// No neighbour in the set.
const NONE: u32 = u32::MAX;

/// `Stencil::x` bits: the row before (after) is the voxel's -x (+x) neighbour.
const MINUS_X: u8 = 1;
const PLUS_X: u8 = 2;

/// The neighbours and weights of a window of the set's rows (whole z-planes), found once per slab, so that the
/// steps read them instead of looking the neighbours up in the `RowSpans` and weighting them by the guide again at
/// every step (the same bits either way). A weight is symmetric (the same bits from either side: (a - b)² = (b -
/// a)²), so each row keeps those of its +z, +y and +x neighbours and reads a -z, -y or -x one from that neighbour's
/// row; a set in grid order has its ±x neighbours in the rows beside it. Rows are the window's (0: its first); a
/// neighbour outside the window is none. 29 bytes per row of the window.
struct Stencil {
    /// the set's row of the window's row 0
    first: usize,
    /// rows of the -z, +z, -y, +y neighbours (`NONE`: not in the set)
    nb: Vec<[u32; 4]>,
    /// weights towards the +z, +y, +x neighbours (0 where there is none)
    w: Vec<[f32; 3]>,
    /// `MINUS_X` | `PLUS_X`
    x: Vec<u8>,
}

impl Stencil {
    fn new(
        n: [usize; 3],
        set_voxel: impl Fn(usize) -> i64 + Sync,
        window: std::ops::Range<usize>,
        set: &RowSpans,
        alpha: f32,
        guide: Option<Guide>,
    ) -> Stencil {
        let [nz, ny, nx] = n;
        let plane = ny * nx;
        let (first, rows) = (window.start, window.len());
        let voxel = |row: usize| set_voxel(first + row);
        let row_of = |j: usize| set.rank(j).filter(|r| window.contains(r)).map_or(NONE, |r| (r - first) as u32);
        let weight = |row: usize, q: u32| match guide {
            _ if q == NONE => 0.0,
            Some(g) => g.weight(first + row, first + q as usize, alpha),
            None => alpha,
        };
        let mut nb = vec![[NONE; 4]; rows];
        let mut w = vec![[0.0f32; 3]; rows];
        let mut xs = vec![0u8; rows];
        nb.par_chunks_mut(BLOCK).zip(w.par_chunks_mut(BLOCK)).zip(xs.par_chunks_mut(BLOCK)).enumerate().for_each(
            |(b, ((nbb, wb), xb))| {
                for (k, ((nr, wr), xr)) in nbb.iter_mut().zip(wb.iter_mut()).zip(xb.iter_mut()).enumerate() {
                    let row = b * BLOCK + k;
                    let j = voxel(row) as usize;
                    let (z, y, x) = (j / plane, j / nx % ny, j % nx);
                    *nr = [
                        if z > 0 { row_of(j - plane) } else { NONE },
                        if z + 1 < nz { row_of(j + plane) } else { NONE },
                        if y > 0 { row_of(j - nx) } else { NONE },
                        if y + 1 < ny { row_of(j + nx) } else { NONE },
                    ];
                    let minus_x = x > 0 && row > 0 && voxel(row - 1) as usize == j - 1;
                    let plus_x = x + 1 < nx && row + 1 < rows && voxel(row + 1) as usize == j + 1;
                    *xr = if minus_x { MINUS_X } else { 0 } | if plus_x { PLUS_X } else { 0 };
                    let next = if plus_x { row as u32 + 1 } else { NONE };
                    *wr = [weight(row, nr[1]), weight(row, nr[3]), weight(row, next)];
                }
            },
        );
        Stencil { first, nb, w, x: xs }
    }

    /// `steps` steps of each channel of `values` (the set's row r at `row_of(r)`) over the window, one channel at a
    /// time; the result of the set's rows `out` (within the window, at least `steps` planes from its ends unless
    /// those are the set's), rows × `channels`.
    fn diffuse(
        &self,
        values: &[f32],
        row_of: impl Fn(usize) -> usize,
        channels: usize,
        steps: usize,
        out: std::ops::Range<usize>,
    ) -> Vec<f32> {
        let rows = self.nb.len();
        let (mut a, mut b) = (vec![0.0f32; rows], vec![0.0f32; rows]);
        let mut result = vec![0.0f32; out.len() * channels];
        for c in 0..channels {
            a.iter_mut().enumerate().for_each(|(r, v)| *v = values[row_of(self.first + r) * channels + c]);
            for s in 0..steps {
                // After an odd number of steps the latest values are in `b`, else in `a`.
                let (from, to): (&[f32], &mut [f32]) = if s % 2 == 0 { (&a, &mut b) } else { (&b, &mut a) };
                to.par_chunks_mut(BLOCK).enumerate().for_each(|(k, o)| self.step(from, o, k * BLOCK));
            }
            let last = if steps.is_multiple_of(2) { &a } else { &b };
            for (k, r) in out.clone().enumerate() {
                result[k * channels + c] = last[r - self.first];
            }
        }
        result
    }

    /// One step of one channel for rows `first..first + out.len()`: the neighbours in a fixed order, -z, +z, -y,
    /// +y, -x, +x.
    fn step(&self, from: &[f32], out: &mut [f32], first: usize) {
        for (k, o) in out.iter_mut().enumerate() {
            let row = first + k;
            let (nb, w, x) = (&self.nb[row], &self.w[row], self.x[row]);
            let v = from[row];
            let mut acc = 0.0f32;
            let mut add = |q: usize, wk: f32| acc += wk * (from[q] - v);
            if nb[0] != NONE {
                add(nb[0] as usize, self.w[nb[0] as usize][0]);
            }
            if nb[1] != NONE {
                add(nb[1] as usize, w[0]);
            }
            if nb[2] != NONE {
                add(nb[2] as usize, self.w[nb[2] as usize][1]);
            }
            if nb[3] != NONE {
                add(nb[3] as usize, w[1]);
            }
            if x & MINUS_X != 0 {
                add(row - 1, self.w[row - 1][2]);
            }
            if x & PLUS_X != 0 {
                add(row + 1, w[2]);
            }
            *o = v + acc;
        }
    }
}
