//! Sparse shading normals. Only voxels at the surface have a shading normal, so storing 3 floats for every
//! grid voxel (12 bytes) is mostly zeros: `ShadingNormals` keeps the voxels that have one, grid row by grid row
//! (a row is the voxels of one (y, z) along x), 16 bytes per such voxel plus 4 bytes per row.

use crate::transport::sampling::{scale, V3};

/// The unit shading normal of a stored normal vector `n`: n / |n|, or None unless |n|^2 > 0.5 (zero, short or
/// NaN vectors are no usable normal).
#[inline(always)]
pub fn unit_normal(n: V3) -> Option<V3> {
    let l2 = n[0] * n[0] + n[1] * n[1] + n[2] * n[2];
    if l2 > 0.5 {
        Some(scale(n, 1.0 / l2.sqrt()))
    } else {
        None
    }
}

/// The `unit_normal`s of the voxels that have one, by grid row: row r = z ny + y holds entries
/// `rows[r]..rows[r + 1]`, their x ascending in `xs`, their unit normals in `normals`. A lookup is two loads
/// of `rows` and a binary search among the few surface voxels of one row.
pub struct ShadingNormals {
    n: [usize; 3],
    rows: Vec<u32>,
    xs: Vec<u32>,
    normals: Vec<V3>,
}

impl ShadingNormals {
    /// From dense normals (x, y, z) interleaved per voxel of an (nx, ny, nz) grid in linear-index order (a
    /// (z, y, x, 3) array's memory), read once without copying.
    pub fn from_dense(dense: &[f32], n: [usize; 3]) -> Result<Self, String> {
        let (nx, n_rows) = (n[0], n[1] * n[2]);
        if dense.len() != 3 * nx * n_rows {
            return Err("normals size differs from 3 x the grid".into());
        }
        let mut s = ShadingNormals { n, rows: Vec::with_capacity(n_rows + 1), xs: vec![], normals: vec![] };
        s.rows.push(0);
        for row in dense.chunks_exact(3 * nx) {
            for (x, v) in row.chunks_exact(3).enumerate() {
                if let Some(u) = unit_normal([v[0], v[1], v[2]]) {
                    s.xs.push(x as u32);
                    s.normals.push(u);
                }
            }
            let end = u32::try_from(s.xs.len()).map_err(|_| "more than 2^32 voxels with a normal")?;
            s.rows.push(end);
        }
        s.xs.shrink_to_fit();
        s.normals.shrink_to_fit();
        Ok(s)
    }

    /// From the voxels that have a normal: `index` their linear indices (strictly increasing), `vectors` their
    /// normals (x, y, z) interleaved, 3 per index. Entries that are no `unit_normal` are dropped, as in
    /// `from_dense`, so both forms of one field give the same lookups.
    pub fn from_sparse(index: &[i64], vectors: &[f32], n: [usize; 3]) -> Result<Self, String> {
        let (nx, n_rows) = (n[0], n[1] * n[2]);
        if vectors.len() != 3 * index.len() {
            return Err(format!("{} normal vectors for {} voxel indices", vectors.len() / 3, index.len()));
        }
        let mut s = ShadingNormals {
            n,
            rows: Vec::with_capacity(n_rows + 1),
            xs: Vec::with_capacity(index.len()),
            normals: Vec::with_capacity(index.len()),
        };
        s.rows.push(0);
        let mut prev = -1i64;
        for (&j, v) in index.iter().zip(vectors.chunks_exact(3)) {
            if j <= prev || j >= (nx * n_rows) as i64 {
                return Err(format!("normal voxel indices must increase and lie in the grid (got {j} after {prev})"));
            }
            prev = j;
            let (row, x) = (j as usize / nx, j as usize % nx);
            while s.rows.len() <= row {
                s.rows.push(s.xs.len() as u32);
            }
            if let Some(u) = unit_normal([v[0], v[1], v[2]]) {
                s.xs.push(x as u32);
                s.normals.push(u);
            }
        }
        let end = u32::try_from(s.xs.len()).map_err(|_| "more than 2^32 voxels with a normal")?;
        while s.rows.len() <= n_rows {
            s.rows.push(end);
        }
        Ok(s)
    }

    /// The unit shading normal of in-grid voxel v = (x, y, z), if it has one.
    #[inline(always)]
    pub fn get(&self, v: [i32; 3]) -> Option<V3> {
        let r = v[2] as usize * self.n[1] + v[1] as usize;
        let (a, b) = (self.rows[r] as usize, self.rows[r + 1] as usize);
        let k = self.xs[a..b].binary_search(&(v[0] as u32)).ok()?;
        Some(self.normals[a + k])
    }

    /// Number of voxels with a normal.
    pub fn len(&self) -> usize {
        self.xs.len()
    }

    pub fn is_empty(&self) -> bool {
        self.xs.is_empty()
    }

    /// Bytes held (for memory accounting).
    pub fn bytes(&self) -> usize {
        4 * self.rows.len() + 4 * self.xs.len() + 12 * self.normals.len()
    }
}
