//! Ink labels of a grid stored by bricks of `BRICK`^3 voxels (`LabelBricks`), built from z-planes pushed in order
//! (`LabelBricksBuilder`), so that a printer-resolution grid never exists as one byte per voxel: a printed object is
//! empty outside and one ink (white) in its core, and only the bricks near its surface hold differing labels.
//!
//! Layout: `bricks::Bricks`, whose first 256 bricks hold one label each (brick v is all v); the stored bricks follow
//! in the order their layers were pushed.

use crate::transport::bricks::{Bricks, Part, BRICK};

/// Label of an empty voxel (outside the object).
pub const EMPTY: u8 = 255;

/// Pool bricks of one label each, for every label 0..=255.
const SHARED: usize = 256;

/// A grid's labels (one byte per voxel: an ink, or `EMPTY` outside the object) by bricks.
pub struct LabelBricks {
    store: Bricks<u8>,
    /// Whether each label occurs in the grid.
    used: [bool; 256],
}

impl LabelBricks {
    /// The labels of an (nx, ny, nz) grid given as one byte per voxel (x fastest).
    pub fn from_dense(labels: &[u8], n: [usize; 3]) -> Result<Self, String> {
        let mut b = LabelBricksBuilder::new(n)?;
        if labels.len() != b.planes_left() * n[0] * n[1] {
            return Err(format!("{} labels for a grid of {n:?} voxels", labels.len()));
        }
        for slab in labels.chunks(n[0] * n[1] * BRICK) {
            b.push(slab)?;
        }
        b.finish()
    }

    /// Voxels along x, y, z.
    pub fn shape(&self) -> [usize; 3] {
        self.store.n
    }

    /// Voxels of the grid.
    pub fn len(&self) -> usize {
        self.store.n.iter().product()
    }

    pub fn is_empty(&self) -> bool {
        self.len() == 0
    }

    /// The label of in-grid voxel v (x, y, z).
    #[inline(always)]
    pub fn get(&self, v: [i32; 3]) -> u8 {
        self.store.get(v)
    }

    /// The label of voxel j (linear index, x fastest).
    #[inline(always)]
    pub fn get_index(&self, j: usize) -> u8 {
        let (nx, ny) = (self.store.n[0], self.store.n[1]);
        self.get([(j % nx) as i32, ((j / nx) % ny) as i32, (j / (nx * ny)) as i32])
    }

    /// Voxels a..b (linear indices, a <= b <= `len()`) as bytes 1 (a label other than `EMPTY`: inside) or 0.
    pub fn inside_span(&self, a: usize, b: usize) -> Vec<u8> {
        assert!(a <= b && b <= self.len(), "label span {a}..{b} outside its {} voxels", self.len());
        let [nx, ny, _] = self.store.n;
        let mut out = Vec::with_capacity(b - a);
        let mut j = a;
        while j < b {
            let row_end = ((j / nx + 1) * nx).min(b);
            let (y, z) = (((j / nx) % ny) as i32, (j / (nx * ny)) as i32);
            out.extend((j % nx..j % nx + (row_end - j)).map(|x| (self.get([x as i32, y, z]) != EMPTY) as u8));
            j = row_end;
        }
        out
    }

    /// Whether each label occurs in the grid.
    pub fn used(&self) -> &[bool; 256] {
        &self.used
    }

    /// Bricks stored in the pool (those whose voxels differ).
    pub fn stored_bricks(&self) -> usize {
        self.store.stored_bricks()
    }

    /// Bricks of the grid.
    pub fn bricks(&self) -> usize {
        self.store.bricks()
    }

    /// Bytes held: the table and the pool.
    pub fn bytes(&self) -> usize {
        self.store.bytes()
    }
}

impl std::fmt::Debug for LabelBricks {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(f, "LabelBricks({:?} voxels, {} of {} bricks stored)", self.shape(), self.stored_bricks(), self.bricks())
    }
}

/// Builds `LabelBricks` from the grid's z-planes, pushed in order (any number of whole planes at a time): it holds
/// the bricks built so far and at most one layer of bricks' planes (`BRICK` planes).
pub struct LabelBricksBuilder {
    bricks: LabelBricks,
    /// Why a push failed after taking planes: the builder refuses everything after it.
    broken: Option<String>,
    /// The planes of the layer of bricks being filled.
    slab: Vec<u8>,
    /// Planes pushed so far.
    z: usize,
}

impl LabelBricksBuilder {
    /// A builder for an (nx, ny, nz) grid.
    pub fn new(n: [usize; 3]) -> Result<Self, String> {
        if n.contains(&0) {
            return Err(format!("grid size {n:?} must be positive"));
        }
        let bricks = LabelBricks { store: Bricks::new(n, SHARED, |i| i as u8), used: [false; 256] };
        Ok(LabelBricksBuilder { bricks, broken: None, slab: Vec::with_capacity(n[0] * n[1] * BRICK), z: 0 })
    }

    /// Planes not pushed yet.
    pub fn planes_left(&self) -> usize {
        self.bricks.store.n[2] - self.z
    }

    /// Push the next whole z-planes (x fastest): an error, nothing taken, if `planes` is not whole planes or holds
    /// more than are left; an error that leaves the builder refusing everything after it if the bricks of mixed
    /// labels outgrow the pool's 32-bit offsets.
    pub fn push(&mut self, planes: &[u8]) -> Result<(), String> {
        if let Some(why) = &self.broken {
            return Err(why.clone());
        }
        let plane = self.bricks.store.n[0] * self.bricks.store.n[1];
        if !planes.len().is_multiple_of(plane) || planes.len() / plane > self.planes_left() {
            return Err(format!(
                "{} labels are not whole planes of {plane} or exceed the {} planes left",
                planes.len(),
                self.planes_left()
            ));
        }
        for chunk in planes.chunks(plane) {
            self.slab.extend_from_slice(chunk);
            self.z += 1;
            if self.z.is_multiple_of(BRICK) || self.z == self.bricks.store.n[2] {
                if let Err(why) = self.brick_layer() {
                    self.broken = Some(why.clone());
                    return Err(why);
                }
            }
        }
        Ok(())
    }

    /// The bricks, once every plane is pushed.
    pub fn finish(self) -> Result<LabelBricks, String> {
        if let Some(why) = self.broken {
            return Err(why);
        }
        if self.planes_left() > 0 {
            return Err(format!("{} of {} planes were not pushed", self.planes_left(), self.bricks.store.n[2]));
        }
        let mut bricks = self.bricks;
        bricks.store.pool.shrink_to_fit();
        Ok(bricks)
    }

    /// Turn the planes in `slab` (the layer of bricks that ends at plane `z`) into bricks, and empty it.
    fn brick_layer(&mut self) -> Result<(), String> {
        let b = &mut self.bricks;
        let (n, nb) = (b.store.n, b.store.nb);
        let z0 = (self.z - 1) / BRICK * BRICK;
        let part = Part { values: &self.slab, n, z0, nb: [nb[0], nb[1], n[2].div_ceil(BRICK)] };
        let layer = nb[0] * nb[1];
        b.store.store(&part, z0 / BRICK * layer..(z0 / BRICK + 1) * layer, |v| v as usize)?;
        self.slab.iter().for_each(|&l| b.used[l as usize] = true);
        self.slab.clear();
        Ok(())
    }
}
