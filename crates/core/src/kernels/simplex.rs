//! Row-wise softmax of the optimiser's variables and its backward map (`python/inkopt/optim/param.py`, the
//! softmax parameterisation of each free voxel's mixture).
//!
//! `x` holds `rows × n` logits, row r the variables of one voxel. The forward map is
//!
//! ```text
//!   p[r, k] = exp(x[r, k] - max_j x[r, j]) / sum_j exp(x[r, j] - max_j x[r, j])
//! ```
//!
//! and the backward map takes a gradient `g = dE/dp` (scaled per row by `scale[r]`, the voxel's free share) to
//!
//! ```text
//!   c[r, k] = scale[r] g[r, k] - sum_j scale[r] g[r, j] p[r, j]     (the natural, exponentiated-gradient direction)
//!   dE/dx[r, k] = p[r, k] c[r, k]                                  (the Euclidean gradient)
//! ```
//!
//! Every row is computed on its own in a fixed order (f32, rows in parallel), so the result does not depend on
//! the thread count.

use rayon::prelude::*;

/// Rows per parallel block.
const BLOCK: usize = 4096;

fn check(x: &[f32], n: usize, others: &[(&str, usize)]) -> Result<usize, String> {
    if n == 0 || !x.len().is_multiple_of(n) {
        return Err(format!("x ({} values) is not a whole number of rows of {n}", x.len()));
    }
    for &(name, len) in others {
        if len != x.len() {
            return Err(format!("{name} has {len} values, x has {}", x.len()));
        }
    }
    Ok(x.len() / n)
}

/// One row's softmax into `p` (same length as `x`).
#[inline]
fn softmax_row(x: &[f32], p: &mut [f32]) {
    let m = x.iter().copied().fold(f32::NEG_INFINITY, f32::max);
    let mut s = 0.0f32;
    for (pk, &xk) in p.iter_mut().zip(x) {
        *pk = (xk - m).exp();
        s += *pk;
    }
    for pk in p.iter_mut() {
        *pk /= s;
    }
}

/// p = softmax of each row of `x` (rows × `n`), written into `p`.
pub fn softmax_rows(x: &[f32], n: usize, p: &mut [f32]) -> Result<(), String> {
    check(x, n, &[("p", p.len())])?;
    p.par_chunks_mut(BLOCK * n).zip(x.par_chunks(BLOCK * n)).for_each(|(pb, xb)| {
        for (pr, xr) in pb.chunks_exact_mut(n).zip(xb.chunks_exact(n)) {
            softmax_row(xr, pr);
        }
    });
    Ok(())
}

/// The backward map of [`softmax_rows`] (module docs): `out` = the natural direction c if `natural`, else p c,
/// from logits `x` and `g` = dE/dp (both rows × `n`) and the per-row `scale` (rows).
pub fn softmax_backward(
    x: &[f32],
    g: &[f32],
    scale: &[f32],
    n: usize,
    natural: bool,
    out: &mut [f32],
) -> Result<(), String> {
    let rows = check(x, n, &[("g", g.len()), ("out", out.len())])?;
    if scale.len() != rows {
        return Err(format!("scale has {} values for {rows} rows", scale.len()));
    }
    out.par_chunks_mut(BLOCK * n).enumerate().for_each(|(b, ob)| {
        let mut p = vec![0.0f32; n];
        for (k, or) in ob.chunks_exact_mut(n).enumerate() {
            let r = b * BLOCK + k;
            let (xr, gr, s) = (&x[r * n..(r + 1) * n], &g[r * n..(r + 1) * n], scale[r]);
            softmax_row(xr, &mut p);
            let dot: f32 = gr.iter().zip(&p).map(|(&gk, &pk)| s * gk * pk).sum();
            for ((ok, &gk), &pk) in or.iter_mut().zip(gr).zip(&p) {
                let c = s * gk - dot;
                *ok = if natural { c } else { pk * c };
            }
        }
    });
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    fn rows() -> (Vec<f32>, Vec<f32>, Vec<f32>) {
        // 9 001 rows of 5 (more than two blocks, a partial last one), spread logits incl. large ones
        let n = 5usize;
        let r = 9001;
        let x: Vec<f32> = (0..r * n)
            .map(|i| ((i * 7919 % 1000) as f32 / 50.0 - 10.0) * if i % 11 == 0 { 9.0 } else { 1.0 })
            .collect();
        let g: Vec<f32> = (0..r * n).map(|i| (i * 104_729 % 997) as f32 / 997.0 - 0.5).collect();
        let s: Vec<f32> = (0..r).map(|i| 0.2 + (i % 9) as f32 / 10.0).collect();
        (x, g, s)
    }

    #[test]
    fn softmax_is_a_distribution_and_matches_f64() {
        let (x, _, _) = rows();
        let mut p = vec![0.0; x.len()];
        softmax_rows(&x, 5, &mut p).unwrap();
        for (pr, xr) in p.chunks(5).zip(x.chunks(5)) {
            let m = xr.iter().copied().fold(f64::NEG_INFINITY, |a, b| a.max(b as f64));
            let e: Vec<f64> = xr.iter().map(|&v| (v as f64 - m).exp()).collect();
            let s: f64 = e.iter().sum();
            assert!((pr.iter().sum::<f32>() - 1.0).abs() < 1e-5);
            for (a, b) in pr.iter().zip(&e) {
                // f32 rounding of exp, the sum and the product: a few ulp of 1
                assert!((*a as f64 - b / s).abs() < 1e-6, "{a} vs {}", b / s);
            }
        }
    }

    #[test]
    fn backward_matches_finite_differences() {
        // E = sum_k w_k p_k scaled by s: dE/dp = w; the Euclidean output is d(s * sum w p)/dx (f64 differences)
        let (x, g, s) = rows();
        let mut out = vec![0.0; x.len()];
        softmax_backward(&x, &g, &s, 5, false, &mut out).unwrap();
        let p64 = |xr: &[f64]| {
            let m = xr.iter().copied().fold(f64::NEG_INFINITY, f64::max);
            let e: Vec<f64> = xr.iter().map(|v| (v - m).exp()).collect();
            let t: f64 = e.iter().sum();
            e.into_iter().map(|v| v / t).collect::<Vec<f64>>()
        };
        for r in (0..9001).step_by(97) {
            let xr: Vec<f64> = x[r * 5..r * 5 + 5].iter().map(|&v| v as f64).collect();
            let e = |xv: &[f64]| -> f64 {
                p64(xv).iter().zip(&g[r * 5..r * 5 + 5]).map(|(p, &w)| s[r] as f64 * p * w as f64).sum()
            };
            for k in 0..5 {
                let h = 1e-6;
                let (mut a, mut b) = (xr.clone(), xr.clone());
                a[k] += h;
                b[k] -= h;
                let fd = (e(&a) - e(&b)) / (2.0 * h);
                // f32 arithmetic on values of order 1: ~1e-6 absolute; the f64 central difference's error is ~1e-9
                assert!((out[r * 5 + k] as f64 - fd).abs() < 2e-6, "row {r} ink {k}: {} vs {fd}", out[r * 5 + k]);
            }
        }
    }

    #[test]
    fn natural_direction_is_centred_and_times_p_gives_the_gradient() {
        let (x, g, s) = rows();
        let (mut nat, mut euc, mut p) = (vec![0.0; x.len()], vec![0.0; x.len()], vec![0.0; x.len()]);
        softmax_backward(&x, &g, &s, 5, true, &mut nat).unwrap();
        softmax_backward(&x, &g, &s, 5, false, &mut euc).unwrap();
        softmax_rows(&x, 5, &mut p).unwrap();
        for i in 0..x.len() {
            assert_eq!(euc[i], p[i] * nat[i]);
        }
        for (cr, pr) in nat.chunks(5).zip(p.chunks(5)) {
            // <c, p> = 0 up to the f32 rounding of terms of order 1
            assert!(cr.iter().zip(pr).map(|(c, p)| c * p).sum::<f32>().abs() < 1e-5);
        }
    }

    #[test]
    fn same_bits_for_any_thread_count() {
        let (x, g, s) = rows();
        let run = |threads: usize| {
            let (mut p, mut c) = (vec![0.0; x.len()], vec![0.0; x.len()]);
            rayon::ThreadPoolBuilder::new().num_threads(threads).build().unwrap().install(|| {
                softmax_rows(&x, 5, &mut p).unwrap();
                softmax_backward(&x, &g, &s, 5, true, &mut c).unwrap();
            });
            (p, c)
        };
        assert_eq!(run(1), run(3));
    }

    #[test]
    fn bad_sizes_are_errors() {
        let mut p = vec![0.0; 6];
        assert!(softmax_rows(&[0.0; 7], 3, &mut p).is_err());
        assert!(softmax_rows(&[0.0; 6], 0, &mut p).is_err());
        assert!(softmax_rows(&[0.0; 6], 3, &mut p[..3]).is_err());
        assert!(softmax_backward(&[0.0; 6], &[0.0; 6], &[1.0], 3, true, &mut p).is_err());
        assert!(softmax_backward(&[0.0; 6], &[0.0; 3], &[1.0, 1.0], 3, true, &mut p).is_err());
    }
}
