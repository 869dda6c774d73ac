//! Bricks of `BRICK`^3 voxels, the storage of the grid-sized arrays that are mostly of one value far from an object's
//! surface (`distance::BrickedDistances`, `label_bricks::LabelBricks`): `Bricks`, a grid's values by bricks, and the
//! cutting of a slab of z-planes into bricks (`Part`).
//!
//! Layout: voxel (x, y, z) of an (nx, ny, nz) grid has linear index `(z * ny + y) * nx + x` (x fastest); bricks are
//! numbered the same way over `ceil(n / BRICK)` bricks per axis, and a brick's voxels are in (z, y, x) order. A
//! `Bricks` pool holds whole bricks: first its shared bricks of one value each, then the stored bricks in the order
//! they were stored; its table holds, per brick of the grid, the pool offset of the brick it reads, so a brick of one
//! value costs its 4-byte entry and a lookup is two loads and no branch. Bricks at the grid's far faces hold voxels
//! beyond the grid, which are never read (the default value in the pool).

use std::ops::Range;

use rayon::prelude::*;

/// Edge of the bricks, in voxels.
pub const BRICK: usize = 8;
/// log2 of `BRICK`: a voxel's brick and its place in it are shifts and masks of its coordinates.
pub(crate) const SHIFT: u32 = BRICK.trailing_zeros();
const _: () = assert!(1 << SHIFT == BRICK);
/// Voxels of a brick.
pub(crate) const BRICK_VOXELS: usize = BRICK * BRICK * BRICK;

/// A grid's values by bricks (module doc): the table and the pool.
pub(crate) struct Bricks<T> {
    /// Voxels along x, y, z.
    pub(crate) n: [usize; 3],
    /// Bricks along x and y.
    pub(crate) nb: [usize; 2],
    /// Per brick of the grid (x fastest), the offset in `pool` of the brick it reads (a multiple of `BRICK`^3).
    pub(crate) table: Vec<u32>,
    /// The `shared` bricks of one value, then the stored bricks.
    pub(crate) pool: Vec<T>,
    shared: usize,
}

impl<T: Copy + PartialEq + Default + Send + Sync> Bricks<T> {
    /// An (nx, ny, nz) grid with `shared` bricks of one value each (brick i all `value(i)`), every entry reading the
    /// first until its bricks are stored.
    pub(crate) fn new(n: [usize; 3], shared: usize, value: impl Fn(usize) -> T) -> Self {
        let nb: [usize; 3] = std::array::from_fn(|a| n[a].div_ceil(BRICK));
        let pool = (0..shared * BRICK_VOXELS).map(|i| value(i / BRICK_VOXELS)).collect();
        Bricks { n, nb: [nb[0], nb[1]], table: vec![0; nb[0] * nb[1] * nb[2]], pool, shared }
    }

    /// Store bricks `ks` of `part`: a brick of one value v reads shared brick `shared_of(v)`, any other is copied to
    /// the pool. An error, nothing written, if the pool's offsets would outgrow 32 bits.
    pub(crate) fn store(
        &mut self,
        part: &Part<T>,
        ks: Range<usize>,
        shared_of: impl Fn(T) -> usize,
    ) -> Result<(), String> {
        let uniform: Vec<Option<T>> = ks.clone().into_par_iter().map(|k| part.uniform(k)).collect();
        let first = self.pool.len() / BRICK_VOXELS;
        if (first + uniform.iter().filter(|u| u.is_none()).count()) * BRICK_VOXELS > u32::MAX as usize + 1 {
            return Err(format!("more than {} stored bricks", (u32::MAX as usize + 1) / BRICK_VOXELS - self.shared));
        }
        let mut stored = vec![];
        for (k, u) in ks.zip(uniform) {
            let brick = u.map_or_else(|| first + stored.len(), &shared_of);
            if u.is_none() {
                stored.push(k);
            }
            self.table[k] = (brick * BRICK_VOXELS) as u32; // fits: checked above
        }
        self.pool.resize((first + stored.len()) * BRICK_VOXELS, T::default());
        let new = &mut self.pool[first * BRICK_VOXELS..];
        new.par_chunks_mut(BRICK_VOXELS).zip(&stored).for_each(|(out, &k)| part.copy(k, out));
        Ok(())
    }

    /// The value of in-grid voxel v (x, y, z): its brick's table entry, then its place within the brick.
    #[inline(always)]
    pub(crate) fn get(&self, v: [i32; 3]) -> T {
        let [x, y, z] = v.map(|c| c as usize);
        debug_assert!(x < self.n[0] && y < self.n[1] && z < self.n[2], "voxel {v:?} outside the grid {:?}", self.n);
        let b = ((z >> SHIFT) * self.nb[1] + (y >> SHIFT)) * self.nb[0] + (x >> SHIFT);
        let m = BRICK - 1;
        let within = (((z & m) << SHIFT | (y & m)) << SHIFT) | (x & m);
        let offset = self.table[b] as usize;
        // SAFETY: every table entry is the offset of a whole brick of the pool (`new`, `store`) and `within` <
        // BRICK^3.
        unsafe { *self.pool.get_unchecked(offset + within) }
    }

    /// Bricks stored in the pool (those whose voxels differ).
    pub(crate) fn stored_bricks(&self) -> usize {
        self.pool.len() / BRICK_VOXELS - self.shared
    }

    /// Bricks of the grid.
    pub(crate) fn bricks(&self) -> usize {
        self.table.len()
    }

    /// Bytes held: the table and the pool.
    pub(crate) fn bytes(&self) -> usize {
        self.table.len() * std::mem::size_of::<u32>() + self.pool.len() * std::mem::size_of::<T>()
    }
}

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
