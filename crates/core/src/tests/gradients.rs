//! Gradients against central finite differences with common random numbers (`assert_gradient_matches_fd`).

use super::*;

#[test]
fn replay_gradient_matches_finite_differences() {
    // Path replay per voxel: voxels at 3 depths, channels 0 and 1, for sigma_s and sigma_a, of a periodic slab.
    // 10 seeds: the standard error of the difference is estimated from them, so the bound is Student's t with
    // 9 degrees of freedom at a two-sided false-alarm rate of 1e-4 per probe (6.59), not a normal 4 sigma, plus
    // 2 % for the O(h^2) finite-difference bias.
    let n = [3, 3, 4];
    let nv = 36;
    let mut coeffs = [
        (0..3 * nv).map(|i| 3.0 + ((i * 31) % 7) as f32).collect::<Vec<f32>>(),
        (0..3 * nv).map(|i| 0.5 + ((i * 17) % 5) as f32 * 0.5).collect(),
    ];
    let geo = Geometry::new(n, [0.1; 3], Boundary::PeriodicXY, 1.5, 0.4).unwrap();
    let texels = top_texels(n);
    let adj: Vec<[f32; 3]> = (0..texels.len()).map(|i| [1.0, -0.5 + 0.1 * i as f32, 0.3]).collect();
    // Voxel (1, 1) of layers z = 3, 2 and 0 (9 voxels per layer), and a channel each.
    let probes = [(4 + 9 * 3, 0usize), (4 + 9 * 2, 1), (4, 0)];
    let opts = |seed| RenderOptions { spp: 1500, seed, include_specular: true };
    let medium = |c: &[Vec<f32>; 2]| DenseMedium::from_interleaved(&c[0], &c[1]).unwrap();
    for &(j, c) in &probes {
        for which in 0..2 {
            let (mut grads, mut fds) = (vec![], vec![]);
            for seed in 11..21u64 {
                let (gs, ga) = replay_gradient(&geo, &medium(&coeffs), &texels, &adj, &opts(seed));
                grads.push(if which == 0 { gs[3 * j + c] } else { ga[3 * j + c] } as f64);
                let h = 0.25f32;
                let orig = coeffs[which][3 * j + c];
                coeffs[which][3 * j + c] = orig + h;
                let fp = objective(&geo, &medium(&coeffs), &texels, &adj, &opts(seed));
                coeffs[which][3 * j + c] = orig - h;
                let fm = objective(&geo, &medium(&coeffs), &texels, &adj, &opts(seed));
                coeffs[which][3 * j + c] = orig;
                fds.push((fp - fm) / (2.0 * h as f64));
            }
            let what = format!("voxel {j} c {c} {}", ["sigma_s", "sigma_a"][which]);
            assert_gradient_matches_fd(&grads, &fds, 6.59, 0.02, 1e-4, &what);
        }
    }
}

#[test]
fn total_gradient_matches_a_uniform_shift() {
    // The gradient summed over all voxels is the derivative for shifting every voxel's coefficient by the same
    // amount: a sharp check of systematic errors in track lengths and scattering counts (a 10 % error in the
    // tallied lengths fails it), on the three gradient paths: packets in a periodic slab (delta tracking),
    // packets in a masked box (safe balls + general walk) and the scalar walk (periodic slab with a mask).
    // Tested against Student's t (8 seeds, two-sided 1e-4: 5.41) x its standard error, plus 1 % for the O(h^2)
    // bias.
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
        (
            Geometry::new(n, [0.1; 3], Boundary::Box, 1.5, 0.4).unwrap().with_inside(inside_notch.clone()).unwrap(),
            inside_notch.clone(),
        ),
        (
            Geometry::new(n, [0.1; 3], Boundary::PeriodicXY, 1.5, 0.4).unwrap().with_inside(vec![1u8; nv]).unwrap(),
            vec![1u8; nv],
        ),
    ];
    let texels: Vec<Texel> =
        top_texels(n).into_iter().filter(|t| !(t.voxel[1] >= 2 && t.voxel[1] < 4 && t.voxel[0] < 2)).collect();
    let adj: Vec<[f32; 3]> = (0..texels.len()).map(|i| [1.0, 0.5 + 0.05 * i as f32, -0.7]).collect();
    let base_s: Vec<f32> = (0..3 * nv).map(|i| 4.0 + ((i * 31) % 7) as f32).collect();
    let base_a: Vec<f32> = (0..3 * nv).map(|i| 0.5 + ((i * 17) % 5) as f32 * 0.3).collect();
    for (geo, inside) in cases {
        let coeffs = |ds: f32, da: f32| -> DenseMedium {
            let s: Vec<f32> = (0..3 * nv).map(|i| if inside[i / 3] != 0 { base_s[i] + ds } else { 0.0 }).collect();
            let a: Vec<f32> = (0..3 * nv).map(|i| if inside[i / 3] != 0 { base_a[i] + da } else { 0.0 }).collect();
            DenseMedium::from_interleaved(&s, &a).unwrap()
        };
        let opts = |seed| RenderOptions { spp: 1000, seed, include_specular: true };
        for which in 0..2 {
            let (mut g, mut fd) = (vec![], vec![]);
            for seed in 40..48u64 {
                let (gs, ga) = replay_gradient(&geo, &coeffs(0.0, 0.0), &texels, &adj, &opts(seed));
                let grad = if which == 0 { &gs } else { &ga };
                g.push((0..3 * nv).filter(|i| inside[i / 3] != 0).map(|i| grad[i] as f64).sum::<f64>());
                let h = 0.2f32;
                let shift = |x: f32| if which == 0 { coeffs(x, 0.0) } else { coeffs(0.0, x) };
                let (fp, fm) = (
                    objective(&geo, &shift(h), &texels, &adj, &opts(seed)),
                    objective(&geo, &shift(-h), &texels, &adj, &opts(seed)),
                );
                fd.push((fp - fm) / (2.0 * h as f64));
            }
            let what = format!("{:?} masked {} {}", geo.boundary, geo.masked(), ["sigma_s", "sigma_a"][which]);
            assert_gradient_matches_fd(&g, &fd, 5.41, 0.01, 0.0, &what);
        }
    }
}

#[test]
fn li1_gives_sigma_a_only() {
    // Under the L_i = 1 approximation the sigma_s derivative vanishes: the buffers' sigma_s sums (rebuilt from the
    // difference sums) are exactly 0 and the sigma_a sums are not, on a mask-free box (packets) and a masked
    // periodic slab (scalar tracer).
    let n = [4, 3, 3];
    let nv = 36;
    let med = heterogeneous(nv);
    for geo in [
        Geometry::new(n, [0.1; 3], Boundary::Box, 1.5, 0.4).unwrap(),
        Geometry::new(n, [0.1; 3], Boundary::PeriodicXY, 1.5, 0.4).unwrap().with_inside(vec![1; nv]).unwrap(),
    ] {
        let texels = top_texels(n);
        let adj: Vec<[f32; 3]> = (0..texels.len()).map(|i| [1.0, -0.5 + 0.1 * i as f32, 0.3]).collect();
        let mut gb = GradBuffers::new(nv);
        gb.zero(1.0);
        backward(
            &geo,
            &med,
            &texels,
            0,
            &adj,
            &RenderOptions { spp: 64, seed: 3, include_specular: true },
            GradMethod::Li1,
            &gb,
        );
        let (mut gs, mut ga) = (vec![1.0; 3 * nv], vec![0.0; 3 * nv]);
        gb.collect(&mut gs, &mut ga);
        assert!(gs.iter().all(|&g| g == 0.0), "{:?}: sigma_s gradient {gs:?}", geo.boundary);
        assert!(ga.iter().filter(|&&g| g != 0.0).count() > nv, "{:?}: sigma_a gradient {ga:?}", geo.boundary);
    }
}
