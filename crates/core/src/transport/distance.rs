//! Distances of an inside mask: safe distances (inside voxels to the nearest voxel outside the object or the grid),
//! empty distances (outside voxels to the nearest inside voxel), both Chebyshev, in voxels, capped at `SAFE_CAP`,
//! found by erosions with the 3 x 3 x 3 cube; the empty distances of bricks of `BRICK`^3 voxels; and the signed byte
//! per grid voxel the walks read (`signed_distances`), stored by bricks (`BrickedDistances`).
//!
//! Layout: voxel (x, y, z) of an (nx, ny, nz) grid has linear index `(z * ny + y) * nx + x` (x fastest).

use rayon::prelude::*;
use wide::i32x8;

pub use crate::transport::bricks::BRICK;
use crate::transport::bricks::{Bricks, Part, SHIFT};
use crate::transport::mask::MaskRef;

/// Largest safe distance stored: 16 voxels (1.3 mm at 300 DPI), far beyond a free flight in any ink.
pub const SAFE_CAP: u8 = 16;
// Safe and empty distances share a signed byte (`signed_distances`).
const _: () = assert!(SAFE_CAP <= 127);

/// Safe distances of a mask (non-zero = inside) over an (nx, ny, nz) grid: the number of successive erosions by
/// the 3 x 3 x 3 cube (separable: three 1D passes) a voxel survives, outside the grid counting as outside. A
/// voxel with safe distance s has every voxel within s - 1 steps (any of the 26 directions) inside.
pub fn safe_distances(inside: &[u8], n: [usize; 3]) -> Vec<u8> {
    erosion_depths(inside.par_iter().map(|&m| (m != 0) as u8).collect(), n, 0, SAFE_CAP)
}

/// `empty_distances` at the scale of bricks of `BRICK`^3 voxels (x fastest over ceil(n / BRICK) bricks): each
/// brick's Chebyshev distance in bricks to the nearest brick holding an inside voxel (capped at 255; the grid's
/// exterior is empty). A brick with distance e has every voxel of the bricks within e - 1 brick steps outside.
pub fn brick_empty_distances<'m>(inside: impl Into<MaskRef<'m>>, n: [usize; 3]) -> Vec<u8> {
    let inside = inside.into();
    let nb: [usize; 3] = std::array::from_fn(|a| n[a].div_ceil(BRICK));
    let mut free = vec![1u8; nb[0] * nb[1] * nb[2]];
    let plane = n[0] * n[1];
    for z in 0..n[2] {
        let layer = inside.span(z * plane, (z + 1) * plane); // a plane at a time (a bit mask unpacked)
        for y in 0..n[1] {
            let row = &layer[y * n[0]..][..n[0]];
            let b = ((z / BRICK) * nb[1] + y / BRICK) * nb[0];
            for (x, &m) in row.iter().enumerate() {
                if m != 0 {
                    free[b + x / BRICK] = 0;
                }
            }
        }
    }
    erosion_depths(free, nb, 1, 255)
}

/// Empty distances of a mask (non-zero = inside): `safe_distances` of its complement, with the grid's exterior
/// counting as empty. An outside voxel with empty distance e has every voxel within e - 1 steps outside the
/// object (or beyond the grid); inside voxels have 0.
pub fn empty_distances(inside: &[u8], n: [usize; 3]) -> Vec<u8> {
    erosion_depths(inside.par_iter().map(|&m| (m == 0) as u8).collect(), n, 1, SAFE_CAP)
}

/// For a set (1 = in it, 0 = not), the number of successive erosions by the 3 x 3 x 3 cube each voxel survives
/// (its Chebyshev distance to the nearest voxel not in the set), capped at `cap`; beyond the grid is in the set
/// if `border` is 1.
fn erosion_depths(cur: Vec<u8>, n: [usize; 3], border: u8, cap: u8) -> Vec<u8> {
    let mut depth = cur.clone();
    erode_counting(cur, n, border, cap, &mut depth, |d, c| *d += c);
    depth
}

/// Erodes the set `cur` (1 = in it) by the 3 x 3 x 3 cube up to `cap` - 1 times (beyond the grid is in the set if
/// `border` is 1), calling `count(acc[j], c)` after each erosion with voxel j's membership c (0 or 1); stops once
/// the set is empty.
fn erode_counting<T: Send>(
    mut cur: Vec<u8>,
    n: [usize; 3],
    border: u8,
    cap: u8,
    acc: &mut [T],
    count: impl Fn(&mut T, u8) + Sync,
) {
    let plane = n[0] * n[1];
    let mut tmp = vec![0u8; cur.len()];
    for _ in 1..cap {
        for a in 0..3 {
            erode_axis(&cur, &mut tmp, n, a, border);
            std::mem::swap(&mut cur, &mut tmp);
        }
        let any = acc
            .par_chunks_mut(plane)
            .zip(cur.par_chunks(plane))
            .map(|(s, c)| {
                s.iter_mut().zip(c).for_each(|(s, &c)| count(s, c));
                c.iter().any(|&c| c != 0)
            })
            .reduce(|| false, |x, y| x || y);
        if !any {
            break;
        }
    }
}

/// out = cur eroded along axis a by one voxel (a voxel stays only if both neighbours on that axis are in the set;
/// beyond the grid counts as `border`). Whole rows and planes at a time, so the loops vectorise.
fn erode_axis(cur: &[u8], out: &mut [u8], n: [usize; 3], a: usize, border: u8) {
    let (nx, plane) = (n[0], n[0] * n[1]);
    let and3 = |o: &mut [u8], x: &[u8], y: &[u8], z: &[u8]| {
        o.iter_mut().zip(x).zip(y).zip(z).for_each(|(((o, &x), &y), &z)| *o = x & y & z);
    };
    // The first and last of m cells of `st` bytes each (a row's voxels, a plane's rows): one neighbour beyond
    // the grid; the interior cells are done by `and3`.
    let ends = |o: &mut [u8], c: &[u8], m: usize, st: usize| {
        let cell = |i: usize| &c[i * st..(i + 1) * st];
        if m == 1 {
            o.iter_mut().zip(c).for_each(|(o, &c)| *o = c & border);
            return;
        }
        let (first, last) = (cell(0).iter().zip(cell(1)), cell(m - 1).iter().zip(cell(m - 2)));
        o[..st].iter_mut().zip(first).for_each(|(o, (&c, &b))| *o = c & b & border);
        o[(m - 1) * st..].iter_mut().zip(last).for_each(|(o, (&c, &b))| *o = c & b & border);
    };
    out.par_chunks_mut(plane).enumerate().for_each(|(k, o)| {
        let c = &cur[k * plane..(k + 1) * plane];
        match a {
            0 => {
                for (o, c) in o.chunks_mut(nx).zip(c.chunks(nx)) {
                    ends(o, c, nx, 1);
                    if nx > 2 {
                        and3(&mut o[1..nx - 1], &c[..nx - 2], &c[1..nx - 1], &c[2..]);
                    }
                }
            }
            1 => {
                let ny = n[1];
                ends(o, c, ny, nx);
                if ny > 2 {
                    and3(&mut o[nx..plane - nx], &c[..plane - 2 * nx], &c[nx..plane - nx], &c[2 * nx..]);
                }
            }
            _ => {
                let nz = n[2];
                if nz == 1 {
                    o.iter_mut().zip(c).for_each(|(o, &c)| *o = c & border);
                } else if k == 0 || k + 1 == nz {
                    let m = if k == 0 { 1 } else { k - 1 };
                    let nb = &cur[m * plane..(m + 1) * plane];
                    o.iter_mut().zip(c).zip(nb).for_each(|((o, &c), &b)| *o = c & b & border);
                } else {
                    and3(o, &cur[(k - 1) * plane..k * plane], c, &cur[(k + 1) * plane..(k + 2) * plane]);
                }
            }
        }
    });
}

/// The signed distance byte of every voxel of an (nx, ny, nz) grid from its inside mask (non-zero = inside): an
/// inside voxel holds its safe distance (1 at the surface), an outside voxel minus its empty distance (-1 next to
/// the object), both capped at `SAFE_CAP`; without `empty` (periodic grids, whose flights re-enter on the other
/// side) every outside voxel holds -1. A voxel is inside iff its value is positive. Works in three bytes per voxel:
/// the result and two erosion buffers.
pub fn signed_distances(inside: &[u8], n: [usize; 3], empty: bool) -> Vec<i8> {
    // safe distances turned into the signed byte in place (same size and alignment: no second array)
    let mut dist: Vec<i8> = safe_distances(inside, n).into_iter().map(|s| if s > 0 { s as i8 } else { -1 }).collect();
    if empty {
        // each erosion an outside voxel survives deepens its -1 by one (inside voxels are never in the set):
        // `empty_distances` counted into `dist` directly
        let outside = inside.par_iter().map(|&m| (m == 0) as u8).collect();
        erode_counting(outside, n, 1, SAFE_CAP, &mut dist, |d, c| *d -= c as i8);
    }
    dist
}

/// Pool bricks of one value each, for the values -`SAFE_CAP` ..= `SAFE_CAP` (value v at brick v + `SAFE_CAP`).
const SHARED: usize = 2 * SAFE_CAP as usize + 1;
/// z-planes of the grid built at a time (a multiple of `BRICK`).
pub const SLAB_PLANES: usize = 16 * BRICK;
/// Planes of the mask read beyond a slab on either side: a voxel's capped value depends only on the voxels
/// within `SAFE_CAP` steps of it (nearer than that to the cut, the cut bounds a safe distance by more than the
/// cap and hides only inside voxels farther than the cap from the slab).
const HALO: usize = SAFE_CAP as usize;

/// `signed_distances` of a grid stored by bricks of `BRICK`^3 voxels. Far from the surface (more than `SAFE_CAP`
/// voxels) every value is +-`SAFE_CAP`, so a big object's bricks are mostly of one value.
///
/// Layout: `bricks::Bricks`, whose first `SHARED` bricks hold one value each, -`SAFE_CAP` ..= `SAFE_CAP` (brick
/// v + `SAFE_CAP` is all v); `get8` reads eight SIMD lanes' voxels.
pub struct BrickedDistances {
    store: Bricks<i8>,
}

impl BrickedDistances {
    /// The signed distances of the inside mask (non-zero = inside; x fastest, a byte or a bit per voxel, read a
    /// slab at a time and not kept) of an (nx, ny, nz) grid (`signed_distances` with `empty`), found `SLAB_PLANES` z-planes at a time
    /// with `HALO` planes either side: besides the bricks it works in three bytes per voxel of a slab and its halo.
    pub fn new<'m>(inside: impl Into<MaskRef<'m>>, n: [usize; 3], empty: bool) -> Self {
        Self::in_slabs(inside, n, empty, SLAB_PLANES)
    }

    /// `new`, `slab` z-planes at a time (a positive multiple of `BRICK`).
    pub fn in_slabs<'m>(inside: impl Into<MaskRef<'m>>, n: [usize; 3], empty: bool, slab: usize) -> Self {
        let inside = inside.into();
        assert!(slab > 0 && slab.is_multiple_of(BRICK) && inside.len() == n.iter().product::<usize>());
        let nb: [usize; 3] = std::array::from_fn(|a| n[a].div_ceil(BRICK));
        let (plane, layer) = (n[0] * n[1], nb[0] * nb[1]);
        let mut store = Bricks::new(n, SHARED, |i| i as i8 - SAFE_CAP as i8);
        for z0 in (0..n[2]).step_by(slab) {
            let z1 = (z0 + slab).min(n[2]);
            let (h0, h1) = (z0.saturating_sub(HALO), (z1 + HALO).min(n[2]));
            let dist = signed_distances(&inside.span(h0 * plane, h1 * plane), [n[0], n[1], h1 - h0], empty);
            let part = Part { values: &dist, n, z0: h0, nb };
            let bricks = z0 / BRICK * layer..z1.div_ceil(BRICK) * layer;
            let shared_of = |v: i8| (v as i32 + SAFE_CAP as i32) as usize;
            store.store(&part, bricks, shared_of).expect("the pool's offsets fit 32 bits");
        }
        store.pool.shrink_to_fit();
        BrickedDistances { store }
    }

    /// The value of in-grid voxel v (x, y, z): its brick's table entry (the pool offset of the brick it reads), then
    /// the byte at its place within the brick.
    #[inline(always)]
    pub fn get(&self, v: [i32; 3]) -> i8 {
        self.store.get(v)
    }

    /// `get` of eight in-grid voxels (x, y, z lanes), their bricks and places found in SIMD lanes.
    #[inline(always)]
    pub fn get8(&self, v: [i32x8; 3]) -> [i8; 8] {
        let m = i32x8::splat(BRICK as i32 - 1);
        let (table, pool) = (&self.store.table, &self.store.pool);
        let (nbx, nby) = (i32x8::splat(self.store.nb[0] as i32), i32x8::splat(self.store.nb[1] as i32));
        let b = (((v[2] >> SHIFT) * nby + (v[1] >> SHIFT)) * nbx + (v[0] >> SHIFT)).to_array();
        let within = ((((v[2] & m) << SHIFT) | (v[1] & m)) << SHIFT | (v[0] & m)).to_array();
        std::array::from_fn(|l| {
            let offset = table[b[l] as usize] as usize;
            // SAFETY: as in `Bricks::get` (`within` < BRICK^3: the low bits of each coordinate).
            unsafe { *pool.get_unchecked(offset + within[l] as usize) }
        })
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
