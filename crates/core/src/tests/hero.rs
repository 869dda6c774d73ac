//! Hero-channel paths (`transport::hero`) against the per-channel renderer, finite differences, thread counts,
//! and their variance where the channels' extinctions differ 3.5x.

use super::*;
use crate::transport::hero::hero_of;

/// Render with hero paths under a pool of `threads` threads.
fn hero_in_pool<M: Medium>(
    threads: usize,
    geo: &Geometry,
    med: &M,
    texels: &[Texel],
    opts: &RenderOptions,
) -> (Vec<TexelEstimate>, Stats) {
    let pool = rayon::ThreadPoolBuilder::new().num_threads(threads).build().unwrap();
    pool.install(|| render_hero(geo, med, texels, 0, opts))
}

/// Per channel, the hero render's texel mean against the per-channel render's, within `z` combined standard
/// errors (independent estimates of the same value).
fn assert_agree(hero: &[TexelEstimate], rgb: &[TexelEstimate], z: f64, what: &str) {
    for c in 0..3 {
        let ((mh, sh), (mr, sr)) = (mean_and_se(hero, c), mean_and_se(rgb, c));
        let se = (sh * sh + sr * sr).sqrt();
        assert!((mh - mr).abs() < z * se, "{what} channel {c}: hero {mh} rgb {mr} (se {se})");
    }
}

#[test]
fn heroes_are_stratified_in_triples_then_uniform() {
    // Each full triple of samples has heroes 0, 1, 2; the remainder's are uniform: over 3000 (texel, sample)
    // pairs each channel's count is within 5 binomial standard deviations (sqrt(3000 * 2/9) = 25.8) of 1000.
    assert!((0..30).all(|s| hero_of(1, 7, s, 31) == (s % 3) as usize));
    let mut counts = [0i32; 3];
    for t in 0..1500u64 {
        counts[hero_of(4, t, 3, 5)] += 1;
        counts[hero_of(4, t, 0, 1)] += 1;
    }
    assert!(counts.iter().all(|&k| (k - 1000).abs() < 129), "{counts:?}");
}

#[test]
fn hero_render_is_unbiased_with_fewer_samples_than_channels() {
    // spp 1 and 2 (no full triple: random heroes): the mean over 40 seeds of the texels' mean against the
    // channel render's at 4.5 standard errors (the seeds' spread and the channel render's own).
    let n = [8, 8, 6];
    let (geo, med) = slab(n, 0.05, [5.0, 10.0, 19.0], [0.5, 2.0, 0.25], 1.5, 0.4);
    let texels = top_texels(n);
    let (rgb, _) = render(&geo, &med, &texels, 0, &RenderOptions { spp: 200, seed: 1, include_specular: true });
    for spp in [1u32, 2] {
        for c in 0..3 {
            let m: Vec<f64> = (0..40)
                .map(|seed| {
                    let (e, _) =
                        render_hero(&geo, &med, &texels, 0, &RenderOptions { spp, seed, include_specular: true });
                    mean_and_se(&e, c).0
                })
                .collect();
            let mh = m.iter().sum::<f64>() / 40.0;
            let sh = (m.iter().map(|x| (x - mh).powi(2)).sum::<f64>() / 39.0 / 40.0).sqrt();
            let (mr, sr) = mean_and_se(&rgb, c);
            let se = (sh * sh + sr * sr).sqrt();
            assert!((mh - mr).abs() < 4.5 * se, "spp {spp} channel {c}: hero {mh} rgb {mr} (se {se})");
        }
    }
}

#[test]
fn hero_render_agrees_with_the_channel_render_per_channel() {
    // A homogeneous periodic slab whose channels differ (sigma_t 5.5, 12 and 19.25: 3.5x), a heterogeneous
    // slab, and a heterogeneous masked box (the scalar walk's regular tracking): the hero estimate of each
    // channel against the channel's own render at 4.5 standard errors (a false alarm 7e-6 per comparison).
    let n = [8, 8, 6];
    let (geo, med) = slab(n, 0.05, [5.0, 10.0, 19.0], [0.5, 2.0, 0.25], 1.5, 0.4);
    let texels = top_texels(n);
    let opts = RenderOptions { spp: 96, seed: 3, include_specular: true };
    assert_agree(&render_hero(&geo, &med, &texels, 0, &opts).0, &render(&geo, &med, &texels, 0, &opts).0, 4.5, "slab");
    let het = heterogeneous(8 * 8 * 6);
    let (h, r) = (render_hero(&geo, &het, &texels, 0, &opts).0, render(&geo, &het, &texels, 0, &opts).0);
    assert_agree(&h, &r, 4.5, "heterogeneous slab");
    let mut inside = vec![1u8; 8 * 8 * 6];
    inside[..64].iter_mut().step_by(3).for_each(|x| *x = 0);
    let boxed = Geometry::new(n, [0.05; 3], Boundary::Box, 1.4, 0.2).unwrap().with_inside(inside).unwrap();
    let tex = box_texels(n, &[1, 3, 5]);
    let opts = RenderOptions { spp: 301, seed: 5, include_specular: false };
    assert_agree(&render_hero(&boxed, &het, &tex, 0, &opts).0, &render(&boxed, &het, &tex, 0, &opts).0, 4.5, "box");
}

#[test]
fn hero_variance_is_bounded_where_extinctions_differ() {
    // sigma_t 2, 7 and 7 mm^-1 (3.5x) with albedos 0.99, 0.6, 0.95: each channel's second moment per path is at
    // most 3x its analog estimator's ((1/3) sum_k p_k >= p_j / 3), up to the roulettes' difference (10 % slack)
    // and the estimates' noise (5 standard errors of the second moments, from their own spread over texels).
    let n = [6, 6, 8];
    let (geo, med) = slab(n, 0.05, [1.98, 4.2, 6.65], [0.02, 2.8, 0.35], 1.5, 0.6);
    let texels = top_texels(n);
    let opts = RenderOptions { spp: 300, seed: 9, include_specular: false };
    let (hero, rgb) = (render_hero(&geo, &med, &texels, 0, &opts).0, render(&geo, &med, &texels, 0, &opts).0);
    let second = |e: &TexelEstimate, c: usize| (e.var_mean[c] * opts.spp as f32 + e.mean[c] * e.mean[c]) as f64;
    for c in 0..3 {
        let stats = |est: &[TexelEstimate]| {
            let x: Vec<f64> = est.iter().map(|e| second(e, c)).collect();
            let m = x.iter().sum::<f64>() / x.len() as f64;
            let v = x.iter().map(|y| (y - m).powi(2)).sum::<f64>() / (x.len() - 1) as f64;
            (m, (v / x.len() as f64).sqrt())
        };
        let ((mh, sh), (mr, sr)) = (stats(&hero), stats(&rgb));
        assert!(mh.is_finite() && mh > 0.0, "channel {c}: second moment {mh}");
        assert!(mh < 3.3 * mr + 5.0 * (sh * sh + 9.0 * sr * sr).sqrt(), "channel {c}: hero {mh} analog {mr}");
    }
}

#[test]
fn hero_passes_are_bit_identical_for_any_thread_count() {
    // The lanes (mask-free box) and the scalar walk (a box with a notch): renders and gradients.
    let n = [10, 9, 6];
    let mut notch = vec![1u8; 540];
    notch[..90].iter_mut().step_by(4).for_each(|x| *x = 0);
    let plain = Geometry::new(n, [0.0847; 3], Boundary::Box, 1.5, 0.4).unwrap();
    let masked = Geometry::new(n, [0.0847; 3], Boundary::Box, 1.5, 0.4).unwrap().with_inside(notch).unwrap();
    let med = heterogeneous(540);
    let texels = top_texels(n);
    let opts = RenderOptions { spp: 7, seed: 42, include_specular: true };
    for geo in [&plain, &masked] {
        let (a1, s1) = hero_in_pool(1, geo, &med, &texels, &opts);
        let (a2, s2) = hero_in_pool(2, geo, &med, &texels, &opts);
        assert_eq!(s1.events, s2.events);
        for (x, y) in a1.iter().zip(&a2) {
            assert_eq!((x.mean, x.var_mean), (y.mean, y.var_mean));
        }
        let (c1, _) = render_hero(geo, &med, &texels[..37], 0, &opts);
        let (c2, _) = render_hero(geo, &med, &texels[37..], 37, &opts);
        assert!(c1.iter().chain(&c2).zip(&a1).all(|(x, y)| x.mean == y.mean));
        let adj: Vec<[f32; 3]> = (0..texels.len()).map(|i| [1.0, -0.5, 0.1 * i as f32]).collect();
        let grad = |threads: usize| {
            let mut gb = GradBuffers::new(540);
            gb.zero(10.0);
            let pool = rayon::ThreadPoolBuilder::new().num_threads(threads).build().unwrap();
            let (est, _) = pool.install(|| backward_hero(geo, &med, &texels, 0, &adj, &opts, &gb));
            let (mut gs, mut ga) = (vec![0i64; 3 * 540], vec![0i64; 3 * 540]);
            gb.collect_fixed(&mut gs, &mut ga);
            (gs, ga, est.iter().map(|e| e.mean).collect::<Vec<_>>())
        };
        let (g1, g2) = (grad(1), grad(2));
        assert!(g1.0.iter().any(|&x| x != 0) && g1.1.iter().any(|&x| x != 0));
        assert_eq!(g1, g2);
        assert!(g1.2.iter().zip(&a1).all(|(x, y)| *x == y.mean), "the gradient pass's own render is the render");
    }
}

/// sum_i adj_i . c_i of a hero render.
fn hero_objective<M: Medium>(geo: &Geometry, med: &M, texels: &[Texel], adj: &[[f32; 3]], opts: &RenderOptions) -> f64 {
    let (est, _) = render_hero(geo, med, texels, 0, opts);
    est.iter().zip(adj).map(|(e, w)| (0..3).map(|c| e.mean[c] as f64 * w[c] as f64).sum::<f64>()).sum()
}

#[test]
fn hero_gradient_matches_finite_differences() {
    // As `replay_gradient_matches_finite_differences`, with hero paths: voxels at 3 depths, each probed in one
    // channel (the hero of a third of the paths; the others carry it), sigma_s and sigma_a, 10 seeds, Student's t
    // with 9 degrees of freedom at 1e-4 two-sided (6.59) plus 2 % for the finite differences' O(h^2) bias.
    let n = [3, 3, 4];
    let nv = 36;
    let mut coeffs = [
        (0..3 * nv).map(|i| 3.0 + ((i * 31) % 7) as f32).collect::<Vec<f32>>(),
        (0..3 * nv).map(|i| 0.5 + ((i * 17) % 5) as f32 * 0.5).collect(),
    ];
    let geo = Geometry::new(n, [0.1; 3], Boundary::PeriodicXY, 1.5, 0.4).unwrap();
    let texels = top_texels(n);
    let adj: Vec<[f32; 3]> = (0..texels.len()).map(|i| [1.0, -0.5 + 0.1 * i as f32, 0.3]).collect();
    let probes = [(4 + 9 * 3, 0usize), (4 + 9 * 2, 1), (4, 2)];
    let opts = |seed| RenderOptions { spp: 1500, seed, include_specular: true };
    let medium = |c: &[Vec<f32>; 2]| DenseMedium::from_interleaved(&c[0], &c[1]).unwrap();
    for &(j, c) in &probes {
        for which in 0..2 {
            let (mut grads, mut fds) = (vec![], vec![]);
            for seed in 11..21u64 {
                let mut gb = GradBuffers::new(nv);
                gb.zero(1.0);
                backward_hero(&geo, &medium(&coeffs), &texels, 0, &adj, &opts(seed), &gb);
                let (mut gs, mut ga) = (vec![0.0; 3 * nv], vec![0.0; 3 * nv]);
                gb.collect(&mut gs, &mut ga);
                grads.push(if which == 0 { gs[3 * j + c] } else { ga[3 * j + c] } as f64);
                let h = 0.25f32;
                let orig = coeffs[which][3 * j + c];
                coeffs[which][3 * j + c] = orig + h;
                let fp = hero_objective(&geo, &medium(&coeffs), &texels, &adj, &opts(seed));
                coeffs[which][3 * j + c] = orig - h;
                let fm = hero_objective(&geo, &medium(&coeffs), &texels, &adj, &opts(seed));
                coeffs[which][3 * j + c] = orig;
                fds.push((fp - fm) / (2.0 * h as f64));
            }
            let what = format!("hero voxel {j} c {c} {}", ["sigma_s", "sigma_a"][which]);
            assert_gradient_matches_fd(&grads, &fds, 6.59, 0.02, 1e-4, &what);
        }
    }
}

#[test]
fn hero_total_gradient_matches_a_uniform_shift() {
    // The gradient summed over voxels against the derivative of shifting every voxel's sigma_a or sigma_s of one
    // channel together, for the lanes (mask-free slab; a masked box with a notch: safe balls and the scalar walk
    // near the surface) and the scalar walk alone (a masked periodic slab): a systematic error in the tallied
    // lengths or collisions fails it. 8 seeds, Student's t (5.41 at 1e-4 two-sided) plus 1 % for the O(h^2) bias.
    let n = [6usize, 6, 6];
    let nv = 216;
    let plain = Geometry::new(n, [0.05; 3], Boundary::PeriodicXY, 1.5, 0.3).unwrap();
    let masked =
        Geometry::new(n, [0.05; 3], Boundary::PeriodicXY, 1.5, 0.3).unwrap().with_inside(vec![1u8; nv]).unwrap();
    let mut notch = vec![1u8; nv];
    notch[..36].iter_mut().step_by(2).for_each(|x| *x = 0);
    let boxed = Geometry::new(n, [0.05; 3], Boundary::Box, 1.5, 0.3).unwrap().with_inside(notch).unwrap();
    let texels = top_texels(n);
    let adj: Vec<[f32; 3]> = (0..texels.len()).map(|i| [0.5, 1.0, -0.3 - 0.01 * i as f32]).collect();
    let base = [
        (0..3 * nv).map(|i| 4.0 + ((i * 13) % 9) as f32).collect::<Vec<f32>>(),
        (0..3 * nv).map(|i| 0.2 + ((i * 7) % 4) as f32 * 0.6).collect(),
    ];
    let cases =
        [(&plain, 1usize, 1usize), (&plain, 0, 2), (&masked, 1, 0), (&masked, 0, 2), (&boxed, 1, 2), (&boxed, 0, 0)];
    for (geo, which, c) in cases {
        let (mut grads, mut fds) = (vec![], vec![]);
        for seed in 1..9u64 {
            let opts = RenderOptions { spp: 240, seed, include_specular: true };
            let shifted = |h: f32| {
                let mut k = base.clone();
                (0..nv).for_each(|j| k[which][3 * j + c] += h);
                DenseMedium::from_interleaved(&k[0], &k[1]).unwrap()
            };
            let mut gb = GradBuffers::new(nv);
            gb.zero(1.0);
            backward_hero(geo, &shifted(0.0), &texels, 0, &adj, &opts, &gb);
            let (mut gs, mut ga) = (vec![0.0; 3 * nv], vec![0.0; 3 * nv]);
            gb.collect(&mut gs, &mut ga);
            let g = if which == 0 { &gs } else { &ga };
            grads.push((0..nv).map(|j| g[3 * j + c] as f64).sum());
            let h = 0.1;
            let fp = hero_objective(geo, &shifted(h), &texels, &adj, &opts);
            let fm = hero_objective(geo, &shifted(-h), &texels, &adj, &opts);
            fds.push((fp - fm) / (2.0 * h as f64));
        }
        let what = format!("masked {} {:?} shift {which} channel {c}", geo.masked(), geo.boundary);
        assert_gradient_matches_fd(&grads, &fds, 5.41, 0.01, 1e-4, &what);
    }
}
