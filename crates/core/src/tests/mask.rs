//! The inside mask given as bits (`MaskRef::Bits`, numpy's `packbits` order) against the same mask as bytes: its
//! spans, and every build that reads it (the distances by bricks, the bricks' empty distances, the band medium's
//! runs), value for value.

use crate::transport::distance::{brick_empty_distances, BrickedDistances, BRICK};
use crate::transport::mask::MaskRef;
use crate::transport::rng::PathRng;
use crate::*;

/// `bytes` (non-zero: set) as bits, most significant first (`np.packbits`).
fn pack(bytes: &[u8]) -> Vec<u8> {
    let mut bits = vec![0u8; bytes.len().div_ceil(8)];
    for (j, &b) in bytes.iter().enumerate() {
        bits[j / 8] |= ((b != 0) as u8) << (7 - j % 8);
    }
    bits
}

fn random_mask(rng: &mut PathRng, n: usize, density: f32) -> Vec<u8> {
    (0..n).map(|_| (rng.next_f32() < density) as u8).collect()
}

#[test]
fn bit_spans_equal_the_bytes() {
    let mut rng = PathRng::new(11, 0, 0, 0);
    for len in [0usize, 1, 7, 8, 9, 23, 64, 70] {
        let bytes = random_mask(&mut rng, len, 0.5);
        let bits = pack(&bytes);
        let mask = MaskRef::bits(&bits, len).unwrap();
        assert_eq!(mask.len(), len);
        for a in 0..=len {
            for b in a..=len {
                assert_eq!(&*mask.span(a, b), &bytes[a..b], "span {a}..{b} of {len}");
            }
        }
        for (j, &m) in bytes.iter().enumerate() {
            assert_eq!(mask.get(j), m != 0);
        }
    }
    assert!(MaskRef::bits(&[0u8; 2], 17).is_err()); // 17 voxels need 3 bytes
}

#[test]
fn builds_from_bits_equal_those_from_bytes() {
    // Grids whose planes are not a multiple of 8 voxels (a plane's bits start inside a byte) and are.
    let mut rng = PathRng::new(12, 0, 0, 0);
    for n in [[9usize, 7, 5], [17, 10, 41], [8, 16, 24], [5, 3, 150]] {
        let nv: usize = n.iter().product();
        for density in [0.05f32, 0.6, 0.97] {
            let bytes = random_mask(&mut rng, nv, density);
            let bits = pack(&bytes);
            let mask = MaskRef::bits(&bits, nv).unwrap();
            for slab in [BRICK, 2 * BRICK] {
                let (a, b) = (
                    BrickedDistances::in_slabs(&bytes, n, true, slab),
                    BrickedDistances::in_slabs(mask, n, true, slab),
                );
                for z in 0..n[2] as i32 {
                    for y in 0..n[1] as i32 {
                        for x in 0..n[0] as i32 {
                            assert_eq!(a.get([x, y, z]), b.get([x, y, z]), "grid {n:?} voxel {:?}", [x, y, z]);
                        }
                    }
                }
            }
            assert_eq!(brick_empty_distances(&bytes, n), brick_empty_distances(mask, n));
            // The band medium: a random part of the inside voxels as the band, the rest core.
            let band: Vec<i64> = (0..nv).filter(|&j| bytes[j] != 0 && rng.next_f32() < 0.4).map(|j| j as i64).collect();
            let s: Vec<f32> = (0..3 * band.len()).map(|i| 1.0 + (i % 5) as f32).collect();
            let a: Vec<f32> = (0..3 * band.len()).map(|i| (i % 3) as f32 * 0.5).collect();
            let core = ([2.0f32, 3.0, 4.0], [0.1f32, 0.2, 0.3]);
            let from_bytes = BandMedium::new(n, &bytes, &band, &s, &a, core).unwrap();
            let from_bits = BandMedium::new(n, mask, &band, &s, &a, core).unwrap();
            for j in 0..nv {
                assert_eq!(from_bytes.class(j), from_bits.class(j), "grid {n:?} voxel {j}");
            }
            // The geometry's distances.
            let geo = |m: MaskRef<'_>| {
                Geometry::new(n, [0.1; 3], Boundary::Box, 1.5, 0.0).unwrap().with_inside_mask(m).unwrap()
            };
            let (ga, gb) = (geo(MaskRef::Bytes(&bytes)), geo(mask));
            for z in 0..n[2] as i32 {
                for y in 0..n[1] as i32 {
                    for x in 0..n[0] as i32 {
                        let v = [x, y, z];
                        assert_eq!(ga.safe_distance(v), gb.safe_distance(v));
                        assert_eq!(ga.empty_distance(v), gb.empty_distance(v));
                    }
                }
            }
            assert_eq!(ga.brick_empty, gb.brick_empty);
        }
    }
}
