//! The signed distances stored by bricks (`BrickedDistances`, read through the geometry's accessors) against the
//! dense signed distances of the whole grid, voxel for voxel.

use crate::transport::distance::{signed_distances, BrickedDistances, BRICK, SAFE_CAP, SLAB_PLANES};
use crate::transport::rng::PathRng;
use crate::*;

/// Every voxel of `bricked` equals the dense signed distance of `inside` over the (nx, ny, nz) grid.
fn assert_same(bricked: &BrickedDistances, inside: &[u8], n: [usize; 3], empty: bool, what: &str) {
    let dense = signed_distances(inside, n, empty);
    for z in 0..n[2] {
        for y in 0..n[1] {
            for x in 0..n[0] {
                let v = [x as i32, y as i32, z as i32];
                assert_eq!(bricked.get(v), dense[(z * n[1] + y) * n[0] + x], "{what}: grid {n:?}, voxel {v:?}");
            }
        }
    }
}

/// A mesh-like mask: a solid ellipsoid whose semi-axes are `fill` of the grid's half-extents less 1.5 voxels (at
/// `fill` 1 one empty voxel at the grid's faces, as the voxelization pads it), with a tunnel bored through it along x
/// (a concave, thin-walled part).
fn ellipsoid(n: [usize; 3], fill: f32) -> Vec<u8> {
    let c: [f32; 3] = std::array::from_fn(|a| (n[a] as f32 - 1.0) / 2.0);
    let r: [f32; 3] = std::array::from_fn(|a| fill * n[a] as f32 / 2.0 - 1.5);
    let mut inside = vec![0u8; n.iter().product()];
    for z in 0..n[2] {
        for y in 0..n[1] {
            for x in 0..n[0] {
                let p = [x as f32, y as f32, z as f32];
                let e: f32 = (0..3).map(|a| ((p[a] - c[a]) / r[a]).powi(2)).sum();
                let tunnel = (p[1] - c[1]).powi(2) + (p[2] - c[2] * 0.6).powi(2) < 9.0;
                inside[(z * n[1] + y) * n[0] + x] = (e < 1.0 && !tunnel) as u8;
            }
        }
    }
    inside
}

#[test]
fn bricks_equal_the_dense_distances_on_random_masks() {
    // Random masks of several densities on grids whose sizes are not multiples of the brick (and smaller than
    // one), with and without empty distances, built in slabs thinner than the halo, of the halo and the default.
    let mut rng = PathRng::new(5, 0, 0, 0);
    let grids = [[1usize, 1, 1], [3, 1, 2], [9, 7, 5], [8, 16, 24], [17, 10, 41], [5, 3, 150]];
    for n in grids {
        for density in [0.02f32, 0.5, 0.97] {
            let inside: Vec<u8> = (0..n.iter().product()).map(|_| (rng.next_f32() < density) as u8).collect();
            for empty in [true, false] {
                for slab in [BRICK, 2 * BRICK, SLAB_PLANES] {
                    let b = BrickedDistances::in_slabs(&inside, n, empty, slab);
                    assert_same(&b, &inside, n, empty, &format!("density {density}, empty {empty}, slab {slab}"));
                    assert_eq!(b.bricks(), n.iter().map(|&k| k.div_ceil(BRICK)).product::<usize>());
                }
            }
        }
    }
}

#[test]
fn bricks_equal_the_dense_distances_on_mesh_like_masks() {
    // Solid ellipsoids with a tunnel: their deep interior and the far exterior are bricks of one value (+-cap),
    // stored as table entries only; the bricks near the surface hold their bytes; all read as the dense values.
    for n in [[45usize, 37, 70], [64, 40, 160], [30, 29, 19]] {
        let inside = ellipsoid(n, 1.0);
        for empty in [true, false] {
            for slab in [BRICK, 3 * BRICK, SLAB_PLANES] {
                let b = BrickedDistances::in_slabs(&inside, n, empty, slab);
                assert_same(&b, &inside, n, empty, &format!("ellipsoid, empty {empty}, slab {slab}"));
                let same = BrickedDistances::in_slabs(&inside, n, empty, BRICK);
                assert_eq!(b.stored_bricks(), same.stored_bricks(), "the slabs do not change what is stored");
            }
        }
    }
    // A thick object with room around it has bricks of one value both deep inside and far outside: fewer bricks
    // stored than the grid's, fewer bytes than voxels.
    let n = [100usize, 92, 140];
    let inside = ellipsoid(n, 0.7);
    let b = BrickedDistances::new(&inside, n, true);
    assert_same(&b, &inside, n, true, "thick ellipsoid");
    assert!(b.stored_bricks() < b.bricks() * 3 / 4, "{} of {} bricks stored", b.stored_bricks(), b.bricks());
    assert!(b.bytes() < n.iter().product::<usize>(), "{} bytes", b.bytes());
}

#[test]
fn geometry_accessors_read_the_dense_distances() {
    // Through the geometry (box: safe and empty distances; periodic: safe distances, -1 outside): every accessor
    // of every voxel as read from the dense signed byte, and nothing beyond the grid is inside.
    let n = [45usize, 37, 70];
    let inside = ellipsoid(n, 1.0);
    for boundary in [Boundary::Box, Boundary::PeriodicXY] {
        let dense = signed_distances(&inside, n, boundary == Boundary::Box);
        let geo = Geometry::new(n, [0.1; 3], boundary, 1.5, 0.4).unwrap().with_inside(&inside).unwrap();
        for z in 0..n[2] {
            for y in 0..n[1] {
                for x in 0..n[0] {
                    let (v, d) = ([x as i32, y as i32, z as i32], dense[(z * n[1] + y) * n[0] + x]);
                    let want = (d.max(0) as u8, (-d).max(0) as u8, d > 0);
                    assert_eq!((geo.safe_distance(v), geo.empty_distance(v), geo.mask_inside(v)), want, "{v:?}");
                    assert_eq!(geo.is_inside(v), d > 0);
                    assert!(geo.safe_distance(v) <= SAFE_CAP && geo.empty_distance(v) <= SAFE_CAP);
                }
            }
        }
        for v in [[-1, 0, 0], [0, n[1] as i32, 0], [0, 0, n[2] as i32]] {
            assert!(!geo.is_inside(v));
        }
    }
}
