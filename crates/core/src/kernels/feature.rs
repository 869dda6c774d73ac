//! The exact Euclidean feature transform of a (z, y, x) grid one z plane at a time: for every voxel of plane z the
//! (z, y, x) of its nearest feature voxel, the same answer, ties included, as
//! `scipy.ndimage.distance_transform_edt(..., return_indices=True)` on the whole grid, without its
//! 12 bytes per grid voxel.
//!
//! scipy runs Maurer, Qi and Raghavan's separable passes (IEEE PAMI 25, 265-270, 2003) along z, then y, then x.
//! The z pass gives every column's nearest feature (ties to the lower z); the y and x passes of plane z read only
//! plane z's column answers. So the caller gives plane z's column answers (`site_z`) and `feature_plane` runs the
//! y and x passes on them with scipy's arithmetic in scipy's order (`voronoi_line`), in f64 without fused
//! operations, so that every comparison, tie and answer is scipy's.

/// The plane's size (y, x) and the grid's voxel size per axis (z, y, x; any unit), scipy's `sampling`.
#[derive(Clone, Copy, Debug)]
pub struct PlaneShape {
    pub ny: usize,
    pub nx: usize,
    pub sampling: [f64; 3],
}

/// Plane z's nearest features: `site_z` (y, x) row-major, the z of each column's nearest feature to plane z (-1:
/// the column has none); `out` (3, y, x) planar receives each voxel's nearest feature's z, y and x (z -1 where the
/// grid has no feature). Err on mismatched lengths.
pub fn feature_plane(z: i64, site_z: &[i32], shape: PlaneShape, out: &mut [i32]) -> Result<(), String> {
    let (ny, nx) = (shape.ny, shape.nx);
    if site_z.len() != ny * nx || out.len() != 3 * ny * nx {
        return Err(format!("site_z must hold {} and out {} values", ny * nx, 3 * ny * nx));
    }
    let plane = ny * nx;
    // the z pass's answers as scipy holds them: (z, y, x) per voxel, z -1 without a feature
    let mut f: Vec<[i64; 3]> = Vec::with_capacity(plane);
    for y in 0..ny {
        for x in 0..nx {
            f.push([site_z[y * nx + x] as i64, y as i64, x as i64]);
        }
    }
    let len = ny.max(nx);
    let mut line = vec![[0i64; 3]; len];
    let mut g = vec![0usize; len];
    for x in 0..nx {
        // the y pass: each line along y at this x
        for y in 0..ny {
            line[y] = f[y * nx + x];
        }
        voronoi_line(&mut line[..ny], [z, 0, x as i64], 1, &shape.sampling, &mut g);
        for y in 0..ny {
            f[y * nx + x] = line[y];
        }
    }
    for y in 0..ny {
        // the x pass: each line along x at this y
        let row = &mut f[y * nx..(y + 1) * nx];
        voronoi_line(row, [z, y as i64, 0], 2, &shape.sampling, &mut g);
    }
    for (i, v) in f.iter().enumerate() {
        for c in 0..3 {
            out[c * plane + i] = v[c] as i32;
        }
    }
    Ok(())
}

/// scipy's `_VoronoiFT` on one line along axis `d` at coordinates `coor` (the entry at `d` unused): each entry of
/// `f` (a feature's (z, y, x), z < 0: none) is replaced by the nearest of the line's features to its position;
/// a line without features is left as it is. `g`: scratch of at least the line's length.
fn voronoi_line(f: &mut [[i64; 3]], coor: [i64; 3], d: usize, s: &[f64; 3], g: &mut [usize]) {
    let mut l: isize = -1;
    for ii in 0..f.len() {
        if f[ii][0] < 0 {
            continue;
        }
        let fd = f[ii][d] as f64;
        let mut w_r = 0.0f64;
        for jj in (0..3).filter(|&jj| jj != d) {
            let tw = (f[ii][jj] - coor[jj]) as f64 * s[jj];
            w_r += tw * tw;
        }
        while l >= 1 {
            let (idx1, idx2) = (g[l as usize], g[l as usize - 1]);
            let f1 = f[idx1][d] as f64;
            let a = (f1 - f[idx2][d] as f64) * s[d];
            let b = (fd - f1) * s[d];
            let c = a + b;
            let (mut u_r, mut v_r) = (0.0f64, 0.0f64);
            for jj in (0..3).filter(|&jj| jj != d) {
                let cc = coor[jj] as f64;
                let tu = (f[idx2][jj] as f64 - cc) * s[jj];
                let tv = (f[idx1][jj] as f64 - cc) * s[jj];
                u_r += tu * tu;
                v_r += tv * tv;
            }
            if c * v_r - b * u_r - a * w_r - a * b * c <= 0.0 {
                break;
            }
            l -= 1;
        }
        l += 1;
        g[l as usize] = ii;
    }
    if l < 0 {
        return;
    }
    let maxl = l as usize;
    let sites: Vec<[i64; 3]> = g[..=maxl].iter().map(|&i| f[i]).collect();
    let dist = |site: &[i64; 3], ii: usize| -> f64 {
        let mut delta = 0.0f64;
        for jj in 0..3 {
            let t = if jj == d { site[jj] - ii as i64 } else { site[jj] - coor[jj] };
            let t = t as f64 * s[jj];
            delta += t * t;
        }
        delta
    };
    let mut l = 0usize;
    for (ii, out) in f.iter_mut().enumerate() {
        let mut delta1 = dist(&sites[l], ii);
        while l < maxl {
            let delta2 = dist(&sites[l + 1], ii);
            if delta1 <= delta2 {
                break;
            }
            delta1 = delta2;
            l += 1;
        }
        *out = sites[l];
    }
}
