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
//! e.g. the target colour the voxel shows) each term is weighted by w = exp(-|guide[r] - guide[q]|² / tau²),
//! symmetric in r and q, so the flux between rows that should look different fades (an edge-stopping
//! diffusion, as in Perona and Malik's) and the properties above still hold. Each output row is a fixed-order
//! sum of its own inputs, so the result does not depend on the thread count. A neighbour's row is found through
//! a `RowSpans` of the set (16 bytes per grid row and a bit per stored voxel), not a map over the grid, once per call
//! (with the guide's weights); work per step: the rows in parallel blocks; memory: one more copy of the values and
//! 48 bytes per row for the call.

use rayon::prelude::*;

use crate::spans::RowSpans;

/// Per-row vectors that weight the diffusion between two rows by exp(-|a - b|² / tau²).
#[derive(Clone, Copy)]
pub struct Guide<'a> {
    /// rows × `dims` values
    pub values: &'a [f32],
    pub dims: usize,
    pub tau: f32,
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
    let [nz, ny, nx] = n;
    if nz * ny * nx == 0 {
        return Err(format!("the grid {nz} x {ny} x {nx} has no voxels"));
    }
    if channels == 0 || !values.len().is_multiple_of(channels) {
        return Err(format!("values ({}) are not a whole number of rows of {channels} channels", values.len()));
    }
    let rows = values.len() / channels;
    if index.len() != rows {
        return Err(format!("index has {} voxels, values have {rows} rows", index.len()));
    }
    let set = RowSpans::new([nx, ny, nz], index)?;
    if let Some(g) = guide {
        // `!(tau > 0)` rejects NaN too.
        #[allow(clippy::neg_cmp_op_on_partial_ord)]
        if g.dims == 0 || g.values.len() != rows * g.dims || !(g.tau > 0.0) {
            return Err(format!("guide: {} values for {rows} rows of {} dims, tau {}", g.values.len(), g.dims, g.tau));
        }
    }
    if rows >= NONE as usize {
        return Err(format!("{rows} rows: at most {} can be diffused", NONE - 1));
    }
    if steps == 0 || rows == 0 {
        return Ok(());
    }
    let stencil = Stencil::new(n, index, &set, alpha, guide);
    let mut src = values.to_vec();
    for s in 0..steps {
        // After an odd number of steps the latest values are in `values`, else in `src`.
        let (from, to): (&[f32], &mut [f32]) = if s % 2 == 0 { (&src, &mut *values) } else { (&*values, &mut src) };
        to.par_chunks_mut(BLOCK * channels)
            .enumerate()
            .for_each(|(b, out)| stencil.step(from, out, b * BLOCK, channels));
    }
    if steps.is_multiple_of(2) {
        values.copy_from_slice(&src);
    }
    Ok(())
}

/// No neighbour in the set.
const NONE: u32 = u32::MAX;

/// Every row's 6 neighbours' rows (`NONE`: not in the set) and their weights, found once per call, so that the
/// steps read them instead of looking the neighbours up in the `RowSpans` and weighting them by the guide again
/// at every step (the same bits either way).
/// 48 bytes per row, for the call only (its two copies of the values are 8 bytes per row and channel).
struct Stencil {
    nb: Vec<[u32; 6]>,
    w: Vec<[f32; 6]>,
}

impl Stencil {
    fn new(n: [usize; 3], index: &[i64], set: &RowSpans, alpha: f32, guide: Option<Guide>) -> Stencil {
        let [nz, ny, nx] = n;
        let plane = ny * nx;
        let row_of = |j: usize| set.rank(j).map_or(NONE, |r| r as u32);
        let mut nb = vec![[NONE; 6]; index.len()];
        let mut w = vec![[0.0f32; 6]; index.len()];
        nb.par_chunks_mut(BLOCK).zip(w.par_chunks_mut(BLOCK)).enumerate().for_each(|(b, (nbb, wb))| {
            for (k, (nr, wr)) in nbb.iter_mut().zip(wb.iter_mut()).enumerate() {
                let row = b * BLOCK + k;
                let j = index[row] as usize;
                let (z, y, x) = (j / plane, j / nx % ny, j % nx);
                // neighbours in a fixed order: -z, +z, -y, +y, -x, +x
                *nr = [
                    if z > 0 { row_of(j - plane) } else { NONE },
                    if z + 1 < nz { row_of(j + plane) } else { NONE },
                    if y > 0 { row_of(j - nx) } else { NONE },
                    if y + 1 < ny { row_of(j + nx) } else { NONE },
                    if x > 0 { row_of(j - 1) } else { NONE },
                    if x + 1 < nx { row_of(j + 1) } else { NONE },
                ];
                for (wk, &q) in wr.iter_mut().zip(nr.iter()) {
                    if q == NONE {
                        continue;
                    }
                    *wk = match guide {
                        Some(g) => {
                            let a = &g.values[row * g.dims..(row + 1) * g.dims];
                            let b = &g.values[q as usize * g.dims..(q as usize + 1) * g.dims];
                            let d2: f32 = a.iter().zip(b).map(|(x, y)| (x - y) * (x - y)).sum();
                            alpha * (-d2 / (g.tau * g.tau)).exp()
                        }
                        None => alpha,
                    };
                }
            }
        });
        Stencil { nb, w }
    }

    /// One step for rows `first..first + out.len() / channels`.
    fn step(&self, from: &[f32], out: &mut [f32], first: usize, channels: usize) {
        for (k, o) in out.chunks_exact_mut(channels).enumerate() {
            let row = first + k;
            let (nb, w) = (&self.nb[row], &self.w[row]);
            let r = row * channels;
            for (c, oc) in o.iter_mut().enumerate() {
                let v = from[r + c];
                let mut acc = 0.0f32;
                for (&q, &wk) in nb.iter().zip(w) {
                    if q != NONE {
                        acc += wk * (from[q as usize * channels + c] - v);
                    }
                }
                *oc = v + acc;
            }
        }
    }
}
