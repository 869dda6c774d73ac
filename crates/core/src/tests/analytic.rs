//! Exact results: furnaces (energy conservation), a purely absorbing slab (Fresnel series), free-flight
//! distances in a layered column.

use super::*;

#[test]
fn white_furnace_is_one() {
    // No absorption and an index-matched boundary: every path escapes with radiance 1, so every texel is
    // exactly 1 whatever the scattering (zero variance: any deviation is a bug, not noise).
    let n = [6, 5, 4];
    let geo = Geometry::new(n, [0.1, 0.07, 0.05], Boundary::Box, 1.0, 0.4).unwrap();
    let nv = 120;
    let s: Vec<f32> = (0..3 * nv).map(|i| 1.0 + (i % 17) as f32 * 3.0).collect();
    let med = DenseMedium::from_interleaved(&s, &vec![0.0; 3 * nv]).unwrap();
    let mut texels = vec![];
    for f in 0..6u8 {
        texels.push(Texel {
            voxel: [if f == 1 { 5 } else { 0 }, if f == 3 { 4 } else { 0 }, if f == 5 { 3 } else { 0 }],
            face: f,
            normal: face_normal(f),
        });
    }
    let (est, _) = render(&geo, &med, &texels, 0, &RenderOptions { spp: 200, seed: 1, include_specular: true });
    for e in &est {
        for c in 0..3 {
            assert_eq!(e.mean[c], 1.0);
        }
    }
}

#[test]
fn furnace_with_fresnel_boundary_is_one() {
    // Non-absorbing medium inside a dielectric (ior 1.5) box: energy is conserved, paths only bounce longer.
    let n = [4, 4, 4];
    let geo = Geometry::new(n, [0.1; 3], Boundary::Box, 1.5, 0.4).unwrap();
    let med = DenseMedium::from_interleaved(&vec![8.0; 3 * 64], &vec![0.0; 3 * 64]).unwrap();
    let texels: Vec<Texel> = (0..6u8)
        .map(|f| Texel { voxel: [1, 2, if f == 5 { 3 } else { 0 }], face: f, normal: face_normal(f) })
        .collect();
    let (est, _) = render(&geo, &med, &texels, 0, &RenderOptions { spp: 50, seed: 2, include_specular: true });
    assert!(est.iter().all(|e| e.mean.iter().all(|&m| m == 1.0)));
}

#[test]
fn absorbing_slab_matches_fresnel_series() {
    // Purely absorbing slab, normal incidence: the path stays on the normal, so with R0 = 0.04 and
    // x = exp(-sigma_a L):  R + T = R0 + (1-R0)^2 x (1 + R0 x) / (1 - R0^2 x^2)   (reflections summed).
    let n = [8, 8, 10];
    let size = 0.05f32;
    for &sa in &[0.5f32, 2.0, 6.0] {
        let (geo, med) = slab(n, size, [0.0; 3], [sa, sa * 2.0, sa * 0.5], 1.5, 0.4);
        let texels = top_texels(n);
        let (est, _) = render(&geo, &med, &texels, 0, &RenderOptions { spp: 400, seed: 3, include_specular: true });
        for c in 0..3 {
            let r0 = 0.04f64;
            let x = (-([sa, sa * 2.0, sa * 0.5][c] as f64) * 10.0 * size as f64).exp();
            let expect = r0 + (1.0 - r0).powi(2) * x * (1.0 + r0 * x) / (1.0 - r0 * r0 * x * x);
            let (m, se) = mean_and_se(&est, c);
            assert!((m - expect).abs() < 4.0 * se + 1e-6, "sa={sa} c={c}: {m} vs {expect} (se {se})");
        }
    }
}

struct PathLength(f64);

impl crate::transport::path::Tally for PathLength {
    fn segment(&mut self, _: usize, len: f32) {
        self.0 += len as f64;
    }
    fn scatter(&mut self, _: usize) {}
}

#[test]
fn free_flight_histogram_matches_piecewise_exponential() {
    // A black (albedo 0) column with a different sigma_t in every layer, index-matched, camera ray along -z:
    // the path is absorbed at its first collision, so its length is the free-flight distance, whose pdf is
    // sigma_t(z) exp(-tau(z)). Bins hold >= ~4k expected samples; each is tested at 5 standard errors.
    let sig = [3.0f32, 9.0, 1.0, 6.0, 20.0, 2.0];
    let nz = sig.len();
    let h = 0.1f32;
    let geo = Geometry::new([1, 1, nz], [h; 3], Boundary::PeriodicXY, 1.0, 0.4).unwrap();
    // Layer z = nz - 1 is the top, hit first.
    let s = vec![0.0f32; 3 * nz];
    let a: Vec<f32> = (0..nz).flat_map(|z| [sig[nz - 1 - z]; 3]).collect();
    let med = DenseMedium::from_interleaved(&s, &a).unwrap();
    let tex = Texel { voxel: [0, 0, nz as i32 - 1], face: 5, normal: [0.0, 0.0, 1.0] };
    let n = 400_000;
    let bins_per_layer = 4;
    let nb = nz * bins_per_layer;
    let mut hist = vec![0usize; nb + 1];
    for i in 0..n {
        let mut rng = crate::transport::rng::PathRng::new(9, i as u64, 0, 0);
        let mut t = PathLength(0.0);
        let r = crate::transport::trace::trace(&geo, &med, &tex, 0, &mut rng, false, &mut t);
        let b = if r.events == 0 { nb } else { ((t.0 / (h as f64 / bins_per_layer as f64)) as usize).min(nb - 1) };
        hist[b] += 1;
    }
    let mut tau0 = 0.0f64;
    for layer in 0..nz {
        let st = sig[layer] as f64;
        for k in 0..bins_per_layer {
            let w = h as f64 / bins_per_layer as f64;
            let p = (-tau0 - st * w * k as f64).exp() * (1.0 - (-st * w).exp());
            let expect = p * n as f64;
            let sd = (expect * (1.0 - p)).sqrt();
            let got = hist[layer * bins_per_layer + k] as f64;
            assert!((got - expect).abs() < 5.0 * sd + 1.0, "layer {layer} bin {k}: {got} vs {expect}");
        }
        tau0 += st * h as f64;
    }
    let p_escape = (-tau0).exp();
    assert!((hist[nb] as f64 - p_escape * n as f64).abs() < 5.0 * (p_escape * n as f64).sqrt() + 1.0);
}
