//! Statistical tests of the renderer against exact results, one file per topic: `analytic` (furnaces, slabs
//! and free flights with closed forms), `samplers` (the samplers and walks against each other), `gradients`
//! (gradients against finite differences), `light` (environment maps), `determinism` (thread counts, chunking,
//! media forms), `geometry` (safe distances and balls), `bricks` (the
//! distances stored by bricks against the dense ones), `label_bricks` (labels stored by bricks against the dense
//! labels), `mask` (builds from a bit mask against a byte mask), `smooth` (the step preconditioner against a plain
//! implementation), `storage` (in-place updates and compact storage against the plain forms, bit for bit), `band`
//! (the band medium against them), `layering` (the module layering, on the source). Tolerances are multiples of the estimator's own standard
//! error (computed from the samples), never fixed image values.

mod analytic;
mod band;
mod bricks;
mod determinism;
mod geometry;
mod gradients;
mod hero;
mod label_bricks;
mod layering;
mod light;
mod mask;
mod samplers;
mod smooth;
mod storage;

use crate::*;

/// A periodic slab of n voxels (cubes of edge `size`) with the same coefficients everywhere.
fn slab(n: [usize; 3], size: f32, sigma_s: [f32; 3], sigma_a: [f32; 3], ior: f32, g: f32) -> (Geometry, DenseMedium) {
    let geo = Geometry::new(n, [size; 3], Boundary::PeriodicXY, ior, g).unwrap();
    let nv = n.iter().product::<usize>();
    let s: Vec<f32> = (0..nv).flat_map(|_| sigma_s).collect();
    let a: Vec<f32> = (0..nv).flat_map(|_| sigma_a).collect();
    (geo, DenseMedium::from_interleaved(&s, &a).unwrap())
}

/// The texels of the top (+z) face of an n-voxel grid.
fn top_texels(n: [usize; 3]) -> Vec<Texel> {
    let mut t = vec![];
    for y in 0..n[1] {
        for x in 0..n[0] {
            t.push(Texel { voxel: [x as i32, y as i32, n[2] as i32 - 1], face: 5, normal: [0.0, 0.0, 1.0] });
        }
    }
    t
}

/// Up to five texels on each of `faces` of the box of n voxels.
fn box_texels(n: [usize; 3], faces: &[u8]) -> Vec<Texel> {
    let last = |a: usize| n[a] as i32 - 1;
    faces
        .iter()
        .flat_map(|&f| {
            (0..5).map(move |k| {
                let v = [
                    if f == 1 { last(0) } else { k % last(0) },
                    if f == 3 { last(1) } else { k % last(1) },
                    if f == 5 { last(2) } else { k % last(2) },
                ];
                Texel { voxel: v, face: f, normal: face_normal(f) }
            })
        })
        .filter(|t| t.voxel[(t.face / 2) as usize] == if t.face % 2 == 1 { last((t.face / 2) as usize) } else { 0 })
        .collect()
}

/// A heterogeneous medium of nv voxels (sigma_s 1..23, sigma_a 0..4.8 mm^-1 in a fixed pattern).
fn heterogeneous(nv: usize) -> DenseMedium {
    let s: Vec<f32> = (0..3 * nv).map(|i| 1.0 + ((i * 7919) % 23) as f32).collect();
    let a: Vec<f32> = (0..3 * nv).map(|i| ((i * 104729) % 7) as f32 * 0.8).collect();
    DenseMedium::from_interleaved(&s, &a).unwrap()
}

/// Mean over texels and its standard error (texels are independent).
fn mean_and_se(est: &[TexelEstimate], c: usize) -> (f64, f64) {
    let n = est.len() as f64;
    let m = est.iter().map(|e| e.mean[c] as f64).sum::<f64>() / n;
    let v = est.iter().map(|e| e.var_mean[c] as f64).sum::<f64>() / (n * n);
    (m, v.sqrt())
}

/// sum_i adj_i . c_i of a render: the objective whose gradient `backward` accumulates.
fn objective<M: Medium>(geo: &Geometry, med: &M, texels: &[Texel], adj: &[[f32; 3]], opts: &RenderOptions) -> f64 {
    let (est, _) = render(geo, med, texels, 0, opts);
    est.iter().zip(adj).map(|(e, w)| (0..3).map(|c| e.mean[c] as f64 * w[c] as f64).sum::<f64>()).sum()
}

/// The path-replay gradient of `objective`: (d/d sigma_s, d/d sigma_a), interleaved (voxel, channel).
fn replay_gradient<M: Medium>(
    geo: &Geometry,
    med: &M,
    texels: &[Texel],
    adj: &[[f32; 3]],
    opts: &RenderOptions,
) -> (Vec<f32>, Vec<f32>) {
    let nv = med.len();
    let mut gb = GradBuffers::new(nv);
    gb.zero(1.0);
    backward(geo, med, texels, 0, adj, opts, GradMethod::Replay, &gb);
    let (mut gs, mut ga) = (vec![0.0; 3 * nv], vec![0.0; 3 * nv]);
    gb.collect(&mut gs, &mut ga);
    (gs, ga)
}

/// The gradient estimator against central finite differences with common random numbers, one pair per seed.
/// They are different estimators of the same derivative, so their mean difference is tested against Student's
/// `t` quantile (for len - 1 degrees of freedom) times its standard error estimated over the seeds, plus
/// `rel` x |mean gradient| + `abs` for the O(h^2) finite-difference bias.
fn assert_gradient_matches_fd(grads: &[f64], fds: &[f64], t: f64, rel: f64, abs: f64, what: &str) {
    let k = grads.len() as f64;
    let d: Vec<f64> = grads.iter().zip(fds).map(|(g, f)| g - f).collect();
    let md = d.iter().sum::<f64>() / k;
    let sd = (d.iter().map(|x| (x - md).powi(2)).sum::<f64>() / (k - 1.0)).sqrt() / k.sqrt();
    let mg = grads.iter().sum::<f64>() / k;
    assert!(md.abs() < t * sd + rel * mg.abs() + abs, "{what}: grad {mg} fd {} (se {sd})", fds.iter().sum::<f64>() / k);
}
