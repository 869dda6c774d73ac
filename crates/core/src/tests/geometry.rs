//! Safe distances of masks and the safe balls of the masked packet walk.

use wide::{f32x8, i32x8};

use crate::grid::safe_radius8;
use crate::sampling::V3;
use crate::*;

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
fn safe_balls_stay_inside_the_object() {
    // Random points in the voxels of a random blob (anisotropic voxels): no voxel that the ball of radius
    // safe_radius8 around the point reaches (box-to-point distance below the radius) is outside.
    let n = [14usize, 12, 13];
    let size = [0.05f32, 0.08, 0.03];
    let mut inside = vec![0u8; n.iter().product()];
    for z in 0..n[2] {
        for y in 0..n[1] {
            for x in 0..n[0] {
                let r2 = ((x as f32 - 6.5) / 6.0).powi(2) + ((y as f32 - 5.5) / 5.0).powi(2) + ((z as f32 - 6.0) / 5.5).powi(2);
                inside[(z * n[1] + y) * n[0] + x] = (r2 < 1.0 && (x + 2 * y) % 11 != 3) as u8;
            }
        }
    }
    let geo = Geometry::new(n, size, Boundary::Box, 1.5, 0.4).unwrap().with_inside(inside.clone()).unwrap();
    let mut rng = crate::rng::PathRng::new(9, 0, 0, 0);
    let mut checked = 0;
    for j in 0..inside.len() {
        let s = geo.safe_distance(j);
        if s < 2 {
            continue;
        }
        let v = [(j % n[0]) as i32, ((j / n[0]) % n[1]) as i32, (j / (n[0] * n[1])) as i32];
        for _ in 0..20 {
            let p: V3 = std::array::from_fn(|a| (v[a] as f32 + rng.next_f32()) * size[a]);
            let r = safe_radius8(&geo, p.map(f32x8::splat), v.map(i32x8::splat), f32x8::splat(s as f32)).to_array()[0];
            assert!(r >= (s as f32 - 1.0) * 0.03 * (1.0 - 1e-4) - 1e-6);
            for k in 0..inside.len() {
                let w = [(k % n[0]) as i32, ((k / n[0]) % n[1]) as i32, (k / (n[0] * n[1])) as i32];
                let d2: f32 = (0..3)
                    .map(|a| {
                        let (lo, hi) = (w[a] as f32 * size[a], (w[a] + 1) as f32 * size[a]);
                        (lo - p[a]).max(p[a] - hi).max(0.0).powi(2)
                    })
                    .sum();
                if d2 < r * r * (1.0 - 1e-5) {
                    assert_eq!(inside[k], 1, "point {p:?} in voxel {v:?} (safe {s}) radius {r} reaches {w:?}");
                }
            }
            checked += 1;
        }
    }
    assert!(checked > 500, "{checked}");
}
