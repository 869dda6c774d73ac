//! Sampling routines: Henyey-Greenstein phase function, dielectric Fresnel, reflection and refraction.
//! Directions are unit `[f32; 3]` vectors (x, y, z).

pub type V3 = [f32; 3];

#[inline(always)]
pub fn dot(a: V3, b: V3) -> f32 {
    a[0] * b[0] + a[1] * b[1] + a[2] * b[2]
}

#[inline(always)]
pub fn scale(a: V3, s: f32) -> V3 {
    [a[0] * s, a[1] * s, a[2] * s]
}

#[inline(always)]
pub fn add(a: V3, b: V3) -> V3 {
    [a[0] + b[0], a[1] + b[1], a[2] + b[2]]
}

#[inline(always)]
pub fn normalize(a: V3) -> V3 {
    scale(a, 1.0 / dot(a, a).sqrt())
}

/// An orthonormal basis (s, t) perpendicular to unit n (Duff et al. 2017).
#[inline(always)]
pub fn basis(n: V3) -> (V3, V3) {
    let sign = if n[2] >= 0.0 { 1.0f32 } else { -1.0 };
    let a = -1.0 / (sign + n[2]);
    let b = n[0] * n[1] * a;
    ([1.0 + sign * n[0] * n[0] * a, sign * b, -sign * n[0]], [b, sign + n[1] * n[1] * a, -n[1]])
}

/// Henyey-Greenstein pdf (per steradian) of the cosine between the old and the new direction.
pub fn hg_pdf(cos_theta: f32, g: f32) -> f32 {
    let denom = 1.0 + g * g - 2.0 * g * cos_theta;
    (1.0 - g * g) / (4.0 * std::f32::consts::PI * denom * denom.sqrt())
}

/// Cosine of the scattering angle, distributed by HG with parameter g, from a uniform u in [0, 1).
#[inline(always)]
pub fn hg_sample_cos(g: f32, u: f32) -> f32 {
    if g.abs() < 1e-3 {
        return 1.0 - 2.0 * u;
    }
    let sq = (1.0 - g * g) / (1.0 - g + 2.0 * g * u);
    ((1.0 + g * g - sq * sq) / (2.0 * g)).clamp(-1.0, 1.0)
}

/// (sin, cos) of 2 pi u for u in [0, 1): odd/even minimax-style Taylor polynomials on [-pi/8, pi/8] after
/// octant reduction; absolute error below 1e-6 (tested), far below the 2^-24 resolution of the azimuth sample
/// and any Monte Carlo noise.
#[inline(always)]
pub fn sin_cos_2pi(u: f32) -> (f32, f32) {
    // Octant k (the nearest multiple of pi/4) and the remainder angle x in [-pi/8, pi/8].
    let t = u * 8.0;
    let k = (t + 0.5).floor();
    let x = (t - k) * (std::f32::consts::PI / 4.0);
    let x2 = x * x;
    let s = x * (1.0 + x2 * (-1.0 / 6.0 + x2 * (1.0 / 120.0 + x2 * (-1.0 / 5040.0))));
    let c = 1.0 + x2 * (-0.5 + x2 * (1.0 / 24.0 + x2 * (-1.0 / 720.0 + x2 * (1.0 / 40320.0))));
    // Rotate by k * pi/4: by pi/4 for odd k, then by q * pi/2 (q = k / 2 mod 4: a swap and sign flips), with
    // selects and sign bits rather than a jump on the random octant (a mispredicted branch per scattering).
    let h = std::f32::consts::FRAC_1_SQRT_2;
    let k = k as i32;
    let odd = k & 1 == 1;
    let (s1, c1) = (if odd { h * (s + c) } else { s }, if odd { h * (c - s) } else { c });
    let q = (k >> 1) & 3;
    let (a, b) = if q & 1 == 1 { (c1, s1) } else { (s1, c1) };
    // q = 0: (a, b); 1: (c1, -s1); 2: (-s1, -c1); 3: (-c1, s1).
    let flip = |x: f32, neg: bool| f32::from_bits(x.to_bits() ^ ((neg as u32) << 31));
    (flip(a, q >= 2), flip(b, q == 1 || q == 2))
}

/// New direction after HG scattering of direction d.
#[inline(always)]
pub fn hg_sample(d: V3, g: f32, u1: f32, u2: f32) -> V3 {
    let c = hg_sample_cos(g, u1);
    let s = (1.0 - c * c).max(0.0).sqrt();
    let (b1, b2) = basis(d);
    let (sp, cp) = sin_cos_2pi(u2);
    let w = add(add(scale(b1, s * cp), scale(b2, s * sp)), scale(d, c));
    // |w| = 1 up to rounding: one Newton step of 1/sqrt keeps it unit without a square root or division.
    scale(w, 0.5 * (3.0 - dot(w, w)))
}

/// Unpolarised Fresnel reflectance of a smooth dielectric for incidence cosine `cos_i` (> 0) and relative index
/// `eta` = n_incident / n_transmitted. Returns 1 under total internal reflection.
#[inline(always)]
pub fn fresnel(cos_i: f32, eta: f32) -> f32 {
    let sin_t2 = eta * eta * (1.0 - cos_i * cos_i).max(0.0);
    if sin_t2 >= 1.0 {
        return 1.0;
    }
    let cos_t = (1.0 - sin_t2).sqrt();
    let rs = (eta * cos_i - cos_t) / (eta * cos_i + cos_t);
    let rp = (cos_i - eta * cos_t) / (cos_i + eta * cos_t);
    0.5 * (rs * rs + rp * rp)
}

/// Mirror direction of d about the unit normal n.
#[inline(always)]
pub fn reflect(d: V3, n: V3) -> V3 {
    add(d, scale(n, -2.0 * dot(d, n)))
}

/// Refracted direction of d through a surface with unit normal n facing the incident side (dot(d, n) < 0),
/// relative index eta = n_i / n_t. None under total internal reflection.
#[inline(always)]
pub fn refract(d: V3, n: V3, eta: f32) -> Option<V3> {
    let cos_i = -dot(d, n);
    let sin_t2 = eta * eta * (1.0 - cos_i * cos_i).max(0.0);
    if sin_t2 >= 1.0 {
        return None;
    }
    let cos_t = (1.0 - sin_t2).sqrt();
    Some(normalize(add(scale(d, eta), scale(n, eta * cos_i - cos_t))))
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::transport::rng::PathRng;

    /// Histogram of sampled HG cosines against the integral of the pdf over each bin.
    /// Bins of 50k expected counts have a relative standard error of 0.45 %; we test each at 5 sigma.
    #[test]
    fn hg_histogram_matches_pdf() {
        for &g in &[0.4f32, -0.3, 0.85, 0.0] {
            let bins = 20;
            let n = 1_000_000usize;
            let mut hist = vec![0usize; bins];
            for i in 0..n {
                let mut r = PathRng::new(3, i as u64, 0, 0);
                let c = hg_sample_cos(g, r.next_f32());
                hist[(((c + 1.0) * 0.5 * bins as f32) as usize).min(bins - 1)] += 1;
            }
            for b in 0..bins {
                // Integrate 2 pi * pdf over the bin with Simpson's rule on 64 sub-intervals.
                let (lo, hi) = (-1.0 + 2.0 * b as f64 / bins as f64, -1.0 + 2.0 * (b + 1) as f64 / bins as f64);
                let m = 64;
                let h = (hi - lo) / m as f64;
                let mut acc = 0.0;
                for k in 0..=m {
                    let w = if k == 0 || k == m {
                        1.0
                    } else if k % 2 == 1 {
                        4.0
                    } else {
                        2.0
                    };
                    acc += w * 2.0 * std::f64::consts::PI * hg_pdf((lo + k as f64 * h) as f32, g) as f64;
                }
                let expect = acc * h / 3.0 * n as f64;
                let sd = expect.sqrt();
                assert!((hist[b] as f64 - expect).abs() < 5.0 * sd + 1.0, "g={g} bin {b}: {} vs {expect}", hist[b]);
            }
        }
    }

    #[test]
    fn hg_mean_cosine_is_g() {
        // E[cos] = g; Var[cos] <= 1, n = 4e5: standard error <= 1.6e-3, tested at 4 sigma.
        let n = 400_000;
        for &g in &[0.4f32, 0.9, -0.5] {
            let d = normalize([0.3, -0.2, 0.9]);
            let mut s = 0.0f64;
            for i in 0..n {
                let mut r = PathRng::new(5, i as u64, 1, 0);
                let w = hg_sample(d, g, r.next_f32(), r.next_f32());
                assert!((dot(w, w) - 1.0).abs() < 1e-5);
                s += dot(w, d) as f64;
            }
            assert!((s / n as f64 - g as f64).abs() < 6.5e-3, "g={g}: {}", s / n as f64);
        }
    }

    #[test]
    fn sin_cos_2pi_is_accurate() {
        for i in 0..100_000 {
            let u = i as f32 / 100_000.0;
            let (s, c) = sin_cos_2pi(u);
            let (s0, c0) = (2.0 * std::f64::consts::PI * u as f64).sin_cos();
            assert!((s as f64 - s0).abs() < 1e-6 && (c as f64 - c0).abs() < 1e-6, "u={u}: {s},{c} vs {s0},{c0}");
        }
    }

    #[test]
    fn fresnel_known_values() {
        // Normal incidence: ((n1-n2)/(n1+n2))^2 = 0.04 for 1 -> 1.5, from either side.
        assert!((fresnel(1.0, 1.0 / 1.5) - 0.04).abs() < 1e-6);
        assert!((fresnel(1.0, 1.5) - 0.04).abs() < 1e-6);
        // Total internal reflection beyond the critical angle asin(1/1.5) = 41.8 deg.
        assert_eq!(fresnel((45f32).to_radians().cos(), 1.5), 1.0);
        // Grazing incidence reflects everything.
        assert!(fresnel(1e-6, 1.0 / 1.5) > 0.999);
        // Index-matched: no reflection.
        assert!(fresnel(0.3, 1.0) < 1e-12);
        // Brewster angle atan(1.5): rp = 0, so R = rs^2 / 2 = 0.0740 (hand-computed).
        let cb = (1.5f32).atan().cos();
        assert!((fresnel(cb, 1.0 / 1.5) - 0.07396).abs() < 2e-4);
    }

    #[test]
    fn refraction_obeys_snell() {
        let n = [0.0, 0.0, 1.0];
        let d = normalize([0.5, 0.1, -0.8]);
        let t = refract(d, n, 1.0 / 1.5).unwrap();
        let sin_i = (1.0 - dot(d, n).powi(2)).sqrt();
        let sin_t = (1.0 - dot(t, n).powi(2)).sqrt();
        assert!((sin_i - 1.5 * sin_t).abs() < 1e-5);
        assert!(t[2] < 0.0);
        // Beyond the critical angle from inside: no refraction.
        assert!(refract(normalize([0.9, 0.0, -0.3]), n, 1.5).is_none());
        let r = reflect(d, n);
        assert!((r[2] + d[2]).abs() < 1e-6 && (r[0] - d[0]).abs() < 1e-6);
    }
}
