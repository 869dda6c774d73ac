//! Labels stored by bricks (`LabelBricks`) against the dense labels they were made from, voxel for voxel, whatever
//! the planes' grouping when pushed; a printed volume's mask taken from its own labels (`MaskRef::Labels`) against
//! the same mask as bytes; and a label medium's renders against dense coefficients of the same inks, bit for bit.

use crate::transport::label_bricks::{LabelBricks, LabelBricksBuilder};
use crate::transport::mask::MaskRef;
use crate::transport::rng::PathRng;
use crate::*;

/// A printed-looking label grid: `EMPTY` outside an ellipsoid, ink 0 in its core and random inks 0..inks within
/// `band` voxels of its surface (by the ellipsoid's own radius).
fn printed(n: [usize; 3], band: f32, inks: u8, seed: u64) -> Vec<u8> {
    let mut rng = PathRng::new(seed, 0, 0, 0);
    let c: [f32; 3] = std::array::from_fn(|a| (n[a] as f32 - 1.0) / 2.0);
    let r: [f32; 3] = std::array::from_fn(|a| n[a] as f32 / 2.0 - 1.5);
    let mut labels = vec![EMPTY; n.iter().product()];
    for z in 0..n[2] {
        for y in 0..n[1] {
            for x in 0..n[0] {
                let p = [x as f32, y as f32, z as f32];
                let e = (0..3).map(|a| ((p[a] - c[a]) / r[a]).powi(2)).sum::<f32>().sqrt();
                let depth = (1.0 - e) * r.iter().cloned().fold(f32::MAX, f32::min);
                let u = rng.next_f32();
                if e < 1.0 {
                    labels[(z * n[1] + y) * n[0] + x] = if depth < band { (u * inks as f32) as u8 } else { 0 };
                }
            }
        }
    }
    labels
}

fn assert_same(b: &LabelBricks, labels: &[u8], n: [usize; 3], what: &str) {
    assert_eq!(b.shape(), n);
    for z in 0..n[2] {
        for y in 0..n[1] {
            for x in 0..n[0] {
                let j = (z * n[1] + y) * n[0] + x;
                assert_eq!(b.get([x as i32, y as i32, z as i32]), labels[j], "{what}: grid {n:?}, voxel {j}");
                assert_eq!(b.get_index(j), labels[j], "{what}: grid {n:?}, voxel {j}");
            }
        }
    }
    let inside: Vec<u8> = labels.iter().map(|&l| (l != EMPTY) as u8).collect();
    assert_eq!(b.inside_span(0, labels.len()), inside, "{what}");
    let (a, e) = (labels.len() / 3, labels.len() / 3 + labels.len() / 2);
    assert_eq!(MaskRef::Labels(b).span(a, e).as_ref(), &inside[a..e], "{what}: a span across rows and planes");
    for l in 0..256 {
        assert_eq!(b.used()[l], labels.contains(&(l as u8)), "{what}: label {l} used");
    }
}

#[test]
fn bricks_equal_the_dense_labels_however_the_planes_are_pushed() {
    let mut rng = PathRng::new(9, 0, 0, 0);
    for n in [[1usize, 1, 1], [3, 1, 2], [9, 7, 5], [17, 10, 41], [24, 16, 32]] {
        let random: Vec<u8> = (0..n.iter().product()).map(|_| (rng.next_f32() * 4.0) as u8).collect();
        for (what, labels) in [("random", random), ("printed", printed(n, 2.5, 5, 3))] {
            let dense = LabelBricks::from_dense(&labels, n).unwrap();
            assert_same(&dense, &labels, n, what);
            for group in [1, 3, 8, 13] {
                let mut b = LabelBricksBuilder::new(n).unwrap();
                for planes in labels.chunks(n[0] * n[1] * group) {
                    b.push(planes).unwrap();
                }
                let b = b.finish().unwrap();
                assert_same(&b, &labels, n, &format!("{what}, {group} planes a push"));
                assert_eq!(b.bytes(), dense.bytes());
            }
        }
    }
}

#[test]
fn only_bricks_of_mixed_labels_are_stored() {
    // A printed grid stores the bricks of its band and surface; the empty outside and the one-ink core cost a
    // table entry each.
    let n = [64usize, 56, 72];
    let labels = printed(n, 2.5, 5, 1);
    let b = LabelBricks::from_dense(&labels, n).unwrap();
    let nb = n.map(|k| k.div_ceil(8));
    assert_eq!(b.bricks(), nb.iter().product::<usize>());
    let mixed = (0..b.bricks())
        .filter(|&k| {
            let (bx, by, bz) = (k % nb[0] * 8, k / nb[0] % nb[1] * 8, k / (nb[0] * nb[1]) * 8);
            let first = labels[(bz * n[1] + by) * n[0] + bx];
            (bz..(bz + 8).min(n[2])).any(|z| {
                (by..(by + 8).min(n[1]))
                    .any(|y| (bx..(bx + 8).min(n[0])).any(|x| labels[(z * n[1] + y) * n[0] + x] != first))
            })
        })
        .count();
    assert_eq!(b.stored_bricks(), mixed);
    assert!(mixed < b.bricks(), "{mixed} of {} bricks mixed", b.bricks());
    assert_eq!(b.bytes(), 4 * b.bricks() + 512 * (256 + mixed));
}

#[test]
fn a_builder_refuses_wrong_planes() {
    let n = [4usize, 3, 5];
    let mut b = LabelBricksBuilder::new(n).unwrap();
    assert!(b.push(&[0u8; 13]).is_err(), "not whole planes");
    assert!(b.push(&[0u8; 72]).is_err(), "six planes of five");
    b.push(&[0u8; 48]).unwrap();
    assert_eq!(b.planes_left(), 1);
    assert!(b.finish().unwrap_err().contains("1 of 5 planes"));
    assert!(LabelBricksBuilder::new([0, 3, 5]).is_err());
    assert!(LabelBricks::from_dense(&[0u8; 59], n).is_err());
}

#[test]
fn a_label_medium_renders_its_own_mask_as_dense_coefficients_do() {
    // The printed grid as a label medium whose geometry's mask is its labels, against dense coefficients of the
    // same inks (vacuum outside) with the mask given as bytes: the same numbers, bit for bit.
    let n = [20usize, 18, 22];
    let labels = printed(n, 3.0, 3, 7);
    let ink_s = [4.0f32, 6.0, 5.0, 1.0, 2.0, 0.5, 8.0, 3.0, 9.0];
    let ink_a = [0.1f32, 0.05, 0.2, 2.0, 0.3, 1.5, 0.2, 0.9, 0.0];
    let coef = |t: &[f32; 9]| -> Vec<f32> {
        labels.iter().flat_map(|&l| if l == EMPTY { vec![0.0; 3] } else { t[3 * l as usize..][..3].to_vec() }).collect()
    };
    let lm = LabelMedium::new(n, &labels, &ink_s, &ink_a).unwrap();
    let dm = DenseMedium::from_interleaved(&coef(&ink_s), &coef(&ink_a)).unwrap();
    let inside: Vec<u8> = labels.iter().map(|&l| (l != EMPTY) as u8).collect();
    let geo = |m: MaskRef| Geometry::new(n, [0.04, 0.08, 0.03], Boundary::Box, 1.5, 0.4).unwrap().with_inside_mask(m);
    let (g_labels, g_bytes) = (geo(MaskRef::Labels(lm.labels())).unwrap(), geo(MaskRef::Bytes(&inside)).unwrap());
    let mid = n[1] / 2;
    let texels: Vec<Texel> = (0..n[0])
        .filter_map(|x| {
            let z = (0..n[2]).rev().find(|&z| inside[(z * n[1] + mid) * n[0] + x] != 0)?;
            Some(Texel { voxel: [x as i32, mid as i32, z as i32], face: 5, normal: [0.0, 0.0, 1.0] })
        })
        .collect();
    assert!(texels.len() > 10);
    let opts = RenderOptions { spp: 64, seed: 11, include_specular: false };
    let (x, _) = render(&g_labels, &lm, &texels, 0, &opts);
    let (y, _) = render(&g_bytes, &dm, &texels, 0, &opts);
    for (p, q) in x.iter().zip(&y) {
        assert_eq!(p.mean, q.mean);
        assert_eq!(p.var_mean, q.var_mean);
    }
    for c in 0..3 {
        assert_eq!(lm.majorant(c), dm.majorant(c));
    }
}
