//! Vector error diffusion of whole ink counts between optimisation voxels, one optimisation layer at a time.
//!
//! Each optimisation voxel encloses a block of `b` printer voxels (under nearest upsampling, all of them inside when
//! the voxel is); a halftone gives it whole numbers of printer voxels of each ink, so its shares are quantized in
//! steps of 1/b. This kernel chooses those counts so that the rounding error of one voxel is carried to its
//! unvisited neighbours (the ink placement inside a block is the caller's).
//!
//! Order: layers in increasing z; within a layer, rows in increasing y, each row serpentine in x (left to right
//! when `y + z` is even, right to left otherwise), as `kernels::diffuse`. Per voxel: the corrected target
//! `u = b * share + e` (`e` the carried error, a vector of n inks whose components sum to 0), the counts `c` the
//! nearest (Euclidean) non-negative integer vector with `sum c = b` (greedy: b times, one more voxel to the ink
//! with the largest `u_k - c_k`, ties to the lowest index; exact for this separable convex problem, and largest
//! remainder rounding where `u >= 0`), and the residual `r = u - c` (components summing to 0) goes to unvisited
//! inside neighbours:
//!
//! ```text
//!   this layer, x (1 - down) / 16 (d = sweep direction):    next layer z + 1, x down / 16:
//!                  *       7 (x+d, y)                                 2 (x, y-1)
//!   3 (x-d, y+1)   5 (x, y+1)   1 (x+d, y+1)              2 (x-1, y)  8 (x, y)  2 (x+1, y)
//!                                                                     2 (x, y+1)
//! ```
//!
//! Floyd–Steinberg's proportions in the layer (a texel sees its neighbours side by side under the surface), the
//! fraction `down` to the next layer. Each inside voxel has a class (`inside`, 1 to 254: the caller's depth shell
//! under the surface), and passes error only to neighbours of its own class, so that the surface's voxels keep their
//! errors among themselves rather than taking those of the hidden voxels below. The weights are renormalised over
//! the neighbours that exist, are of the voxel's class and have a positive weight; a voxel with none drops its
//! residual. Voxels outside (`inside == 0`) get counts 0 and neither take nor pass error; inside voxels with an
//! empty block (`b == 0`, at the printer grid's rounded edges) take their carried error and pass it on whole.
//!
//! The dither's own counts (class `DITHER_CLASS`): such a voxel takes the counts an ordered dither gives its block
//! (`CountLayer::thresholds`, the block's thresholds sorted): its mixture cut into bands at its cumulative shares,
//! `c_k` the number of thresholds in band k, the last band taking the rest; it neither takes nor passes error.
//! The caller gives this class to voxels where the dither alone does better than the diffusion (a smooth mixture).
//!
//! Local error: error is conserved (non-negative weights summing to 1), so the counts of any window of voxels
//! differ from its summed `b * share` only by the residuals crossing its boundary: each component at most
//! `max |r_k|` (returned) times the number of voxels that pass error across it. Sequential and deterministic;
//! f64 throughout. Memory: two (ny, nx, n) f64 error planes (this layer's and the next one's).

/// (dx in sweep direction, dy, weight in 16ths) within the layer: Floyd–Steinberg.
const IN_LAYER: [(i64, i64, f64); 4] = [(1, 0, 7.0), (-1, 1, 3.0), (0, 1, 5.0), (1, 1, 1.0)];
/// (dx, dy, weight in 16ths) on the next layer.
const NEXT_LAYER: [(i64, i64, f64); 5] = [(0, 0, 8.0), (-1, 0, 2.0), (1, 0, 2.0), (0, -1, 2.0), (0, 1, 2.0)];

/// The class of voxels that take the ordered dither's own counts and carry no error (module docs).
pub const DITHER_CLASS: u8 = 255;

/// Shape of an optimisation layer: `n` inks on an `ny` × `nx` grid.
#[derive(Clone, Copy, Debug)]
pub struct CountShape {
    pub n: usize,
    pub ny: usize,
    pub nx: usize,
}

/// One optimisation layer's inputs: `share` (n, ny, nx) planar, each inside row summing to 1 (band order, any
/// order the caller keeps); `block` (ny, nx) the printer voxels each voxel encloses; `inside`, `inside_next`
/// (ny, nx): 0 outside, else the voxel's class, for this layer and the next (all zero after the last).
/// `thresholds`: (ny, nx, t) each block's ordered-dither thresholds in increasing order, the first `block` of each
/// row used (t at least the largest block); needed only where a voxel is of `DITHER_CLASS`.
pub struct CountLayer<'a> {
    pub z: usize,
    pub share: &'a [f64],
    pub block: &'a [u32],
    pub inside: &'a [u8],
    pub inside_next: &'a [u8],
    pub thresholds: Option<&'a [f64]>,
}

/// Nearest non-negative integer vector to `u` with sum `b` (module docs), written into `c`.
fn nearest_counts(u: &[f64], b: u32, c: &mut [u32]) {
    c.fill(0);
    for _ in 0..b {
        let mut best = 0;
        let mut best_v = f64::NEG_INFINITY;
        for (k, (&uk, &ck)) in u.iter().zip(c.iter()).enumerate() {
            let v = uk - ck as f64;
            if v > best_v {
                best_v = v;
                best = k;
            }
        }
        c[best] += 1;
    }
}

/// The counts an ordered dither gives a block of mixture `share` (summing to 1) whose sorted thresholds are `t`
/// (module docs), written into `c`: a threshold below the k-th cumulative share and not below the one before it
/// takes ink k, as `printing.dithers.Thresholds` labels a voxel.
fn threshold_counts(share: &[f64], t: &[f64], c: &mut [u32]) {
    c.fill(0);
    let n = share.len();
    let mut i = 0;
    let mut edge = 0.0;
    for (k, &s) in share[..n - 1].iter().enumerate() {
        edge += s;
        while i < t.len() && t[i] < edge {
            c[k] += 1;
            i += 1;
        }
    }
    c[n - 1] += (t.len() - i) as u32;
}

/// Diffuse the counts of optimisation layer `layer.z` with the fraction `down` of each residual to the next layer.
///
/// `err` (ny, nx, n): the error carried into this layer (it receives this layer's own diffusion too, and is zeroed
/// on return, ready to be the next call's `err_next`); `err_next` (ny, nx, n) accumulates the next layer's;
/// `counts` (ny, nx, n) receives the counts. Returns the largest |residual component| of the layer.
pub fn diffuse_counts_layer(
    shape: CountShape,
    layer: &CountLayer<'_>,
    down: f64,
    err: &mut [f64],
    err_next: &mut [f64],
    counts: &mut [u32],
) -> Result<f64, String> {
    let CountShape { n, ny, nx } = shape;
    let m = ny * nx;
    let want = [
        (layer.share.len(), n * m, "share"),
        (layer.block.len(), m, "block"),
        (layer.inside.len(), m, "inside"),
        (layer.inside_next.len(), m, "inside_next"),
        (err.len(), n * m, "error"),
        (err_next.len(), n * m, "error_next"),
        (counts.len(), n * m, "counts"),
    ];
    if n == 0 {
        return Err("need at least one ink".into());
    }
    for (got, expect, name) in want {
        if got != expect {
            return Err(format!("{name} has {got} elements, expected {expect}"));
        }
    }
    if !(0.0..=1.0).contains(&down) {
        return Err(format!("down must be in [0, 1], got {down}"));
    }
    let width = match layer.thresholds {
        Some(t) if m > 0 => t.len() / m,
        _ => 0,
    };
    let big = layer.block.iter().zip(layer.inside).filter(|(_, &c)| c == DITHER_CLASS).map(|(&b, _)| b).max();
    if let Some(big) = big {
        if layer.thresholds.is_none_or(|t| t.len() != m * width) || width < big as usize {
            return Err(format!("the dither's class needs (ny, nx, >= {big}) thresholds"));
        }
    }
    let (inside, inside_next) = (layer.inside, layer.inside_next);
    let mut u = vec![0.0f64; n];
    let mut worst = 0.0f64;
    for y in 0..ny {
        let d: i64 = if (y + layer.z).is_multiple_of(2) { 1 } else { -1 };
        for step in 0..nx {
            let x = if d > 0 { step } else { nx - 1 - step };
            let i = y * nx + x;
            let c = &mut counts[i * n..(i + 1) * n];
            if inside[i] == 0 {
                c.fill(0);
                err[i * n..(i + 1) * n].fill(0.0);
                continue;
            }
            let b = layer.block[i];
            if inside[i] == DITHER_CLASS {
                for k in 0..n {
                    u[k] = layer.share[k * m + i];
                }
                let t = layer.thresholds.unwrap_or_default();
                threshold_counts(&u, &t[i * width..i * width + b as usize], c);
                err[i * n..(i + 1) * n].fill(0.0);
                continue;
            }
            for k in 0..n {
                u[k] = b as f64 * layer.share[k * m + i] + err[i * n + k];
            }
            nearest_counts(&u, b, c);
            for k in 0..n {
                u[k] -= c[k] as f64;
                worst = worst.max(u[k].abs());
            }
            let at = |dx: i64, dy: i64| -> Option<usize> {
                let (xx, yy) = (x as i64 + dx, y as i64 + dy);
                (xx >= 0 && yy >= 0 && (xx as usize) < nx && (yy as usize) < ny).then(|| yy as usize * nx + xx as usize)
            };
            let mut targets: [(usize, bool, f64); 9] = [(0, false, 0.0); 9];
            let mut cnt = 0;
            let mut total = 0.0f64;
            let lists = [(&IN_LAYER[..], false, 1.0 - down, inside), (&NEXT_LAYER[..], true, down, inside_next)];
            for (list, next, scale, mask) in lists {
                for &(dx, dy, w) in list {
                    let j = if next { at(dx, dy) } else { at(dx * d, dy) };
                    if let Some(j) = j.filter(|&j| mask[j] == inside[i] && w * scale > 0.0) {
                        targets[cnt] = (j, next, w * scale);
                        cnt += 1;
                        total += w * scale;
                    }
                }
            }
            for &(j, next, w) in &targets[..cnt] {
                let dst = if next { &mut err_next[j * n..(j + 1) * n] } else { &mut err[j * n..(j + 1) * n] };
                let f = w / total;
                for k in 0..n {
                    dst[k] += f * u[k];
                }
            }
            err[i * n..(i + 1) * n].fill(0.0);
        }
    }
    Ok(worst)
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Diffuse `nz` layers of a uniform share `p` with blocks of `b`; returns the counts (nz, ny, nx, n) and the
    /// largest residual.
    fn run(shape: CountShape, nz: usize, p: &[f64], b: u32, down: f64) -> (Vec<u32>, f64) {
        let m = shape.ny * shape.nx;
        let n = shape.n;
        let share: Vec<f64> = p.iter().flat_map(|&v| std::iter::repeat_n(v, m)).collect();
        let (block, ins, none) = (vec![b; m], vec![1u8; m], vec![0u8; m]);
        let (mut e, mut en) = (vec![0.0; n * m], vec![0.0; n * m]);
        let mut out = vec![0u32; nz * n * m];
        let mut worst = 0.0f64;
        for z in 0..nz {
            let nxt = if z + 1 < nz { &ins[..] } else { &none[..] };
            let layer =
                CountLayer { z, share: &share, block: &block, inside: &ins, inside_next: nxt, thresholds: None };
            let c = &mut out[z * n * m..(z + 1) * n * m];
            worst = worst.max(diffuse_counts_layer(shape, &layer, down, &mut e, &mut en, c).unwrap());
            std::mem::swap(&mut e, &mut en);
        }
        (out, worst)
    }

    #[test]
    fn nearest_is_largest_remainder() {
        let mut c = [0u32; 4];
        nearest_counts(&[1.4, 2.7, 0.6, 1.3], 6, &mut c);
        assert_eq!(c, [1, 3, 1, 1]);
        nearest_counts(&[-0.8, 3.5, 2.2, 1.1], 6, &mut c);
        assert_eq!(c, [0, 3, 2, 1]);
    }

    #[test]
    fn blocks_sum_and_totals_conserved() {
        let shape = CountShape { n: 5, ny: 20, nx: 30 };
        let p = [0.11, 0.23, 0.07, 0.31, 0.28];
        for down in [0.0, 0.125, 0.5] {
            let (c, worst) = run(shape, 10, &p, 6, down);
            for blk in c.chunks(5) {
                assert_eq!(blk.iter().sum::<u32>(), 6);
            }
            assert!(worst < 1.5, "{worst}");
            // error is conserved inside the box: only the residuals with no unvisited neighbour are dropped
            let total = (c.len() / 5 * 6) as f64;
            for k in 0..5 {
                let got: u32 = c.iter().skip(k).step_by(5).sum();
                let lost = if down > 0.0 { 1.0 } else { 10.0 };
                assert!((got as f64 - p[k] * total).abs() <= lost * worst + 1e-9, "{down} {k} {got}");
            }
        }
    }

    #[test]
    fn threshold_counts_are_the_dithers_bands() {
        let mut c = [0u32; 3];
        let t = [0.05, 0.2, 0.3, 0.55, 0.7, 0.9];
        threshold_counts(&[0.3, 0.5, 0.2], &t, &mut c); // edges 0.3 and 0.8; a threshold on an edge is above it
        assert_eq!(c, [2, 3, 1]);
        threshold_counts(&[0.0, 1.0, 0.0], &t, &mut c);
        assert_eq!(c, [0, 6, 0]);
        threshold_counts(&[0.5, 0.5, 0.0], &t[..2], &mut c);
        assert_eq!(c, [2, 0, 0]);
    }

    #[test]
    fn dither_class_takes_the_dithers_counts_and_no_error() {
        // a 3 x 4 layer, the dither's class on a checkerboard, the others one diffusion class among themselves
        let shape = CountShape { n: 3, ny: 3, nx: 4 };
        let m = 12;
        let rows: Vec<[f64; 3]> = (0..m).map(|i| [0.1 + 0.05 * i as f64, 0.3, 0.6 - 0.05 * i as f64]).collect();
        let share: Vec<f64> = (0..3).flat_map(|k| rows.iter().map(move |r| r[k])).collect();
        let ins: Vec<u8> = (0..m).map(|i| if (i / 4 + i % 4) % 2 == 0 { DITHER_CLASS } else { 1 }).collect();
        let t: Vec<f64> = (0..m).flat_map(|i| (0..6).map(move |s| ((i * 7 + s * 11) % 60) as f64 / 60.0)).collect();
        let t: Vec<f64> = t
            .chunks(6)
            .flat_map(|r| {
                let mut r = r.to_vec();
                r.sort_by(f64::total_cmp);
                r
            })
            .collect();
        let layer = CountLayer {
            z: 0,
            share: &share,
            block: &[6; 12],
            inside: &ins,
            inside_next: &[0; 12],
            thresholds: Some(&t),
        };
        let (mut e, mut en, mut c) = (vec![0.0; 36], vec![0.0; 36], vec![0u32; 36]);
        let worst = diffuse_counts_layer(shape, &layer, 0.0, &mut e, &mut en, &mut c).unwrap();
        let mut own = [0u32; 3];
        let mut total = [0.0f64; 3];
        for i in 0..m {
            if ins[i] == DITHER_CLASS {
                threshold_counts(&rows[i], &t[i * 6..i * 6 + 6], &mut own);
                assert_eq!(&c[i * 3..i * 3 + 3], &own, "{i}");
            } else {
                for k in 0..3 {
                    total[k] += c[i * 3 + k] as f64 - 6.0 * rows[i][k];
                }
            }
        }
        // the diffusion class conserves its error but for the last voxel's residual
        assert!(total.iter().all(|d| d.abs() <= worst + 1e-9), "{total:?} {worst}");
        let short = CountLayer { thresholds: Some(&t[..30]), ..layer };
        assert!(diffuse_counts_layer(shape, &short, 0.0, &mut e, &mut en, &mut c).unwrap_err().contains("thresholds"));
        let none = CountLayer { thresholds: None, ..layer };
        assert!(diffuse_counts_layer(shape, &none, 0.0, &mut e, &mut en, &mut c).is_err());
    }

    #[test]
    fn classes_keep_their_errors() {
        // two classes in alternate columns: each column's count of ink 0 stays within one residual of its target
        let shape = CountShape { n: 2, ny: 30, nx: 2 };
        let share: Vec<f64> = [0.3; 60].into_iter().chain([0.7; 60]).collect();
        let ins: Vec<u8> = (0..60).map(|i| 1 + (i % 2) as u8).collect();
        let layer =
            CountLayer { z: 0, share: &share, block: &[6; 60], inside: &ins, inside_next: &[0; 60], thresholds: None };
        let (mut e, mut en, mut c) = (vec![0.0; 120], vec![0.0; 120], vec![0u32; 120]);
        let worst = diffuse_counts_layer(shape, &layer, 0.0, &mut e, &mut en, &mut c).unwrap();
        for col in 0..2 {
            let got: u32 = (0..30).map(|y| c[(y * 2 + col) * 2]).sum();
            assert!((got as f64 - 0.3 * 6.0 * 30.0).abs() <= worst + 1e-9, "{col} {got}");
        }
    }

    #[test]
    fn outside_gets_nothing_and_bad_sizes() {
        let shape = CountShape { n: 2, ny: 2, nx: 2 };
        let share = [0.5; 8];
        let layer = CountLayer {
            z: 0,
            share: &share,
            block: &[6; 4],
            inside: &[1, 0, 1, 1],
            inside_next: &[0; 4],
            thresholds: None,
        };
        let (mut e, mut en, mut c) = (vec![0.0; 8], vec![0.0; 8], vec![9u32; 8]);
        diffuse_counts_layer(shape, &layer, 0.1, &mut e, &mut en, &mut c).unwrap();
        assert_eq!(&c[2..4], &[0, 0]);
        assert_eq!(c.iter().sum::<u32>(), 18);
        let short = CountLayer { share: &share[..7], ..layer };
        assert!(diffuse_counts_layer(shape, &short, 0.1, &mut e, &mut en, &mut c).is_err());
        assert!(diffuse_counts_layer(shape, &layer, 1.5, &mut e, &mut en, &mut c).is_err());
    }
}
