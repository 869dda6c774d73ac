//! The voxel scene: grid geometry (size, boundary, inside mask as signed distances, shading normals), the
//! light it is lit by (a `Light`, see `light`; set with `Geometry::with_light`) and texels. The media (behind
//! the `Medium` trait) are in `medium` and re-exported here.
//!
//! Layout: voxel (x, y, z) has linear index `(z * ny + y) * nx + x`, i.e. C order of a (z, y, x) array.

pub use crate::transport::distance::{
    brick_empty_distances, empty_distances, safe_distances, signed_distances, BrickedDistances, BRICK, SAFE_CAP,
};
pub use crate::transport::light::{Light, UniformLight};
pub use crate::transport::mask::MaskRef;
pub use crate::transport::medium::{DenseMedium, LabelMedium, Medium, SparseMedium, EMPTY};
pub use crate::transport::normals::ShadingNormals;
use crate::transport::sampling::V3;
use wide::i32x8;

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
    /// With an inside mask (`with_inside`): each voxel's signed distance (`signed_distances`) stored by bricks of
    /// `BRICK`^3 voxels (`BrickedDistances`: a brick of one value costs a table entry, the others their bytes; read
    /// by voxel coordinates). Inside voxels hold their safe distance, the Chebyshev distance in voxels to the
    /// nearest voxel outside the object or the grid (1 at the surface); outside voxels minus their empty distance,
    /// the Chebyshev distance to the nearest inside voxel (-1 next to the object; the grid's exterior counts as
    /// empty); both capped at `SAFE_CAP`. A voxel is inside iff its value is positive. One store for both, so the
    /// flight that leaves the object finds the empty distance of its next voxel in the brick it just read. None:
    /// the whole box is inside.
    pub dist: Option<BrickedDistances>,
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
    /// safe and empty distances from it (`BrickedDistances::new`: a slab of the grid at a time, so besides the
    /// bricks it works in three bytes per voxel of a slab and its halo).
    pub fn with_inside(self, inside: impl AsRef<[u8]>) -> Result<Self, String> {
        self.with_inside_mask(MaskRef::Bytes(inside.as_ref()))
    }

    /// `with_inside` of a mask given as bytes or bits (`MaskRef`), read a slab at a time and not kept.
    pub fn with_inside_mask(mut self, inside: MaskRef<'_>) -> Result<Self, String> {
        if inside.len() != self.voxel_count() {
            return Err("inside mask size differs from the grid".into());
        }
        let n = [self.n[0] as usize, self.n[1] as usize, self.n[2] as usize];
        // On periodic axes a flight leaving the grid re-enters on the other side: no empty distances (every outside
        // voxel -1, "next to the object") and no jumps there.
        let boxed = self.boundary == Boundary::Box;
        self.dist = Some(BrickedDistances::new(inside, n, boxed));
        if boxed {
            self.brick_empty = Some(brick_empty_distances(inside, n));
        }
        Ok(self)
    }

    /// Whether an inside mask bounds the object (else the whole grid is inside).
    #[inline(always)]
    pub fn masked(&self) -> bool {
        self.dist.is_some()
    }

    /// Safe distance of in-grid voxel v (x, y, z) (`dist`; 0 outside the object); `SAFE_CAP` when there is no
    /// mask.
    #[inline(always)]
    pub fn safe_distance(&self, v: [i32; 3]) -> u8 {
        match &self.dist {
            None => SAFE_CAP,
            Some(d) => d.get(v).max(0) as u8,
        }
    }

    /// `safe_distance` of eight in-grid voxels (x, y, z lanes), as floats; only with a mask.
    #[inline(always)]
    pub fn safe_distances8(&self, v: [i32x8; 3]) -> [f32; 8] {
        let d = self.dist.as_ref().expect("safe_distances8 needs a mask").get8(v);
        d.map(|d| d.max(0) as f32)
    }

    /// Empty distance of in-grid voxel v (x, y, z) (`dist`; 0 inside the object and without a mask; 1 everywhere
    /// outside on periodic grids, which have no empty distances).
    #[inline(always)]
    pub fn empty_distance(&self, v: [i32; 3]) -> u8 {
        match &self.dist {
            None => 0,
            Some(d) => (-d.get(v)).max(0) as u8,
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
        self.in_grid(v) && self.mask_inside(v)
    }

    /// Whether in-grid voxel v (x, y, z) is inside the object.
    #[inline(always)]
    pub fn mask_inside(&self, v: [i32; 3]) -> bool {
        match &self.dist {
            None => true,
            Some(d) => d.get(v) > 0,
        }
    }

    /// Outward shading normal of inside voxel v, if the scene has normals and it is a usable unit vector.
    #[inline(always)]
    pub fn shading_normal(&self, v: [i32; 3]) -> Option<V3> {
        self.normals.as_ref()?.get(v)
    }
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
