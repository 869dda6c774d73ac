//! The band medium against the dense and sparse forms holding the same coefficients, bit for bit: lookups,
//! majorants, renders and path-replay gradients for several thread counts, before and after `set_voxels`; its
//! errors.

use super::storage::lookup_bits;
use super::*;
use crate::transport::band::Class;

/// A (12, 11, 10) object: the box minus a cavity and a notch; its band (voxels within 2 of a face or a
/// hole, plus two deep ones of another mixture) and a core of one mixture (sigma_s, sigma_a per channel).
struct Object {
    n: [usize; 3],
    inside: Vec<u8>,
    band: Vec<i64>,
    core: ([f32; 3], [f32; 3]),
    /// Every grid voxel's interleaved (voxel, channel) coefficients: the band's own, the core's, vacuum outside.
    s: Vec<f32>,
    a: Vec<f32>,
}

fn object(core: ([f32; 3], [f32; 3])) -> Object {
    let n = [12usize, 11, 10];
    let nv = n.iter().product::<usize>();
    let xyz = |j: usize| [j % n[0], (j / n[0]) % n[1], j / (n[0] * n[1])];
    let outside = |[x, y, z]: [usize; 3]| {
        ((4..=5).contains(&z) && (5..7).contains(&x) && (5..7).contains(&y)) || (z == 3 && y == 0 && x < 4)
    };
    let inside: Vec<u8> = (0..nv).map(|j| !outside(xyz(j)) as u8).collect();
    // Within 2 voxels (Chebyshev) of the box's faces or of an outside voxel.
    let near = |v: [usize; 3]| {
        (0..3).any(|i| v[i] < 2 || v[i] + 2 >= n[i])
            || (0..nv).any(|q| {
                let w = xyz(q);
                outside(w) && (0..3).all(|i| w[i].abs_diff(v[i]) <= 2)
            })
    };
    let deep = [(n[1] + 3) * n[0] + 8, (5 * n[1] + 8) * n[0] + 3]; // two fixed voxels of another mixture
    let band: Vec<i64> =
        (0..nv).filter(|&j| inside[j] != 0 && (near(xyz(j)) || deep.contains(&j))).map(|j| j as i64).collect();
    let mut s: Vec<f32> = (0..3 * nv).map(|i| 1.0 + ((i * 7919) % 23) as f32).collect();
    let mut a: Vec<f32> = (0..3 * nv).map(|i| ((i * 104729) % 7) as f32 * 0.8).collect();
    for j in 0..nv {
        let in_band = band.binary_search(&(j as i64)).is_ok();
        let (cs, ca) = if inside[j] == 0 { ([0.0; 3], [0.0; 3]) } else { core };
        if !in_band {
            s[3 * j..3 * j + 3].copy_from_slice(&cs);
            a[3 * j..3 * j + 3].copy_from_slice(&ca);
        }
    }
    Object { n, inside, band, core, s, a }
}

impl Object {
    fn gather(&self, v: &[f32], index: &[i64]) -> Vec<f32> {
        index.iter().flat_map(|&j| v[3 * j as usize..3 * j as usize + 3].to_vec()).collect()
    }
    fn band_medium(&self) -> BandMedium {
        let (s, a) = (self.gather(&self.s, &self.band), self.gather(&self.a, &self.band));
        BandMedium::new(self.n, &self.inside, &self.band, &s, &a, self.core).unwrap()
    }
    fn sparse(&self) -> SparseMedium {
        let index: Vec<i64> = (0..self.inside.len() as i64).filter(|&j| self.inside[j as usize] != 0).collect();
        SparseMedium::new(self.n, &index, &self.gather(&self.s, &index), &self.gather(&self.a, &index)).unwrap()
    }
    fn dense(&self) -> DenseMedium {
        DenseMedium::from_interleaved(&self.s, &self.a).unwrap()
    }
}

/// A render's (mean, var_mean) bits per texel, its events, and the path-replay gradient (d/d sigma_s, d/d sigma_a).
type Passes = (Vec<[u32; 6]>, u64, (Vec<f32>, Vec<f32>));

/// Render and path-replay gradient bits of a medium on `threads` threads.
fn passes<M: Medium>(geo: &Geometry, m: &M, threads: usize) -> Passes {
    let pool = rayon::ThreadPoolBuilder::new().num_threads(threads).build().unwrap();
    pool.install(|| {
        let texels = box_texels(geo.n.map(|v| v as usize), &[0, 1, 2, 3, 4, 5]);
        let adj: Vec<[f32; 3]> = (0..texels.len()).map(|i| [1.0, -0.4 + 0.05 * i as f32, 0.2]).collect();
        let opts = RenderOptions { spp: 8, seed: 11, include_specular: true };
        let (est, stats) = render(geo, m, &texels, 0, &opts);
        let bits = est.iter().map(|e| {
            let (m, v) = (e.mean.map(f32::to_bits), e.var_mean.map(f32::to_bits));
            [m[0], m[1], m[2], v[0], v[1], v[2]]
        });
        (bits.collect(), stats.events, replay_gradient(geo, m, &texels, &adj, &opts))
    })
}

#[test]
fn band_medium_matches_the_dense_and_sparse_ones_bit_for_bit() {
    let obj = object(([2.5, 4.0, 6.5], [0.3, 0.0, 1.1]));
    let mut band = obj.band_medium();
    let (nv, k) = (obj.inside.len(), obj.band.len());
    let inside = obj.inside.iter().filter(|&&b| b != 0).count();
    assert!(k > 100 && inside - k > 50, "a band of {k} and a core of {} voxels", inside - k);
    assert_eq!(band.band(), k);
    assert_eq!(lookup_bits(&band), lookup_bits(&obj.dense()));
    assert_eq!(lookup_bits(&band), lookup_bits(&obj.sparse()));
    let geo = Geometry::new(obj.n, [0.1; 3], Boundary::Box, 1.5, 0.4).unwrap().with_inside(obj.inside.clone()).unwrap();
    let want = passes(&geo, &obj.sparse(), 2);
    assert!(want.1 > 1000, "paths scatter: {}", want.1);
    for threads in [1, 2, 3] {
        assert!(passes(&geo, &band, threads) == want, "{threads} threads");
    }
    // set_voxels on band voxels (one listed twice: the last values win) = the dense medium rebuilt.
    let sub: Vec<i64> = obj.band.iter().copied().step_by(3).chain([obj.band[5], obj.band[5]]).collect();
    let q = sub.len();
    let ns: Vec<f32> = (0..3 * q).map(|i| 0.5 + ((i * 31) % 11) as f32 * 0.9).collect();
    let na: Vec<f32> = (0..3 * q).map(|i| ((i * 17) % 7) as f32 * 0.3).collect();
    let (mut s, mut a) = (obj.s.clone(), obj.a.clone());
    for (e, &j) in sub.iter().enumerate() {
        s[3 * j as usize..3 * j as usize + 3].copy_from_slice(&ns[3 * e..3 * e + 3]);
        a[3 * j as usize..3 * j as usize + 3].copy_from_slice(&na[3 * e..3 * e + 3]);
    }
    band.set_voxels(&sub, &ns, &na).unwrap();
    let dense = DenseMedium::from_interleaved(&s, &a).unwrap();
    assert_eq!(lookup_bits(&band), lookup_bits(&dense));
    assert!(passes(&geo, &band, 2) == passes(&geo, &dense, 1));
    // Errors: one line each, and the medium is left as it was.
    let before = lookup_bits(&band);
    let core = (0..nv).find(|&j| band.class(j) == Class::Core).unwrap() as i64;
    let hole = (0..nv).find(|&j| obj.inside[j] == 0).unwrap() as i64;
    let errs = [
        band.set_voxels(&[obj.band[2], core], &[1.0; 6], &[0.0; 6]).unwrap_err(),
        band.set_voxels(&[hole], &[1.0; 3], &[0.0; 3]).unwrap_err(),
        band.set_voxels(&[nv as i64], &[1.0; 3], &[0.0; 3]).unwrap_err(),
        band.set_voxels(&[obj.band[2]], &[1.0; 3], &[-1.0, 0.0, 0.0]).unwrap_err(),
    ];
    let want = [
        format!("voxel {core}, which is in the core (one mixture), not in the band"),
        format!("voxel {hole}, which is outside the object"),
        format!("voxel {nv}, outside the grid"),
        "entry 0 (voxel".to_string(),
    ];
    for (e, w) in errs.iter().zip(&want) {
        assert!(e.contains(w.as_str()) && !e.contains('\n'), "{e} (want {w})");
    }
    assert!(lookup_bits(&band) == before, "a refused update changed the medium");
    assert_eq!(band.in_band(&[obj.band[0], core, hole, -1, nv as i64]), [true, false, false, false, false]);
}

#[test]
fn band_majorant_covers_the_core_and_builds_are_checked() {
    // A core denser than every band voxel sets the majorant; lowering the band does not lower it.
    let obj = object(([40.0, 0.5, 3.0], [2.0, 0.0, 0.0]));
    let mut band = obj.band_medium();
    assert_eq!([0, 1, 2].map(|c| band.majorant(c)), [0, 1, 2].map(|c| obj.dense().majorant(c)));
    assert_eq!(band.majorant(0), 42.0);
    let k = obj.band.len();
    band.set_voxels(&obj.band, &vec![0.1; 3 * k], &vec![0.0; 3 * k]).unwrap();
    assert_eq!([band.majorant(0), band.majorant(1), band.majorant(2)], [42.0, 0.5, 3.0]);
    // Without core voxels the core's coefficients do not count.
    let all: Vec<i64> = (0..obj.inside.len() as i64).filter(|&j| obj.inside[j as usize] != 0).collect();
    let m = all.len();
    let full = BandMedium::new(obj.n, &obj.inside, &all, &vec![1.0; 3 * m], &vec![0.0; 3 * m], obj.core).unwrap();
    assert_eq!(full.majorant(0), 1.0);
    let build = |ix: &[i64], inside: &[u8], core: ([f32; 3], [f32; 3])| {
        let q = ix.len();
        BandMedium::new(obj.n, inside, ix, &vec![1.0; 3 * q], &vec![0.0; 3 * q], core).err().unwrap()
    };
    let hole = (0..obj.inside.len()).find(|&j| obj.inside[j] == 0).unwrap() as i64;
    let cases = [
        (build(&[3, 3], &obj.inside, obj.core), "strictly increasing".to_string()),
        (build(&[hole], &obj.inside, obj.core), format!("voxel {hole}, which is not inside")),
        (build(&[-1], &obj.inside, obj.core), "voxel -1, outside the grid".to_string()),
        (build(&[3], &obj.inside[1..], obj.core), "inside mask has".to_string()),
        (build(&[3], &obj.inside, ([1.0, f32::NAN, 0.0], [0.0; 3])), "core's coefficients of channel 1".to_string()),
    ];
    for (e, w) in cases {
        assert!(e.contains(w.as_str()) && !e.contains('\n'), "{e} (want {w})");
    }
}
