//! One monochromatic random walk from a texel's camera ray through the voxel medium.
//!
//! Estimator: analog. Free-flight distances are sampled exactly in the piecewise-constant medium by regular
//! tracking (voxel by voxel, subtracting each voxel's optical depth from an exponential sample); at a collision
//! the path scatters with probability albedo (Henyey-Greenstein) and is absorbed otherwise; at the object's
//! boundary it is reflected with the Fresnel probability and refracted otherwise. A path that leaves the grid
//! picks up the environment radiance. The throughput is always 1 (or 1 - F with specular excluded), so the
//! value of a path is the environment radiance at its exit or 0. No Russian roulette is needed.
//!
//! Path-space derivatives (for path replay backpropagation): the path's probability density, as a function of
//! the coefficients of voxel j, is  sigma_s,j^(k_j) * exp(-sigma_t,j * l_j)  with k_j scattering events in j and
//! l_j the length of path inside j. A `Tally` receives every segment (voxel, length) and scattering event.

use crate::rng::PathRng;
use crate::sampling::{add, dot, fresnel, hg_sample, reflect, refract, scale, V3};
use crate::scene::{face_normal, Boundary, Geometry, Medium, Texel};

/// Receives the events of a path (for gradients). The forward pass uses `NoTally`.
pub trait Tally {
    fn segment(&mut self, idx: usize, len: f32);
    fn scatter(&mut self, idx: usize);
}

pub struct NoTally;

impl Tally for NoTally {
    #[inline(always)]
    fn segment(&mut self, _: usize, _: f32) {}
    #[inline(always)]
    fn scatter(&mut self, _: usize) {}
}

/// Paths that are still going after this many collisions are cut (value 0). At albedo 0.9997 the chance to
/// survive 2e6 collisions is exp(-600): the cut never biases a physical medium.
const MAX_EVENTS: u32 = 2_000_000;
const MAX_STEPS: u64 = 50_000_000;

/// Result of one path: its value (radiance reaching the texel) and its number of collisions.
#[derive(Clone, Copy, Debug)]
pub struct PathValue {
    pub value: f32,
    pub events: u32,
}

/// Direction after an interface event. `n_geo`: geometric unit normal on the incident side
/// (dot(d, n_geo) < 0); `n_sh`: shading normal on the incident side; eta = n_incident / n_transmitted.
/// Reflects with the Fresnel probability, else refracts. Shading normals that would send the path to the wrong
/// side of the geometric face fall back to the geometric normal (exact on planar faces, where they agree).
#[inline(always)]
fn interface(d: V3, n_geo: V3, n_sh: V3, eta: f32, u: f32) -> (V3, bool) {
    let n = pick_normal(d, n_geo, n_sh);
    let f = fresnel(-dot(d, n), eta);
    if u < f {
        let r = reflect(d, n);
        return (if dot(r, n_geo) > 0.0 { r } else { reflect(d, n_geo) }, false);
    }
    match refract(d, n, eta) {
        Some(t) if dot(t, n_geo) < 0.0 => (t, true),
        _ => match refract(d, n_geo, eta) {
            Some(t) => (t, true),
            None => (reflect(d, n_geo), false),
        },
    }
}

#[inline(always)]
fn pick_normal(d: V3, n_geo: V3, n_sh: V3) -> V3 {
    if dot(n_sh, n_geo) > 0.0 && dot(d, n_sh) < 0.0 {
        n_sh
    } else {
        n_geo
    }
}

#[inline(always)]
fn free_flight(rng: &mut PathRng) -> f32 {
    -(1.0 - rng.next_f32()).ln()
}

#[inline(always)]
fn inv(d: V3) -> V3 {
    [1.0 / d[0], 1.0 / d[1], 1.0 / d[2]]
}

/// Distance along d from p to the boundary of voxel v, and the axis crossed there.
#[inline(always)]
fn exit_distance(geo: &Geometry, p: V3, d: V3, inv_d: V3, v: [i32; 3]) -> (f32, usize) {
    let mut t = f32::INFINITY;
    let mut axis = 0;
    for a in 0..3 {
        if d[a] != 0.0 {
            let b = if d[a] > 0.0 { (v[a] + 1) as f32 } else { v[a] as f32 } * geo.size[a];
            let ta = ((b - p[a]) * inv_d[a]).max(0.0);
            if ta < t {
                t = ta;
                axis = a;
            }
        }
    }
    (t, axis)
}

/// Move p by t along d onto the face of voxel v on `axis`, return the neighbour across it (wrapped if periodic).
#[inline(always)]
fn cross(geo: &Geometry, p: &mut V3, d: V3, t: f32, axis: usize, v: [i32; 3]) -> ([i32; 3], i32) {
    *p = add(*p, scale(d, t));
    let step = if d[axis] > 0.0 { 1 } else { -1 };
    p[axis] = (if step > 0 { v[axis] + 1 } else { v[axis] }) as f32 * geo.size[axis];
    let mut nb = v;
    nb[axis] += step;
    if geo.boundary == Boundary::PeriodicXY && axis < 2 {
        let n = geo.n[axis];
        let span = n as f32 * geo.size[axis];
        if nb[axis] >= n {
            nb[axis] = 0;
            p[axis] -= span;
        } else if nb[axis] < 0 {
            nb[axis] = n - 1;
            p[axis] += span;
        }
    }
    (nb, step)
}

/// Trace one path of channel `c` for `texel`. `include_specular`: the camera ray's Fresnel reflection of the
/// environment counts (else the first interface refracts with weight 1 - F).
pub fn trace<M: Medium, T: Tally>(
    geo: &Geometry,
    med: &M,
    texel: &Texel,
    c: usize,
    rng: &mut PathRng,
    include_specular: bool,
    tally: &mut T,
) -> PathValue {
    let mut v = texel.voxel;
    let fa = (texel.face / 2) as usize;
    let mut p = [0.0f32; 3];
    for a in 0..3 {
        p[a] = if a == fa {
            (v[a] + (texel.face % 2) as i32) as f32 * geo.size[a]
        } else {
            (v[a] as f32 + rng.next_f32()) * geo.size[a]
        };
    }
    let n_face = face_normal(texel.face);
    let mut d = scale(texel.normal, -1.0);
    let mut weight = 1.0f32;
    let eta_in = 1.0 / geo.ior;
    let mut in_medium;
    if include_specular {
        let (nd, transmitted) = interface(d, n_face, texel.normal, eta_in, rng.next_f32());
        d = nd;
        in_medium = transmitted;
        if !transmitted {
            v[fa] += if texel.face % 2 == 1 { 1 } else { -1 };
        }
    } else {
        let n = pick_normal(d, n_face, texel.normal);
        weight = 1.0 - fresnel(-dot(d, n), eta_in);
        match refract(d, n, eta_in) {
            Some(t) if dot(t, n_face) < 0.0 => d = t,
            _ => return PathValue { value: 0.0, events: 0 },
        }
        in_medium = true;
    }
    let mut inv_d = inv(d);
    let mut events = 0u32;
    let mut steps = 0u64;
    loop {
        if in_medium {
            let mut tau = free_flight(rng);
            loop {
                steps += 1;
                if steps > MAX_STEPS {
                    return PathValue { value: 0.0, events };
                }
                let j = geo.index(v);
                let (st, albedo) = med.coeffs(j, c);
                let (t, axis) = exit_distance(geo, p, d, inv_d, v);
                if st * t > tau {
                    let s = tau / st;
                    p = add(p, scale(d, s));
                    tally.segment(j, s);
                    events += 1;
                    if rng.next_f32() >= albedo || events > MAX_EVENTS {
                        return PathValue { value: 0.0, events };
                    }
                    tally.scatter(j);
                    d = hg_sample(d, geo.g, rng.next_f32(), rng.next_f32());
                    inv_d = inv(d);
                    tau = free_flight(rng);
                    continue;
                }
                tau -= st * t;
                tally.segment(j, t);
                let (nb, step) = cross(geo, &mut p, d, t, axis, v);
                if geo.is_inside(nb) {
                    v = nb;
                    continue;
                }
                // Leaving the object: the incident side is inside.
                let mut n_geo = [0.0f32; 3];
                n_geo[axis] = -step as f32;
                let n_sh = geo.shading_normal(v).map(|n| scale(n, -1.0)).unwrap_or(n_geo);
                let (nd, transmitted) = interface(d, n_geo, n_sh, geo.ior, rng.next_f32());
                d = nd;
                inv_d = inv(d);
                if transmitted {
                    v = nb;
                    in_medium = false;
                    break;
                }
            }
        } else {
            loop {
                steps += 1;
                if !geo.in_grid(v) {
                    return PathValue { value: weight * geo.env.eval(d, c), events };
                }
                if steps > MAX_STEPS {
                    return PathValue { value: 0.0, events };
                }
                let (t, axis) = exit_distance(geo, p, d, inv_d, v);
                let (nb, step) = cross(geo, &mut p, d, t, axis, v);
                if geo.is_inside(nb) {
                    // Entering voxel nb: the incident side is outside, nb's face normal points back at v.
                    let mut n_geo = [0.0f32; 3];
                    n_geo[axis] = -step as f32;
                    let n_sh = geo.shading_normal(nb).unwrap_or(n_geo);
                    let (nd, transmitted) = interface(d, n_geo, n_sh, eta_in, rng.next_f32());
                    d = nd;
                    inv_d = inv(d);
                    if transmitted {
                        v = nb;
                        in_medium = true;
                        break;
                    }
                } else {
                    v = nb;
                }
            }
        }
    }
}
