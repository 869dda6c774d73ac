//! The samplers against each other: regular and delta tracking, the packets against the scalar tracer, the
//! eight-lane phase function against the scalar one.

use wide::f32x8;

use super::*;
use crate::transport::packet::step::hg8;

/// Mean, variance of the mean and collisions of `spp` scalar-traced paths of texel i (`trace::trace`).
pub(super) fn scalar_estimate<M: Medium>(
    geo: &Geometry,
    med: &M,
    tex: &Texel,
    i: u64,
    c: usize,
    spp: u32,
    seed: u64,
    include_specular: bool,
) -> (f64, f64, u64) {
    let (mut sum, mut sq, mut events) = (0.0f64, 0.0f64, 0u64);
    for k in 0..spp {
        let mut rng = crate::transport::rng::PathRng::new(seed, i, k, c as u32);
        let r = crate::transport::trace::trace(
            geo,
            med,
            tex,
            c,
            &mut rng,
            include_specular,
            &mut crate::transport::path::NoTally,
        );
        sum += r.value as f64;
        sq += (r.value as f64).powi(2);
        events += r.events as u64;
    }
    let m = sum / spp as f64;
    (m, (sq / spp as f64 - m * m) / (spp - 1) as f64, events)
}

#[test]
fn regular_and_delta_tracking_agree_on_heterogeneous_media() {
    // The scalar tracer in the same heterogeneous box with an all-true inside mask (regular tracking, voxel by
    // voxel) and without (delta tracking): two exact samplers of the same transport, within 4 standard errors.
    let n = [7, 6, 5];
    let geo_d = Geometry::new(n, [0.08, 0.05, 0.1], Boundary::Box, 1.5, 0.4).unwrap();
    let geo_r =
        Geometry::new(n, [0.08, 0.05, 0.1], Boundary::Box, 1.5, 0.4).unwrap().with_inside(vec![1; 210]).unwrap();
    let med = heterogeneous(210);
    for (i, tex) in box_texels(n, &[0, 1, 2, 3, 4, 5]).iter().enumerate() {
        for c in 0..3 {
            let (md, vd, _) = scalar_estimate(&geo_d, &med, tex, i as u64, c, 2000, 8, true);
            let (mr, vr, _) = scalar_estimate(&geo_r, &med, tex, i as u64, c, 2000, 9, true);
            let se = (vd + vr).sqrt();
            assert!((md - mr).abs() < 4.0 * se + 1e-6, "texel {i} c {c}: {md} vs {mr} (se {se})");
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
    let med = heterogeneous(210);
    let box_texels = |faces: &[u8]| box_texels(n, faces);
    // A masked object: the box minus a notch (a concave part light can re-enter) and one corner, whose interior
    // is deep enough for the delta-tracking balls (voxels 0.05 mm, safe distances up to 3).
    let big = [12usize, 11, 10];
    let mut inside = vec![1u8; big.iter().product()];
    for z in 0..big[2] {
        for y in 0..big[1] {
            for x in 0..big[0] {
                if ((5..=6).contains(&x) && z >= 6) || (x + y + z < 4) {
                    inside[(z * big[1] + y) * big[0] + x] = 0;
                }
            }
        }
    }
    // Vacuum outside the object, as in voxelized meshes.
    // Channel 0 thin (free paths of several voxels: flights often reach the edge of their safe ball), 1-2 dense.
    let big_s: Vec<f32> = (0..3 * inside.len())
        .map(|i| {
            if inside[i / 3] == 0 {
                0.0
            } else if i % 3 == 0 {
                2.0 + ((i * 7919) % 5) as f32
            } else {
                5.0 + ((i * 7919) % 23) as f32
            }
        })
        .collect();
    let big_a: Vec<f32> = (0..3 * inside.len())
        .map(|i| {
            if inside[i / 3] == 0 {
                0.0
            } else if i % 3 == 0 {
                0.2
            } else {
                ((i * 104729) % 7) as f32 * 0.5
            }
        })
        .collect();
    let big_med = DenseMedium::from_interleaved(&big_s, &big_a).unwrap();
    let masked_geo =
        Geometry::new(big, [0.05; 3], Boundary::Box, 1.5, 0.4).unwrap().with_inside(inside.clone()).unwrap();
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
        (
            Geometry::new(big, [0.05; 3], Boundary::Box, 1.5, 0.4).unwrap().with_inside(inside.clone()).unwrap(),
            &big_med,
            masked_texels,
        ),
    ];
    for (geo, med, texels) in cases {
        let boundary = (geo.boundary, geo.masked());
        for include_specular in [true, false] {
            let spp = 3000u32;
            let (packed, stats) = render(&geo, med, &texels, 0, &RenderOptions { spp, seed: 21, include_specular });
            let mut scalar_events = 0u64;
            for (i, (tex, x)) in texels.iter().zip(&packed).enumerate() {
                for c in 0..3 {
                    let (m, var_mean, ev) = scalar_estimate(&geo, med, tex, i as u64, c, spp, 22, include_specular);
                    scalar_events += ev;
                    let se = (x.var_mean[c] as f64 + var_mean).sqrt();
                    assert!(
                        (x.mean[c] as f64 - m).abs() < 4.5 * se + 1e-6,
                        "{boundary:?} specular {include_specular} texel {i} c {c}: {} vs {m} (se {se})",
                        x.mean[c]
                    );
                }
            }
            // Collisions per path agree too (same walk): within 3 %, far above the noise of ~1e5 paths.
            let ratio = stats.events as f64 / scalar_events as f64;
            assert!((ratio - 1.0).abs() < 0.03, "events ratio {ratio}");
        }
    }
}

#[test]
fn hg8_matches_the_scalar_sampler() {
    let d = crate::transport::sampling::normalize([0.3, -0.5, 0.81]);
    let u1 = f32x8::from([0.01, 0.2, 0.35, 0.5, 0.61, 0.77, 0.9, 0.999]);
    let u2 = f32x8::from([0.9, 0.1, 0.33, 0.5, 0.7, 0.25, 0.05, 0.6]);
    let w = hg8(d.map(f32x8::splat), 0.4, u1, u2);
    let (a, b) = (u1.to_array(), u2.to_array());
    for l in 0..8 {
        let s = crate::transport::sampling::hg_sample(d, 0.4, a[l], b[l]);
        for k in 0..3 {
            assert!((w[k].to_array()[l] - s[k]).abs() < 2e-5, "lane {l}: {:?} vs {s:?}", w.map(|x| x.to_array()[l]));
        }
    }
}

#[test]
fn jumps_across_empty_space_leave_renders_unchanged() {
    // Two plates facing each other across 30 voxels of vacuum: light leaving the lower plate's inner face
    // crosses the gap (brick-level and voxel-level jumps, `grid::empty_jump`) and re-enters the upper plate.
    // Jumping changes only where a flight in vacuum is computed, not which voxels it meets, so the render with
    // jumps equals the voxel-by-voxel one up to the float rounding of re-entry points: nearly every texel
    // bit-identical (95 %; measured: all but 1 of 576) and none by more than a tenth of its standard error; walks
    // across the gap take far fewer steps with the jumps and reach the same voxels. Without the upper
    // plate the texels differ by many standard errors (it shades them from the light above and sends some back):
    // what the flights across the gap meet matters.
    let n = [40usize, 36, 40];
    let plate = |z: usize, upper: bool| z < 4 || (upper && z >= 34);
    let mask = |upper: bool| -> Vec<u8> {
        (0..n.iter().product::<usize>()).map(|j| plate(j / (n[0] * n[1]), upper) as u8).collect()
    };
    let (both, lower) = (mask(true), mask(false));
    let coeffs =
        |m: &[u8], v: f32| -> Vec<f32> { (0..3 * m.len()).map(|i| if m[i / 3] == 0 { 0.0 } else { v }).collect() };
    let med = |m: &[u8]| DenseMedium::from_interleaved(&coeffs(m, 20.0), &coeffs(m, 0.5)).unwrap();
    let (med_both, med_lower) = (med(&both), med(&lower));
    let geo = |m: &[u8]| Geometry::new(n, [0.05; 3], Boundary::Box, 1.5, 0.4).unwrap().with_inside(m).unwrap();
    let jumps = geo(&both);
    assert!(jumps.brick_empty.as_ref().unwrap().iter().any(|&e| e >= 2), "the gap should hold empty bricks");
    let mut stepped = geo(&both);
    stepped.brick_empty = None;
    let texels: Vec<Texel> = (8..32)
        .flat_map(|y| (8..32).step_by(3).map(move |x| Texel { voxel: [x, y, 3], face: 5, normal: [0.0, 0.0, 1.0] }))
        .collect();
    let opts = RenderOptions { spp: 400, seed: 5, include_specular: false };
    let (a, _) = render(&jumps, &med_both, &texels, 0, &opts);
    let (b, _) = render(&stepped, &med_both, &texels, 0, &opts);
    let (open, _) = render(&geo(&lower), &med_lower, &texels, 0, &opts);
    for c in 0..3 {
        let ((ma, se), (mb, _), (mo, seo)) = (mean_and_se(&a, c), mean_and_se(&b, c), mean_and_se(&open, c));
        assert!((ma - mb).abs() < 1e-3 * ma, "channel {c}: {ma} with jumps, {mb} voxel by voxel");
        assert!(
            (ma - mo).abs() > 10.0 * (se * se + seo * seo).sqrt(),
            "channel {c}: {ma} with the upper plate, {mo} without"
        );
        let mut same = 0;
        for (i, (x, y)) in a.iter().zip(&b).enumerate() {
            let se = (x.var_mean[c] as f64).sqrt();
            same += (x.mean[c] == y.mean[c]) as usize;
            assert!((x.mean[c] as f64 - y.mean[c] as f64).abs() <= 0.1 * se, "texel {i} channel {c}");
        }
        assert!(same * 20 >= a.len() * 19, "channel {c}: {same} of {} texels bit-identical", a.len());
    }
    // Flights leaving the lower plate straight up from the middle of its inner face, each walked (with its own
    // random numbers) until it scatters deep in a plate or ends: the same outcome and voxel either way, and
    // fewer steps with the jumps whenever it scatters in the upper plate.
    let walk = |geo: &Geometry, key: u64| {
        let mut w = crate::transport::path::Walk {
            p: [1.0, 0.9, 0.2],
            d: [0.0, 0.0, 1.0],
            v: [20, 18, 4],
            weight: 1.0,
            in_medium: false,
            events: 0,
            steps: 0,
        };
        let mut rng = crate::transport::rng::PathRng::new(1, key, 3, 0);
        let mut tracker = crate::transport::flight::Regular::new();
        match crate::transport::trace::walk(
            geo,
            &med_both,
            0,
            &mut w,
            &mut tracker,
            &mut rng,
            &mut crate::transport::path::NoTally,
            true,
        ) {
            crate::transport::trace::WalkEnd::Deep => Some((w.steps, w.v)),
            crate::transport::trace::WalkEnd::Done(_) => None,
        }
    };
    let mut upper = 0;
    for key in 0..64 {
        let (a, b) = (walk(&jumps, key), walk(&stepped, key));
        assert_eq!(a.map(|x| x.1), b.map(|x| x.1), "key {key}");
        if let (Some((ja, v)), Some((jb, _))) = (a, b) {
            if v[2] >= 30 {
                upper += 1;
                assert!(ja + 15 < jb, "key {key}: {ja} steps with jumps, {jb} voxel by voxel");
            }
        }
    }
    assert!(upper >= 5, "{upper} of 64 flights scattered deep in the upper plate");
}
