//! 3D vector error diffusion: one ink per printer voxel from a per-voxel ink mixture, layer by layer.
//!
//! Order: layers in increasing z; within a layer, rows in increasing y, each row serpentine in x (left to right
//! when `y + z` is even, right to left otherwise, so that neither rows nor layers share a sweep direction).
//! Choice: the ink whose one-hot vector is nearest (Euclidean) to the corrected mixture `u = m + e`, i.e. the
//! largest component of `u` (ties: the lowest ink index) — standard vector error diffusion for targets in the
//! simplex. The residual `r = u - onehot` goes to unvisited neighbours with fixed weights (sum 1):
//!
//! ```text
//!   this layer (Floyd–Steinberg × 7/8, d = sweep direction):  next layer z + 1:
//!                  *       49 (x+d, y)                           2 (x, y-1)
//!   21 (x-d, y+1)  35 (x, y+1)  7 (x+d, y+1)          2 (x-1, y)  8 (x, y)  2 (x+1, y)
//!                                                                2 (x, y+1)
//!   (in 128ths: 112 stay in the layer, 16 go down)
//! ```
//!
//! Seven eighths of the residual stay in the layer with Floyd–Steinberg's proportions (7, 3, 5, 1)/16, one
//! eighth goes to the next layer, half of it straight down and the rest to the four in-plane neighbours of that
//! voxel. Chosen by measurement on uniform and smooth random 2- and 4-ink fields at 600 × 300 DPI × 27 µm, the
//! figures being the RMS error of the ink volumes low-passed by a 0.1 mm Gaussian (scattering's blur) against
//! the mixture, and the per-layer ink fractions: pushing more error down (1/2, 3/4) lowers the low-pass error on
//! periodic fields but sets up a decaying oscillation of the layer fractions in z (1/2 down: layers 0-2 at
//! -0.13, +0.10, -0.07 off a 0.3 share, the top layer +0.065; 3/4 down: -0.30, +0.46, -0.28) that shows at the
//! bottom and top faces; 7/8 in the layer keeps every layer within ~0.015 (layer 0) and 0.002 (inside) of the
//! share and low-passes to 0.0029-0.0036 (blue noise 0.0038-0.0053, random 0.015-0.022; 1/4 down 0.0041-0.0043,
//! 1/16 down 0.0034-0.0037, all in the layer (2D Floyd–Steinberg per layer) 0.0053-0.0094).
//!
//! Local error: the ink counts of a window differ from its summed mixture only by the residuals that cross its
//! boundary (weights are non-negative and sum to 1, so error is conserved); with two inks every residual
//! component is in [-1/2, 1/2] (`tests/printing/test_diffuse.py` derives the window bound).
//!
//! Voxels outside the object (`inside == 0`) get [`EMPTY`] and neither take nor pass error: a voxel's weights
//! are renormalised over its neighbours that exist and are inside (if none, its residual is dropped), so error
//! is conserved up to the object's boundary. Memory: the caller keeps two (ny, nx, n) f32 error planes (this
//! layer's and the next one's); the mixture of one layer at a time. Sequential and deterministic.

use crate::transport::medium::EMPTY;

/// (dx in sweep direction, dy, weight in 128ths) within the layer; Floyd–Steinberg.
const IN_LAYER: [(i64, i64, f32); 4] = [(1, 0, 49.0), (-1, 1, 21.0), (0, 1, 35.0), (1, 1, 7.0)];
/// (dx, dy, weight in 128ths) on the next layer.
const NEXT_LAYER: [(i64, i64, f32); 5] = [(0, 0, 8.0), (-1, 0, 2.0), (1, 0, 2.0), (0, -1, 2.0), (0, 1, 2.0)];

/// Shape of a printer layer: `n` inks on an `ny` × `nx` grid.
#[derive(Clone, Copy, Debug)]
pub struct LayerShape {
    pub n: usize,
    pub ny: usize,
    pub nx: usize,
}

impl LayerShape {
    fn check(
        &self,
        mixture: &[f32],
        inside: &[u8],
        inside_next: &[u8],
        err: &[f32],
        err_next: &[f32],
        out: &[u8],
    ) -> Result<(), String> {
        let (n, m) = (self.n, self.ny * self.nx);
        if n == 0 || n >= EMPTY as usize {
            return Err(format!("need 1 to {} inks, got {n}", EMPTY as usize - 1));
        }
        let want = [
            (mixture.len(), n * m, "mixture"),
            (inside.len(), m, "inside"),
            (inside_next.len(), m, "inside_next"),
            (err.len(), n * m, "error"),
            (err_next.len(), n * m, "error_next"),
            (out.len(), m, "labels"),
        ];
        for (got, expect, name) in want {
            if got != expect {
                return Err(format!("{name} has {got} elements, expected {expect}"));
            }
        }
        Ok(())
    }
}

/// Error-diffuse printer layer `z`.
///
/// `mixture` (n, ny, nx) planar, rows summing to 1 where inside; `inside`, `inside_next` (ny, nx), nonzero =
/// inside, for this layer and the next (all zero after the last layer); `err` (ny, nx, n): the error carried
/// into this layer (it receives this layer's own diffusion too, and is zeroed on return, ready to be the next
/// call's `err_next`); `err_next` (ny, nx, n): accumulates the error for layer z + 1 (zero before the first
/// call that writes it); `out` (ny, nx): ink index or [`EMPTY`].
pub fn diffuse_layer(
    shape: LayerShape,
    z: usize,
    mixture: &[f32],
    inside: &[u8],
    inside_next: &[u8],
    err: &mut [f32],
    err_next: &mut [f32],
    out: &mut [u8],
) -> Result<(), String> {
    shape.check(mixture, inside, inside_next, err, err_next, out)?;
    let LayerShape { n, ny, nx } = shape;
    let plane = ny * nx;
    let mut r = vec![0.0f32; n];
    for y in 0..ny {
        let d: i64 = if (y + z).is_multiple_of(2) { 1 } else { -1 };
        for step in 0..nx {
            let x = if d > 0 { step } else { nx - 1 - step };
            let i = y * nx + x;
            if inside[i] == 0 {
                out[i] = EMPTY;
                err[i * n..(i + 1) * n].fill(0.0);
                continue;
            }
            let e = &err[i * n..(i + 1) * n];
            let mut best = 0;
            let mut best_u = f32::NEG_INFINITY;
            for k in 0..n {
                let u = mixture[k * plane + i] + e[k];
                r[k] = u;
                if u > best_u {
                    best_u = u;
                    best = k;
                }
            }
            r[best] -= 1.0;
            out[i] = best as u8;
            // neighbours that exist, are inside and unvisited; weights renormalised over them
            let at = |dx: i64, dy: i64| -> Option<usize> {
                let (xx, yy) = (x as i64 + dx, y as i64 + dy);
                (xx >= 0 && yy >= 0 && (xx as usize) < nx && (yy as usize) < ny).then(|| yy as usize * nx + xx as usize)
            };
            let mut targets: [(usize, bool, f32); 9] = [(0, false, 0.0); 9];
            let mut cnt = 0;
            let mut total = 0.0f32;
            for &(dx, dy, w) in &IN_LAYER {
                if let Some(j) = at(dx * d, dy).filter(|&j| inside[j] != 0) {
                    targets[cnt] = (j, false, w);
                    cnt += 1;
                    total += w;
                }
            }
            for &(dx, dy, w) in &NEXT_LAYER {
                if let Some(j) = at(dx, dy).filter(|&j| inside_next[j] != 0) {
                    targets[cnt] = (j, true, w);
                    cnt += 1;
                    total += w;
                }
            }
            for &(j, next, w) in &targets[..cnt] {
                let dst = if next { &mut err_next[j * n..(j + 1) * n] } else { &mut err[j * n..(j + 1) * n] };
                let f = w / total;
                for k in 0..n {
                    dst[k] += f * r[k];
                }
            }
            err[i * n..(i + 1) * n].fill(0.0);
        }
    }
    Ok(())
}

/// Error-diffuse a whole volume: `mixture` (nz, n, ny, nx) (layer-major, each layer planar), `inside`
/// (nz, ny, nx). Returns labels (nz, ny, nx). For tests and small volumes; the Python package streams layers
/// through [`diffuse_layer`].
pub fn diffuse_volume(shape: LayerShape, nz: usize, mixture: &[f32], inside: &[u8]) -> Result<Vec<u8>, String> {
    let (m, n) = (shape.ny * shape.nx, shape.n);
    if mixture.len() != nz * n * m || inside.len() != nz * m {
        return Err(format!(
            "mixture / inside sizes {} / {} do not match {nz} layers of {shape:?}",
            mixture.len(),
            inside.len()
        ));
    }
    let mut out = vec![0u8; nz * m];
    let (mut err, mut err_next) = (vec![0.0f32; n * m], vec![0.0f32; n * m]);
    let none = vec![0u8; m];
    for z in 0..nz {
        let nxt = if z + 1 < nz { &inside[(z + 1) * m..(z + 2) * m] } else { &none[..] };
        diffuse_layer(
            shape,
            z,
            &mixture[z * n * m..(z + 1) * n * m],
            &inside[z * m..(z + 1) * m],
            nxt,
            &mut err,
            &mut err_next,
            &mut out[z * m..(z + 1) * m],
        )?;
        std::mem::swap(&mut err, &mut err_next);
    }
    Ok(out)
}

#[cfg(test)]
mod tests {
    use super::*;

    fn uniform(shape: LayerShape, nz: usize, p: &[f32]) -> Vec<f32> {
        let m = shape.ny * shape.nx;
        (0..nz).flat_map(|_| p.iter().flat_map(move |&v| std::iter::repeat_n(v, m))).collect()
    }

    fn counts(labels: &[u8], n: usize) -> Vec<usize> {
        let mut c = vec![0usize; n + 1];
        for &l in labels {
            c[if l == EMPTY { n } else { l as usize }] += 1;
        }
        c
    }

    #[test]
    fn weights_sum_to_one() {
        let s: f32 = IN_LAYER.iter().chain(NEXT_LAYER.iter()).map(|t| t.2).sum();
        assert_eq!(s, 128.0);
    }

    #[test]
    fn uniform_counts_match_mixture() {
        let shape = LayerShape { n: 4, ny: 40, nx: 60 };
        let nz = 30;
        let p = [0.1f32, 0.23, 0.3, 0.37];
        let lab = diffuse_volume(shape, nz, &uniform(shape, nz, &p), &vec![1u8; nz * 2400]).unwrap();
        let c = counts(&lab, 4);
        let total = lab.len() as f32;
        for k in 0..4 {
            // error is conserved inside the box: only the last voxel's residual is dropped
            assert!((c[k] as f32 - p[k] * total).abs() <= 1.5, "{k}: {} vs {}", c[k], p[k] * total);
        }
        assert_eq!(c[4], 0);
    }

    #[test]
    fn pure_ink_outside_and_deterministic() {
        let shape = LayerShape { n: 3, ny: 9, nx: 11 };
        let nz = 5;
        let mut mix = uniform(shape, nz, &[0.0, 1.0, 0.0]);
        let m = 99;
        let inside: Vec<u8> = (0..nz * m).map(|i| u8::from(i % 7 != 3)).collect();
        for (i, &ins) in inside.iter().enumerate() {
            if ins == 0 {
                let (z, j) = (i / m, i % m);
                for k in 0..3 {
                    mix[z * 3 * m + k * m + j] = 0.0;
                }
            }
        }
        let lab = diffuse_volume(shape, nz, &mix, &inside).unwrap();
        for (l, &ins) in lab.iter().zip(&inside) {
            assert_eq!(*l, if ins != 0 { 1 } else { EMPTY });
        }
        let mix2 = uniform(shape, nz, &[0.3, 0.5, 0.2]);
        let a = diffuse_volume(shape, nz, &mix2, &inside).unwrap();
        assert_eq!(a, diffuse_volume(shape, nz, &mix2, &inside).unwrap());
    }

    #[test]
    fn two_inks_total_within_half_a_voxel() {
        // error is conserved inside the box except the very last voxel's residual, and with two inks every
        // residual is in [-1/2, 1/2]: the total count of each ink is within 1/2 of the expected (+ f32 rounding)
        let shape = LayerShape { n: 2, ny: 16, nx: 24 };
        let nz = 16;
        for &p in &[0.01f32, 0.137, 0.5, 0.77] {
            let lab = diffuse_volume(shape, nz, &uniform(shape, nz, &[p, 1.0 - p]), &vec![1u8; nz * 384]).unwrap();
            let c0 = counts(&lab, 2)[0] as f64;
            assert!((c0 - p as f64 * lab.len() as f64).abs() <= 0.51, "{p} {c0}");
        }
    }

    #[test]
    fn bad_sizes() {
        let shape = LayerShape { n: 2, ny: 2, nx: 2 };
        let (mut e, mut en, mut o) = (vec![0.0; 8], vec![0.0; 8], vec![0u8; 4]);
        assert!(diffuse_layer(shape, 0, &[0.5; 7], &[1; 4], &[1; 4], &mut e, &mut en, &mut o).is_err());
        let no_inks = LayerShape { n: 0, ..shape };
        assert!(diffuse_layer(no_inks, 0, &[], &[1; 4], &[1; 4], &mut e, &mut en, &mut o).is_err());
    }

    #[test]
    fn a_large_volume_gets_a_label_per_voxel() {
        // 2.5 M printer voxels, 5 inks (its time is a benchmark's, not this test's)
        let shape = LayerShape { n: 5, ny: 118, nx: 354 };
        let nz = 60;
        let mix = uniform(shape, nz, &[0.1, 0.2, 0.3, 0.15, 0.25]);
        let lab = diffuse_volume(shape, nz, &mix, &vec![1u8; nz * 118 * 354]).unwrap();
        assert_eq!(lab.len(), nz * 118 * 354);
    }
}
