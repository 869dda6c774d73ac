//! Bricks of `BRICK`^3 voxels, the storage unit of the grid-sized arrays that are mostly of one value far from an
//! object's surface (`distance::BrickedDistances`, `label_bricks::LabelBricks`): the constants of a voxel's brick
//! and its place in it, and the cutting of a slab of z-planes into bricks.
//!
//! Layout: voxel (x, y, z) of an (nx, ny, nz) grid has linear index `(z * ny + y) * nx + x` (x fastest); bricks are
//! numbered the same way over `ceil(n / BRICK)` bricks per axis, and a brick's voxels are in (z, y, x) order.

/// Edge of the bricks, in voxels.
pub const BRICK: usize = 8;
/// log2 of `BRICK`: a voxel's brick and its place in it are shifts and masks of its coordinates.
pub(crate) const SHIFT: u32 = BRICK.trailing_zeros();
const _: () = assert!(1 << SHIFT == BRICK);
/// Voxels of a brick.
pub(crate) const BRICK_VOXELS: usize = BRICK * BRICK * BRICK;

/// The values of a slab of z-planes (a slab of signed distances with its halo, a layer of bricks' labels): planes z0..
/// of an (nx, ny, nz) grid of `nb` bricks, cut into bricks.
pub(crate) struct Part<'a, T> {
    pub(crate) values: &'a [T],
    pub(crate) n: [usize; 3],
    pub(crate) z0: usize,
    pub(crate) nb: [usize; 3],
}

impl<T: Copy + PartialEq> Part<'_, T> {
    /// Brick k's in-grid rows: (z, y) within the brick and the row's values, each `BRICK` or fewer at the far face.
    fn rows(&self, k: usize) -> impl Iterator<Item = (usize, usize, &[T])> + '_ {
        let (n, nb) = (self.n, self.nb);
        let b = [k % nb[0], (k / nb[0]) % nb[1], k / (nb[0] * nb[1])];
        let lo: [usize; 3] = std::array::from_fn(|a| b[a] * BRICK);
        let hi: [usize; 3] = std::array::from_fn(|a| (lo[a] + BRICK).min(n[a]));
        (lo[2]..hi[2]).flat_map(move |z| {
            (lo[1]..hi[1]).map(move |y| {
                let row = ((z - self.z0) * n[1] + y) * n[0];
                (z - lo[2], y - lo[1], &self.values[row + lo[0]..row + hi[0]])
            })
        })
    }

    /// The one value of brick k's in-grid voxels, or None if they differ.
    pub(crate) fn uniform(&self, k: usize) -> Option<T> {
        let first = self.rows(k).next()?.2[0];
        self.rows(k).all(|(_, _, r)| r.iter().all(|&d| d == first)).then_some(first)
    }

    /// Brick k's values into `out` (`BRICK`^3, (z, y, x) order, x fastest).
    pub(crate) fn copy(&self, k: usize, out: &mut [T]) {
        for (z, y, r) in self.rows(k) {
            out[(z * BRICK + y) * BRICK..][..r.len()].copy_from_slice(r);
        }
    }
}
