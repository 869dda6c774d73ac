//! The light arriving at the object from outside, behind one trait: `UniformLight` (the same radiance from every
//! direction, the default) and `EnvMap` (an equirectangular environment map). Every tracer (scalar, packets,
//! gradient replay) calls `Light::radiance` once per path that leaves the object, with the world-frame direction
//! it leaves in; a new kind of light (e.g. a finite-size area light) is one more type implementing the trait,
//! given to `Geometry::with_light`, and the tracers need no change.

use crate::transport::sampling::V3;
use std::f32::consts::{PI, TAU};

/// The light outside the object. Every path that leaves the grid calls `radiance` once with the direction it
/// leaves in; its value is the path's weight times that radiance.
pub trait Light: Send + Sync {
    /// Radiance (linear, channel `channel` of RGB) arriving along -`dir`, i.e. seen looking out along the unit
    /// direction `dir` (x, y, z).
    fn radiance(&self, dir: V3, channel: usize) -> f32;
}

/// The same radiance from every direction, per RGB channel (the default: 1, a white furnace).
#[derive(Clone, Copy, Debug)]
pub struct UniformLight(pub [f32; 3]);

impl Light for UniformLight {
    #[inline(always)]
    fn radiance(&self, _dir: V3, channel: usize) -> f32 {
        self.0[channel]
    }
}

/// An equirectangular (latitude-longitude) environment map of linear radiance, H rows by W = 2H columns.
///
/// World frame (z up): pixel (i, j) covers colatitude [i, i + 1] * pi / H measured from +z (row 0 looks
/// straight up, the middle of the map is the horizon, the last row looks straight down) and longitude
/// [j, j + 1] * 2 pi / W measured from +x towards +y (column 0 starts at +x). A direction's radiance is the
/// bilinear interpolation between the four nearest pixel centres, per channel; longitude wraps around, and
/// colatitude is clamped to the first and last row's centres near the poles. `rotate_deg` turns the map about z
/// (from +x towards +y): a feature at longitude phi of the stored map is seen at phi + rotate.
#[derive(Clone, Debug)]
pub struct EnvMap {
    h: usize,
    w: usize,
    /// Planar by channel: all pixels of R in C order of (row, column), then G, then B.
    planes: Vec<f32>,
    /// The rotation in radians.
    rotate: f32,
}

impl EnvMap {
    /// A map from `rgb`, the memory of an (h, w, 3) C-order array; `w` must be 2 `h` and every radiance finite
    /// and non-negative.
    pub fn new(h: usize, w: usize, rgb: &[f32], rotate_deg: f32) -> Result<Self, String> {
        if h == 0 || w != 2 * h {
            return Err(format!("an equirectangular map has twice as many columns as rows; got {h} x {w}"));
        }
        if rgb.len() != 3 * h * w {
            return Err(format!("map data has {} values, expected {h} x {w} x 3", rgb.len()));
        }
        if let Some(k) = rgb.iter().position(|x| !(x.is_finite() && *x >= 0.0)) {
            let (p, c) = (k / 3, k % 3);
            return Err(format!(
                "map radiance at row {} column {} channel {c} is {} (must be finite and >= 0)",
                p / w,
                p % w,
                rgb[k]
            ));
        }
        if !rotate_deg.is_finite() {
            return Err(format!("map rotation {rotate_deg} must be finite"));
        }
        let n = h * w;
        let mut planes = vec![0.0f32; 3 * n];
        for p in 0..n {
            for c in 0..3 {
                planes[c * n + p] = rgb[3 * p + c];
            }
        }
        Ok(EnvMap { h, w, planes, rotate: rotate_deg.to_radians() })
    }

    /// (rows, columns).
    pub fn size(&self) -> (usize, usize) {
        (self.h, self.w)
    }
}

impl Light for EnvMap {
    #[inline]
    fn radiance(&self, d: V3, channel: usize) -> f32 {
        let (h, w) = (self.h, self.w);
        // Continuous pixel coordinates whose integer points are pixel centres.
        let v = d[2].clamp(-1.0, 1.0).acos() * (h as f32 / PI) - 0.5;
        let u = ((d[1].atan2(d[0]) - self.rotate) * (w as f32 / TAU) - 0.5).rem_euclid(w as f32);
        let (v0, u0) = (v.floor(), u.floor());
        let (fv, fu) = (v - v0, u - u0);
        let row = |k: f32| (k.max(0.0) as usize).min(h - 1) * w;
        let (r0, r1) = (row(v0), row(v0 + 1.0));
        let c0 = (u0 as usize) % w;
        let c1 = (c0 + 1) % w;
        let px = &self.planes[channel * h * w..(channel + 1) * h * w];
        let top = px[r0 + c0] + fu * (px[r0 + c1] - px[r0 + c0]);
        let bottom = px[r1 + c0] + fu * (px[r1 + c1] - px[r1 + c0]);
        top + fv * (bottom - top)
    }
}
