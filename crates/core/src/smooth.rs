//! Explicit diffusion of per-voxel values over a sparse set of grid voxels (the optimiser's step
//! preconditioner, `python/inkopt/optim/smooth.py`, which says why).
//!
//! The set is given by `index`, a (z, y, x) grid of row numbers (-1: not in the set) whose rows are numbered in
//! grid (C) order: 0, 1, 2, ... as the flat index grows, like `Parameterization.grad_index`. Values are
//! `rows × channels` f32. One step:
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
//! sum of its own inputs, so the result does not depend on the thread count. Work per step: one pass over the
//! grid's index plane by plane (in parallel over planes) and the rows of the plane and its two neighbours;
//! memory: one more copy of the values.

use rayon::prelude::*;

/// Per-row vectors that weight the diffusion between two rows by exp(-|a - b|² / tau²).
#[derive(Clone, Copy)]
pub struct Guide<'a> {
    /// rows × `dims` values
    pub values: &'a [f32],
    pub dims: usize,
    pub tau: f32,
}

/// Diffuse `values` (rows × `channels`, rows numbered as in `index`) `steps` times with weight `alpha`
/// (and `guide`'s weights if given). `n` = (nz, ny, nx) of `index`. Errors if `index` does not number its rows
/// 0, 1, ... in grid order, or if the sizes disagree.
pub fn diffuse_rows(n: [usize; 3], index: &[i32], values: &mut [f32], channels: usize, steps: usize, alpha: f32,
                    guide: Option<Guide>) -> Result<(), String> {
    let [nz, ny, nx] = n;
    let plane = ny * nx;
    if index.len() != nz * plane {
        return Err(format!("index has {} entries, expected {nz} x {ny} x {nx}", index.len()));
    }
    if channels == 0 || values.len() % channels != 0 {
        return Err(format!("values ({}) are not a whole number of rows of {channels} channels", values.len()));
    }
    let rows = values.len() / channels;
    // First row of every plane (and the total), checking that the rows are numbered in grid order.
    let mut first = Vec::with_capacity(nz + 1);
    let mut next = 0usize;
    for z in 0..nz {
        first.push(next);
        for &r in &index[z * plane..(z + 1) * plane] {
            if r >= 0 {
                if r as usize != next {
                    return Err(format!("index numbers its rows out of grid order (found {r}, expected {next})"));
                }
                next += 1;
            }
        }
    }
    first.push(next);
    if next != rows {
        return Err(format!("index has {next} rows in the set, values have {rows}"));
    }
    if let Some(g) = guide {
        if g.dims == 0 || g.values.len() != rows * g.dims || !(g.tau > 0.0) {
            return Err(format!("guide: {} values for {rows} rows of {} dims, tau {}", g.values.len(), g.dims, g.tau));
        }
    }
    if steps == 0 || rows == 0 {
        return Ok(());
    }
    let mut src = values.to_vec();
    for s in 0..steps {
        // After an odd number of steps the latest values are in `values`, else in `src`.
        let (from, to): (&[f32], &mut [f32]) = if s % 2 == 0 { (&src, &mut *values) } else { (&*values, &mut src) };
        let mut chunks = Vec::with_capacity(nz);
        let mut rest = to;
        for z in 0..nz {
            let (head, tail) = rest.split_at_mut((first[z + 1] - first[z]) * channels);
            chunks.push((z, head));
            rest = tail;
        }
        chunks.into_par_iter().for_each(|(z, out)| step_plane(n, index, from, out, channels, alpha, guide, z));
    }
    if steps % 2 == 0 {
        values.copy_from_slice(&src);
    }
    Ok(())
}

/// One step for the rows of plane z (`out`: those rows, in order).
#[allow(clippy::too_many_arguments)]
fn step_plane(n: [usize; 3], index: &[i32], from: &[f32], out: &mut [f32], channels: usize, alpha: f32,
              guide: Option<Guide>, z: usize) {
    let [nz, ny, nx] = n;
    let plane = ny * nx;
    let mut o = 0usize;
    for y in 0..ny {
        for x in 0..nx {
            let j = z * plane + y * nx + x;
            let r = index[j];
            if r < 0 {
                continue;
            }
            let row = r as usize;
            let r = row * channels;
            // neighbours in a fixed order: -z, +z, -y, +y, -x, +x
            let nb = [
                if z > 0 { index[j - plane] } else { -1 },
                if z + 1 < nz { index[j + plane] } else { -1 },
                if y > 0 { index[j - nx] } else { -1 },
                if y + 1 < ny { index[j + nx] } else { -1 },
                if x > 0 { index[j - 1] } else { -1 },
                if x + 1 < nx { index[j + 1] } else { -1 },
            ];
            let mut w = [alpha; 6];
            if let Some(g) = guide {
                let a = &g.values[row * g.dims..(row + 1) * g.dims];
                for (wk, &q) in w.iter_mut().zip(&nb) {
                    if q >= 0 {
                        let b = &g.values[q as usize * g.dims..(q as usize + 1) * g.dims];
                        let d2: f32 = a.iter().zip(b).map(|(x, y)| (x - y) * (x - y)).sum();
                        *wk = alpha * (-d2 / (g.tau * g.tau)).exp();
                    }
                }
            }
            for c in 0..channels {
                let v = from[r + c];
                let mut acc = 0.0f32;
                for (&q, &wk) in nb.iter().zip(&w) {
                    if q >= 0 {
                        acc += wk * (from[q as usize * channels + c] - v);
                    }
                }
                out[o + c] = v + acc;
            }
            o += channels;
        }
    }
}
