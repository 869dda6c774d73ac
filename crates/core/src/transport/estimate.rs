//! What a render asks for and what it returns: `RenderOptions` (samples per texel, seed, whether the specular
//! reflection counts), the per-texel `TexelEstimate`s and the pass's `Stats`, and the fixed-order sums
//! (`Moments`, `estimates`) that turn path values into estimates. Shared by the drivers (`render`, `grad`) and
//! the packets, which read the options.

/// What a render or gradient pass traces: `spp` paths per texel and channel, random numbers keyed by `seed`,
/// and whether the camera ray's specular (Fresnel) reflection of the light counts.
#[derive(Clone, Copy, Debug)]
pub struct RenderOptions {
    pub spp: u32,
    pub seed: u64,
    pub include_specular: bool,
}

/// Per-texel estimate: mean linear RGB radiance and the variance of that mean (squared standard error).
#[derive(Clone, Copy, Debug, Default)]
pub struct TexelEstimate {
    pub mean: [f32; 3],
    pub var_mean: [f32; 3],
}

/// What a render or gradient pass traced: paths and collisions, its own and replayed.
#[derive(Clone, Copy, Debug, Default)]
pub struct Stats {
    /// Monochromatic paths traced (texels x spp x 3 channels), replays not included.
    pub paths: u64,
    /// Collisions (scattering + absorption events) of those paths.
    pub events: u64,
    /// Paths traced a second time by path replay, and their collisions.
    pub replayed_paths: u64,
    pub replayed_events: u64,
}

impl Stats {
    pub(crate) fn merge(a: Stats, b: Stats) -> Stats {
        Stats {
            paths: a.paths + b.paths,
            events: a.events + b.events,
            replayed_paths: a.replayed_paths + b.replayed_paths,
            replayed_events: a.replayed_events + b.replayed_events,
        }
    }
}

/// Running sums of one texel's path values and their squares per channel (f64, in the order added).
pub(crate) struct Moments {
    sum: [f64; 3],
    sq: [f64; 3],
}

impl Moments {
    pub(crate) fn new() -> Self {
        Moments { sum: [0.0; 3], sq: [0.0; 3] }
    }
    pub(crate) fn add(&mut self, c: usize, x: f32) {
        self.sum[c] += x as f64;
        self.sq[c] += (x as f64) * (x as f64);
    }
    pub(crate) fn estimate(&self, spp: u32) -> TexelEstimate {
        let n = spp as f64;
        let mut e = TexelEstimate::default();
        for c in 0..3 {
            let m = self.sum[c] / n;
            e.mean[c] = m as f32;
            e.var_mean[c] = if spp > 1 { ((self.sq[c] / n - m * m).max(0.0) * n / (n - 1.0) / n) as f32 } else { 0.0 };
        }
        e
    }
}

/// Per-texel estimates from path values laid out [texel][channel][sample], summed in that order.
pub(crate) fn estimates(values: &[f32], spp: usize) -> Vec<TexelEstimate> {
    values
        .chunks(3 * spp)
        .map(|v| {
            let mut m = Moments::new();
            for c in 0..3 {
                v[c * spp..(c + 1) * spp].iter().for_each(|&x| m.add(c, x));
            }
            m.estimate(spp as u32)
        })
        .collect()
}
