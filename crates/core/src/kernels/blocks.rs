//! The printer voxels of an optimisation layer's blocks, sorted by their dither thresholds, and the labels that
//! whole ink counts give them (the placement of `kernels::counts`).
//!
//! Under nearest upsampling the printer rows of optimisation row y are `ry[y]..ry[y + 1]` and its columns
//! `rx[x]..rx[x + 1]` (the upsampling's index maps are non-decreasing), and all `k` printer layers of the layer
//! belong to it: block (y, x) is those rows × columns × layers. `sort_blocks` lists each block's voxels (flat
//! indices into the layer's (k, Y, X) printer voxels) in increasing threshold, ties to the lower index;
//! `place_blocks` gives the first `c_0` of them band 0, the next `c_1` band 1, and so on. Where the counts are the
//! ones the thresholds give the block's mixture, the labels are the ordered dither's own. Blocks are sorted in
//! parallel by optimisation row; each block's order depends only on its own thresholds.

use rayon::prelude::*;

/// An optimisation layer's blocks: `k` printer layers of `ny` × `nx` blocks over a `(k, Y, X)` printer slab, with
/// `ry` (ny + 1) and `rx` (nx + 1) the printer rows' and columns' offsets; `width` the largest block's voxels.
#[derive(Clone, Copy)]
pub struct Blocks<'a> {
    pub k: usize,
    pub ry: &'a [u32],
    pub rx: &'a [u32],
    pub width: usize,
}

impl Blocks<'_> {
    fn check(&self, printer: usize) -> Result<(usize, usize, usize, usize), String> {
        let (ny, nx) = (self.ry.len().saturating_sub(1), self.rx.len().saturating_sub(1));
        let monotone = |r: &[u32]| r.windows(2).all(|w| w[0] <= w[1]);
        if ny == 0 || nx == 0 || !monotone(self.ry) || !monotone(self.rx) {
            return Err("row and column offsets must be non-decreasing, at least two each".into());
        }
        let (yy, xx) = (self.ry[ny] as usize, self.rx[nx] as usize);
        if self.k * yy * xx != printer {
            return Err(format!("{printer} printer voxels, expected {} x {yy} x {xx}", self.k));
        }
        let big = (0..ny).map(|y| (self.ry[y + 1] - self.ry[y]) as usize).max().unwrap_or(0)
            * (0..nx).map(|x| (self.rx[x + 1] - self.rx[x]) as usize).max().unwrap_or(0)
            * self.k;
        if self.width < big {
            return Err(format!("width {} is less than the largest block's {big} voxels", self.width));
        }
        Ok((ny, nx, yy, xx))
    }

    /// The flat (k, Y, X) indices of block (y, x)'s printer voxels, in increasing index.
    fn voxels(&self, y: usize, x: usize, yy: usize, xx: usize, out: &mut Vec<u32>) {
        out.clear();
        for kk in 0..self.k {
            for py in self.ry[y]..self.ry[y + 1] {
                for px in self.rx[x]..self.rx[x + 1] {
                    out.push(((kk * yy + py as usize) * xx + px as usize) as u32);
                }
            }
        }
    }
}

/// Each block's voxels in increasing threshold `t` ((k, Y, X) f32, ties to the lower index): `order` (ny, nx,
/// width) their flat indices, `sorted` (ny, nx, width) their thresholds; a block's unused slots get `u32::MAX`
/// and 2.0.
pub fn sort_blocks(b: Blocks<'_>, t: &[f32], order: &mut [u32], sorted: &mut [f64]) -> Result<(), String> {
    let (ny, nx, yy, xx) = b.check(t.len())?;
    let slots = ny * nx * b.width;
    if order.len() != slots || sorted.len() != slots {
        return Err(format!("order and sorted need {slots} slots, got {} and {}", order.len(), sorted.len()));
    }
    let row = nx * b.width;
    if row == 0 {
        return Ok(());
    }
    order.par_chunks_mut(row).zip(sorted.par_chunks_mut(row)).enumerate().for_each(|(y, (o, s))| {
        let mut ids = Vec::with_capacity(b.width);
        for x in 0..nx {
            b.voxels(y, x, yy, xx, &mut ids);
            ids.sort_by(|&p, &q| t[p as usize].total_cmp(&t[q as usize]).then(p.cmp(&q)));
            for slot in 0..b.width {
                o[x * b.width + slot] = ids.get(slot).copied().unwrap_or(u32::MAX);
                s[x * b.width + slot] = ids.get(slot).map_or(2.0, |&i| t[i as usize] as f64);
            }
        }
    });
    Ok(())
}

/// The bands of every printer voxel: block (y, x)'s voxels in `order` take `counts` (ny, nx, n) bands in turn;
/// `labels` (k, Y, X) u8. A block's counts must sum to its voxels, or to 0 (its labels are left as they are).
pub fn place_blocks(b: Blocks<'_>, order: &[u32], counts: &[u32], n: usize, labels: &mut [u8]) -> Result<(), String> {
    let (ny, nx, _, _) = b.check(labels.len())?;
    if order.len() != ny * nx * b.width || counts.len() != ny * nx * n || n == 0 || n > 255 {
        return Err(format!("order or counts have the wrong size for {ny} x {nx} blocks of {n} inks"));
    }
    for i in 0..ny * nx {
        let ids = order[i * b.width..(i + 1) * b.width].iter().take_while(|&&v| v != u32::MAX);
        let c = &counts[i * n..(i + 1) * n];
        let total = c.iter().sum::<u32>() as usize;
        if total == 0 {
            continue; // a block outside the object: its labels are the caller's
        }
        if total != ids.clone().count() {
            return Err(format!("block {i}'s counts do not sum to its voxels"));
        }
        let (mut band, mut left) = (0usize, c[0]);
        for &id in ids {
            while left == 0 {
                band += 1;
                left = c[band];
            }
            labels[id as usize] = band as u8;
            left -= 1;
        }
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn sorts_each_block_and_places_its_counts() {
        // 2 printer layers over 1 x 2 blocks; block 0 is 2 x 1 printer voxels, block 1 is 2 x 2 (x offsets 0, 1, 3)
        let b = Blocks { k: 2, ry: &[0, 2], rx: &[0, 1, 3], width: 8 };
        let t: Vec<f32> = vec![0.9, 0.1, 0.5, 0.3, 0.3, 0.7, 0.2, 0.6, 0.4, 0.8, 0.0, 0.5];
        let (mut order, mut sorted) = (vec![0u32; 16], vec![0.0f64; 16]);
        sort_blocks(b, &t, &mut order, &mut sorted).unwrap();
        // block 0: voxels (k, y, x=0): indices 0, 3, 6, 9 with t 0.9, 0.3, 0.2, 0.8
        assert_eq!(&order[..4], &[6, 3, 9, 0]);
        assert_eq!(&order[4..8], &[u32::MAX; 4]);
        assert_eq!(sorted[7], 2.0);
        // block 1: indices 1, 2, 4, 5, 7, 8, 10, 11 with t 0.1, 0.5, 0.3, 0.7, 0.6, 0.4, 0.0, 0.5 (2 before 11 at 0.5)
        assert_eq!(&order[8..], &[10, 1, 4, 8, 2, 11, 7, 5]);
        let mut labels = vec![9u8; 12];
        place_blocks(b, &order, &[1, 0, 3, 2, 5, 1], 3, &mut labels).unwrap();
        assert_eq!(labels, vec![2, 0, 1, 2, 1, 2, 0, 1, 1, 2, 0, 1]);
        assert!(place_blocks(b, &order, &[1, 1, 3, 2, 5, 1], 3, &mut labels).is_err());
        place_blocks(b, &order, &[0, 0, 0, 2, 5, 1], 3, &mut labels).unwrap(); // block 0 outside: untouched
        assert_eq!(labels, vec![2, 0, 1, 2, 1, 2, 0, 1, 1, 2, 0, 1]);
    }

    #[test]
    fn refuses_bad_shapes() {
        let b = Blocks { k: 2, ry: &[0, 2], rx: &[0, 1, 3], width: 3 };
        let (mut o, mut s) = (vec![0u32; 6], vec![0.0; 6]);
        assert!(sort_blocks(b, &[0.0; 12], &mut o, &mut s).unwrap_err().contains("width"));
        let b = Blocks { width: 8, ..b };
        assert!(sort_blocks(b, &[0.0; 10], &mut o, &mut s).is_err());
        let b = Blocks { rx: &[0, 2, 1], ..b };
        assert!(sort_blocks(b, &[0.0; 12], &mut o, &mut s).is_err());
        let empty = Blocks { k: 0, ry: &[0, 2], rx: &[0, 1, 3], width: 0 };
        assert!(sort_blocks(empty, &[], &mut [], &mut []).is_ok());
    }
}
