//! The exponentiated-gradient optimiser's element-wise work (`python/inkopt/optim/optimizers.py`): the momentum
//! step over every variable and the order statistics of |g| that set its step scale.
//!
//! The momentum step, in f32 and in this order (the order numpy evaluates the same expression in, so the two agree
//! bit for bit):
//!
//! ```text
//!   m'[i] = beta m[i] + (1 - beta) g[i]
//!   x'[i] = x[i] - (lr (m'[i] / bias)) / scale
//! ```
//!
//! The order statistics of |g| come from a two-pass radix selection on the bit patterns of |g| (the patterns of
//! non-negative floats sort as the floats do): a histogram of their upper 16 bits finds the bucket holding each
//! asked-for rank, a histogram of the lower 16 bits inside that bucket the value. No copy of g is made (numpy's
//! percentile partitions a full copy of |g|), and the counts are exact, so the result is the same for any thread
//! count.

use rayon::prelude::*;

/// Elements per parallel block.
const BLOCK: usize = 1 << 16;
/// Buckets of each radix pass (16 bits).
const BUCKETS: usize = 1 << 16;

/// The momentum step (module docs): writes `x_out` and `m_out` from `x`, `m` and `g` (all the same length).
#[allow(clippy::too_many_arguments)]
pub fn momentum_step(
    x: &[f32],
    m: &[f32],
    g: &[f32],
    beta: f64,
    lr: f64,
    bias: f64,
    scale: f32,
    x_out: &mut [f32],
    m_out: &mut [f32],
) -> Result<(), String> {
    let n = x.len();
    for (name, len) in [("m", m.len()), ("g", g.len()), ("x_out", x_out.len()), ("m_out", m_out.len())] {
        if len != n {
            return Err(format!("{name} has {len} values, x has {n}"));
        }
    }
    // numpy's scalar casts: each Python float meets an f32 array as an f32 (1 - beta is formed in f64 first)
    let (b, ob, lr, bias) = (beta as f32, (1.0 - beta) as f32, lr as f32, bias as f32);
    x_out.par_chunks_mut(BLOCK).zip(m_out.par_chunks_mut(BLOCK)).enumerate().for_each(|(c, (xo, mo))| {
        let lo = c * BLOCK;
        let (xs, ms, gs) = (&x[lo..lo + xo.len()], &m[lo..lo + xo.len()], &g[lo..lo + xo.len()]);
        for i in 0..xo.len() {
            let mi = b * ms[i] + ob * gs[i];
            mo[i] = mi;
            xo[i] = xs[i] - (lr * (mi / bias)) / scale;
        }
    });
    Ok(())
}

/// Bucket counts of `key(bits of |v|)` over the values whose bits pass `keep`.
fn histogram(values: &[f32], key: impl Fn(u32) -> usize + Sync, keep: impl Fn(u32) -> bool + Sync) -> Vec<u64> {
    values
        .par_chunks(BLOCK)
        .fold(
            || vec![0u64; BUCKETS],
            |mut h, chunk| {
                for v in chunk {
                    let bits = v.to_bits() & 0x7fff_ffff;
                    if keep(bits) {
                        h[key(bits)] += 1;
                    }
                }
                h
            },
        )
        .reduce(
            || vec![0u64; BUCKETS],
            |mut a, b| {
                a.iter_mut().zip(&b).for_each(|(x, y)| *x += y);
                a
            },
        )
}

/// The bucket holding rank `r` (0-based) of a histogram, and r's rank inside it.
fn bucket_of(h: &[u64], r: u64) -> (usize, u64) {
    let mut before = 0u64;
    for (k, &c) in h.iter().enumerate() {
        if r < before + c {
            return (k, r - before);
        }
        before += c;
    }
    unreachable!("rank {r} beyond the {before} counted values")
}

/// The values of |v| at the given ranks (0-based, each < v.len()) of |v| sorted increasingly; NaN if v holds a NaN.
pub fn abs_order_statistics(values: &[f32], ranks: &[usize]) -> Result<Vec<f32>, String> {
    let n = values.len();
    if let Some(&r) = ranks.iter().find(|&&r| r >= n) {
        return Err(format!("rank {r} of {n} values"));
    }
    if values.par_iter().any(|v| v.is_nan()) {
        return Ok(vec![f32::NAN; ranks.len()]);
    }
    let high = histogram(values, |b| (b >> 16) as usize, |_| true);
    let mut out = Vec::with_capacity(ranks.len());
    let mut low: Option<(usize, Vec<u64>)> = None; // the last bucket's lower-bit histogram (neighbouring ranks share it)
    for &r in ranks {
        let (bucket, inner) = bucket_of(&high, r as u64);
        if low.as_ref().is_none_or(|(k, _)| *k != bucket) {
            let h = histogram(values, |b| (b & 0xffff) as usize, |b| (b >> 16) as usize == bucket);
            low = Some((bucket, h));
        }
        let (lower, _) = bucket_of(&low.as_ref().unwrap().1, inner);
        out.push(f32::from_bits(((bucket as u32) << 16) | lower as u32));
    }
    Ok(out)
}

#[cfg(test)]
mod tests {
    use super::*;

    fn values(n: usize) -> Vec<f32> {
        // signed values over many binades, with ties and zeros
        (0..n)
            .map(|i| {
                let u = (i * 7919 % 10007) as f32 / 10007.0 - 0.5;
                match i % 13 {
                    0 => 0.0,
                    1 => -0.25,
                    _ => u * (1.0 + (i % 7) as f32).exp2() * if i % 5 == 0 { 1e-4 } else { 1.0 },
                }
            })
            .collect()
    }

    #[test]
    fn order_statistics_match_a_sort() {
        for n in [1usize, 2, 17, 70_001, 200_003] {
            let v = values(n);
            let mut sorted: Vec<f32> = v.iter().map(|x| x.abs()).collect();
            sorted.sort_by(f32::total_cmp);
            let ranks: Vec<usize> = [0, n / 3, n * 99 / 100, (n * 99 / 100 + 1).min(n - 1), n - 1].to_vec();
            let got = abs_order_statistics(&v, &ranks).unwrap();
            for (&r, g) in ranks.iter().zip(&got) {
                assert_eq!(g.to_bits(), sorted[r].to_bits(), "n {n} rank {r}");
            }
        }
    }

    #[test]
    fn order_statistics_edge_cases() {
        assert!(abs_order_statistics(&[1.0, 2.0], &[2]).is_err());
        assert!(abs_order_statistics(&[1.0, f32::NAN], &[0]).unwrap().iter().all(|v| v.is_nan()));
        assert_eq!(abs_order_statistics(&[-0.0, 3.0, -2.0], &[0, 1, 2]).unwrap(), vec![0.0, 2.0, 3.0]);
        assert_eq!(abs_order_statistics(&[5.0, f32::INFINITY], &[1]).unwrap(), vec![f32::INFINITY]);
    }

    #[test]
    fn momentum_step_matches_the_formula_in_f64() {
        let n = 150_001;
        let (x, m, g) = (values(n), values(n + 3)[3..].to_vec(), values(n + 7)[7..].to_vec());
        let (mut xo, mut mo) = (vec![0.0; n], vec![0.0; n]);
        let (beta, lr, bias, scale) = (0.8f64, 0.5f64, 1.0 - 0.8f64.powi(3), 0.37f32);
        momentum_step(&x, &m, &g, beta, lr, bias, scale, &mut xo, &mut mo).unwrap();
        for i in 0..n {
            let mi = beta * m[i] as f64 + (1.0 - beta) * g[i] as f64;
            let xi = x[i] as f64 - lr * (mi / bias) / scale as f64;
            // f32 rounding of each operation: a few ulp (6e-8 relative each) of the largest term
            let tm = (m[i].abs() + g[i].abs()) as f64;
            let tx = x[i].abs() as f64 + lr * tm / bias / scale as f64;
            assert!((mo[i] as f64 - mi).abs() <= 4e-7 * tm, "m {i}: {} vs {mi}", mo[i]);
            assert!((xo[i] as f64 - xi).abs() <= 8e-7 * tx, "x {i}: {} vs {xi}", xo[i]);
        }
        assert!(momentum_step(&x, &m[1..], &g, 0.8, 0.5, 1.0, 1.0, &mut xo, &mut mo).is_err());
    }

    #[test]
    fn same_bits_for_any_thread_count() {
        let n = 300_007;
        let (x, m, g) = (values(n), values(n + 1)[1..].to_vec(), values(n + 2)[2..].to_vec());
        let run = |threads: usize| {
            let (mut xo, mut mo) = (vec![0.0; n], vec![0.0; n]);
            rayon::ThreadPoolBuilder::new().num_threads(threads).build().unwrap().install(|| {
                momentum_step(&x, &m, &g, 0.8, 1.0, 0.2, 2.0, &mut xo, &mut mo).unwrap();
                (xo, mo, abs_order_statistics(&g, &[n / 2, n - 9]).unwrap())
            })
        };
        assert_eq!(run(1), run(3));
    }
}
