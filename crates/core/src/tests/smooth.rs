//! `smooth::diffuse_rows` against a plain dense implementation (f64, every neighbour looked up by coordinates in
//! a map over the grid; and the same in f32 in the core's order of operations, bit for bit), its conservation,
//! thread-count independence, its slabs of z-planes and its refusal of bad sets. The set has more than two parallel
//! blocks of rows.

use crate::kernels::smooth::{diffuse_rows, diffuse_subset, Guide};
use crate::transport::rng::uniform;

/// An irregular set (about 60 % of a 26 x 24 x 22 grid: ~8 200 rows, more than two of the core's parallel blocks
/// of 4 096) as its increasing linear indices, and random values.
fn set(channels: usize) -> ([usize; 3], Vec<i64>, Vec<f32>) {
    let n = [26usize, 24, 22];
    let index: Vec<i64> = (0..n.iter().product::<usize>() as i64).filter(|&j| uniform(11, 0, j as u32) < 0.6).collect();
    let values = (0..index.len() * channels).map(|i| uniform(12, 0, i as u32) * 2.0 - 1.0).collect();
    (n, index, values)
}

#[test]
fn matches_a_plain_implementation_and_conserves_sums() {
    check_against_plain(false);
}

#[test]
fn guided_matches_a_plain_implementation_and_conserves_sums() {
    check_against_plain(true);
}

/// Against an f64 implementation from the formula; with a guide (2 dims, tau 0.4), weights exp(-d²/tau²).
fn check_against_plain(guided: bool) {
    let ch = 3;
    let (n, index, v0) = set(ch);
    let rows = v0.len() / ch;
    let gv: Vec<f32> = (0..rows * 2).map(|i| uniform(14, 0, i as u32)).collect();
    let tau = 0.4f32;
    let guide = guided.then_some(Guide::rows(&gv, 2, tau));
    let (steps, alpha) = (5, 0.125f32);
    let mut v = v0.clone();
    diffuse_rows(n, &index, &mut v, ch, steps, alpha, guide).unwrap();
    let weight = |p: usize, q: usize| -> f64 {
        if !guided {
            return 1.0;
        }
        let d2: f64 = (0..2).map(|k| (gv[p * 2 + k] as f64 - gv[q * 2 + k] as f64).powi(2)).sum();
        (-d2 / (tau as f64 * tau as f64)).exp()
    };
    let mut r: Vec<f64> = v0.iter().map(|&x| x as f64).collect();
    let mut map = vec![-1i64; n.iter().product()]; // row of each grid voxel, -1 outside the set
    for (row, &j) in index.iter().enumerate() {
        map[j as usize] = row as i64;
    }
    let at = |z: i64, y: i64, x: i64| -> Option<usize> {
        if z < 0 || y < 0 || x < 0 || z >= n[0] as i64 || y >= n[1] as i64 || x >= n[2] as i64 {
            return None;
        }
        let q = map[((z as usize) * n[1] + y as usize) * n[2] + x as usize];
        (q >= 0).then_some(q as usize)
    };
    for _ in 0..steps {
        let mut next = r.clone();
        for z in 0..n[0] as i64 {
            for y in 0..n[1] as i64 {
                for x in 0..n[2] as i64 {
                    let Some(p) = at(z, y, x) else { continue };
                    for (dz, dy, dx) in [(1, 0, 0), (-1, 0, 0), (0, 1, 0), (0, -1, 0), (0, 0, 1), (0, 0, -1)] {
                        if let Some(q) = at(z + dz, y + dy, x + dx) {
                            for c in 0..ch {
                                next[p * ch + c] += alpha as f64 * weight(p, q) * (r[q * ch + c] - r[p * ch + c]);
                            }
                        }
                    }
                }
            }
        }
        r = next;
    }
    for (a, b) in v.iter().zip(&r) {
        assert!((*a as f64 - b).abs() < 1e-5, "{a} vs {b}");
    }
    // f32 in the core's order (neighbours -z, +z, -y, +y, -x, +x; weight alpha * exp(-d2 / tau^2)): the same bits
    let mut r32 = v0.clone();
    for _ in 0..steps {
        let mut next = r32.clone();
        for (p, &j) in index.iter().enumerate() {
            let (z, y, x) = (j / (n[1] * n[2]) as i64, j / n[2] as i64 % n[1] as i64, j % n[2] as i64);
            let nb: Vec<Option<usize>> = [(-1, 0, 0), (1, 0, 0), (0, -1, 0), (0, 1, 0), (0, 0, -1), (0, 0, 1)]
                .iter()
                .map(|&(dz, dy, dx)| at(z + dz, y + dy, x + dx))
                .collect();
            for c in 0..ch {
                let v = r32[p * ch + c];
                let mut acc = 0.0f32;
                for q in nb.iter().flatten() {
                    let w = if guided {
                        let d2: f32 =
                            (0..2).map(|k| (gv[p * 2 + k] - gv[q * 2 + k]) * (gv[p * 2 + k] - gv[q * 2 + k])).sum();
                        alpha * (-d2 / (tau * tau)).exp()
                    } else {
                        alpha
                    };
                    acc += w * (r32[q * ch + c] - v);
                }
                next[p * ch + c] = v + acc;
            }
        }
        r32 = next;
    }
    assert_eq!(v, r32);
    for c in 0..ch {
        let (s0, s1): (f64, f64) = (
            v0.iter().skip(c).step_by(ch).map(|&x| x as f64).sum(),
            v.iter().skip(c).step_by(ch).map(|&x| x as f64).sum(),
        );
        assert!((s0 - s1).abs() < 1e-4, "channel {c}: {s0} vs {s1}");
    }
}

#[test]
fn same_bits_for_any_thread_count() {
    let (n, index, v0) = set(2);
    let gv: Vec<f32> = (0..v0.len()).map(|i| uniform(13, 0, i as u32)).collect();
    let guide = Guide::rows(&gv, 2, 0.5);
    let run = |threads: usize| {
        let mut v = v0.clone();
        rayon::ThreadPoolBuilder::new()
            .num_threads(threads)
            .build()
            .unwrap()
            .install(|| diffuse_rows(n, &index, &mut v, 2, 4, 0.125, Some(guide)).unwrap());
        v
    };
    assert_eq!(run(1), run(3));
}

#[test]
fn refuses_sets_out_of_grid_order_and_size_mismatches() {
    let (n, mut index, mut v) = set(1);
    index.swap(0, 1);
    assert!(diffuse_rows(n, &index, &mut v, 1, 1, 0.125, None).unwrap_err().contains("increasing"));
    index.swap(0, 1);
    v.push(0.0);
    assert!(diffuse_rows(n, &index, &mut v, 1, 1, 0.125, None).unwrap_err().contains("rows"));
    v.pop();
    assert!(diffuse_rows([1, 1, 1], &index, &mut v, 1, 1, 0.125, None).unwrap_err().contains("outside the grid"));
}

/// A guide held as a key per row into a shared table plus a per-row extra component (the loop's form: a texel's
/// target colour and the voxel's depth) gives the same bits as the same vectors held per row.
#[test]
fn a_keyed_guide_is_its_vectors_per_row_bit_for_bit() {
    let (n, index, v0) = set(2);
    let rows = index.len();
    let entries = 37;
    let table: Vec<f32> = (0..entries * 3).map(|i| uniform(15, 0, i as u32) * 20.0).collect();
    let key: Vec<u32> =
        (0..rows).map(|r| (uniform(16, 0, r as u32) * entries as f32) as u32 % entries as u32).collect();
    let extra: Vec<f32> = (0..rows).map(|r| uniform(17, 0, r as u32) * 5.0).collect();
    let dense: Vec<f32> = (0..rows)
        .flat_map(|r| {
            let e = key[r] as usize * 3;
            [table[e], table[e + 1], table[e + 2], extra[r]]
        })
        .collect();
    let keyed = Guide { table: &table, dims: 3, key: Some(&key), extra: Some(&extra), tau: 4.0 };
    let (mut a, mut b) = (v0.clone(), v0.clone());
    diffuse_rows(n, &index, &mut a, 2, 6, 0.125, Some(keyed)).unwrap();
    diffuse_rows(n, &index, &mut b, 2, 6, 0.125, Some(Guide::rows(&dense, 4, 4.0))).unwrap();
    assert_ne!(a, v0);
    assert_eq!(a, b);
    // a key past the table's end, or a key or extra value per row missing, is refused
    let mut bad = key.clone();
    bad[5] = entries as u32;
    let mut v = v0.clone();
    for g in [
        Guide { key: Some(&bad), ..keyed },
        Guide { key: Some(&key[1..]), ..keyed },
        Guide { extra: Some(&extra[1..]), ..keyed },
        Guide { key: None, ..keyed },
    ] {
        assert!(diffuse_rows(n, &index, &mut v, 2, 2, 0.125, Some(g)).unwrap_err().contains("guide"));
    }
}

/// Diffused a slab of z-planes at a time (any thickness, planes without a row of the set between slabs, a subset of
/// the rows, with or without a guide), the set's values are those of the whole set at once, bit for bit.
#[test]
fn slabs_of_any_thickness_are_the_whole_set_bit_for_bit() {
    let (n, full, _) = set(2);
    let plane = (n[1] * n[2]) as i64;
    // planes 9..12 hold no voxel of the set: a slab can be empty, and rows on either side are not neighbours
    let index: Vec<i64> = full.into_iter().filter(|&j| !(9..12).contains(&(j / plane))).collect();
    let v0: Vec<f32> = (0..index.len() * 2).map(|i| uniform(18, 0, i as u32) * 2.0 - 1.0).collect();
    let gv: Vec<f32> = (0..index.len() * 2).map(|i| uniform(19, 0, i as u32)).collect();
    let subset: Vec<u32> = (0..index.len() as u32).filter(|&r| uniform(20, 0, r) < 0.8).collect();
    let sub_guide: Vec<f32> = subset.iter().flat_map(|&r| [gv[2 * r as usize], gv[2 * r as usize + 1]]).collect();
    for (rows, guide) in [(None, None), (Some(&subset[..]), None), (Some(&subset[..]), Some(&sub_guide[..]))] {
        let guide = guide.map(|g| Guide::rows(g, 2, 0.5));
        for steps in [1, 3, 6] {
            let run = |slab: usize| {
                let mut v = v0.clone();
                diffuse_subset(n, &index, rows, &mut v, 2, steps, 0.125, guide, slab).unwrap();
                v
            };
            let whole = run(1000);
            assert_ne!(whole, v0);
            for slab in [1, 2, 3, 5, 7, 64] {
                assert_eq!(run(slab), whole, "{steps} steps, {slab} planes a slab, subset {}", rows.is_some());
            }
        }
    }
}
