//! Counter-based random numbers.
//!
//! Every random number is a pure function of (seed, texel, sample, channel, draw index): the key is a hash of
//! the first four, and draw `i` is SplitMix64's output for counter `key + i * GAMMA`. A path can therefore be
//! replayed exactly (path replay backpropagation), and results do not depend on how work is split over threads.
//!
//! Two generators: `PathRng` (SplitMix64, 64-bit; the scalar walk) and the packets' 32-bit counter-based hash
//! (draw i of path key k is lowbias32(lowbias32(i ^ k_hi) + k_lo), 24 bits per uniform), which vectorises
//! (`uniform8`) where 64-bit multiplies do not; `LaneRng` is one lane's stream of it as scalar uniforms.

use wide::{f32x8, i32x8, u32x8};

const GAMMA: u64 = 0x9E37_79B9_7F4A_7C15;

#[inline(always)]
pub fn mix64(mut z: u64) -> u64 {
    z = (z ^ (z >> 30)).wrapping_mul(0xBF58_476D_1CE4_E5B9);
    z = (z ^ (z >> 27)).wrapping_mul(0x94D0_49BB_1331_11EB);
    z ^ (z >> 31)
}

/// A path's source of uniforms in [0, 1) (24 random bits each).
pub trait Uniforms {
    fn next_f32(&mut self) -> f32;
    /// Two independent uniforms.
    fn next_f32_pair(&mut self) -> (f32, f32);
}

impl Uniforms for PathRng {
    #[inline(always)]
    fn next_f32(&mut self) -> f32 {
        PathRng::next_f32(self)
    }
    #[inline(always)]
    fn next_f32_pair(&mut self) -> (f32, f32) {
        PathRng::next_f32_pair(self)
    }
}

/// The 64-bit key of one path's stream: a hash of (seed, texel, sample, channel).
#[inline]
pub fn path_key(seed: u64, texel: u64, sample: u32, channel: u32) -> u64 {
    let k = mix64(seed.wrapping_add(GAMMA));
    let k = mix64(k ^ texel.wrapping_mul(0xD6E8_FEB8_6659_FD93));
    mix64(k ^ (((sample as u64) << 8) | channel as u64))
}

/// The stream of one path: one (seed, texel, sample, channel) tuple.
#[derive(Clone, Debug)]
pub struct PathRng {
    state: u64,
}

impl PathRng {
    #[inline]
    pub fn new(seed: u64, texel: u64, sample: u32, channel: u32) -> Self {
        PathRng { state: path_key(seed, texel, sample, channel) }
    }

    #[inline(always)]
    pub fn next_u64(&mut self) -> u64 {
        self.state = self.state.wrapping_add(GAMMA);
        mix64(self.state)
    }

    /// Two independent uniforms in [0, 1), 24 random bits each, from one hash.
    #[inline(always)]
    pub fn next_f32_pair(&mut self) -> (f32, f32) {
        let x = self.next_u64();
        ((x >> 40) as f32 * (1.0 / 16_777_216.0), ((x >> 8) & 0xFF_FFFF) as f32 * (1.0 / 16_777_216.0))
    }

    /// Uniform in [0, 1) with 24 random bits.
    #[inline(always)]
    pub fn next_f32(&mut self) -> f32 {
        (self.next_u64() >> 40) as f32 * (1.0 / 16_777_216.0)
    }
}

#[inline(always)]
fn lowbias32(mut x: u32) -> u32 {
    x ^= x >> 16;
    x = x.wrapping_mul(0x7FEB_352D);
    x ^= x >> 15;
    x = x.wrapping_mul(0x846C_A68B);
    x ^ (x >> 16)
}

#[inline(always)]
fn lowbias32x8(mut x: u32x8) -> u32x8 {
    x = x ^ (x >> 16u32);
    x = x * u32x8::splat(0x7FEB_352D);
    x = x ^ (x >> 15u32);
    x = x * u32x8::splat(0x846C_A68B);
    x ^ (x >> 16u32)
}

/// Uniform in [0, 1) with 24 random bits: draw `i` of the packet stream keyed (k_lo, k_hi).
#[inline(always)]
pub(crate) fn uniform(k_lo: u32, k_hi: u32, i: u32) -> f32 {
    (lowbias32(lowbias32(i ^ k_hi).wrapping_add(k_lo)) >> 8) as f32 * (1.0 / 16_777_216.0)
}

/// `uniform` in eight lanes: draw i[l] of the stream keyed (k_lo[l], k_hi[l]), bit-identical per lane.
#[inline(always)]
pub(crate) fn uniform8(k_lo: u32x8, k_hi: u32x8, i: u32x8) -> f32x8 {
    let h = lowbias32x8(lowbias32x8(i ^ k_hi) + k_lo) >> 8u32;
    bytemuck::cast::<u32x8, i32x8>(h).round_float() * f32x8::splat(1.0 / 16_777_216.0)
}

/// One packet lane's stream as scalar uniforms (camera rays and the walk near the surface): the next draw is
/// number `draw`.
pub(crate) struct LaneRng {
    pub k_lo: u32,
    pub k_hi: u32,
    pub draw: u32,
}

impl LaneRng {
    /// The stream of path key `key`, from its first draw.
    pub fn new(key: u64) -> Self {
        LaneRng { k_lo: key as u32, k_hi: (key >> 32) as u32, draw: 0 }
    }
}

impl Uniforms for LaneRng {
    #[inline(always)]
    fn next_f32(&mut self) -> f32 {
        self.draw += 1;
        uniform(self.k_lo, self.k_hi, self.draw - 1)
    }
    #[inline(always)]
    fn next_f32_pair(&mut self) -> (f32, f32) {
        (self.next_f32(), self.next_f32())
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn replay_is_exact_and_streams_differ() {
        let mut a = PathRng::new(7, 11, 3, 1);
        let mut b = PathRng::new(7, 11, 3, 1);
        let mut c = PathRng::new(7, 11, 3, 2);
        let xa: Vec<u64> = (0..100).map(|_| a.next_u64()).collect();
        let xb: Vec<u64> = (0..100).map(|_| b.next_u64()).collect();
        let xc: Vec<u64> = (0..100).map(|_| c.next_u64()).collect();
        assert_eq!(xa, xb);
        assert!(xa.iter().zip(&xc).all(|(p, q)| p != q));
    }

    #[test]
    fn uniform_moments() {
        // Mean 1/2, variance 1/12; with n = 1e6 the standard error of the mean is 2.9e-4: test at 5 sigma.
        let n = 1_000_000;
        let mut s = 0.0f64;
        let mut s2 = 0.0f64;
        for t in 0..n {
            let mut r = PathRng::new(1, t as u64, 0, 0);
            let x = r.next_f32() as f64;
            assert!((0.0..1.0).contains(&x));
            s += x;
            s2 += x * x;
        }
        let mean = s / n as f64;
        let var = s2 / n as f64 - mean * mean;
        assert!((mean - 0.5).abs() < 5.0 * (1.0f64 / 12.0 / n as f64).sqrt());
        assert!((var - 1.0 / 12.0).abs() < 1e-3);
    }

    #[test]
    fn vector_and_scalar_uniforms_agree_and_are_uniform() {
        let (k_lo, k_hi) = (0x1234_5678u32, 0x9ABC_DEF0u32);
        let v = uniform8(u32x8::splat(k_lo), u32x8::splat(k_hi), u32x8::from([0, 1, 2, 3, 4, 5, 6, 7])).to_array();
        for (i, x) in v.iter().enumerate() {
            assert_eq!(*x, uniform(k_lo, k_hi, i as u32));
        }
        // Mean and variance over many keys and draws: n = 1e6, standard error of the mean 2.9e-4, test at 5 sigma.
        let n = 1_000_000u32;
        let (mut s, mut s2) = (0.0f64, 0.0f64);
        for t in 0..n {
            let key = path_key(3, t as u64 / 8, 0, 0);
            let x = uniform(key as u32, (key >> 32) as u32, t % 8) as f64;
            assert!((0.0..1.0).contains(&x));
            s += x;
            s2 += x * x;
        }
        let mean = s / n as f64;
        assert!((mean - 0.5).abs() < 5.0 * (1.0f64 / 12.0 / n as f64).sqrt());
        assert!((s2 / n as f64 - mean * mean - 1.0 / 12.0).abs() < 1e-3);
    }
}
