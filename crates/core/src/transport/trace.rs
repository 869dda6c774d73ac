//! The scalar reference walk: one monochromatic path from a texel's camera ray through the voxel medium.
//!
//! `trace` = `camera_ray` (a point on the texel's face, the first interface) + `walk`, the one scalar walk:
//! inside the object it asks a free-flight sampler (`flight::Tracker`: delta tracking in mask-free grids,
//! regular tracking elsewhere) where the flight ends; at a collision the path scatters (Henyey-Greenstein) and
//! its weight is multiplied by the albedo (implicit absorption; a weight below `path::RR_THRESHOLD` plays Russian
//! roulette: it survives with probability weight / threshold, then carries the threshold; compared with analog
//! absorption the variance is never larger and, for dark inks, much smaller); at the object's surface the path
//! is reflected with the Fresnel probability and refracted otherwise (shading normals where the scene has
//! them); outside it flies straight, voxel by voxel next to the object and across empty balls away from it
//! (`grid::empty_jump`), until it re-enters a concave part or leaves the grid, where it picks up the light's
//! radiance (`scene::Light`) times its weight. `packet` runs the same estimator eight paths at a time and uses
//! `walk` per lane near surfaces.
//!
//! Path-space derivatives (for path replay backpropagation): the density of the collision points is
//! prod sigma_t(x_i) exp(-sum sigma_t l) and the weight prod sigma_s(x_i) / sigma_t(x_i); together, as a
//! function of voxel j, sigma_s,j^(k_j) exp(-sigma_t,j l_j), with k_j collisions in j and l_j the length of path
//! inside j: d/d sigma_s,j = k_j / sigma_s,j - l_j and d/d sigma_a,j = -l_j, times the path's value (the
//! roulette's survival probabilities are sampling decisions, not differentiated: unbiased). A `Tally` receives
//! every segment (voxel, length) and collision; replaying a path (same key, same random numbers) with a tally
//! gives its gradient.

use crate::transport::flight::{survive, Delta, Event, Regular, Tracker};
use crate::transport::grid::{cross, empty_jump, facing_normal, voxel_exit};
use crate::transport::path::{PathValue, Tally, Walk, MAX_EVENTS, MAX_STEPS};
use crate::transport::rng::{PathRng, Uniforms};
use crate::transport::sampling::{dot, fresnel, hg_sample, reflect, refract, scale, V3};
use crate::transport::scene::{face_normal, Geometry, Medium, Texel};

/// Direction after an interface event. `n_geo`: geometric unit normal on the incident side
/// (dot(d, n_geo) < 0); `n_sh`: shading normal on the incident side; eta = n_incident / n_transmitted.
/// Reflects with the Fresnel probability, else refracts. Shading normals that would send the path to the wrong
/// side of the geometric face fall back to the geometric normal (exact on planar faces, where they agree).
#[inline(always)]
pub(crate) fn interface(d: V3, n_geo: V3, n_sh: V3, eta: f32, u: f32) -> (V3, bool) {
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

/// Where a camera ray is after its first interface.
pub(crate) enum Start {
    /// Refracted into the medium at p (voxel v), direction d, with this weight.
    Medium(V3, V3, [i32; 3], f32),
    /// Reflected (specular included): outside at p, in voxel v (the face's outer neighbour), direction d.
    Outside(V3, V3, [i32; 3]),
    /// The path ends here (the camera ray cannot refract and the specular is excluded).
    Done(PathValue),
}

/// The camera ray of `texel`: a uniform point on its face (two uniforms), looking along -normal, through the
/// first interface (one uniform when `include_specular`: the Fresnel reflection is sampled and counts; else the
/// ray refracts with weight 1 - F).
#[inline(always)]
pub(crate) fn camera_ray<U: Uniforms>(geo: &Geometry, texel: &Texel, include_specular: bool, rng: &mut U) -> Start {
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
    let d = scale(texel.normal, -1.0);
    let eta_in = 1.0 / geo.ior;
    if include_specular {
        let (nd, transmitted) = interface(d, n_face, texel.normal, eta_in, rng.next_f32());
        if transmitted {
            return Start::Medium(p, nd, v, 1.0);
        }
        v[fa] += if texel.face % 2 == 1 { 1 } else { -1 };
        return Start::Outside(p, nd, v);
    }
    let n = pick_normal(d, n_face, texel.normal);
    let weight = 1.0 - fresnel(-dot(d, n), eta_in);
    match refract(d, n, eta_in) {
        Some(t) if dot(t, n_face) < 0.0 => Start::Medium(p, t, v, weight),
        _ => Start::Done(PathValue { value: 0.0, events: 0 }),
    }
}

/// Trace one path of channel `c` for `texel`. `include_specular`: the camera ray's Fresnel reflection of the
/// light counts (else the first interface refracts with weight 1 - F).
pub fn trace<M: Medium, T: Tally>(
    geo: &Geometry,
    med: &M,
    texel: &Texel,
    c: usize,
    rng: &mut PathRng,
    include_specular: bool,
    tally: &mut T,
) -> PathValue {
    let mut w = match camera_ray(geo, texel, include_specular, rng) {
        Start::Medium(p, d, v, weight) => Walk { p, d, v, weight, in_medium: true, events: 0, steps: 0 },
        Start::Outside(p, d, v) => Walk { p, d, v, weight: 1.0, in_medium: false, events: 0, steps: 0 },
        Start::Done(r) => return r,
    };
    let end = if w.in_medium && !geo.masked() {
        walk(geo, med, c, &mut w, &mut Delta::new(med.majorant(c)), rng, tally, false)
    } else {
        walk(geo, med, c, &mut w, &mut Regular::new(), rng, tally, false)
    };
    match end {
        WalkEnd::Done(r) => r,
        WalkEnd::Deep => unreachable!("walk stops at deep voxels only when asked"),
    }
}

pub(crate) enum WalkEnd {
    /// The path ended with this value.
    Done(PathValue),
    /// It scattered (state updated) in a voxel at least 2 voxels from the object's surface, where delta
    /// tracking inside a safe ball can take over (only when `stop_deep`).
    Deep,
}

/// The walk of one path from state `w`: free flights inside the object from `tracker`, straight flights
/// outside it. With `stop_deep` it returns `Deep` after a collision in a voxel whose safe distance is at
/// least 2 (the packets' delta tracking takes over there).
#[inline(always)]
pub(crate) fn walk<K: Tracker, M: Medium, T: Tally, U: Uniforms>(
    geo: &Geometry,
    med: &M,
    c: usize,
    w: &mut Walk,
    tracker: &mut K,
    rng: &mut U,
    tally: &mut T,
    stop_deep: bool,
) -> WalkEnd {
    let mut s = *w;
    let cut = |s: &Walk| WalkEnd::Done(PathValue { value: 0.0, events: s.events });
    loop {
        if s.in_medium {
            tracker.start(geo, &s, rng);
            loop {
                match tracker.next(geo, med, c, &mut s, rng, tally) {
                    Event::Cut => return cut(&s),
                    Event::Collision(j, albedo) => {
                        s.events += 1;
                        if !survive(&mut s.weight, albedo, rng) || s.events > MAX_EVENTS {
                            return cut(&s);
                        }
                        tally.scatter(j);
                        let (u1, u2) = rng.next_f32_pair();
                        s.d = hg_sample(s.d, geo.g, u1, u2);
                        if stop_deep && geo.safe_distance(s.v) >= 2 {
                            *w = s;
                            return WalkEnd::Deep;
                        }
                        tracker.start(geo, &s, rng);
                    }
                    Event::Surface { axis, step, nb, n_sh } => {
                        let (nd, transmitted) =
                            interface(s.d, facing_normal(axis, step), n_sh, geo.ior, rng.next_f32());
                        s.d = nd;
                        if transmitted {
                            s.v = nb;
                            s.in_medium = false;
                            break;
                        }
                        tracker.redirect(geo, &s);
                    }
                }
            }
        } else {
            match outside(geo, &mut s, rng) {
                Outside::Entered => {}
                Outside::Escaped => {
                    return WalkEnd::Done(PathValue { value: s.weight * geo.light.radiance(s.d, c), events: s.events })
                }
                Outside::Cut => return cut(&s),
            }
        }
    }
}

/// How a flight outside the object ended.
pub(crate) enum Outside {
    /// It entered the object (the walk is in the medium).
    Entered,
    /// It left the grid: the light is reached.
    Escaped,
    /// It took more than `MAX_STEPS` steps.
    Cut,
}

/// The straight flight outside the object (`walk`'s and the hero walk's): voxel by voxel next to it, across empty
/// balls away from it, until it refracts into the object or leaves the grid.
#[inline(always)]
pub(crate) fn outside<U: Uniforms>(geo: &Geometry, s: &mut Walk, rng: &mut U) -> Outside {
    let eta_in = 1.0 / geo.ior;
    loop {
        s.steps += 1;
        if !geo.in_grid(s.v) {
            return Outside::Escaped;
        }
        if s.steps > MAX_STEPS {
            return Outside::Cut;
        }
        if let Some((p, v)) = empty_jump(geo, s.p, s.d, s.v) {
            (s.p, s.v) = (p, v);
            continue;
        }
        let (t, axis) = voxel_exit(geo, s.p, s.d, s.v);
        let (nb, step) = cross(geo, &mut s.p, s.d, t, axis, s.v);
        if geo.is_inside(nb) {
            let n_geo = facing_normal(axis, step);
            let n_sh = geo.shading_normal(nb).unwrap_or(n_geo);
            let (nd, transmitted) = interface(s.d, n_geo, n_sh, eta_in, rng.next_f32());
            s.d = nd;
            if transmitted {
                s.v = nb;
                s.in_medium = true;
                return Outside::Entered;
            }
        } else {
            s.v = nb;
        }
    }
}
