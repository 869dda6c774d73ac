//! A set of voxels stored per grid row: each (z, y) row keeps the span from its first to its last listed voxel,
//! so a voxel's position in the store is one small table lookup (16 bytes per row, which stays in cache) away,
//! and a bitset over the stored positions says which of them were listed (a cavity inside a span is stored but
//! not listed). Positions run in grid order. Used by `SparseMedium` (coefficients per position) and by the
//! gradient buffers (slots = a listed voxel's rank, for the optimiser's free voxels: no map per grid voxel).

/// The grid row (z * ny + y) of linear voxel index `j` in rows of `nx` voxels, `inv_nx` = 1 / nx: j / nx by a float
/// reciprocal (no integer division in the walk's lookups), corrected by one where rounding crossed a row boundary.
#[inline(always)]
pub(crate) fn row_of(j: usize, nx: usize, inv_nx: f64) -> usize {
    let row = (j as f64 * inv_nx) as usize;
    if row * nx > j {
        row - 1
    } else if (row + 1) * nx <= j {
        row + 1
    } else {
        row
    }
}

/// One (z, y) row: voxels x0..x1 are stored, voxel x at position `off + x`.
#[derive(Clone, Copy)]
struct Span {
    off: i64,
    x0: u32,
    x1: u32,
}

pub struct RowSpans {
    /// Grid voxels, voxels per row (x), and rows per layer (y).
    n: usize,
    nx: usize,
    ny: usize,
    /// 1 / nx, to find a voxel's row without an integer division.
    inv_nx: f64,
    spans: Vec<Span>,
    /// Stored positions, and how many voxels were listed.
    positions: usize,
    listed: usize,
    /// Bit p: position p is a listed voxel.
    bits: Vec<u64>,
    /// Listed voxels before each 64-bit word of `bits` (their rank).
    before: Vec<u32>,
}

impl RowSpans {
    /// The voxels `index` (strictly increasing linear indices) of a grid of (nx, ny, nz) voxels.
    pub fn new(n_xyz: [usize; 3], index: &[i64]) -> Result<Self, String> {
        Self::of(n_xyz, index.len(), |e| index[e])
    }

    /// The `listed` voxels `voxel(0)`, `voxel(1)`, ... (strictly increasing linear indices) of a grid of (nx, ny,
    /// nz) voxels, read through `voxel` (e.g. a subset of another list, without gathering it).
    pub fn of(n_xyz: [usize; 3], listed: usize, voxel: impl Fn(usize) -> i64) -> Result<Self, String> {
        let (nx, n) = (n_xyz[0], n_xyz.iter().product::<usize>());
        if let Some(e) = (0..listed).find(|&e| voxel(e) < 0 || voxel(e) as u64 >= n as u64) {
            return Err(format!("index entry {e} is voxel {}, outside the grid of {n} voxels", voxel(e)));
        }
        if let Some(e) = (1..listed).find(|&e| voxel(e) <= voxel(e - 1)) {
            return Err(format!(
                "index must be strictly increasing; entry {e} is voxel {} after {}",
                voxel(e),
                voxel(e - 1)
            ));
        }
        let mut spans = vec![Span { off: 0, x0: 0, x1: 0 }; n / nx];
        let mut positions = 0usize;
        let mut e = 0;
        while e < listed {
            let row = voxel(e) as usize / nx;
            let first = e;
            while e < listed && voxel(e) as usize / nx == row {
                e += 1;
            }
            let (x0, x1) = (voxel(first) as usize % nx, voxel(e - 1) as usize % nx + 1);
            spans[row] = Span { off: positions as i64 - x0 as i64, x0: x0 as u32, x1: x1 as u32 };
            positions += x1 - x0;
        }
        if positions >= u32::MAX as usize {
            return Err(format!("{positions} stored voxels are more than a row-span store numbers"));
        }
        let mut s = RowSpans {
            n,
            nx,
            ny: n_xyz[1],
            inv_nx: 1.0 / nx as f64,
            spans,
            positions,
            listed,
            bits: vec![0u64; positions.div_ceil(64)],
            before: vec![],
        };
        for e in 0..listed {
            let p = s.position(voxel(e) as usize).expect("a listed voxel lies in its row's span");
            s.bits[p / 64] |= 1 << (p % 64);
        }
        let mut count = 0u32;
        s.before = s
            .bits
            .iter()
            .map(|w| {
                let b = count;
                count += w.count_ones();
                b
            })
            .collect();
        Ok(s)
    }

    /// The stored position of voxel j, if its row's span holds it.
    #[inline(always)]
    pub fn position(&self, j: usize) -> Option<usize> {
        let row = row_of(j, self.nx, self.inv_nx);
        self.position_in_row(row, j - row * self.nx)
    }

    /// `position` of the in-grid voxel at (x, y, z) = v: its row without the division.
    #[inline(always)]
    pub fn position_at(&self, v: [i32; 3]) -> Option<usize> {
        self.position_in_row(v[2] as usize * self.ny + v[1] as usize, v[0] as usize)
    }

    #[inline(always)]
    fn position_in_row(&self, row: usize, x: usize) -> Option<usize> {
        let sp = self.spans[row];
        if x < sp.x0 as usize || x >= sp.x1 as usize {
            return None;
        }
        Some((sp.off + x as i64) as usize)
    }

    /// Whether stored position p is a listed voxel.
    #[inline(always)]
    pub fn is_listed(&self, p: usize) -> bool {
        self.bits[p / 64] >> (p % 64) & 1 == 1
    }

    /// The position of voxel j if it was listed.
    #[inline(always)]
    pub fn listed_position(&self, j: usize) -> Option<usize> {
        self.position(j).filter(|&p| self.is_listed(p))
    }

    /// The rank of voxel j among the listed voxels (its entry in `index`), if it was listed.
    #[inline(always)]
    pub fn rank(&self, j: usize) -> Option<usize> {
        let p = self.listed_position(j)?;
        let below = self.bits[p / 64] & ((1u64 << (p % 64)) - 1);
        Some(self.before[p / 64] as usize + below.count_ones() as usize)
    }

    /// Whether these are exactly the voxels `index` (strictly increasing). O(len).
    pub fn lists(&self, index: &[i64]) -> bool {
        index.len() == self.listed
            && (1..index.len()).all(|e| index[e] > index[e - 1])
            && index.iter().all(|&j| j >= 0 && (j as u64) < self.n as u64 && self.listed_position(j as usize).is_some())
    }

    /// Grid voxels.
    pub fn grid(&self) -> usize {
        self.n
    }

    /// Stored positions (listed voxels and the unlisted ones between them in their rows).
    pub fn positions(&self) -> usize {
        self.positions
    }

    /// Listed voxels.
    pub fn listed(&self) -> usize {
        self.listed
    }

    /// The listed positions in order (entry e of `index` is at the e-th).
    pub fn listed_positions(&self) -> impl Iterator<Item = usize> + '_ {
        (0..self.positions).filter(|&p| self.is_listed(p))
    }
}
