//! Parallel drivers of the forward render of a list of texels (the gradient pass, `grad`, shares them).
//! Mask-free volumes and masked boxes run eight paths at a time (`packet`, chunks of `PACKET_CHUNK` texels per
//! work item); masked periodic slabs run the scalar `trace`, one texel per work item. Every path's random
//! numbers come from its (seed, texel, sample, channel) key and each texel's path values are summed in a fixed
//! order, so per-texel results and gradients are bit-identical for any thread count and work split.
use rayon::prelude::*;

use crate::transport::estimate::{estimates, Moments, RenderOptions, Stats, TexelEstimate};
use crate::transport::packet::{self, trace_paths, NoPathTally};
use crate::transport::path::NoTally;
use crate::transport::rng::PathRng;
use crate::transport::scene::{Geometry, Medium, Texel};
use crate::transport::trace::trace;

/// Forward render. `first_texel` is the global index of `texels[0]` (the random-number key), so a texel list
/// can be rendered in chunks with the same result as in one call.
pub fn render<M: Medium>(
    geo: &Geometry,
    med: &M,
    texels: &[Texel],
    first_texel: u64,
    opts: &RenderOptions,
) -> (Vec<TexelEstimate>, Stats) {
    if packet::supported(geo) {
        return render_packets(geo, med, texels, first_texel, opts);
    }
    let results: Vec<(TexelEstimate, Stats)> = texels
        .par_iter()
        .enumerate()
        .map(|(i, tex)| {
            let mut m = Moments::new();
            let mut st = Stats::default();
            // Channel-major: consecutive paths read the same coefficient plane near the same texel (L2 hits).
            for c in 0..3 {
                for s in 0..opts.spp {
                    let mut rng = PathRng::new(opts.seed, first_texel + i as u64, s, c as u32);
                    let r = trace(geo, med, tex, c, &mut rng, opts.include_specular, &mut NoTally);
                    m.add(c, r.value);
                    st.events += r.events as u64;
                }
            }
            st.paths = 3 * opts.spp as u64;
            (m.estimate(opts.spp), st)
        })
        .collect();
    let stats = results.iter().fold(Stats::default(), |a, r| Stats::merge(a, r.1));
    (results.into_iter().map(|r| r.0).collect(), stats)
}

/// Texels per work item of the eight-lane renderer: enough paths to keep the lanes busy (a lane idles only
/// while the item's last paths finish), few enough to balance the threads.
pub(crate) const PACKET_CHUNK: usize = 64;

/// `render` for mask-free volumes and masked boxes: eight paths at a time (`packet`), each texel's path values
/// summed in a fixed order, so results are bit-identical for any thread count.
fn render_packets<M: Medium>(
    geo: &Geometry,
    med: &M,
    texels: &[Texel],
    first_texel: u64,
    opts: &RenderOptions,
) -> (Vec<TexelEstimate>, Stats) {
    let spp = opts.spp as usize;
    let chunks: Vec<(Vec<TexelEstimate>, Stats)> = texels
        .par_chunks(PACKET_CHUNK)
        .enumerate()
        .map(|(k, chunk)| {
            let mut values = vec![0.0f32; chunk.len() * 3 * spp];
            let key = first_texel + (k * PACKET_CHUNK) as u64;
            let events = trace_paths(geo, med, chunk, key, opts, &mut values, &mut NoPathTally);
            (estimates(&values, spp), Stats { paths: (chunk.len() * 3 * spp) as u64, events, ..Stats::default() })
        })
        .collect();
    let stats = chunks.iter().fold(Stats::default(), |a, r| Stats::merge(a, r.1));
    (chunks.into_iter().flat_map(|r| r.0).collect(), stats)
}
