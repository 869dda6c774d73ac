//! Statistical tests of the renderer against exact results. Tolerances are multiples of the estimator's own
//! standard error (computed from the samples), never fixed image values.

use crate::*;

fn slab(n: [usize; 3], size: f32, sigma_s: [f32; 3], sigma_a: [f32; 3], ior: f32, g: f32) -> (Geometry, DenseMedium) {
    let geo = Geometry::new(n, [size; 3], Boundary::PeriodicXY, ior, g).unwrap();
    let nv = n.iter().product::<usize>();
    let s: Vec<f32> = (0..nv).flat_map(|_| sigma_s).collect();
    let a: Vec<f32> = (0..nv).flat_map(|_| sigma_a).collect();
    (geo, DenseMedium::from_interleaved(&s, &a).unwrap())
}

fn top_texels(n: [usize; 3]) -> Vec<Texel> {
    let mut t = vec![];
    for y in 0..n[1] {
        for x in 0..n[0] {
            t.push(Texel { voxel: [x as i32, y as i32, n[2] as i32 - 1], face: 5, normal: [0.0, 0.0, 1.0] });
        }
    }
    t
}

/// Mean over texels and its standard error (texels are independent).
fn mean_and_se(est: &[TexelEstimate], c: usize) -> (f64, f64) {
    let n = est.len() as f64;
    let m = est.iter().map(|e| e.mean[c] as f64).sum::<f64>() / n;
    let v = est.iter().map(|e| e.var_mean[c] as f64).sum::<f64>() / (n * n);
    (m, v.sqrt())
}

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
        texels.push(Texel { voxel: [if f == 1 { 5 } else { 0 }, if f == 3 { 4 } else { 0 }, if f == 5 { 3 } else { 0 }], face: f, normal: face_normal(f) });
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
    let texels: Vec<Texel> = (0..6u8).map(|f| Texel { voxel: [1, 2, if f == 5 { 3 } else { 0 }], face: f, normal: face_normal(f) }).collect();
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
        rayon::ThreadPoolBuilder::new().num_threads(threads).build().unwrap().install(|| render(&geo, &med, &texels, 0, &opts))
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

/// Path-replay gradient against central finite differences with common random numbers. The finite-difference
/// estimator and the gradient estimator are different estimators of the same derivative, so we compare them
/// within the standard error of their difference, estimated over independent seeds.
#[test]
fn replay_gradient_matches_finite_differences() {
    let n = [3, 3, 4];
    let nv = 36;
    let size = 0.1f32;
    let mut s: Vec<f32> = (0..3 * nv).map(|i| 3.0 + ((i * 31) % 7) as f32).collect();
    let mut a: Vec<f32> = (0..3 * nv).map(|i| 0.5 + ((i * 17) % 5) as f32 * 0.5).collect();
    let geo = Geometry::new(n, [size; 3], Boundary::PeriodicXY, 1.5, 0.4).unwrap();
    let texels = top_texels(n);
    let adj: Vec<[f32; 3]> = (0..texels.len()).map(|i| [1.0, -0.5 + 0.1 * i as f32, 0.3]).collect();
    // Objective: sum_i adj_i . c_i ; check voxels at 3 depths, channel 0 and 1, for sigma_s and sigma_a.
    let probes = [(4 + 9 * 3, 0usize), (4 + 9 * 2, 1), (4 + 9 * 0, 0)];
    let spp = 1500;
    let objective = |s: &[f32], a: &[f32], seed: u64| -> f64 {
        let med = DenseMedium::from_interleaved(s, a).unwrap();
        let (est, _) = render(&geo, &med, &texels, 0, &RenderOptions { spp, seed, include_specular: true });
        est.iter().zip(&adj).map(|(e, w)| (0..3).map(|c| e.mean[c] as f64 * w[c] as f64).sum::<f64>()).sum()
    };
    // 10 seeds: the standard error of the difference is estimated from them, so the bound is Student's t with
    // 9 degrees of freedom at a two-sided false-alarm rate of 1e-4 per probe (6.59), not a normal 4 sigma.
    let seeds: Vec<u64> = (11..21).collect();
    for &(j, c) in &probes {
        for which in 0..2 {
            let mut diffs = vec![];
            let mut grads = vec![];
            for &seed in &seeds {
                let med = DenseMedium::from_interleaved(&s, &a).unwrap();
                let mut gb = GradBuffers::new(nv, 1);
                gb.zero(1.0);
                backward(&geo, &med, &texels, 0, &adj, &RenderOptions { spp, seed, include_specular: true }, GradMethod::Replay, &gb);
                let mut gs = vec![0.0; 3 * nv];
                let mut ga = vec![0.0; 3 * nv];
                gb.collect(&mut gs, &mut ga);
                grads.push(if which == 0 { gs[3 * j + c] } else { ga[3 * j + c] } as f64);
                let h = 0.25f32;
                let arr = if which == 0 { &mut s } else { &mut a };
                let orig = arr[3 * j + c];
                arr[3 * j + c] = orig + h;
                let fp = objective(&s, &a, seed);
                let arr = if which == 0 { &mut s } else { &mut a };
                arr[3 * j + c] = orig - h;
                let fm = objective(&s, &a, seed);
                let arr = if which == 0 { &mut s } else { &mut a };
                arr[3 * j + c] = orig;
                diffs.push((fp - fm) / (2.0 * h as f64));
            }
            let k = seeds.len() as f64;
            let d: Vec<f64> = grads.iter().zip(&diffs).map(|(g, f)| g - f).collect();
            let md = d.iter().sum::<f64>() / k;
            let sd = (d.iter().map(|x| (x - md).powi(2)).sum::<f64>() / (k - 1.0)).sqrt() / k.sqrt();
            let mg = grads.iter().sum::<f64>() / k;
            // t quantile x standard error of the mean difference, plus 2 % for the O(h^2) finite-difference bias.
            assert!(md.abs() < 6.59 * sd + 0.02 * mg.abs() + 1e-4, "voxel {j} c {c} {}: grad {mg} fd {} (se {sd})",
                    if which == 0 { "sigma_s" } else { "sigma_a" }, diffs.iter().sum::<f64>() / k);
        }
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
    let lm = LabelMedium::new(labels, &ink_s, &ink_a).unwrap();
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

struct PathLength(f64);

impl crate::trace::Tally for PathLength {
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
        let mut rng = crate::rng::PathRng::new(9, i as u64, 0, 0);
        let mut t = PathLength(0.0);
        let r = crate::trace::trace(&geo, &med, &tex, 0, &mut rng, false, &mut t);
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

#[test]
fn regular_and_delta_tracking_agree_on_heterogeneous_media() {
    // The same heterogeneous box rendered with an all-true inside mask (regular tracking, voxel by voxel) and
    // without (delta tracking): two exact samplers of the same transport, compared within 4 standard errors.
    let n = [7, 6, 5];
    let nv = 210;
    let s: Vec<f32> = (0..3 * nv).map(|i| 1.0 + ((i * 7919) % 23) as f32).collect();
    let a: Vec<f32> = (0..3 * nv).map(|i| ((i * 104729) % 7) as f32 * 0.8).collect();
    let geo_d = Geometry::new(n, [0.08, 0.05, 0.1], Boundary::Box, 1.5, 0.4).unwrap();
    let geo_r = Geometry::new(n, [0.08, 0.05, 0.1], Boundary::Box, 1.5, 0.4).unwrap().with_inside(vec![1; nv]).unwrap();
    let med = DenseMedium::from_interleaved(&s, &a).unwrap();
    let texels: Vec<Texel> = (0..6u8)
        .flat_map(|f| (0..5).map(move |k| Texel { voxel: [if f == 1 { 6 } else { k % 6 }, if f == 3 { 5 } else { k % 5 }, if f == 5 { 4 } else { k % 4 }], face: f, normal: face_normal(f) }))
        .filter(|t| t.voxel[(t.face / 2) as usize] == if t.face % 2 == 1 { n[(t.face / 2) as usize] as i32 - 1 } else { 0 })
        .collect();
    let opts = RenderOptions { spp: 4000, seed: 8, include_specular: true };
    let (ed, _) = render(&geo_d, &med, &texels, 0, &opts);
    let (er, _) = render(&geo_r, &med, &texels, 0, &RenderOptions { seed: 9, ..opts });
    for (x, y) in ed.iter().zip(&er) {
        for c in 0..3 {
            let se = (x.var_mean[c] + y.var_mean[c]).sqrt();
            assert!((x.mean[c] - y.mean[c]).abs() < 4.0 * se + 1e-6, "{} vs {} (se {se})", x.mean[c], y.mean[c]);
        }
    }
}

#[test]
fn packet_renderer_matches_scalar_trace() {
    // Mask-free volumes render eight paths at a time with their own random numbers (packet.rs); the scalar
    // `trace` is the reference. Heterogeneous box (all six faces) and periodic slab, specular included or not:
    // and a masked box with a concave notch (general walk near the surface, delta tracking in safe balls deeper):
    // per texel and channel within 4.5 standard errors (about 400 comparisons; a false alarm has odds ~0.3 %).
    let n = [7, 6, 5];
    let nv = 210;
    let s: Vec<f32> = (0..3 * nv).map(|i| 1.0 + ((i * 7919) % 23) as f32).collect();
    let a: Vec<f32> = (0..3 * nv).map(|i| ((i * 104729) % 7) as f32 * 0.8).collect();
    let med = DenseMedium::from_interleaved(&s, &a).unwrap();
    let box_texels = |faces: &[u8]| -> Vec<Texel> {
        faces
            .iter()
            .flat_map(|&f| (0..5).map(move |k| Texel { voxel: [if f == 1 { 6 } else { k % 6 }, if f == 3 { 5 } else { k % 5 }, if f == 5 { 4 } else { k % 4 }], face: f, normal: face_normal(f) }))
            .filter(|t| t.voxel[(t.face / 2) as usize] == if t.face % 2 == 1 { n[(t.face / 2) as usize] as i32 - 1 } else { 0 })
            .collect()
    };
    // A masked object: the box minus a notch (a concave part light can re-enter) and one corner, whose interior
    // is deep enough for the delta-tracking balls (voxels 0.05 mm, safe distances up to 3).
    let big = [12usize, 11, 10];
    let mut inside = vec![1u8; big.iter().product()];
    for z in 0..big[2] {
        for y in 0..big[1] {
            for x in 0..big[0] {
                if (x >= 5 && x <= 6 && z >= 6) || (x + y + z < 4) {
                    inside[(z * big[1] + y) * big[0] + x] = 0;
                }
            }
        }
    }
    // Vacuum outside the object, as in voxelized meshes.
    // Channel 0 thin (free paths of several voxels: flights often reach the edge of their safe ball), 1-2 dense.
    let big_s: Vec<f32> = (0..3 * inside.len()).map(|i| if inside[i / 3] == 0 { 0.0 } else if i % 3 == 0 { 2.0 + ((i * 7919) % 5) as f32 } else { 5.0 + ((i * 7919) % 23) as f32 }).collect();
    let big_a: Vec<f32> = (0..3 * inside.len()).map(|i| if inside[i / 3] == 0 { 0.0 } else if i % 3 == 0 { 0.2 } else { ((i * 104729) % 7) as f32 * 0.5 }).collect();
    let big_med = DenseMedium::from_interleaved(&big_s, &big_a).unwrap();
    let masked_geo = Geometry::new(big, [0.05; 3], Boundary::Box, 1.5, 0.4).unwrap().with_inside(inside.clone()).unwrap();
    let masked_texels: Vec<Texel> = (0..inside.len())
        .filter(|&j| inside[j] != 0)
        .flat_map(|j| {
            let v = [(j % big[0]) as i32, ((j / big[0]) % big[1]) as i32, (j / (big[0] * big[1])) as i32];
            (0..6u8).map(move |f| (v, f))
        })
        .filter(|&(v, f)| {
            let mut nb = v;
            nb[(f / 2) as usize] += if f % 2 == 1 { 1 } else { -1 };
            !masked_geo.is_inside(nb)
        })
        .step_by(17)
        .map(|(v, f)| Texel { voxel: v, face: f, normal: face_normal(f) })
        .collect();
    assert!(masked_texels.len() > 20);
    let cases = [
        (Geometry::new(n, [0.08, 0.05, 0.1], Boundary::Box, 1.5, 0.4).unwrap(), &med, box_texels(&[0, 1, 2, 3, 4, 5])),
        (Geometry::new(n, [0.08, 0.05, 0.1], Boundary::PeriodicXY, 1.5, 0.4).unwrap(), &med, box_texels(&[4, 5])),
        (Geometry::new(big, [0.05; 3], Boundary::Box, 1.5, 0.4).unwrap().with_inside(inside.clone()).unwrap(), &big_med, masked_texels),
    ];
    for (geo, med, texels) in cases {
        let boundary = (geo.boundary, geo.inside.is_some());
        for include_specular in [true, false] {
            let spp = 3000u32;
            let (packed, stats) = render(&geo, med, &texels, 0, &RenderOptions { spp, seed: 21, include_specular });
            let mut scalar_events = 0u64;
            for (i, (tex, x)) in texels.iter().zip(&packed).enumerate() {
                for c in 0..3 {
                    let (mut sum, mut sq) = (0.0f64, 0.0f64);
                    for k in 0..spp {
                        let mut rng = crate::rng::PathRng::new(22, i as u64, k, c as u32);
                        let r = crate::trace::trace(&geo, med, tex, c, &mut rng, include_specular, &mut crate::trace::NoTally);
                        sum += r.value as f64;
                        sq += (r.value as f64).powi(2);
                        scalar_events += r.events as u64;
                    }
                    let m = sum / spp as f64;
                    let var_mean = (sq / spp as f64 - m * m) / (spp - 1) as f64;
                    let se = (x.var_mean[c] as f64 + var_mean).sqrt();
                    assert!((x.mean[c] as f64 - m).abs() < 4.5 * se + 1e-6,
                            "{boundary:?} specular {include_specular} texel {i} c {c}: {} vs {m} (se {se})", x.mean[c]);
                }
            }
            // Collisions per path agree too (same walk): within 3 %, far above the noise of ~1e5 paths.
            let ratio = stats.events as f64 / scalar_events as f64;
            assert!((ratio - 1.0).abs() < 0.03, "events ratio {ratio}");
        }
    }
}

#[test]
fn safe_distances_match_brute_force() {
    // Random blobs: every voxel's safe distance equals the brute-force Chebyshev distance to the nearest voxel
    // outside the object or the grid (capped).
    let n = [15usize, 13, 14];
    let mut rng = crate::rng::PathRng::new(5, 0, 0, 0);
    let centres: Vec<[f32; 3]> = (0..3).map(|_| [3.0 + rng.next_f32() * 9.0, 3.0 + rng.next_f32() * 7.0, 3.0 + rng.next_f32() * 8.0]).collect();
    let idx = |x: usize, y: usize, z: usize| (z * n[1] + y) * n[0] + x;
    let mut inside = vec![0u8; n[0] * n[1] * n[2]];
    for z in 0..n[2] {
        for y in 0..n[1] {
            for x in 0..n[0] {
                let p = [x as f32, y as f32, z as f32];
                inside[idx(x, y, z)] = centres.iter().any(|c| (0..3).map(|a| (p[a] - c[a]).powi(2)).sum::<f32>() < 30.0) as u8;
            }
        }
    }
    let safe = crate::scene::safe_distances(&inside, n);
    for z in 0..n[2] as i32 {
        for y in 0..n[1] as i32 {
            for x in 0..n[0] as i32 {
                let mut best = i32::MAX;
                for oz in -1..=n[2] as i32 {
                    for oy in -1..=n[1] as i32 {
                        for ox in -1..=n[0] as i32 {
                            let out = ox < 0 || oy < 0 || oz < 0 || ox >= n[0] as i32 || oy >= n[1] as i32 || oz >= n[2] as i32
                                || inside[idx(ox as usize, oy as usize, oz as usize)] == 0;
                            if out {
                                best = best.min((ox - x).abs().max((oy - y).abs()).max((oz - z).abs()));
                            }
                        }
                    }
                }
                let want = best.min(crate::scene::SAFE_CAP as i32) as u8;
                assert_eq!(safe[idx(x as usize, y as usize, z as usize)], want, "voxel {x} {y} {z}");
            }
        }
    }
    assert!(safe.iter().any(|&s| s >= 3), "the test blobs should have a deep interior");
}

#[test]
fn total_gradient_matches_a_uniform_shift() {
    // The gradient summed over all voxels is the derivative for shifting every voxel's coefficient by the same
    // amount: a sharp check of systematic errors in track lengths and scattering counts (a 10 % error in the
    // tallied lengths fails it), on the three gradient paths: packets in a periodic slab (delta tracking),
    // packets in a masked box (safe balls + general walk) and the scalar walk (periodic slab with a mask).
    // The difference to central finite differences with common random numbers is tested against Student's t
    // (8 seeds, two-sided 1e-4: 5.41) x its standard error, plus 1 % for the O(h^2) bias.
    let n = [6usize, 6, 6];
    let nv = 216;
    let mut inside_notch = vec![1u8; nv];
    for z in 3..6 {
        for y in 2..4 {
            for x in 0..2 {
                inside_notch[(z * 6 + y) * 6 + x] = 0;
            }
        }
    }
    let cases = [
        (Geometry::new(n, [0.1; 3], Boundary::PeriodicXY, 1.5, 0.4).unwrap(), vec![1u8; nv]),
        (Geometry::new(n, [0.1; 3], Boundary::Box, 1.5, 0.4).unwrap().with_inside(inside_notch.clone()).unwrap(), inside_notch.clone()),
        (Geometry::new(n, [0.1; 3], Boundary::PeriodicXY, 1.5, 0.4).unwrap().with_inside(vec![1u8; nv]).unwrap(), vec![1u8; nv]),
    ];
    let texels: Vec<Texel> = top_texels(n).into_iter().filter(|t| !(t.voxel[1] >= 2 && t.voxel[1] < 4 && t.voxel[0] < 2)).collect();
    let adj: Vec<[f32; 3]> = (0..texels.len()).map(|i| [1.0, 0.5 + 0.05 * i as f32, -0.7]).collect();
    let base_s: Vec<f32> = (0..3 * nv).map(|i| 4.0 + ((i * 31) % 7) as f32).collect();
    let base_a: Vec<f32> = (0..3 * nv).map(|i| 0.5 + ((i * 17) % 5) as f32 * 0.3).collect();
    for (geo, inside) in cases {
        let coeffs = |ds: f32, da: f32| -> DenseMedium {
            let s: Vec<f32> = (0..3 * nv).map(|i| if inside[i / 3] != 0 { base_s[i] + ds } else { 0.0 }).collect();
            let a: Vec<f32> = (0..3 * nv).map(|i| if inside[i / 3] != 0 { base_a[i] + da } else { 0.0 }).collect();
            DenseMedium::from_interleaved(&s, &a).unwrap()
        };
        let spp = 1000;
        let objective = |ds: f32, da: f32, seed: u64| -> f64 {
            let (est, _) = render(&geo, &coeffs(ds, da), &texels, 0, &RenderOptions { spp, seed, include_specular: true });
            est.iter().zip(&adj).map(|(e, w)| (0..3).map(|c| e.mean[c] as f64 * w[c] as f64).sum::<f64>()).sum()
        };
        for which in 0..2 {
            let (mut g, mut fd) = (vec![], vec![]);
            for seed in 40..48u64 {
                let mut gb = GradBuffers::new(nv, 1);
                gb.zero(1.0);
                backward(&geo, &coeffs(0.0, 0.0), &texels, 0, &adj, &RenderOptions { spp, seed, include_specular: true }, GradMethod::Replay, &gb);
                let (mut gs, mut ga) = (vec![0.0; 3 * nv], vec![0.0; 3 * nv]);
                gb.collect(&mut gs, &mut ga);
                let grad = if which == 0 { &gs } else { &ga };
                g.push((0..3 * nv).filter(|i| inside[i / 3] != 0).map(|i| grad[i] as f64).sum::<f64>());
                let h = 0.2f32;
                let (fp, fm) = if which == 0 {
                    (objective(h, 0.0, seed), objective(-h, 0.0, seed))
                } else {
                    (objective(0.0, h, seed), objective(0.0, -h, seed))
                };
                fd.push((fp - fm) / (2.0 * h as f64));
            }
            let k = g.len() as f64;
            let d: Vec<f64> = g.iter().zip(&fd).map(|(a, b)| a - b).collect();
            let md = d.iter().sum::<f64>() / k;
            let sd = (d.iter().map(|x| (x - md).powi(2)).sum::<f64>() / (k - 1.0)).sqrt() / k.sqrt();
            let mg = g.iter().sum::<f64>() / k;
            assert!(md.abs() < 5.41 * sd + 0.01 * mg.abs(), "{:?} masked {} {}: grad {mg} fd {} (se {sd})",
                    geo.boundary, geo.inside.is_some(), if which == 0 { "sigma_s" } else { "sigma_a" },
                    fd.iter().sum::<f64>() / k);
        }
    }
}
