//! `BandMedium`: an object stored as a band and a core. The band (the voxels near the surface whose mixture may
//! differ from the core's: the optimiser's free voxels and any fixed ones of another mixture) keeps its own
//! (sigma_t, albedo) per channel, 24 bytes per band voxel; every other inside voxel reads one homogeneous core
//! (one pair per channel); outside voxels are vacuum. No array per grid voxel: each (z, y) row keeps its runs of
//! inside voxels (a run is all band or all core, 12 bytes), 4 bytes per row say where its runs start. A lookup
//! reads the row's few runs (a solid row through a shell has three: band, core, band), then the band's
//! coefficients or the core's, so it returns exactly what a dense medium holding the same coefficients returns
//! and renders and gradients are bit-identical to the dense and sparse forms.

use crate::spans::row_of;
use crate::transport::mask::MaskRef;
use crate::transport::medium::{check_coefficients, extinction_albedo, majorant_of, Medium};

/// `Run::start` of a core run.
const CORE: u32 = u32::MAX;

/// Voxels x0..x1 of one row: core voxels (`start == CORE`) or band voxels, voxel x at band position
/// `start + (x - x0)`.
#[derive(Clone, Copy)]
struct Run {
    x0: u32,
    x1: u32,
    start: u32,
}

/// What a voxel is: vacuum, core, or the band voxel at a position.
#[derive(Clone, Copy, PartialEq, Debug)]
pub enum Class {
    Outside,
    Core,
    Band(usize),
}

pub struct BandMedium {
    /// Grid voxels, voxels per row (x), rows per layer (y); 1 / nx finds a voxel's row without a division.
    n: usize,
    nx: usize,
    ny: usize,
    inv_nx: f64,
    /// Runs of row r: `runs[rows[r]..rows[r + 1]]`, in increasing x.
    rows: Vec<u32>,
    runs: Vec<Run>,
    /// Band voxels; planar by channel: `coef[c * k + position]`, positions in grid order.
    k: usize,
    coef: Vec<[f32; 2]>,
    /// The core's (sigma_t, albedo) per channel, and whether any inside voxel is core.
    core: [[f32; 2]; 3],
    has_core: bool,
    majorant: [f32; 3],
}

impl BandMedium {
    /// A grid of (nx, ny, nz) voxels whose inside voxels are those of the mask `inside` ((z, y, x) order, a byte
    /// (non-zero: inside) or a bit per voxel, `MaskRef`; read a z-plane at a time here, not kept). `index` (strictly increasing linear indices of inside voxels) lists the
    /// band with interleaved (entry, channel) coefficients `sigma_s`, `sigma_a`; every other inside voxel has the
    /// core's `core_sigma_s`, `core_sigma_a` (per channel); all in mm^-1.
    pub fn new<'m>(
        n_xyz: [usize; 3],
        inside: impl Into<MaskRef<'m>>,
        index: &[i64],
        sigma_s: &[f32],
        sigma_a: &[f32],
        core: ([f32; 3], [f32; 3]),
    ) -> Result<Self, String> {
        let inside = inside.into();
        let (nx, ny, n) = (n_xyz[0], n_xyz[1], n_xyz.iter().product::<usize>());
        if inside.len() != n {
            return Err(format!("the inside mask has {} voxels, the grid {n}", inside.len()));
        }
        check_index(index, n)?;
        if let Some(e) = index.iter().position(|&j| !inside.get(j as usize)) {
            return Err(format!("band entry {e} is voxel {}, which is not inside the object", index[e]));
        }
        check_coefficients(index.len(), sigma_s, sigma_a, |e| format!("entry {e} (voxel {})", index[e]))?;
        let mut core_pairs = [[0.0f32, 1.0]; 3];
        for c in 0..3 {
            let (t, a) = extinction_albedo(core.0[c], core.1[c])
                .ok_or_else(|| format!("the core's coefficients of channel {c} are negative or not finite"))?;
            core_pairs[c] = [t, a];
        }
        let (rows, runs, has_core) = row_runs([nx, ny], inside, index)?;
        let k = index.len();
        let mut medium = BandMedium {
            n,
            nx,
            ny,
            inv_nx: 1.0 / nx as f64,
            rows,
            runs,
            k,
            coef: vec![[0.0f32, 1.0f32]; 3 * k],
            core: core_pairs,
            has_core,
            majorant: [0.0; 3],
        };
        medium.store((0..k).map(|e| (e, e)), sigma_s, sigma_a);
        Ok(medium)
    }

    /// What voxel j is (j in the grid).
    #[inline(always)]
    pub fn class(&self, j: usize) -> Class {
        let row = row_of(j, self.nx, self.inv_nx);
        self.class_in_row(row, j - row * self.nx)
    }

    /// `class` of the in-grid voxel at (x, y, z) = v: its row without the division.
    #[inline(always)]
    pub fn class_at(&self, v: [i32; 3]) -> Class {
        self.class_in_row(v[2] as usize * self.ny + v[1] as usize, v[0] as usize)
    }

    #[inline(always)]
    fn class_in_row(&self, row: usize, x: usize) -> Class {
        let x = x as u32;
        for r in &self.runs[self.rows[row] as usize..self.rows[row + 1] as usize] {
            if x < r.x0 {
                break;
            }
            if x < r.x1 {
                return if r.start == CORE { Class::Core } else { Class::Band((r.start + (x - r.x0)) as usize) };
            }
        }
        Class::Outside
    }

    #[inline(always)]
    fn of_class(&self, class: Class, c: usize) -> (f32, f32) {
        let [t, a] = match class {
            Class::Outside => [0.0, 1.0],
            Class::Core => self.core[c],
            Class::Band(p) => self.coef[c * self.k + p],
        };
        (t, a)
    }

    /// Overwrite the coefficients of some band voxels in place (`DenseMedium::set_voxels`: a voxel listed twice
    /// takes its last values) and recompute the majorant. A core or outside voxel is an error: the core holds one
    /// mixture. Checked before anything is written.
    pub fn set_voxels(&mut self, index: &[i64], sigma_s: &[f32], sigma_a: &[f32]) -> Result<(), String> {
        let n = self.n;
        if let Some(e) = index.iter().position(|&j| j < 0 || j as u64 >= n as u64) {
            return Err(format!("index entry {e} is voxel {}, outside the grid of {n} voxels", index[e]));
        }
        let classes: Vec<Class> = index.iter().map(|&j| self.class(j as usize)).collect();
        if let Some(e) = classes.iter().position(|c| !matches!(c, Class::Band(_))) {
            let what = if classes[e] == Class::Core { "in the core (one mixture)" } else { "outside the object" };
            return Err(format!("index entry {e} is voxel {}, which is {what}, not in the band", index[e]));
        }
        check_coefficients(index.len(), sigma_s, sigma_a, |e| format!("entry {e} (voxel {})", index[e]))?;
        let pairs = classes.into_iter().enumerate().map(|(e, c)| match c {
            Class::Band(p) => (e, p),
            _ => unreachable!("checked above"),
        });
        self.store(pairs, sigma_s, sigma_a);
        Ok(())
    }

    /// Whether each voxel of `index` is a band voxel (what `set_voxels` accepts); false outside the grid.
    pub fn in_band(&self, index: &[i64]) -> Vec<bool> {
        index
            .iter()
            .map(|&j| j >= 0 && (j as u64) < self.n as u64 && matches!(self.class(j as usize), Class::Band(_)))
            .collect()
    }

    /// Write checked coefficients of entries e into band positions p for each (e, p), then recompute the
    /// majorant (the band's largest sigma_t and the core's, when it has voxels).
    fn store(&mut self, pairs: impl Iterator<Item = (usize, usize)>, sigma_s: &[f32], sigma_a: &[f32]) {
        let k = self.k;
        for (e, p) in pairs {
            for c in 0..3 {
                let (t, albedo) = extinction_albedo(sigma_s[3 * e + c], sigma_a[3 * e + c]).unwrap();
                self.coef[c * k + p] = [t, albedo];
            }
        }
        let band = majorant_of(&self.coef, k);
        self.majorant = std::array::from_fn(|c| if self.has_core { band[c].max(self.core[c][0]) } else { band[c] });
    }

    /// Band voxels.
    pub fn band(&self) -> usize {
        self.k
    }

    /// Bytes held: coefficients, runs and row table.
    pub fn bytes(&self) -> usize {
        self.coef.len() * 8 + self.runs.len() * std::mem::size_of::<Run>() + self.rows.len() * 4
    }
}

/// Every entry in a grid of n voxels, strictly increasing.
fn check_index(index: &[i64], n: usize) -> Result<(), String> {
    if let Some(e) = index.iter().position(|&j| j < 0 || j as u64 >= n as u64) {
        return Err(format!("index entry {e} is voxel {}, outside the grid of {n} voxels", index[e]));
    }
    if let Some(e) = (1..index.len()).find(|&e| index[e] <= index[e - 1]) {
        return Err(format!(
            "index must be strictly increasing; entry {e} is voxel {} after {}",
            index[e],
            index[e - 1]
        ));
    }
    Ok(())
}

/// The runs of each row of the inside mask (rows of nx voxels), split where a voxel's class (band: listed in
/// `index`, an increasing subset of the inside voxels; core: any other inside voxel) changes: the row table
/// (rows + 1 entries), the runs, and whether any voxel is core.
fn row_runs(n_xy: [usize; 2], inside: MaskRef<'_>, index: &[i64]) -> Result<(Vec<u32>, Vec<Run>, bool), String> {
    let [nx, ny] = n_xy;
    let n_rows = inside.len() / nx;
    let (mut rows, mut runs) = (Vec::with_capacity(n_rows + 1), Vec::new());
    let (mut e, mut has_core) = (0usize, false);
    let mut layer = std::borrow::Cow::Borrowed(&[][..]);
    for row in 0..n_rows {
        rows.push(u32::try_from(runs.len()).map_err(|_| "more runs of inside voxels than a band numbers")?);
        if row % ny == 0 {
            layer = inside.span(row * nx, (row + ny) * nx); // a z-plane at a time (a bit mask unpacked)
        }
        let line = &layer[(row % ny) * nx..(row % ny + 1) * nx];
        let mut x = 0;
        while x < nx {
            if line[x] == 0 {
                x += 1;
                continue;
            }
            let is_band = |x: usize, e: usize| e < index.len() && index[e] as usize == row * nx + x;
            let band = is_band(x, e);
            let (x0, start) = (x, if band { e as u32 } else { CORE });
            while x < nx && line[x] != 0 && is_band(x, e) == band {
                e += band as usize;
                x += 1;
            }
            has_core |= !band;
            runs.push(Run { x0: x0 as u32, x1: x as u32, start });
        }
    }
    rows.push(u32::try_from(runs.len()).map_err(|_| "more runs of inside voxels than a band numbers")?);
    if index.len() >= CORE as usize {
        return Err(format!("{} band voxels are more than a band numbers", index.len()));
    }
    Ok((rows, runs, has_core))
}

impl Medium for BandMedium {
    #[inline(always)]
    fn coeffs(&self, idx: usize, c: usize) -> (f32, f32) {
        self.of_class(self.class(idx), c)
    }
    #[inline(always)]
    fn coeffs_at(&self, idx: usize, v: [i32; 3], c: usize) -> (f32, f32) {
        debug_assert_eq!(self.class_at(v), self.class(idx));
        self.of_class(self.class_at(v), c)
    }
    fn len(&self) -> usize {
        self.n
    }
    fn majorant(&self, c: usize) -> f32 {
        self.majorant[c]
    }
}
