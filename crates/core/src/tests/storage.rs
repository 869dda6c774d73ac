//! Compact and in-place storage of big objects, bit-identical to the plain forms: `DenseMedium::set_voxels`
//! against a medium built from the modified full arrays; gradient buffers zeroed for reuse against fresh ones;
//! sparse shading normals against the dense formula; the sparse medium against the dense one.

use super::*;
use crate::transport::sampling::V3;

/// Every voxel's (sigma_t, albedo) of every channel, as bits, and the majorants.
fn medium_bits(m: &DenseMedium) -> (Vec<(u32, u32)>, [f32; 3]) {
    let bits = (0..3)
        .flat_map(|c| (0..m.len()).map(move |j| (c, j)))
        .map(|(c, j)| {
            let (t, a) = m.coeffs(j, c);
            (t.to_bits(), a.to_bits())
        })
        .collect();
    (bits, [m.majorant(0), m.majorant(1), m.majorant(2)])
}

#[test]
fn set_voxels_matches_a_medium_built_from_the_modified_arrays() {
    let n = [10usize, 9, 6];
    let nv = 540;
    let mut s: Vec<f32> = (0..3 * nv).map(|i| 2.0 + ((i * 7919) % 13) as f32).collect();
    let mut a: Vec<f32> = (0..3 * nv).map(|i| ((i * 104729) % 5) as f32 * 0.7).collect();
    // A few very dense voxels set the majorant; set_voxels lowers all of them, so the majorant must go down.
    for j in [17usize, 230, 401] {
        s[3 * j..3 * j + 3].copy_from_slice(&[60.0, 70.0, 80.0]);
    }
    let mut inside = vec![1u8; nv];
    inside[(5 * 9 + 4) * 10..(5 * 9 + 4) * 10 + 3].fill(0);
    let geo = Geometry::new(n, [0.0847; 3], Boundary::Box, 1.5, 0.4).unwrap().with_inside(inside).unwrap();
    let mut med = DenseMedium::from_interleaved(&s, &a).unwrap();
    let old_majorant = [med.majorant(0), med.majorant(1), med.majorant(2)];
    // Every third voxel, the dense ones, a vacuum voxel and one voxel listed twice (the last values win).
    let mut index: Vec<i64> = (0..nv as i64).step_by(3).chain([17, 230, 401, 5, 5]).collect();
    let k = index.len();
    let mut ns: Vec<f32> = (0..3 * k).map(|q| 0.5 + ((q * 31) % 11) as f32 * 0.9).collect();
    let mut na: Vec<f32> = (0..3 * k).map(|q| ((q * 17) % 7) as f32 * 0.3).collect();
    ns[3 * (k - 2)..3 * (k - 1)].fill(0.0); // voxel 5's first entry is vacuum (albedo 1), its second wins
    na[3 * (k - 2)..3 * (k - 1)].fill(0.0);
    for (e, &j) in index.iter().enumerate() {
        let j = j as usize;
        s[3 * j..3 * j + 3].copy_from_slice(&ns[3 * e..3 * e + 3]);
        a[3 * j..3 * j + 3].copy_from_slice(&na[3 * e..3 * e + 3]);
    }
    med.set_voxels(&index, &ns, &na).unwrap();
    let want = DenseMedium::from_interleaved(&s, &a).unwrap();
    assert_eq!(medium_bits(&med), medium_bits(&want));
    assert!((0..3).all(|c| med.majorant(c) < old_majorant[c]), "the majorant went down");
    let texels = box_texels(n, &[0, 1, 2, 3, 4, 5]);
    let opts = RenderOptions { spp: 8, seed: 9, include_specular: true };
    let (x, sx) = render(&geo, &med, &texels, 0, &opts);
    let (y, sy) = render(&geo, &want, &texels, 0, &opts);
    assert_eq!(sx.events, sy.events);
    for (p, q) in x.iter().zip(&y) {
        assert_eq!(
            (p.mean.map(f32::to_bits), p.var_mean.map(f32::to_bits)),
            (q.mean.map(f32::to_bits), q.var_mean.map(f32::to_bits))
        );
    }
    // Errors name the problem and leave the medium as it was (the valid entries before the bad one included).
    let before = medium_bits(&med);
    let bad_value = |q: usize, x: f32| {
        let mut v = ns.clone();
        v[q] = x;
        v
    };
    type Case = (Vec<i64>, Vec<f32>, Vec<f32>, &'static str); // index, sigma_s, sigma_a, error message
    let cases: Vec<Case> = vec![
        (index.clone(), ns[..3 * k - 3].to_vec(), na.clone(), "3 channels"),
        (
            {
                index[7] = nv as i64;
                index.clone()
            },
            ns.clone(),
            na.clone(),
            "entry 7 is voxel 540, outside",
        ),
        (
            {
                index[7] = -1;
                index.clone()
            },
            ns.clone(),
            na.clone(),
            "entry 7 is voxel -1, outside",
        ),
        (
            {
                index[7] = 21;
                index.clone()
            },
            bad_value(40, f32::NAN),
            na.clone(),
            "entry 13 (voxel 39) channel 1",
        ),
        (index.clone(), ns.clone(), bad_value(5, -1e-3), "entry 1 (voxel 3) channel 2"),
        (index.clone(), bad_value(3 * k - 1, f32::INFINITY), na.clone(), "negative or not finite"),
    ];
    for (ix, cs, ca, msg) in cases {
        let e = med.set_voxels(&ix, &cs, &ca).unwrap_err();
        assert!(e.contains(msg) && !e.contains('\n'), "{e}");
        assert!(medium_bits(&med) == before, "{msg}: the medium changed");
    }
}

#[test]
fn reused_gradient_buffers_match_fresh_ones() {
    // A second pass into a buffer zeroed after a first one (another adjoint bound, seed and texels) gives the
    // same fixed-point sums, quantum and gradient as the same pass into a fresh buffer: per voxel and per slot of
    // a map, on the packet and the scalar paths, with 2 threads against 1 (the shared atomic buffer).
    let n = [6usize, 6, 6];
    let nv = 216;
    let med = heterogeneous(nv);
    let texels = top_texels(n);
    let adj = |scale: f32| -> Vec<[f32; 3]> {
        (0..texels.len()).map(|i| [scale, -0.5 * scale + 0.03 * i as f32, 0.3]).collect()
    };
    let map: Vec<u32> = (0..nv as u32).map(|j| if j % 5 == 2 { NO_GRADIENT } else { j / 2 }).collect();
    let pools = [1, 2].map(|t| rayon::ThreadPoolBuilder::new().num_threads(t).build().unwrap());
    let geos = [
        Geometry::new(n, [0.1; 3], Boundary::Box, 1.5, 0.4).unwrap(),
        Geometry::new(n, [0.1; 3], Boundary::PeriodicXY, 1.5, 0.4).unwrap().with_inside(vec![1; nv]).unwrap(),
    ];
    for geo in &geos {
        for m in [None, Some(map.clone())] {
            for method in [GradMethod::Replay, GradMethod::Li1] {
                let pass = |g: &mut GradBuffers, bound: f32, seed: u64, first: usize, pool: &rayon::ThreadPool| {
                    g.zero(bound);
                    let opts = RenderOptions { spp: 6, seed, include_specular: true };
                    let a = adj(bound);
                    pool.install(|| backward(geo, &med, &texels[first..], 0, &a[first..], &opts, method, g));
                    let k = 3 * g.slots();
                    let (mut fs, mut fa, mut s, mut a) = (vec![0i64; k], vec![0i64; k], vec![0f32; k], vec![0f32; k]);
                    g.collect_fixed(&mut fs, &mut fa);
                    g.collect(&mut s, &mut a);
                    let bits = |v: Vec<f32>| v.iter().map(|x| x.to_bits()).collect::<Vec<_>>();
                    (fs, fa, bits(s), bits(a), g.quantum())
                };
                let mut reused = GradBuffers::with_map(nv, m.clone()).unwrap();
                let first = pass(&mut reused, 3.0, 1, 0, &pools[1]);
                let second = pass(&mut reused, 1.5, 2, 7, &pools[1]);
                let fresh = pass(&mut GradBuffers::with_map(nv, m.clone()).unwrap(), 1.5, 2, 7, &pools[0]);
                assert!(first.1.iter().any(|&x| x != 0) && first.1 != second.1, "the first pass left sums");
                assert!(second == fresh, "{:?} mapped {} {method:?}", geo.boundary, m.is_some());
            }
        }
    }
}

#[test]
fn sparse_normals_match_the_dense_formula() {
    // Every voxel of a random normals field (zero, short, unit, long, borderline |n|^2 = 0.5, NaN and infinite
    // vectors; rows with none and a row with all) gets exactly the shading normal of the former dense lookup.
    let n = [9usize, 5, 4];
    let nv = 180;
    let mut rng = crate::transport::rng::PathRng::new(7, 0, 0, 0);
    let mut dense = vec![0.0f32; 3 * nv];
    for j in 0..nv {
        let mut v = [(); 3].map(|_| 2.0 * rng.next_f32() - 1.0);
        let len = (v[0] * v[0] + v[1] * v[1] + v[2] * v[2]).sqrt();
        let row = j / n[0];
        // Rows 2 and 11 without normals, row 5 with a unit normal everywhere; elsewhere zero, short (|n| < 0.6),
        // around the threshold (|n| 0.69 .. 0.73 against 0.707), unit up to rounding, or |n| 0.5 .. 1.5.
        let s = match (row, j % 7) {
            (2 | 11, _) | (_, 0 | 1) => 0.0,
            (5, _) | (_, 4) => 1.0 / len,
            (_, 2) => 0.6 * rng.next_f32() / len,
            (_, 3) => (0.69 + 0.04 * rng.next_f32()) / len,
            _ => (0.5 + rng.next_f32()) / len,
        };
        v = v.map(|x| x * s);
        dense[3 * j..3 * j + 3].copy_from_slice(&v);
    }
    dense[3 * 3..3 * 4].copy_from_slice(&[0.5, 0.5, 0.0]); // |n|^2 = 0.5 exactly: no normal
    dense[3 * 10..3 * 11].copy_from_slice(&[f32::NAN, 1.0, 0.0]);
    dense[3 * 12..3 * 13].copy_from_slice(&[f32::INFINITY, 0.0, 0.0]);
    // The plain dense lookup, normalising at the query: the sparse store must give the same bits.
    let plain = |j: usize| -> Option<V3> {
        let i = 3 * j;
        let n = [dense[i], dense[i + 1], dense[i + 2]];
        let l2 = n[0] * n[0] + n[1] * n[1] + n[2] * n[2];
        if l2 > 0.5 {
            Some(crate::transport::sampling::scale(n, 1.0 / l2.sqrt()))
        } else {
            None
        }
    };
    let geo = Geometry::new(n, [0.1; 3], Boundary::Box, 1.5, 0.4).unwrap().with_normals(&dense).unwrap();
    let bits = |v: Option<V3>| v.map(|v| v.map(f32::to_bits));
    let mut kept = 0;
    for z in 0..n[2] as i32 {
        for y in 0..n[1] as i32 {
            for x in 0..n[0] as i32 {
                let j = geo.index([x, y, z]);
                let v = &dense[3 * j..3 * j + 3];
                assert_eq!(bits(geo.shading_normal([x, y, z])), bits(plain(j)), "voxel {j} {v:?}");
                kept += plain(j).is_some() as usize;
            }
        }
    }
    let sparse = geo.normals.as_ref().unwrap();
    assert!(kept > 40 && kept < nv - 40 && sparse.len() == kept, "{kept} of {nv} voxels have a normal");
    assert_eq!(sparse.bytes(), 4 * (n[1] * n[2] + 1) + 16 * kept);
    let e = Geometry::new(n, [0.1; 3], Boundary::Box, 1.5, 0.4).unwrap().with_normals(&dense[3..]).err().unwrap();
    assert!(e.contains("normals size"), "{e}");
    // The sparse form of the same field (every voxel with a nonzero vector, NaN and short ones included) gives
    // the same lookups bit for bit, and the same storage.
    let (mut index, mut vectors) = (vec![], vec![]);
    for j in 0..nv {
        if dense[3 * j..3 * j + 3].iter().any(|&c| c != 0.0) {
            index.push(j as i64);
            vectors.extend_from_slice(&dense[3 * j..3 * j + 3]);
        }
    }
    let geo2 =
        Geometry::new(n, [0.1; 3], Boundary::Box, 1.5, 0.4).unwrap().with_sparse_normals(&index, &vectors).unwrap();
    for j in 0..nv {
        let v = [(j % n[0]) as i32, ((j / n[0]) % n[1]) as i32, (j / (n[0] * n[1])) as i32];
        assert_eq!(bits(geo2.shading_normal(v)), bits(geo.shading_normal(v)), "voxel {j}");
    }
    assert_eq!(geo2.normals.as_ref().unwrap().bytes(), sparse.bytes());
    let fresh = || Geometry::new(n, [0.1; 3], Boundary::Box, 1.5, 0.4).unwrap();
    assert!(fresh().with_sparse_normals(&[3, 3], &[0.0; 6]).err().unwrap().contains("increase"));
    assert!(fresh().with_sparse_normals(&[nv as i64], &[0.0; 3]).err().unwrap().contains("in the grid"));
    assert!(fresh().with_sparse_normals(&[1], &[0.0; 6]).err().unwrap().contains("normal vectors"));
}

/// (sigma_t, albedo) bits of every voxel and channel of any medium, and its majorants.
pub(super) fn lookup_bits<M: Medium>(m: &M) -> (Vec<(u32, u32)>, [u32; 3]) {
    let bits = (0..3)
        .flat_map(|c| (0..m.len()).map(move |j| (c, j)))
        .map(|(c, j)| {
            let (t, a) = m.coeffs(j, c);
            (t.to_bits(), a.to_bits())
        })
        .collect();
    (bits, [0, 1, 2].map(|c| m.majorant(c).to_bits()))
}

#[test]
fn sparse_medium_matches_the_dense_one_bit_for_bit() {
    // A masked object (a box with an inner cavity and a notch: vacuum voxels the walks cross) stored only at
    // its inside voxels reads exactly what the dense medium with vacuum outside reads: every lookup, majorant,
    // render and path-replay gradient, before and after set_voxels / refill; errors leave it unchanged.
    let n = [9usize, 8, 7];
    let nv = n.iter().product::<usize>();
    let outside = |j: usize| {
        let (x, y, z) = (j % n[0], (j / n[0]) % n[1], j / (n[0] * n[1]));
        ((2..=4).contains(&z) && (3..6).contains(&x) && (2..5).contains(&y)) || (z == 3 && y == 0 && x < 4)
    };
    let inside: Vec<u8> = (0..nv).map(|j| !outside(j) as u8).collect();
    let index: Vec<i64> = (0..nv as i64).filter(|&j| inside[j as usize] != 0).collect();
    let k = index.len();
    let mut s: Vec<f32> = (0..3 * nv).map(|i| 1.0 + ((i * 7919) % 23) as f32).collect();
    let mut a: Vec<f32> = (0..3 * nv).map(|i| ((i * 104729) % 7) as f32 * 0.8).collect();
    for j in (0..nv).filter(|&j| outside(j)) {
        s[3 * j..3 * j + 3].fill(0.0);
        a[3 * j..3 * j + 3].fill(0.0);
    }
    let gather = |v: &[f32]| -> Vec<f32> {
        index.iter().flat_map(|&j| v[3 * j as usize..3 * j as usize + 3].to_vec()).collect()
    };
    let mut sparse = SparseMedium::new(n, &index, &gather(&s), &gather(&a)).unwrap();
    let dense = DenseMedium::from_interleaved(&s, &a).unwrap();
    // Rows through the cavity store it (vacuum between inside voxels); the notch's rows start after it.
    assert_eq!(sparse.stored(), k + 27);
    assert!(k < nv - 20, "the mask leaves {} voxels outside", nv - k);
    assert_eq!(lookup_bits(&sparse), lookup_bits(&dense));
    let geo = Geometry::new(n, [0.1; 3], Boundary::Box, 1.5, 0.4).unwrap().with_inside(inside).unwrap();
    let texels = box_texels(n, &[0, 1, 2, 3, 4, 5]);
    let adj: Vec<[f32; 3]> = (0..texels.len()).map(|i| [1.0, -0.4 + 0.05 * i as f32, 0.2]).collect();
    let check = |sparse: &SparseMedium, dense: &DenseMedium, seed: u64| {
        assert_eq!(lookup_bits(sparse), lookup_bits(dense));
        let opts = RenderOptions { spp: 8, seed, include_specular: true };
        let ((x, sx), (y, sy)) = (render(&geo, sparse, &texels, 0, &opts), render(&geo, dense, &texels, 0, &opts));
        assert_eq!(sx.events, sy.events);
        assert!(sx.events > 1000, "paths scatter: {}", sx.events);
        let bits = |e: &[TexelEstimate]| {
            e.iter().map(|e| (e.mean.map(f32::to_bits), e.var_mean.map(f32::to_bits))).collect::<Vec<_>>()
        };
        assert_eq!(bits(&x), bits(&y));
        let (gs, ga) = replay_gradient(&geo, sparse, &texels, &adj, &opts);
        assert_eq!((gs, ga), replay_gradient(&geo, dense, &texels, &adj, &opts));
    };
    check(&sparse, &dense, 3);
    // The walks never read an outside voxel's coefficients: a dense medium with matter there (below the
    // majorant, so delta tracking is unchanged) renders exactly as the sparse one does.
    let (mut s_out, mut a_out) = (s.clone(), a.clone());
    for j in (0..nv).filter(|&j| outside(j)) {
        s_out[3 * j..3 * j + 3].copy_from_slice(&[5.0, 7.0, 9.0]);
        a_out[3 * j..3 * j + 3].copy_from_slice(&[0.5, 0.0, 1.0]);
    }
    let matter_outside = DenseMedium::from_interleaved(&s_out, &a_out).unwrap();
    assert_eq!([0, 1, 2].map(|c| matter_outside.majorant(c)), [0, 1, 2].map(|c| dense.majorant(c)));
    let opts = RenderOptions { spp: 8, seed: 3, include_specular: true };
    let bits = |m: &DenseMedium| {
        render(&geo, m, &texels, 0, &opts).0.iter().map(|e| e.mean.map(f32::to_bits)).collect::<Vec<_>>()
    };
    assert_eq!(bits(&matter_outside), bits(&dense));
    assert_eq!(
        replay_gradient(&geo, &matter_outside, &texels, &adj, &opts),
        replay_gradient(&geo, &dense, &texels, &adj, &opts)
    );
    // set_voxels on some stored voxels (one listed twice: the last values win) = the dense medium rebuilt.
    let sub: Vec<i64> = index.iter().copied().step_by(4).chain([index[5], index[5]]).collect();
    let q = sub.len();
    let ns: Vec<f32> = (0..3 * q).map(|i| 0.5 + ((i * 31) % 11) as f32 * 0.9).collect();
    let na: Vec<f32> = (0..3 * q).map(|i| ((i * 17) % 7) as f32 * 0.3).collect();
    for (e, &j) in sub.iter().enumerate() {
        s[3 * j as usize..3 * j as usize + 3].copy_from_slice(&ns[3 * e..3 * e + 3]);
        a[3 * j as usize..3 * j as usize + 3].copy_from_slice(&na[3 * e..3 * e + 3]);
    }
    sparse.set_voxels(&sub, &ns, &na).unwrap();
    check(&sparse, &DenseMedium::from_interleaved(&s, &a).unwrap(), 4);
    // refill of every stored voxel, in index order.
    let (s2, a2): (Vec<f32>, Vec<f32>) = (s.iter().map(|x| 0.5 * x).collect(), a.iter().map(|x| x + 0.1).collect());
    let a2: Vec<f32> = a2.iter().enumerate().map(|(i, &x)| if outside(i / 3) { 0.0 } else { x }).collect();
    assert!(sparse.stores(&index) && !sparse.stores(&index[1..]) && !sparse.stores(&sub));
    sparse.refill(&gather(&s2), &gather(&a2)).unwrap();
    check(&sparse, &DenseMedium::from_interleaved(&s2, &a2).unwrap(), 5);
    // Errors name the problem in one line and leave the medium as it was.
    let before = lookup_bits(&sparse);
    let hole = (0..nv as i64).find(|&j| outside(j as usize)).unwrap(); // in the cavity: inside its row's span
    let notch = ((3 * n[1]) * n[0]) as i64; // (x, y, z) = (0, 0, 3): before its row's span
    let bad = |q: usize, x: f32| {
        let mut v = gather(&s2);
        v[q] = x;
        v
    };
    let errs = [
        sparse.set_voxels(&[index[2], hole], &[1.0; 6], &[0.0; 6]).unwrap_err(),
        sparse.set_voxels(&[nv as i64], &[1.0; 3], &[0.0; 3]).unwrap_err(),
        sparse.set_voxels(&[notch], &[1.0; 3], &[0.0; 3]).unwrap_err(),
        sparse.set_voxels(&[index[2]], &[1.0; 3], &[-1.0, 0.0, 0.0]).unwrap_err(),
        sparse.refill(&bad(7, f32::NAN), &gather(&a2)).unwrap_err(),
        sparse.refill(&gather(&s2)[3..], &gather(&a2)).unwrap_err(),
    ];
    let want = [
        format!("voxel {hole}, which the medium does not store"),
        format!("voxel {nv}, outside the grid"),
        format!("voxel {notch}, which the medium does not store"),
        "entry 0 (voxel".to_string(),
        "entry 2 channel 1".to_string(),
        "3 channels".to_string(),
    ];
    for (e, w) in errs.iter().zip(&want) {
        assert!(e.contains(w.as_str()) && !e.contains('\n'), "{e} (want {w})");
    }
    assert!(lookup_bits(&sparse) == before, "a refused update changed the medium");
    for (ix, w) in
        [(vec![3i64, 3], "strictly increasing"), (vec![-1], "voxel -1, outside"), (vec![nv as i64], "outside")]
    {
        let e = SparseMedium::new(n, &ix, &vec![1.0; 3 * ix.len()], &vec![0.0; 3 * ix.len()]).err().unwrap();
        assert!(e.contains(w), "{e}");
    }
}

#[test]
fn gradient_slots_of_a_voxel_list_match_the_slot_map() {
    // GradBuffers::with_voxels (slots ranked per grid row, no map per voxel) accumulates exactly what the
    // equivalent dense map does, on a masked object whose free voxels leave holes in their rows (a shell).
    let n = [9usize, 8, 7];
    let nv = n.iter().product::<usize>();
    let med = heterogeneous(nv);
    let index: Vec<i64> = (0..nv as i64).filter(|&j| (j * 7919) % 5 != 2 && (j / 9) % 4 != 1).collect();
    let mut map = vec![NO_GRADIENT; nv];
    index.iter().enumerate().for_each(|(e, &j)| map[j as usize] = e as u32);
    let spans = crate::spans::RowSpans::new(n, &index).unwrap();
    for j in 0..nv {
        let want = (map[j] != NO_GRADIENT).then_some(map[j] as usize);
        assert_eq!(spans.rank(j), want, "voxel {j}");
        // The lookup by coordinates (the walk's) finds the position the lookup by index finds.
        let v = [(j % n[0]) as i32, (j / n[0] % n[1]) as i32, (j / (n[0] * n[1])) as i32];
        assert_eq!(spans.position_at(v), spans.position(j), "voxel {j} at {v:?}");
    }
    assert!(spans.lists(&index) && !spans.lists(&index[1..]));
    let geo = Geometry::new(n, [0.1; 3], Boundary::Box, 1.5, 0.4).unwrap();
    let texels = box_texels(n, &[0, 1, 2, 3, 4, 5]);
    let adj: Vec<[f32; 3]> = (0..texels.len()).map(|i| [0.5, -1.0 + 0.1 * i as f32, 0.25]).collect();
    let opts = RenderOptions { spp: 6, seed: 21, include_specular: true };
    let pass = |mut g: GradBuffers, method| {
        g.zero(1.0);
        backward(&geo, &med, &texels, 0, &adj, &opts, method, &g);
        let k = 3 * g.slots();
        let (mut s, mut a) = (vec![0i64; k], vec![0i64; k]);
        g.collect_fixed(&mut s, &mut a);
        (s, a)
    };
    for method in [GradMethod::Replay, GradMethod::Li1] {
        let ranked = pass(GradBuffers::with_voxels(n, &index).unwrap(), method);
        assert_eq!(ranked, pass(GradBuffers::with_map(nv, Some(map.clone())).unwrap(), method));
        assert!(ranked.1.iter().any(|&x| x != 0));
    }
    assert!(GradBuffers::with_voxels(n, &[4, 4]).err().unwrap().contains("strictly increasing"));
}
