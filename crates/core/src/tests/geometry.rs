//! Safe distances of masks and the safe balls of the masked packet walk.

use wide::{f32x8, i32x8};

use crate::transport::grid::safe_radius8;
use crate::transport::sampling::V3;
use crate::*;

/// Voxel (x, y, z) of linear index j in a grid of n voxels.
fn voxel_at(n: [usize; 3], j: usize) -> [i32; 3] {
    [(j % n[0]) as i32, ((j / n[0]) % n[1]) as i32, (j / (n[0] * n[1])) as i32]
}

/// Squared distance from point p to the box of voxel w (edges `size`).
fn box_distance2(p: V3, w: [i32; 3], size: [f32; 3]) -> f32 {
    (0..3)
        .map(|a| {
            let (lo, hi) = (w[a] as f32 * size[a], (w[a] + 1) as f32 * size[a]);
            (lo - p[a]).max(p[a] - hi).max(0.0).powi(2)
        })
        .sum()
}

#[test]
fn safe_distances_match_brute_force() {
    // Random blobs: every voxel's safe distance equals the brute-force Chebyshev distance to the nearest voxel
    // outside the object or the grid (capped).
    let n = [15usize, 13, 14];
    let mut rng = crate::transport::rng::PathRng::new(5, 0, 0, 0);
    let centres: Vec<[f32; 3]> =
        (0..3).map(|_| [3.0 + rng.next_f32() * 9.0, 3.0 + rng.next_f32() * 7.0, 3.0 + rng.next_f32() * 8.0]).collect();
    let idx = |x: usize, y: usize, z: usize| (z * n[1] + y) * n[0] + x;
    let mut inside = vec![0u8; n[0] * n[1] * n[2]];
    for z in 0..n[2] {
        for y in 0..n[1] {
            for x in 0..n[0] {
                let p = [x as f32, y as f32, z as f32];
                inside[idx(x, y, z)] =
                    centres.iter().any(|c| (0..3).map(|a| (p[a] - c[a]).powi(2)).sum::<f32>() < 30.0) as u8;
            }
        }
    }
    let safe = crate::transport::scene::safe_distances(&inside, n);
    for z in 0..n[2] as i32 {
        for y in 0..n[1] as i32 {
            for x in 0..n[0] as i32 {
                let mut best = i32::MAX;
                for oz in -1..=n[2] as i32 {
                    for oy in -1..=n[1] as i32 {
                        for ox in -1..=n[0] as i32 {
                            let out = ox < 0
                                || oy < 0
                                || oz < 0
                                || ox >= n[0] as i32
                                || oy >= n[1] as i32
                                || oz >= n[2] as i32
                                || inside[idx(ox as usize, oy as usize, oz as usize)] == 0;
                            if out {
                                best = best.min((ox - x).abs().max((oy - y).abs()).max((oz - z).abs()));
                            }
                        }
                    }
                }
                let want = best.min(crate::transport::scene::SAFE_CAP as i32) as u8;
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
                let r2 = ((x as f32 - 6.5) / 6.0).powi(2)
                    + ((y as f32 - 5.5) / 5.0).powi(2)
                    + ((z as f32 - 6.0) / 5.5).powi(2);
                inside[(z * n[1] + y) * n[0] + x] = (r2 < 1.0 && (x + 2 * y) % 11 != 3) as u8;
            }
        }
    }
    let geo = Geometry::new(n, size, Boundary::Box, 1.5, 0.4).unwrap().with_inside(inside.clone()).unwrap();
    let mut rng = crate::transport::rng::PathRng::new(9, 0, 0, 0);
    let mut checked = 0;
    for j in 0..inside.len() {
        let v = voxel_at(n, j);
        let s = geo.safe_distance(v);
        if s < 2 {
            continue;
        }
        for _ in 0..20 {
            let p: V3 = std::array::from_fn(|a| (v[a] as f32 + rng.next_f32()) * size[a]);
            let r = safe_radius8(&geo, p.map(f32x8::splat), v.map(i32x8::splat), f32x8::splat(s as f32)).to_array()[0];
            assert!(r >= (s as f32 - 1.0) * 0.03 * (1.0 - 1e-4) - 1e-6);
            for k in 0..inside.len() {
                let w = voxel_at(n, k);
                if box_distance2(p, w, size) < r * r * (1.0 - 1e-5) {
                    assert_eq!(inside[k], 1, "point {p:?} in voxel {v:?} (safe {s}) radius {r} reaches {w:?}");
                }
            }
            checked += 1;
        }
    }
    assert!(checked > 500, "{checked}");
}

/// Brute-force Chebyshev distance (in cells) from cell c to the nearest cell of an (n) grid for which `hit` is
/// true, cells beyond the grid never hit; capped.
fn nearest_hit(n: [usize; 3], c: [i32; 3], cap: i32, hit: impl Fn(usize) -> bool) -> i32 {
    let mut best = cap;
    for z in 0..n[2] {
        for y in 0..n[1] {
            for x in 0..n[0] {
                if hit((z * n[1] + y) * n[0] + x) {
                    best = best.min((x as i32 - c[0]).abs().max((y as i32 - c[1]).abs()).max((z as i32 - c[2]).abs()));
                }
            }
        }
    }
    best
}

/// A mask of three random blobs (concavities between them) in a grid of n voxels.
fn blobs(n: [usize; 3], seed: u64) -> Vec<u8> {
    let mut rng = crate::transport::rng::PathRng::new(seed, 0, 0, 0);
    let centres: Vec<[f32; 3]> =
        (0..3).map(|_| std::array::from_fn(|a| 2.0 + rng.next_f32() * (n[a] as f32 - 4.0))).collect();
    let mut inside = vec![0u8; n.iter().product()];
    for z in 0..n[2] {
        for y in 0..n[1] {
            for x in 0..n[0] {
                let p = [x as f32, y as f32, z as f32];
                inside[(z * n[1] + y) * n[0] + x] =
                    centres.iter().any(|c| (0..3).map(|a| (p[a] - c[a]).powi(2)).sum::<f32>() < 12.0) as u8;
            }
        }
    }
    inside
}

#[test]
fn empty_distances_match_brute_force() {
    // Every voxel's empty distance is its Chebyshev distance to the nearest inside voxel (0 inside, the grid's
    // exterior empty, capped); every brick's, in bricks, to the nearest brick that holds an inside voxel.
    let n = [40usize, 19, 27];
    let inside = blobs(n, 3);
    let empty = crate::transport::scene::empty_distances(&inside, n);
    let cap = crate::transport::scene::SAFE_CAP as i32;
    for z in 0..n[2] {
        for y in 0..n[1] {
            for x in 0..n[0] {
                let want = nearest_hit(n, [x as i32, y as i32, z as i32], cap, |k| inside[k] != 0);
                assert_eq!(empty[(z * n[1] + y) * n[0] + x] as i32, want, "voxel {x} {y} {z}");
            }
        }
    }
    assert!(empty.iter().any(|&e| e >= 4), "the test grid should have empty space");
    // The geometry keeps both in one signed array.
    let safe = crate::transport::scene::safe_distances(&inside, n);
    let geo = Geometry::new(n, [0.1; 3], Boundary::Box, 1.5, 0.4).unwrap().with_inside(inside.clone()).unwrap();
    for j in 0..inside.len() {
        let v = voxel_at(n, j);
        assert_eq!(
            (geo.safe_distance(v), geo.empty_distance(v), geo.mask_inside(v)),
            (safe[j], empty[j], inside[j] != 0)
        );
    }
    let b = crate::transport::scene::BRICK;
    let nb: [usize; 3] = std::array::from_fn(|a| n[a].div_ceil(b));
    let bricks = crate::transport::scene::brick_empty_distances(&inside, n);
    let occupied = |k: usize| {
        let c = [k % nb[0], (k / nb[0]) % nb[1], k / (nb[0] * nb[1])];
        (0..inside.len()).any(|j| {
            let v = [j % n[0], (j / n[0]) % n[1], j / (n[0] * n[1])];
            inside[j] != 0 && (0..3).all(|a| v[a] / b == c[a])
        })
    };
    let occ: Vec<bool> = (0..bricks.len()).map(occupied).collect();
    for k in 0..bricks.len() {
        let c = [(k % nb[0]) as i32, ((k / nb[0]) % nb[1]) as i32, (k / (nb[0] * nb[1])) as i32];
        assert_eq!(bricks[k] as i32, nearest_hit(nb, c, 255, |i| occ[i]), "brick {c:?}");
    }
    // Mask without any inside voxel: everything is empty as far as the cap.
    let none = crate::transport::scene::empty_distances(&[0u8; 60], [5, 4, 3]);
    assert!(none.iter().all(|&e| e == crate::transport::scene::SAFE_CAP));
}

#[test]
fn empty_jumps_cross_no_voxel_of_the_object() {
    // Random points in outside voxels, random directions (anisotropic voxels): no inside voxel lies within the
    // jump's length of its start (the ball it crosses), the voxel it names holds the new position, and away from
    // the object the brick level gives jumps longer than the voxel level could.
    let n = [75usize, 21, 30];
    let size = [0.05f32, 0.08, 0.03];
    // Blobs in the first 30 voxels along x, empty space beyond (bricks far from the object).
    let sub = blobs([30, n[1], n[2]], 11);
    let inside: Vec<u8> = (0..n.iter().product::<usize>())
        .map(|j| if j % n[0] < 30 { sub[(j / n[0]) * 30 + j % n[0]] } else { 0 })
        .collect();
    let geo = Geometry::new(n, size, Boundary::Box, 1.5, 0.4).unwrap().with_inside(inside.clone()).unwrap();
    let mut rng = crate::transport::rng::PathRng::new(4, 0, 0, 0);
    let (mut checked, mut big) = (0, 0);
    let voxel_cap = (crate::transport::scene::SAFE_CAP - 1) as f32 * 0.08 + 0.08;
    for j in (0..inside.len()).filter(|&j| inside[j] == 0).step_by(7) {
        let v = voxel_at(n, j);
        let p: V3 = std::array::from_fn(|a| (v[a] as f32 + rng.next_f32()) * size[a]);
        let d = crate::transport::sampling::hg_sample([0.0, 0.0, 1.0], 0.0, rng.next_f32(), rng.next_f32());
        let Some((q, w)) = crate::transport::grid::empty_jump(&geo, p, d, v) else { continue };
        let r = (0..3).map(|a| (q[a] - p[a]).powi(2)).sum::<f32>().sqrt();
        assert!(r > 0.0);
        big += (r > voxel_cap) as usize;
        assert!(box_distance2(q, w, size) < 1e-10, "jump to {q:?} names voxel {w:?}");
        for k in (0..inside.len()).filter(|&k| inside[k] != 0) {
            let w = voxel_at(n, k);
            assert!(
                box_distance2(p, w, size) >= r * r * (1.0 - 1e-5),
                "point {p:?} in voxel {v:?}: a jump of {r} reaches inside voxel {w:?}"
            );
        }
        checked += 1;
    }
    assert!(checked > 300 && big > 0, "{checked} jumps, {big} from bricks");
    // Periodic grids have none (a flight wraps around).
    let periodic = Geometry::new(n, size, Boundary::PeriodicXY, 1.5, 0.4).unwrap().with_inside(inside).unwrap();
    assert!(periodic.brick_empty.is_none());
}

#[test]
fn empty_jumps_far_from_the_origin_never_land_inside() {
    // 2400 voxels of 27 µm along x: walls every 6 voxels (voxel-level jumps) up to x = 1990, then empty space
    // (brick-level jumps) up to a last wall at the far end. Far from the origin the rounding of the landing point
    // and of its voxel index is larger than the balls' margin; the jump must still never name an inside voxel.
    let n = [2400usize, 3, 3];
    let size = [0.027f32; 3];
    let inside: Vec<u8> = (0..n.iter().product::<usize>())
        .map(|j| {
            let x = j % n[0];
            ((x < 1990 && x.is_multiple_of(6)) || x == n[0] - 1) as u8
        })
        .collect();
    let geo = Geometry::new(n, size, Boundary::Box, 1.5, 0.4).unwrap().with_inside(inside.clone()).unwrap();
    let mut rng = crate::transport::rng::PathRng::new(8, 0, 0, 0);
    let mut jumps = 0;
    for _ in 0..40_000 {
        let x = 1000 + (rng.next_f32() * 1399.0) as i32;
        let v = [x, 1, 1];
        if inside[geo.index(v)] != 0 {
            continue;
        }
        let p: V3 = std::array::from_fn(|a| (v[a] as f32 + rng.next_f32()) * size[a]);
        let d = if rng.next_f32() < 0.5 { [1.0, 0.0, 0.0] } else { [-1.0, 0.0, 0.0] };
        if let Some((_, w)) = crate::transport::grid::empty_jump(&geo, p, d, v) {
            jumps += 1;
            assert!(!geo.is_inside(w), "a jump from {p:?} (voxel {v:?}) along {d:?} named inside voxel {w:?}");
        }
    }
    assert!(jumps > 20_000, "{jumps}");
}

#[test]
fn erosion_of_tiny_grids_matches_brute_force() {
    // Every grid of 1 to 4 voxels per axis (the border cases of the separable erosion), random masks: safe and
    // empty distances as brute force.
    let mut rng = crate::transport::rng::PathRng::new(2, 0, 0, 0);
    for nx in 1..=4usize {
        for ny in 1..=4usize {
            for nz in 1..=4usize {
                let n = [nx, ny, nz];
                for _ in 0..3 {
                    let inside: Vec<u8> = (0..nx * ny * nz).map(|_| (rng.next_f32() < 0.7) as u8).collect();
                    let (safe, empty) = (
                        crate::transport::scene::safe_distances(&inside, n),
                        crate::transport::scene::empty_distances(&inside, n),
                    );
                    for j in 0..inside.len() {
                        let v = voxel_at(n, j);
                        let cap = crate::transport::scene::SAFE_CAP as i32;
                        // Safe: distance to the nearest outside voxel, the grid's exterior (one step beyond a
                        // face) included.
                        let to_border = (0..3).map(|a| (v[a] + 1).min(n[a] as i32 - v[a])).min().unwrap();
                        let want_safe =
                            if inside[j] == 0 { 0 } else { nearest_hit(n, v, cap, |k| inside[k] == 0).min(to_border) };
                        assert_eq!(safe[j] as i32, want_safe.min(cap), "safe, grid {n:?}, voxel {v:?}");
                        let want_empty = nearest_hit(n, v, cap, |k| inside[k] != 0);
                        assert_eq!(empty[j] as i32, want_empty, "empty, grid {n:?}, voxel {v:?}");
                    }
                }
            }
        }
    }
}
