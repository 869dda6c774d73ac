//! Which optimisation voxels of a layer take the ordered dither's own counts in count-adaptive dithering
//! (`kernels::counts::DITHER_CLASS`): those whose mixture is smooth, differing from the mixtures of their inside
//! neighbours (four in the layer, one in the layer below) by less than a threshold, the root mean square over them
//! of the share vectors' Euclidean distance. The others keep their depth shell's class and diffuse their counts.
//!
//! The sums run in a fixed order per voxel (each distance's squares over the inks in turn; then the distances to the
//! neighbour below in y, above in y, after in x, before in x and below in z), so the classes do not depend on the
//! thread count. It is the order of the numpy arithmetic this replaced for up to 7 inks; numpy sums 8 or more inks
//! pairwise, so there a voxel within rounding of the threshold may fall on the other side.

use crate::kernels::counts::{CountShape, DITHER_CLASS};
use rayon::prelude::*;

/// The layer below a layer: its shares (n, ny, nx) planar and its inside mask (ny, nx), nonzero inside.
#[derive(Clone, Copy)]
pub struct Below<'a> {
    pub share: &'a [f64],
    pub inside: &'a [u8],
}

/// Marks smooth voxels: `classes` (ny, nx) holds each voxel's class (0 outside) and receives `DITHER_CLASS` at
/// every inside voxel whose RMS share distance to its inside neighbours is below `smooth` (a voxel without inside
/// neighbours counts as distance 0). `share` (n, ny, nx) planar; `below` the layer under it, if any.
pub fn mark_smooth(
    shape: CountShape,
    share: &[f64],
    below: Option<Below<'_>>,
    smooth: f64,
    classes: &mut [u8],
) -> Result<(), String> {
    let CountShape { n, ny, nx } = shape;
    let m = ny * nx;
    if share.len() != n * m || classes.len() != m {
        return Err(format!("share must be {n} x {ny} x {nx} and classes {ny} x {nx}"));
    }
    if let Some(b) = below {
        if b.share.len() != n * m || b.inside.len() != m {
            return Err(format!("the layer below must be {n} x {ny} x {nx} with a {ny} x {nx} mask"));
        }
    }
    if m == 0 {
        return Ok(());
    }
    let inside: Vec<bool> = classes.iter().map(|&c| c > 0).collect();
    let dist =
        |a: usize, p: &[f64], b: usize| (0..n).fold(0.0f64, |s, j| s + (share[j * m + a] - p[j * m + b]).powi(2));
    classes.par_chunks_mut(nx).enumerate().for_each(|(y, row)| {
        for (x, class) in row.iter_mut().enumerate() {
            let i = y * nx + x;
            if !inside[i] {
                continue;
            }
            let (mut sq, mut cnt) = (0.0f64, 0.0f64);
            let lateral =
                [(y + 1 < ny, i + nx), (y > 0, i.wrapping_sub(nx)), (x + 1 < nx, i + 1), (x > 0, i.wrapping_sub(1))];
            for (exists, j) in lateral {
                if exists && inside[j] {
                    sq += dist(i, share, j);
                    cnt += 1.0;
                }
            }
            if let Some(b) = below.filter(|b| b.inside[i] > 0) {
                sq += dist(i, b.share, i);
                cnt += 1.0;
            }
            if (sq / cnt.max(1.0)).sqrt() < smooth {
                *class = DITHER_CLASS;
            }
        }
    });
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn marks_voxels_whose_neighbours_hold_nearly_their_mixture() {
        // 2 inks, 1 x 4 voxels: shares of ink 0 are 0.5, 0.52, 0.9, 0.9; the last is outside
        let shape = CountShape { n: 2, ny: 1, nx: 4 };
        let share = [0.5, 0.52, 0.9, 0.9, 0.5, 0.48, 0.1, 0.1];
        let mut classes = [1u8, 1, 1, 0];
        mark_smooth(shape, &share, None, 0.05, &mut classes).unwrap();
        // voxel 0: one neighbour at distance 0.02 sqrt 2 (smooth); voxel 1: sqrt((0.0008 + 0.2888) / 2) = 0.38;
        // voxel 2: its only inside neighbour is voxel 1, distance 0.54; voxel 3 stays outside
        assert_eq!(classes, [DITHER_CLASS, 1, 1, 0]);
        // the layer below holds nearly the same mixtures: voxel 0 at distance 0, voxel 1 at 0.02 sqrt 2, voxel 2 at 0;
        // at a threshold of 0.4, voxel 2 (sqrt(0.2888) = 0.54 alone) becomes smooth: sqrt(0.2888 / 2) = 0.38
        let below = Below { share: &[0.5, 0.5, 0.9, 0.9, 0.5, 0.5, 0.1, 0.1], inside: &[1, 1, 1, 1] };
        let mut classes = [2u8, 2, 2, 0];
        mark_smooth(shape, &share, None, 0.4, &mut classes).unwrap();
        assert_eq!(classes, [DITHER_CLASS, DITHER_CLASS, 2, 0]);
        let mut classes = [2u8, 2, 2, 0];
        mark_smooth(shape, &share, Some(below), 0.4, &mut classes).unwrap();
        assert_eq!(classes, [DITHER_CLASS, DITHER_CLASS, DITHER_CLASS, 0]);
        // a voxel without inside neighbours is smooth
        let mut lone = [0u8, 0, 3, 0];
        mark_smooth(shape, &share, None, 0.05, &mut lone).unwrap();
        assert_eq!(lone, [0, 0, DITHER_CLASS, 0]);
        assert!(mark_smooth(shape, &share[..6], None, 0.05, &mut lone).is_err());
        assert!(mark_smooth(CountShape { n: 2, ny: 0, nx: 3 }, &[], None, 0.05, &mut []).is_ok());
    }
}
