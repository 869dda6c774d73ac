//! The voxel scene: grid geometry (size, boundary, inside mask and its safe distances, shading normals), the
//! medium (dense coefficients or ink labels, behind the `Medium` trait), the light it is lit by (a `Light`, see
//! `light`; set with `Geometry::with_light`) and texels.
//!
//! Layout: voxel (x, y, z) has linear index `(z * ny + y) * nx + x`, i.e. C order of a (z, y, x) array.
//! Coefficients are stored per channel in planar arrays (all voxels of R, then G, then B) as extinction
//! sigma_t and single-scattering albedo, the two numbers the random walk needs.

pub use crate::light::{Light, UniformLight};
pub use crate::normals::ShadingNormals;
use crate::sampling::V3;

/// Label of an empty voxel in label media.
pub const EMPTY: u8 = 255;

#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Boundary {
    /// The grid's bounding box (or the `inside` mask) bounds the object.
    Box,
    /// x and y wrap around: an infinite slab in x and y, bounded in z.
    PeriodicXY,
}

/// Per-voxel optical parameters for one channel.
pub trait Medium: Sync {
    /// (sigma_t in mm^-1, albedo) of voxel `idx` in channel `c`.
    fn coeffs(&self, idx: usize, c: usize) -> (f32, f32);
    /// sigma_s in mm^-1 of voxel `idx` in channel `c` (for gradients).
    fn sigma_s(&self, idx: usize, c: usize) -> f32 {
        let (t, a) = self.coeffs(idx, c);
        t * a
    }
    fn len(&self) -> usize;
    /// An upper bound of sigma_t over all voxels in channel c (the majorant of delta tracking).
    fn majorant(&self, c: usize) -> f32;
}

/// (sigma_t, albedo) of coefficients sigma_s, sigma_a (albedo 1 in vacuum); None unless both are finite and
/// non-negative.
fn extinction_albedo(s: f32, a: f32) -> Option<(f32, f32)> {
    if !(s >= 0.0 && a >= 0.0 && s.is_finite() && a.is_finite()) {
        return None;
    }
    let t = s + a;
    Some((t, if t > 0.0 { s / t } else { 1.0 }))
}

/// Dense coefficients: planar by channel, (sigma_t, albedo) pairs interleaved so one lookup is one load.
pub struct DenseMedium {
    n: usize,
    coef: Vec<[f32; 2]>,
    majorant: [f32; 3],
}

impl DenseMedium {
    /// From interleaved (voxel, channel) arrays of sigma_s and sigma_a in mm^-1 (a (z, y, x, 3) array's memory).
    pub fn from_interleaved(sigma_s: &[f32], sigma_a: &[f32]) -> Result<Self, String> {
        if sigma_s.len() != sigma_a.len() || sigma_s.len() % 3 != 0 {
            return Err("sigma_s and sigma_a must both have 3 channels per voxel and equal size".into());
        }
        let n = sigma_s.len() / 3;
        let mut medium = DenseMedium { n, coef: vec![[0.0f32, 1.0f32]; 3 * n], majorant: [0.0; 3] };
        medium.refill(sigma_s, sigma_a)?;
        Ok(medium)
    }

    /// Replace the coefficients by new ones for the same voxels, in place: the optimiser swaps the medium every
    /// iteration, and a second copy of it would be the largest allocation of a big object. Checked before
    /// anything is written, so an error leaves the medium as it was.
    pub fn refill(&mut self, sigma_s: &[f32], sigma_a: &[f32]) -> Result<(), String> {
        let n = self.n;
        if sigma_s.len() != 3 * n || sigma_a.len() != 3 * n {
            return Err(format!("sigma_s and sigma_a must have 3 channels for each of the {n} voxels"));
        }
        if let Some(k) = (0..3 * n).find(|&k| extinction_albedo(sigma_s[k], sigma_a[k]).is_none()) {
            return Err(format!("coefficients of voxel {} channel {} are negative or not finite", k / 3, k % 3));
        }
        for i in 0..n {
            for c in 0..3 {
                let (t, albedo) = extinction_albedo(sigma_s[3 * i + c], sigma_a[3 * i + c]).unwrap();
                self.coef[c * n + i] = [t, albedo];
            }
        }
        self.update_majorant();
        Ok(())
    }

    /// Overwrite the coefficients of some voxels in place, as `refill` would store them: `index` holds linear
    /// voxel indices (a voxel listed twice takes its last values), `sigma_s` and `sigma_a` their interleaved
    /// (entry, channel) coefficients in mm^-1. The optimiser changes only the free voxels of a big object, so
    /// this costs O(K) plus one pass over the coefficients for the majorant (which may go down), and allocates
    /// nothing. Checked before anything is written, so an error leaves the medium as it was.
    pub fn set_voxels(&mut self, index: &[i64], sigma_s: &[f32], sigma_a: &[f32]) -> Result<(), String> {
        let (n, k) = (self.n, index.len());
        if sigma_s.len() != 3 * k || sigma_a.len() != 3 * k {
            return Err(format!("sigma_s and sigma_a must have 3 channels for each of the {k} indexed voxels, \
                                got {} and {} values", sigma_s.len(), sigma_a.len()));
        }
        if let Some(e) = index.iter().position(|&j| j < 0 || j as u64 >= n as u64) {
            return Err(format!("index entry {e} is voxel {}, outside the grid of {n} voxels", index[e]));
        }
        if let Some(q) = (0..3 * k).find(|&q| extinction_albedo(sigma_s[q], sigma_a[q]).is_none()) {
            return Err(format!("coefficients of entry {} (voxel {}) channel {} are negative or not finite",
                               q / 3, index[q / 3], q % 3));
        }
        for (e, &j) in index.iter().enumerate() {
            for c in 0..3 {
                let (t, albedo) = extinction_albedo(sigma_s[3 * e + c], sigma_a[3 * e + c]).unwrap();
                self.coef[c * n + j as usize] = [t, albedo];
            }
        }
        self.update_majorant();
        Ok(())
    }

    /// The largest sigma_t of each channel, over all voxels (in parallel: max is exact in any order).
    fn update_majorant(&mut self) {
        use rayon::prelude::*;
        let (coef, n) = (&self.coef, self.n);
        self.majorant = std::array::from_fn(|c| {
            coef[c * n..(c + 1) * n].par_chunks(1 << 16).map(|b| b.iter().fold(0.0f32, |a, x| a.max(x[0])))
                .reduce(|| 0.0f32, f32::max)
        });
    }
}

impl Medium for DenseMedium {
    #[inline(always)]
    fn coeffs(&self, idx: usize, c: usize) -> (f32, f32) {
        let [t, a] = self.coef[c * self.n + idx];
        (t, a)
    }
    fn len(&self) -> usize {
        self.n
    }
    fn majorant(&self, c: usize) -> f32 {
        self.majorant[c]
    }
}

/// One ink label (u8) per voxel and a small ink table: 1 byte per voxel.
pub struct LabelMedium {
    labels: Vec<u8>,
    majorant: [f32; 3],
    /// [channel][ink] (sigma_t, albedo); index 255 (EMPTY) maps to vacuum.
    table: [[(f32, f32); 256]; 3],
}

impl LabelMedium {
    /// `ink_sigma_s`, `ink_sigma_a`: (N, 3) row-major, mm^-1.
    pub fn new(labels: Vec<u8>, ink_sigma_s: &[f32], ink_sigma_a: &[f32]) -> Result<Self, String> {
        let n_inks = ink_sigma_s.len() / 3;
        if ink_sigma_s.len() != ink_sigma_a.len() || ink_sigma_s.len() % 3 != 0 || n_inks == 0 || n_inks > 255 {
            return Err("ink table must be (N, 3) with 1 <= N <= 255".into());
        }
        let mut table = [[(0.0f32, 1.0f32); 256]; 3];
        for k in 0..n_inks {
            for c in 0..3 {
                table[c][k] = extinction_albedo(ink_sigma_s[3 * k + c], ink_sigma_a[3 * k + c])
                    .ok_or_else(|| format!("ink {k} has negative or non-finite coefficients"))?;
            }
        }
        if let Some(bad) = labels.iter().find(|&&l| l != EMPTY && l as usize >= n_inks) {
            return Err(format!("label {bad} has no ink in a table of {n_inks}"));
        }
        let mut used = [false; 256];
        labels.iter().for_each(|&l| used[l as usize] = true);
        let majorant = std::array::from_fn(|c| (0..256).filter(|&k| used[k]).fold(0.0f32, |a, k| a.max(table[c][k].0)));
        Ok(LabelMedium { labels, majorant, table })
    }
}

impl Medium for LabelMedium {
    #[inline(always)]
    fn coeffs(&self, idx: usize, c: usize) -> (f32, f32) {
        self.table[c][self.labels[idx] as usize]
    }
    fn len(&self) -> usize {
        self.labels.len()
    }
    fn majorant(&self, c: usize) -> f32 {
        self.majorant[c]
    }
}

/// Geometry and boundary of the object: grid size, voxel size, which voxels are inside, shading normals.
pub struct Geometry {
    /// Voxel counts (x, y, z).
    pub n: [i32; 3],
    /// Voxel edge lengths (x, y, z) in mm.
    pub size: [f32; 3],
    /// Reciprocal voxel edge lengths (mm^-1).
    pub inv_size: [f32; 3],
    /// Linear-index stride of a step along x, y, z.
    pub stride: [isize; 3],
    pub boundary: Boundary,
    /// Optional inside mask, one byte per voxel (non-zero = inside). None: the whole box is inside.
    pub inside: Option<Vec<u8>>,
    /// With `inside`: each voxel's safe distance, the Chebyshev distance in voxels to the nearest voxel outside
    /// the object or the grid (0 outside, 1 at the surface, capped at `SAFE_CAP`).
    pub safe: Option<Vec<u8>>,
    /// Optional outward unit shading normals of the (surface) voxels that have one; used where paths meet the
    /// surface.
    pub normals: Option<ShadingNormals>,
    /// Relative index of refraction of the object (outside: 1).
    pub ior: f32,
    /// Henyey-Greenstein anisotropy of the medium.
    pub g: f32,
    /// The light outside the object.
    pub light: Box<dyn Light>,
}

impl Geometry {
    pub fn new(n_xyz: [usize; 3], size: [f32; 3], boundary: Boundary, ior: f32, g: f32) -> Result<Self, String> {
        if n_xyz.iter().any(|&k| k == 0 || k > i32::MAX as usize / 2) {
            return Err(format!("grid size {n_xyz:?} must be positive"));
        }
        if size.iter().any(|&s| !(s > 0.0 && s.is_finite())) {
            return Err(format!("voxel size {size:?} must be positive and finite"));
        }
        if !(ior > 0.0 && ior.is_finite()) {
            return Err(format!("ior {ior} must be positive"));
        }
        if !(g > -1.0 && g < 1.0) {
            return Err(format!("g {g} must lie in (-1, 1)"));
        }
        Ok(Geometry {
            n: [n_xyz[0] as i32, n_xyz[1] as i32, n_xyz[2] as i32],
            size,
            inv_size: [1.0 / size[0], 1.0 / size[1], 1.0 / size[2]],
            stride: [1, n_xyz[0] as isize, (n_xyz[0] * n_xyz[1]) as isize],
            boundary,
            inside: None,
            safe: None,
            normals: None,
            ior,
            g,
            light: Box::new(UniformLight([1.0; 3])),
        })
    }

    /// The same geometry lit by `light`.
    pub fn with_light(mut self, light: Box<dyn Light>) -> Self {
        self.set_light(light);
        self
    }

    /// Light the geometry by `light` from now on (the tracers only call it; nothing else depends on it).
    pub fn set_light(&mut self, light: Box<dyn Light>) {
        self.light = light;
    }

    pub fn voxel_count(&self) -> usize {
        self.n.iter().map(|&k| k as usize).product()
    }

    pub fn with_inside(mut self, inside: Vec<u8>) -> Result<Self, String> {
        if inside.len() != self.voxel_count() {
            return Err("inside mask size differs from the grid".into());
        }
        self.safe = Some(safe_distances(&inside, [self.n[0] as usize, self.n[1] as usize, self.n[2] as usize]));
        self.inside = Some(inside);
        Ok(self)
    }

    /// Safe distance of voxel j (`safe`); `SAFE_CAP` when there is no mask.
    #[inline(always)]
    pub fn safe_distance(&self, j: usize) -> u8 {
        match &self.safe {
            None => SAFE_CAP,
            Some(s) => s[j],
        }
    }

    /// Shading normals from dense (x, y, z) vectors interleaved per voxel (a (z, y, x, 3) array's memory),
    /// unit or zero; only the usable ones (`normals::unit_normal`) are kept, normalised.
    pub fn with_normals(mut self, normals: &[f32]) -> Result<Self, String> {
        let n = [self.n[0] as usize, self.n[1] as usize, self.n[2] as usize];
        self.normals = Some(ShadingNormals::from_dense(normals, n)?);
        Ok(self)
    }

    /// `with_normals` from the voxels that have one (`ShadingNormals::from_sparse`).
    pub fn with_sparse_normals(mut self, index: &[i64], vectors: &[f32]) -> Result<Self, String> {
        let n = [self.n[0] as usize, self.n[1] as usize, self.n[2] as usize];
        self.normals = Some(ShadingNormals::from_sparse(index, vectors, n)?);
        Ok(self)
    }

    #[inline(always)]
    pub fn index(&self, v: [i32; 3]) -> usize {
        ((v[2] as usize * self.n[1] as usize) + v[1] as usize) * self.n[0] as usize + v[0] as usize
    }

    #[inline(always)]
    pub fn in_grid(&self, v: [i32; 3]) -> bool {
        v[0] >= 0 && v[1] >= 0 && v[2] >= 0 && v[0] < self.n[0] && v[1] < self.n[1] && v[2] < self.n[2]
    }

    #[inline(always)]
    pub fn is_inside(&self, v: [i32; 3]) -> bool {
        self.in_grid(v)
            && match &self.inside {
                None => true,
                Some(m) => m[self.index(v)] != 0,
            }
    }

    /// Whether in-grid voxel with linear index j is inside the object.
    #[inline(always)]
    pub fn mask_inside(&self, j: usize) -> bool {
        match &self.inside {
            None => true,
            Some(m) => m[j] != 0,
        }
    }

    /// Outward shading normal of inside voxel v, if the scene has normals and it is a usable unit vector.
    #[inline(always)]
    pub fn shading_normal(&self, v: [i32; 3]) -> Option<V3> {
        self.normals.as_ref()?.get(v)
    }
}

/// Largest safe distance stored: 16 voxels (1.3 mm at 300 DPI), far beyond a free flight in any ink.
pub const SAFE_CAP: u8 = 16;

/// Safe distances of a mask (non-zero = inside) over an (nx, ny, nz) grid: the number of successive erosions by
/// the 3 x 3 x 3 cube (separable: three 1D passes) a voxel survives, outside the grid counting as outside. A
/// voxel with safe distance s has every voxel within s - 1 steps (any of the 26 directions) inside.
pub fn safe_distances(inside: &[u8], n: [usize; 3]) -> Vec<u8> {
    use rayon::prelude::*;
    let plane = n[0] * n[1];
    let mut cur: Vec<u8> = inside.par_iter().map(|&m| (m != 0) as u8).collect();
    let mut safe = cur.clone();
    let mut tmp = vec![0u8; cur.len()];
    for _ in 1..SAFE_CAP {
        for a in 0..3 {
            erode_axis(&cur, &mut tmp, n, a);
            std::mem::swap(&mut cur, &mut tmp);
        }
        let any = safe
            .par_chunks_mut(plane)
            .zip(cur.par_chunks(plane))
            .map(|(s, c)| {
                s.iter_mut().zip(c).for_each(|(s, &c)| *s += c);
                c.iter().any(|&c| c != 0)
            })
            .reduce(|| false, |x, y| x || y);
        if !any {
            break;
        }
    }
    safe
}

/// out = cur eroded along axis a by one voxel (a voxel stays only if both neighbours on that axis are inside;
/// outside the grid counts as outside). Whole rows and planes at a time, so the loops vectorise.
fn erode_axis(cur: &[u8], out: &mut [u8], n: [usize; 3], a: usize) {
    use rayon::prelude::*;
    let (nx, plane) = (n[0], n[0] * n[1]);
    let and3 = |o: &mut [u8], x: &[u8], y: &[u8], z: &[u8]| {
        o.iter_mut().zip(x).zip(y).zip(z).for_each(|(((o, &x), &y), &z)| *o = x & y & z);
    };
    out.par_chunks_mut(plane).enumerate().for_each(|(k, o)| {
        let c = &cur[k * plane..(k + 1) * plane];
        match a {
            0 => {
                for (o, c) in o.chunks_mut(nx).zip(c.chunks(nx)) {
                    o[0] = 0;
                    o[nx - 1] = 0;
                    if nx > 2 {
                        and3(&mut o[1..nx - 1], &c[..nx - 2], &c[1..nx - 1], &c[2..]);
                    }
                }
            }
            1 => {
                let ny = n[1];
                o[..nx].fill(0);
                o[plane - nx..].fill(0);
                if ny > 2 {
                    and3(&mut o[nx..plane - nx], &c[..plane - 2 * nx], &c[nx..plane - nx], &c[2 * nx..]);
                }
            }
            _ => {
                if k == 0 || k + 1 == n[2] {
                    o.fill(0);
                } else {
                    and3(o, &cur[(k - 1) * plane..k * plane], c, &cur[(k + 1) * plane..(k + 2) * plane]);
                }
            }
        }
    });
}

/// The outward unit normal (x, y, z) of face id f: 0 -x, 1 +x, 2 -y, 3 +y, 4 -z, 5 +z.
#[inline(always)]
pub fn face_normal(f: u8) -> V3 {
    let mut n = [0.0f32; 3];
    n[(f / 2) as usize] = if f % 2 == 1 { 1.0 } else { -1.0 };
    n
}

/// A texel: the sensor element of one exposed voxel face.
#[derive(Clone, Copy, Debug)]
pub struct Texel {
    /// Voxel indices (x, y, z).
    pub voxel: [i32; 3],
    /// Face id its camera rays cross.
    pub face: u8,
    /// Outward unit shading normal (x, y, z); the camera looks along -normal.
    pub normal: V3,
}
