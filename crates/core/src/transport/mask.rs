//! An inside mask as its builds read it: one byte per voxel (non-zero: inside), one bit per voxel (numpy's
//! `packbits` of the (z, y, x) C-order flattening: voxel j is bit 7 - j % 8 of byte j / 8, as Python's
//! `model.mask.PackedMask` holds it), or the voxels of a label grid other than `EMPTY` (`LabelBricks`: a printed
//! volume's own labels). The builds (the band medium's runs, the safe and empty distances) read it a grid row or
//! a slab of z-planes at a time as bytes (`span`): a byte mask lends them its own bytes, a bit or label mask makes
//! just that span, so neither is ever expanded to a byte per grid voxel.

use std::borrow::Cow;

use crate::transport::label_bricks::{LabelBricks, EMPTY};

/// An inside mask of `len()` voxels in (z, y, x) order, as bytes, as bits or as a label grid's non-empty voxels.
#[derive(Clone, Copy, Debug)]
pub enum MaskRef<'a> {
    /// One byte per voxel (non-zero: inside).
    Bytes(&'a [u8]),
    /// One bit per voxel, most significant bit first, and the number of voxels (`bits.len() == voxels.div_ceil(8)`).
    Bits(&'a [u8], usize),
    /// The voxels whose label is not `EMPTY`.
    Labels(&'a LabelBricks),
}

impl<'a> MaskRef<'a> {
    /// A bit mask of `voxels` voxels; an error unless `bits` has `voxels.div_ceil(8)` bytes.
    pub fn bits(bits: &'a [u8], voxels: usize) -> Result<Self, String> {
        if bits.len() != voxels.div_ceil(8) {
            return Err(format!("a bit mask of {voxels} voxels has {} bytes, not {}", voxels.div_ceil(8), bits.len()));
        }
        Ok(MaskRef::Bits(bits, voxels))
    }

    /// Voxels in the mask's grid.
    pub fn len(&self) -> usize {
        match self {
            MaskRef::Bytes(b) => b.len(),
            MaskRef::Bits(_, n) => *n,
            MaskRef::Labels(l) => l.len(),
        }
    }

    pub fn is_empty(&self) -> bool {
        self.len() == 0
    }

    /// Whether voxel j (j < `len()`) is inside.
    #[inline]
    pub fn get(&self, j: usize) -> bool {
        match self {
            MaskRef::Bytes(b) => b[j] != 0,
            MaskRef::Bits(b, _) => (b[j >> 3] >> (7 - (j & 7))) & 1 != 0,
            MaskRef::Labels(l) => l.get_index(j) != EMPTY,
        }
    }

    /// Voxels a..b (a <= b <= `len()`) as bytes 0 / 1 (a byte mask's own bytes, which may be any non-zero value
    /// inside; a bit or label mask's span made: b - a bytes, a new vector).
    pub fn span(&self, a: usize, b: usize) -> Cow<'a, [u8]> {
        assert!(a <= b && b <= self.len(), "mask span {a}..{b} outside its {} voxels", self.len());
        match *self {
            MaskRef::Bytes(bytes) => Cow::Borrowed(&bytes[a..b]),
            MaskRef::Bits(bits, _) => {
                let mut out = Vec::with_capacity(b - a);
                let mut j = a;
                while j < b && !j.is_multiple_of(8) {
                    out.push((bits[j >> 3] >> (7 - (j & 7))) & 1);
                    j += 1;
                }
                for &byte in &bits[j / 8..b / 8] {
                    out.extend_from_slice(&EXPAND[byte as usize]);
                }
                j = j.max(b / 8 * 8);
                while j < b {
                    out.push((bits[j >> 3] >> (7 - (j & 7))) & 1);
                    j += 1;
                }
                Cow::Owned(out)
            }
            MaskRef::Labels(l) => Cow::Owned(l.inside_span(a, b)),
        }
    }
}

impl<'a> From<&'a [u8]> for MaskRef<'a> {
    fn from(bytes: &'a [u8]) -> Self {
        MaskRef::Bytes(bytes)
    }
}

/// Each byte's eight bits as bytes 0 / 1, most significant first.
const EXPAND: [[u8; 8]; 256] = {
    let mut t = [[0u8; 8]; 256];
    let mut v = 0;
    while v < 256 {
        let mut k = 0;
        while k < 8 {
            t[v][k] = ((v >> (7 - k)) & 1) as u8;
            k += 1;
        }
        v += 1;
    }
    t
};

impl<'a> From<&'a Vec<u8>> for MaskRef<'a> {
    fn from(bytes: &'a Vec<u8>) -> Self {
        MaskRef::Bytes(bytes)
    }
}
