//! Bit-identical results for any thread count and chunking, and for the two forms of a medium.

use super::*;

#[test]
fn same_result_for_any_thread_count() {
    let n = [10, 9, 6];
    let nv = 540;
    let s: Vec<f32> = (0..3 * nv).map(|i| 2.0 + ((i * 7919) % 13) as f32).collect();
    let a: Vec<f32> = (0..3 * nv).map(|i| ((i * 104729) % 5) as f32 * 0.7).collect();
    let geo = Geometry::new(n, [0.0847, 0.0847, 0.0847], Boundary::Box, 1.5, 0.4).unwrap();
    let med = DenseMedium::from_interleaved(&s, &a).unwrap();
    let texels = top_texels(n);
    let opts = RenderOptions { spp: 8, seed: 42, include_specular: true };
    let run = |threads: usize| {
        rayon::ThreadPoolBuilder::new()
            .num_threads(threads)
            .build()
            .unwrap()
            .install(|| render(&geo, &med, &texels, 0, &opts))
    };
    let (a1, s1) = run(1);
    let (a2, s2) = run(2);
    assert_eq!(s1.events, s2.events);
    for (x, y) in a1.iter().zip(&a2) {
        assert_eq!(x.mean, y.mean);
        assert_eq!(x.var_mean, y.var_mean);
    }
    // Chunked rendering with global texel indices gives the same numbers.
    let (c1, _) = render(&geo, &med, &texels[..37], 0, &opts);
    let (c2, _) = render(&geo, &med, &texels[37..], 37, &opts);
    for (x, y) in c1.iter().chain(&c2).zip(&a1) {
        assert_eq!(x.mean, y.mean);
    }
}

#[test]
fn label_medium_matches_dense() {
    // The same volume given as labels + ink table and as dense coefficients renders bit-identically.
    let n = [5, 4, 3];
    let nv = 60;
    let ink_s = [4.0f32, 1.0, 2.0, 0.5, 8.0, 3.0];
    let ink_a = [0.1f32, 2.0, 0.3, 1.5, 0.2, 0.9];
    let labels: Vec<u8> = (0..nv).map(|i| (i % 2) as u8).collect();
    let s: Vec<f32> = labels.iter().flat_map(|&l| ink_s[3 * l as usize..3 * l as usize + 3].to_vec()).collect();
    let a: Vec<f32> = labels.iter().flat_map(|&l| ink_a[3 * l as usize..3 * l as usize + 3].to_vec()).collect();
    let geo = Geometry::new(n, [0.04, 0.08, 0.03], Boundary::Box, 1.5, 0.4).unwrap();
    let lm = LabelMedium::new(n, &labels, &ink_s, &ink_a).unwrap();
    let dm = DenseMedium::from_interleaved(&s, &a).unwrap();
    let texels = top_texels(n);
    let opts = RenderOptions { spp: 16, seed: 5, include_specular: false };
    let (x, _) = render(&geo, &lm, &texels, 0, &opts);
    let (y, _) = render(&geo, &dm, &texels, 0, &opts);
    for (p, q) in x.iter().zip(&y) {
        for c in 0..3 {
            assert!((p.mean[c] - q.mean[c]).abs() <= 1e-6 * q.mean[c].abs().max(1.0));
        }
    }
}
