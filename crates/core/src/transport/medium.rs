//! The media a walk reads (behind the `Medium` trait): per-voxel (sigma_t, albedo) of each channel.
//!
//! - `DenseMedium`: every grid voxel's coefficients, 24 bytes per voxel.
//! - `SparseMedium`: only some voxels' coefficients (an object's inside voxels), the rest vacuum: 24 bytes per
//!   voxel of each grid row's span from its first to its last inside voxel, and 16 bytes per row. For a
//!   figurine whose inside is a quarter of its bounding grid this is about a third of the dense form, and a
//!   lookup reads the same values, so renders are bit-identical.
//! - `LabelMedium`: one ink label per voxel and an ink table (quantized volumes), the labels stored by bricks
//!   (`label_bricks`): a byte per voxel of the bricks near the surface, 4 bytes per brick of one label.
//! - `BandMedium` (in `band`): a band of voxels near the surface with their own coefficients, one homogeneous
//!   core, no array per grid voxel.
//!
//! Coefficients are stored per channel in planar arrays (all voxels of R, then G, then B) as interleaved
//! (sigma_t, albedo) pairs, the two numbers the random walk needs, so one lookup is one load.

use crate::spans::RowSpans;
use crate::transport::label_bricks::LabelBricks;
pub use crate::transport::label_bricks::EMPTY;

/// Per-voxel optical parameters for one channel.
// A medium always covers its whole grid (`len` voxels), so it has no `is_empty`.
#[allow(clippy::len_without_is_empty)]
pub trait Medium: Sync {
    /// (sigma_t in mm^-1, albedo) of voxel `idx` in channel `c`.
    fn coeffs(&self, idx: usize, c: usize) -> (f32, f32);
    /// `coeffs` of voxel `idx`, whose grid coordinates (x, y, z) are `v`: a walk that tracks both saves a medium
    /// stored per grid row the division that finds the row. Contract: `v` is `idx`'s voxel (a medium may read
    /// either; only debug builds check).
    #[inline(always)]
    fn coeffs_at(&self, idx: usize, _v: [i32; 3], c: usize) -> (f32, f32) {
        self.coeffs(idx, c)
    }
    /// sigma_s in mm^-1 of voxel `idx` in channel `c` (for gradients).
    fn sigma_s(&self, idx: usize, c: usize) -> f32 {
        let (t, a) = self.coeffs(idx, c);
        t * a
    }
    /// The number of voxels.
    fn len(&self) -> usize;
    /// An upper bound of sigma_t over all voxels in channel c (the majorant of delta tracking).
    fn majorant(&self, c: usize) -> f32;
}

/// (sigma_t, albedo) of coefficients sigma_s, sigma_a (albedo 1 in vacuum); None unless both are finite and
/// non-negative.
pub(crate) fn extinction_albedo(s: f32, a: f32) -> Option<(f32, f32)> {
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
        if sigma_s.len() != sigma_a.len() || !sigma_s.len().is_multiple_of(3) {
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
            return Err(format!(
                "sigma_s and sigma_a must have 3 channels for each of the {k} indexed voxels, \
                                got {} and {} values",
                sigma_s.len(),
                sigma_a.len()
            ));
        }
        if let Some(e) = index.iter().position(|&j| j < 0 || j as u64 >= n as u64) {
            return Err(format!("index entry {e} is voxel {}, outside the grid of {n} voxels", index[e]));
        }
        if let Some(q) = (0..3 * k).find(|&q| extinction_albedo(sigma_s[q], sigma_a[q]).is_none()) {
            return Err(format!(
                "coefficients of entry {} (voxel {}) channel {} are negative or not finite",
                q / 3,
                index[q / 3],
                q % 3
            ));
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

    fn update_majorant(&mut self) {
        self.majorant = majorant_of(&self.coef, self.n);
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

/// One ink label (u8) per voxel, stored by bricks (`LabelBricks`: about a byte per voxel near the surface, a
/// table entry per brick of one label), and a small ink table.
pub struct LabelMedium {
    labels: LabelBricks,
    majorant: [f32; 3],
    /// [channel][ink] (sigma_t, albedo); index 255 (EMPTY) maps to vacuum.
    table: [[(f32, f32); 256]; 3],
}

impl LabelMedium {
    /// The labels of an (nx, ny, nz) grid, one byte per voxel (x fastest); `ink_sigma_s`, `ink_sigma_a`: (N, 3)
    /// row-major, mm^-1.
    pub fn new(n: [usize; 3], labels: &[u8], ink_sigma_s: &[f32], ink_sigma_a: &[f32]) -> Result<Self, String> {
        Self::from_bricks(LabelBricks::from_dense(labels, n)?, ink_sigma_s, ink_sigma_a)
    }

    /// Labels already stored by bricks, and the ink table as `new` takes it.
    pub fn from_bricks(labels: LabelBricks, ink_sigma_s: &[f32], ink_sigma_a: &[f32]) -> Result<Self, String> {
        let n_inks = ink_sigma_s.len() / 3;
        let rows = ink_sigma_s.len() == ink_sigma_a.len() && ink_sigma_s.len().is_multiple_of(3);
        if !rows || n_inks == 0 || n_inks > 255 {
            return Err("ink table must be (N, 3) with 1 <= N <= 255".into());
        }
        let mut table = [[(0.0f32, 1.0f32); 256]; 3];
        for k in 0..n_inks {
            for c in 0..3 {
                table[c][k] = extinction_albedo(ink_sigma_s[3 * k + c], ink_sigma_a[3 * k + c])
                    .ok_or_else(|| format!("ink {k} has negative or non-finite coefficients"))?;
            }
        }
        let used = *labels.used();
        if let Some(bad) = (0..256).find(|&l| used[l] && l != EMPTY as usize && l >= n_inks) {
            return Err(format!("label {bad} has no ink in a table of {n_inks}"));
        }
        let majorant = std::array::from_fn(|c| (0..256).filter(|&k| used[k]).fold(0.0f32, |a, k| a.max(table[c][k].0)));
        Ok(LabelMedium { labels, majorant, table })
    }

    /// The labels (the inside mask of a printed volume is their voxels other than `EMPTY`: `MaskRef::Labels`).
    pub fn labels(&self) -> &LabelBricks {
        &self.labels
    }
}

impl Medium for LabelMedium {
    #[inline(always)]
    fn coeffs(&self, idx: usize, c: usize) -> (f32, f32) {
        self.table[c][self.labels.get_index(idx) as usize]
    }
    #[inline(always)]
    fn coeffs_at(&self, idx: usize, v: [i32; 3], c: usize) -> (f32, f32) {
        // (the packets' 32-bit index wraps on grids above 2^31 voxels, where only `v` is right)
        debug_assert!(self.labels.len() > i32::MAX as usize || self.labels.get_index(idx) == self.labels.get(v));
        self.table[c][self.labels.get(v) as usize]
    }
    fn len(&self) -> usize {
        self.labels.len()
    }
    fn majorant(&self, c: usize) -> f32 {
        self.majorant[c]
    }
}

/// Check interleaved (entry, channel) coefficient arrays of `k` entries: lengths, and every pair finite and
/// non-negative. `name(q)` names entry q in the error.
pub(crate) fn check_coefficients(
    k: usize,
    sigma_s: &[f32],
    sigma_a: &[f32],
    name: impl Fn(usize) -> String,
) -> Result<(), String> {
    if sigma_s.len() != 3 * k || sigma_a.len() != 3 * k {
        return Err(format!(
            "sigma_s and sigma_a must have 3 channels for each of the {k} voxels, got {} and {} \
                            values",
            sigma_s.len(),
            sigma_a.len()
        ));
    }
    if let Some(q) = (0..3 * k).find(|&q| extinction_albedo(sigma_s[q], sigma_a[q]).is_none()) {
        return Err(format!("coefficients of {} channel {} are negative or not finite", name(q / 3), q % 3));
    }
    Ok(())
}

/// The largest sigma_t of each channel over planar coefficients of `k` entries per channel (in parallel: max is
/// exact in any order).
pub(crate) fn majorant_of(coef: &[[f32; 2]], k: usize) -> [f32; 3] {
    use rayon::prelude::*;
    std::array::from_fn(|c| {
        coef[c * k..(c + 1) * k]
            .par_chunks(1 << 16)
            .map(|b| b.iter().fold(0.0f32, |a, x| a.max(x[0])))
            .reduce(|| 0.0f32, f32::max)
    })
}

/// Coefficients of the voxels of an index set (the inside of a masked object), every other voxel vacuum
/// (sigma_t 0, albedo 1), stored per grid row span (`RowSpans`: a lookup reads a small per-row table, then the
/// coefficients, which lie closer together than in the dense form; the unlisted voxels inside a span, e.g. a
/// cavity, are stored as vacuum).
pub struct SparseMedium {
    at: RowSpans,
    /// Stored positions.
    k: usize,
    /// Planar by channel: `coef[c * k + position]`.
    coef: Vec<[f32; 2]>,
    majorant: [f32; 3],
}

impl SparseMedium {
    /// A grid of (nx, ny, nz) voxels storing the voxels `index` (strictly increasing linear indices) with
    /// interleaved (entry, channel) coefficients `sigma_s`, `sigma_a` (mm^-1); every other voxel is vacuum.
    pub fn new(n_xyz: [usize; 3], index: &[i64], sigma_s: &[f32], sigma_a: &[f32]) -> Result<Self, String> {
        let at = RowSpans::new(n_xyz, index)?;
        check_coefficients(index.len(), sigma_s, sigma_a, |e| format!("entry {e} (voxel {})", index[e]))?;
        let k = at.positions();
        let mut medium = SparseMedium { at, k, coef: vec![[0.0f32, 1.0f32]; 3 * k], majorant: [0.0; 3] };
        let slots: Vec<usize> = medium.at.listed_positions().collect();
        medium.store(slots.into_iter().enumerate(), sigma_s, sigma_a);
        Ok(medium)
    }

    /// Whether this medium stores exactly the voxels `index` (a `new` argument): then `refill` may replace its
    /// coefficients in place. O(len).
    pub fn stores(&self, index: &[i64]) -> bool {
        self.at.lists(index)
    }

    /// Replace every listed voxel's coefficients (entries in the order of the `index` this medium was built
    /// from), in place. Checked before anything is written.
    pub fn refill(&mut self, sigma_s: &[f32], sigma_a: &[f32]) -> Result<(), String> {
        check_coefficients(self.at.listed(), sigma_s, sigma_a, |e| format!("entry {e}"))?;
        let slots: Vec<usize> = self.at.listed_positions().collect();
        self.store(slots.into_iter().enumerate(), sigma_s, sigma_a);
        Ok(())
    }

    /// `DenseMedium::set_voxels` for listed voxels: overwrite some of them in place (a voxel listed twice takes
    /// its last values); a voxel the medium was not built with is an error. Checked before anything is written.
    pub fn set_voxels(&mut self, index: &[i64], sigma_s: &[f32], sigma_a: &[f32]) -> Result<(), String> {
        let n = self.at.grid();
        if let Some(e) = index.iter().position(|&j| j < 0 || j as u64 >= n as u64) {
            return Err(format!("index entry {e} is voxel {}, outside the grid of {n} voxels", index[e]));
        }
        let slots: Vec<Option<usize>> = index.iter().map(|&j| self.at.listed_position(j as usize)).collect();
        if let Some(e) = slots.iter().position(|s| s.is_none()) {
            return Err(format!(
                "index entry {e} is voxel {}, which the medium does not store (outside the \
                                object)",
                index[e]
            ));
        }
        check_coefficients(index.len(), sigma_s, sigma_a, |e| format!("entry {e} (voxel {})", index[e]))?;
        self.store(slots.into_iter().map(Option::unwrap).enumerate(), sigma_s, sigma_a);
        Ok(())
    }

    /// Write checked coefficients of entries e into positions s for each (e, s), then recompute the majorant.
    fn store(&mut self, pairs: impl Iterator<Item = (usize, usize)>, sigma_s: &[f32], sigma_a: &[f32]) {
        let k = self.k;
        for (e, s) in pairs {
            for c in 0..3 {
                let (t, albedo) = extinction_albedo(sigma_s[3 * e + c], sigma_a[3 * e + c]).unwrap();
                self.coef[c * k + s] = [t, albedo];
            }
        }
        self.majorant = majorant_of(&self.coef, k);
    }

    /// (sigma_t, albedo) at a stored position, vacuum at none.
    #[inline(always)]
    fn at_position(&self, position: Option<usize>, c: usize) -> (f32, f32) {
        match position {
            None => (0.0, 1.0),
            Some(s) => {
                let [t, a] = self.coef[c * self.k + s];
                (t, a)
            }
        }
    }

    /// Number of stored voxels (the listed ones and the vacuum between them in their rows).
    pub fn stored(&self) -> usize {
        self.k
    }
}

impl Medium for SparseMedium {
    #[inline(always)]
    fn coeffs(&self, idx: usize, c: usize) -> (f32, f32) {
        self.at_position(self.at.position(idx), c)
    }
    #[inline(always)]
    fn coeffs_at(&self, idx: usize, v: [i32; 3], c: usize) -> (f32, f32) {
        debug_assert_eq!(self.at.position_at(v), self.at.position(idx));
        self.at_position(self.at.position_at(v), c)
    }
    fn len(&self) -> usize {
        self.at.grid()
    }
    fn majorant(&self, c: usize) -> f32 {
        self.majorant[c]
    }
}
