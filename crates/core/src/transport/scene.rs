//! The voxel scene: grid geometry (size, boundary, inside mask as signed distances, shading normals), the
//! light it is lit by (a `Light`, see `light`; set with `Geometry::with_light`) and texels. The media (behind
//! the `Medium` trait) are in `medium` and re-exported here.
//!
//! Layout: voxel (x, y, z) has linear index `(z * ny + y) * nx + x`, i.e. C order of a (z, y, x) array.

pub use crate::transport::light::{Light, UniformLight};
pub use crate::transport::medium::{DenseMedium, LabelMedium, Medium, SparseMedium, EMPTY};
pub use crate::transport::normals::ShadingNormals;
use crate::transport::sampling::V3;

#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Boundary {
    /// The grid's bounding box (or the `inside` mask) bounds the object.
    Box,
    /// x and y wrap around: an infinite slab in x and y, bounded in z.
    PeriodicXY,
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
    /// With an inside mask (`with_inside`): each voxel's signed distance, one byte per voxel. Inside voxels hold
    /// their safe distance, the Chebyshev distance in voxels to the nearest voxel outside the object or the grid
    /// (1 at the surface); outside voxels minus their empty distance, the Chebyshev distance to the nearest
    /// inside voxel (-1 next to the object; the grid's exterior counts as empty); both capped at `SAFE_CAP`. A
    /// voxel is inside iff its value is positive. One array for both, so the flight that leaves the object
    /// finds the empty distance of its next voxel in the cache line it just read. None: the whole box is inside.
    pub dist: Option<Vec<i8>>,
    /// With a mask and `Boundary::Box`: the empty distance per brick of `BRICK`^3 voxels (x fastest), in bricks
    /// (a brick is occupied if any of its voxels is inside), capped at 255: a few kilobytes that stay in cache,
    /// so a flight far from the object crosses it in a few jumps without touching the per-voxel array. Flights
    /// outside the object jump across the empty balls these guarantee (`grid::empty_jump`, `trace::walk`);
    /// None (periodic grids, where a flight leaving the grid re-enters on the other side): no jumps.
    pub brick_empty: Option<Vec<u8>>,
    /// Bricks along x, y, z.
    pub bricks: [i32; 3],
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
            dist: None,
            brick_empty: None,
            bricks: std::array::from_fn(|a| n_xyz[a].div_ceil(BRICK) as i32),
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

    /// Sets the inside mask (non-zero = inside; x fastest, one byte per voxel, read and not kept) and computes the
    /// safe and empty distances from it. Works in three bytes per voxel besides the mask: the result and two
    /// erosion buffers.
    pub fn with_inside(mut self, inside: impl AsRef<[u8]>) -> Result<Self, String> {
        use rayon::prelude::*;
        let inside = inside.as_ref();
        if inside.len() != self.voxel_count() {
            return Err("inside mask size differs from the grid".into());
        }
        let n = [self.n[0] as usize, self.n[1] as usize, self.n[2] as usize];
        // safe distances turned into the signed byte in place (same size and alignment: no second array)
        let mut dist: Vec<i8> =
            safe_distances(inside, n).into_iter().map(|s| if s > 0 { s as i8 } else { -1 }).collect();
        // On periodic axes a flight leaving the grid re-enters on the other side: no empty distances (every outside
        // voxel -1, "next to the object") and no jumps there.
        if self.boundary == Boundary::Box {
            // each erosion an outside voxel survives deepens its -1 by one (inside voxels are never in the set):
            // `empty_distances` counted into `dist` directly
            let outside = inside.par_iter().map(|&m| (m == 0) as u8).collect();
            erode_counting(outside, n, 1, SAFE_CAP, &mut dist, |d, c| *d -= c as i8);
            self.brick_empty = Some(brick_empty_distances(inside, n));
        }
        self.dist = Some(dist);
        Ok(self)
    }

    /// Whether an inside mask bounds the object (else the whole grid is inside).
    #[inline(always)]
    pub fn masked(&self) -> bool {
        self.dist.is_some()
    }

    /// Safe distance of voxel j (`dist`; 0 outside the object); `SAFE_CAP` when there is no mask.
    #[inline(always)]
    pub fn safe_distance(&self, j: usize) -> u8 {
        match &self.dist {
            None => SAFE_CAP,
            Some(d) => d[j].max(0) as u8,
        }
    }

    /// Empty distance of voxel j (`dist`; 0 inside the object and without a mask; 1 everywhere outside on
    /// periodic grids, which have no empty distances).
    #[inline(always)]
    pub fn empty_distance(&self, j: usize) -> u8 {
        match &self.dist {
            None => 0,
            Some(d) => (-d[j]).max(0) as u8,
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
            && match &self.dist {
                None => true,
                Some(d) => d[self.index(v)] > 0,
            }
    }

    /// Whether in-grid voxel with linear index j is inside the object.
    #[inline(always)]
    pub fn mask_inside(&self, j: usize) -> bool {
        match &self.dist {
            None => true,
            Some(d) => d[j] > 0,
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
// Safe and empty distances share a signed byte (`Geometry::dist`).
const _: () = assert!(SAFE_CAP <= 127);

/// Safe distances of a mask (non-zero = inside) over an (nx, ny, nz) grid: the number of successive erosions by
/// the 3 x 3 x 3 cube (separable: three 1D passes) a voxel survives, outside the grid counting as outside. A
/// voxel with safe distance s has every voxel within s - 1 steps (any of the 26 directions) inside.
pub fn safe_distances(inside: &[u8], n: [usize; 3]) -> Vec<u8> {
    use rayon::prelude::*;
    erosion_depths(inside.par_iter().map(|&m| (m != 0) as u8).collect(), n, 0, SAFE_CAP)
}

/// Edge of the bricks of `Geometry::brick_empty`, in voxels.
pub const BRICK: usize = 8;

/// `empty_distances` at the scale of bricks of `BRICK`^3 voxels (x fastest over ceil(n / BRICK) bricks): each
/// brick's Chebyshev distance in bricks to the nearest brick holding an inside voxel (capped at 255; the grid's
/// exterior is empty). A brick with distance e has every voxel of the bricks within e - 1 brick steps outside.
pub fn brick_empty_distances(inside: &[u8], n: [usize; 3]) -> Vec<u8> {
    let nb: [usize; 3] = std::array::from_fn(|a| n[a].div_ceil(BRICK));
    let mut free = vec![1u8; nb[0] * nb[1] * nb[2]];
    for z in 0..n[2] {
        for y in 0..n[1] {
            let row = &inside[(z * n[1] + y) * n[0]..][..n[0]];
            let b = ((z / BRICK) * nb[1] + y / BRICK) * nb[0];
            for (x, &m) in row.iter().enumerate() {
                if m != 0 {
                    free[b + x / BRICK] = 0;
                }
            }
        }
    }
    erosion_depths(free, nb, 1, 255)
}

/// Empty distances of a mask (non-zero = inside): `safe_distances` of its complement, with the grid's exterior
/// counting as empty. An outside voxel with empty distance e has every voxel within e - 1 steps outside the
/// object (or beyond the grid); inside voxels have 0.
pub fn empty_distances(inside: &[u8], n: [usize; 3]) -> Vec<u8> {
    use rayon::prelude::*;
    erosion_depths(inside.par_iter().map(|&m| (m == 0) as u8).collect(), n, 1, SAFE_CAP)
}

/// For a set (1 = in it, 0 = not), the number of successive erosions by the 3 x 3 x 3 cube each voxel survives
/// (its Chebyshev distance to the nearest voxel not in the set), capped at `cap`; beyond the grid is in the set
/// if `border` is 1.
fn erosion_depths(cur: Vec<u8>, n: [usize; 3], border: u8, cap: u8) -> Vec<u8> {
    let mut depth = cur.clone();
    erode_counting(cur, n, border, cap, &mut depth, |d, c| *d += c);
    depth
}

/// Erodes the set `cur` (1 = in it) by the 3 x 3 x 3 cube up to `cap` - 1 times (beyond the grid is in the set if
/// `border` is 1), calling `count(acc[j], c)` after each erosion with voxel j's membership c (0 or 1); stops once
/// the set is empty.
fn erode_counting<T: Send>(
    mut cur: Vec<u8>,
    n: [usize; 3],
    border: u8,
    cap: u8,
    acc: &mut [T],
    count: impl Fn(&mut T, u8) + Sync,
) {
    use rayon::prelude::*;
    let plane = n[0] * n[1];
    let mut tmp = vec![0u8; cur.len()];
    for _ in 1..cap {
        for a in 0..3 {
            erode_axis(&cur, &mut tmp, n, a, border);
            std::mem::swap(&mut cur, &mut tmp);
        }
        let any = acc
            .par_chunks_mut(plane)
            .zip(cur.par_chunks(plane))
            .map(|(s, c)| {
                s.iter_mut().zip(c).for_each(|(s, &c)| count(s, c));
                c.iter().any(|&c| c != 0)
            })
            .reduce(|| false, |x, y| x || y);
        if !any {
            break;
        }
    }
}

/// out = cur eroded along axis a by one voxel (a voxel stays only if both neighbours on that axis are in the set;
/// beyond the grid counts as `border`). Whole rows and planes at a time, so the loops vectorise.
fn erode_axis(cur: &[u8], out: &mut [u8], n: [usize; 3], a: usize, border: u8) {
    use rayon::prelude::*;
    let (nx, plane) = (n[0], n[0] * n[1]);
    let and3 = |o: &mut [u8], x: &[u8], y: &[u8], z: &[u8]| {
        o.iter_mut().zip(x).zip(y).zip(z).for_each(|(((o, &x), &y), &z)| *o = x & y & z);
    };
    // The first and last of m cells of `st` bytes each (a row's voxels, a plane's rows): one neighbour beyond
    // the grid; the interior cells are done by `and3`.
    let ends = |o: &mut [u8], c: &[u8], m: usize, st: usize| {
        let cell = |i: usize| &c[i * st..(i + 1) * st];
        if m == 1 {
            o.iter_mut().zip(c).for_each(|(o, &c)| *o = c & border);
            return;
        }
        let (first, last) = (cell(0).iter().zip(cell(1)), cell(m - 1).iter().zip(cell(m - 2)));
        o[..st].iter_mut().zip(first).for_each(|(o, (&c, &b))| *o = c & b & border);
        o[(m - 1) * st..].iter_mut().zip(last).for_each(|(o, (&c, &b))| *o = c & b & border);
    };
    out.par_chunks_mut(plane).enumerate().for_each(|(k, o)| {
        let c = &cur[k * plane..(k + 1) * plane];
        match a {
            0 => {
                for (o, c) in o.chunks_mut(nx).zip(c.chunks(nx)) {
                    ends(o, c, nx, 1);
                    if nx > 2 {
                        and3(&mut o[1..nx - 1], &c[..nx - 2], &c[1..nx - 1], &c[2..]);
                    }
                }
            }
            1 => {
                let ny = n[1];
                ends(o, c, ny, nx);
                if ny > 2 {
                    and3(&mut o[nx..plane - nx], &c[..plane - 2 * nx], &c[nx..plane - nx], &c[2 * nx..]);
                }
            }
            _ => {
                let nz = n[2];
                if nz == 1 {
                    o.iter_mut().zip(c).for_each(|(o, &c)| *o = c & border);
                } else if k == 0 || k + 1 == nz {
                    let m = if k == 0 { 1 } else { k - 1 };
                    let nb = &cur[m * plane..(m + 1) * plane];
                    o.iter_mut().zip(c).zip(nb).for_each(|((o, &c), &b)| *o = c & b & border);
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
