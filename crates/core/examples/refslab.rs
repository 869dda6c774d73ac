//! Profiling target: the reference slab (177 x 118 x 30 voxels at 300 DPI, seeded random CMYKW mixture with
//! 50 % white), top face, without Python. `cargo run --release --example refslab -- SPP THREADS`.
use inkopt_core::transport::{path::Tally, rng, trace::trace};
use inkopt_core::*;

fn main() {
    let args: Vec<String> = std::env::args().collect();
    let spp: u32 = args.get(1).and_then(|s| s.parse().ok()).unwrap_or(16);
    let threads: usize = args.get(2).and_then(|s| s.parse().ok()).unwrap_or(2);
    let (nx, ny, nz) = (177usize, 118usize, 30usize);
    let h = 25.4f32 / 300.0;
    // Vero C, M, Y, K, W: (mu_t RGB, albedo RGB).
    let inks: [([f32; 3], [f32; 3]); 5] = [
        ([9.0, 4.5, 7.5], [0.05, 0.7, 0.98]),
        ([2.5, 3.0, 10.0], [0.98, 0.1, 0.9]),
        ([2.25, 3.75, 19.0], [0.997, 0.995, 0.15]),
        ([5.0, 5.5, 6.5], [0.35, 0.35, 0.35]),
        ([6.0, 9.0, 24.0], [0.9991, 0.9997, 0.999]),
    ];
    let n = nx * ny * nz;
    let mut s = vec![0.0f32; 3 * n];
    let mut a = vec![0.0f32; 3 * n];
    let mut rng = rng::PathRng::new(0, 0, 0, 0);
    for i in 0..n {
        let w: Vec<f32> = (0..4).map(|_| rng.next_f32()).collect();
        let tot: f32 = w.iter().sum();
        for c in 0..3 {
            for k in 0..5 {
                let r = if k == 4 { 0.5 } else { 0.5 * w[k] / tot };
                let (mt, al) = inks[k];
                s[3 * i + c] += r * mt[c] * al[c];
                a[3 * i + c] += r * mt[c] * (1.0 - al[c]);
            }
        }
    }
    let geo = Geometry::new([nx, ny, nz], [h; 3], Boundary::Box, 1.5, 0.4).unwrap();
    let med = DenseMedium::from_interleaved(&s, &a).unwrap();
    let texels: Vec<Texel> = (0..ny * nx)
        .map(|i| Texel { voxel: [(i % nx) as i32, (i / nx) as i32, nz as i32 - 1], face: 5, normal: [0.0, 0.0, 1.0] })
        .collect();
    let pool = rayon::ThreadPoolBuilder::new().num_threads(threads).build().unwrap();
    let opts = RenderOptions { spp, seed: 1, include_specular: true };
    let t0 = std::time::Instant::now();
    let (_, st) = pool.install(|| render(&geo, &med, &texels, 0, &opts));
    let dt = t0.elapsed().as_secs_f64();
    let mut cnt = Count(0, 0);
    let mut events = 0u64;
    for (i, tex) in texels.iter().enumerate().take(2000) {
        for c in 0..3 {
            let mut r = rng::PathRng::new(1, i as u64, 0, c as u32);
            events += trace(&geo, &med, tex, c, &mut r, true, &mut cnt).events as u64;
        }
    }
    println!(
        "segments per collision {:.2}, scatters per collision {:.2}",
        cnt.0 as f64 / events as f64,
        cnt.1 as f64 / events as f64
    );
    println!(
        "forward: {:.3} s, {:.2} M events/s, {:.2} M texel-samples/s, {:.2} events/path",
        dt,
        st.events as f64 / dt / 1e6,
        (texels.len() as f64 * spp as f64) / dt / 1e6,
        st.events as f64 / st.paths as f64
    );
}

#[allow(dead_code)]
pub struct Count(pub u64, pub u64);
impl Tally for Count {
    fn segment(&mut self, _: usize, _: f32) {
        self.0 += 1;
    }
    fn scatter(&mut self, _: usize) {
        self.1 += 1;
    }
}
