//! Lights: the environment map's orientation, interpolation, rotation and checks; a constant map renders exactly
//! as the uniform light; the packets and the scalar tracer agree under a directional map.

use super::*;
use crate::transport::sampling::V3;
use std::f32::consts::PI;

/// A map of h x 2h pixels whose channel c at (row i, column j) is f(i, j, c).
fn map_of(h: usize, rotate_deg: f32, f: impl Fn(usize, usize, usize) -> f32) -> EnvMap {
    let w = 2 * h;
    let rgb: Vec<f32> = (0..h * w * 3).map(|k| f(k / 3 / w, k / 3 % w, k % 3)).collect();
    EnvMap::new(h, w, &rgb, rotate_deg).unwrap()
}

/// The unit direction at colatitude theta (from +z) and longitude phi (from +x towards +y).
fn dir(theta: f32, phi: f32) -> V3 {
    [theta.sin() * phi.cos(), theta.sin() * phi.sin(), theta.cos()]
}

fn close(a: f32, b: f32, what: &str) {
    assert!((a - b).abs() < 1e-4, "{what}: {a} vs {b}");
}

#[test]
fn rows_run_from_straight_up_to_straight_down() {
    // Radiance = row index: +z sees row 0, -z the last row, the horizon halfway between the two middle rows.
    let h = 4;
    let m = map_of(h, 0.0, |i, _, _| i as f32);
    close(m.radiance([0.0, 0.0, 1.0], 0), 0.0, "up");
    close(m.radiance([0.0, 0.0, -1.0], 1), 3.0, "down");
    for phi in [0.0, 1.0, 2.5, -2.0] {
        close(m.radiance(dir(PI / 2.0, phi), 2), 1.5, "horizon");
        // The centre of row 1 (colatitude 1.5 pi / h) sees row 1 alone.
        close(m.radiance(dir(1.5 * PI / h as f32, phi), 0), 1.0, "row 1 centre");
    }
}

#[test]
fn column_zero_starts_at_plus_x_and_longitude_grows_towards_plus_y() {
    // Only column 0 is lit. Its centre (longitude pi / w, just on the +y side of +x) sees 1; the mirror
    // direction on the -y side is the centre of the last column and sees 0; +x itself lies on the edge between
    // them (1/2).
    let (h, w) = (8usize, 16usize);
    let m = map_of(h, 0.0, |_, j, _| (j == 0) as u8 as f32);
    let half = PI / w as f32;
    for theta in [0.6, PI / 2.0, 2.2] {
        close(m.radiance(dir(theta, half), 0), 1.0, "column 0 centre");
        close(m.radiance(dir(theta, -half), 0), 0.0, "last column centre");
        close(m.radiance(dir(theta, 0.0), 0), 0.5, "+x");
        close(m.radiance(dir(theta, PI + half), 0), 0.0, "-x");
    }
    // Radiance = column index: linear between neighbouring centres (bilinear), towards +y.
    let m = map_of(h, 0.0, |_, j, _| j as f32);
    for (j, f) in [(3usize, 0.25f32), (7, 0.5), (12, 0.9)] {
        close(m.radiance(dir(PI / 2.0, (j as f32 + 0.5 + f) * 2.0 * half), 1), j as f32 + f, "column interpolation");
    }
    // Across the seam: halfway between the last column's centre and column 0's, towards +y.
    let m = map_of(h, 0.0, |_, j, _| {
        if j == w - 1 {
            4.0
        } else if j == 0 {
            2.0
        } else {
            0.0
        }
    });
    close(m.radiance(dir(PI / 2.0, -0.5 * half), 0), 3.5, "seam");
}

#[test]
fn channels_are_looked_up_separately() {
    let m = map_of(4, 0.0, |i, j, c| (100 * c + 10 * i + j) as f32);
    let d = dir(2.5 * PI / 4.0, 5.5 * 2.0 * PI / 8.0);
    for c in 0..3 {
        close(m.radiance(d, c), (100 * c + 20 + 5) as f32, "pixel (2, 5)");
    }
}

#[test]
fn rotation_turns_the_map_about_z_from_x_towards_y() {
    // Column 0's light, turned by 90 degrees, is seen at longitude 90 degrees + pi / w.
    let (h, w) = (8usize, 16usize);
    let m = map_of(h, 90.0, |_, j, _| (j == 0) as u8 as f32);
    let half = PI / w as f32;
    close(m.radiance(dir(1.0, PI / 2.0 + half), 0), 1.0, "rotated");
    close(m.radiance(dir(1.0, half), 0), 0.0, "where it was");
    let m = map_of(h, -450.0, |_, j, _| (j == 0) as u8 as f32);
    close(m.radiance(dir(1.0, -PI / 2.0 + half), 0), 1.0, "rotated by -450 degrees");
}

#[test]
fn bad_maps_are_refused() {
    let ok = vec![1.0f32; 4 * 8 * 3];
    assert!(EnvMap::new(4, 8, &ok, 0.0).is_ok());
    assert!(EnvMap::new(4, 6, &ok[..72], 0.0).unwrap_err().contains("twice as many columns"));
    assert!(EnvMap::new(4, 8, &ok[..90], 0.0).is_err());
    for bad in [-0.5f32, f32::NAN, f32::INFINITY] {
        let mut v = ok.clone();
        v[3 * 9 + 2] = bad;
        let e = EnvMap::new(4, 8, &v, 0.0).unwrap_err();
        assert!(e.contains("row 1 column 1 channel 2"), "{e}");
    }
    assert!(EnvMap::new(4, 8, &ok, f32::NAN).is_err());
}

#[test]
fn a_constant_map_renders_exactly_as_the_uniform_light() {
    // Bilinear interpolation of a constant is that constant, bit for bit, and the paths do not depend on the
    // light: the same estimates, to the bit, on packets (box, periodic slab) and the scalar walk (masked slab).
    let n = [5, 4, 3];
    let med = heterogeneous(60);
    let k = [0.7f32, 1.3, 2.0];
    let env = map_of(3, 37.0, |_, _, c| k[c]);
    let texels = box_texels(n, &[0, 1, 2, 3, 4, 5]);
    let opts = RenderOptions { spp: 16, seed: 3, include_specular: true };
    for (boundary, mask) in [(Boundary::Box, false), (Boundary::PeriodicXY, false), (Boundary::PeriodicXY, true)] {
        let geo = || {
            let g = Geometry::new(n, [0.1; 3], boundary, 1.5, 0.4).unwrap();
            if mask {
                g.with_inside(vec![1; 60]).unwrap()
            } else {
                g
            }
        };
        let texels: Vec<Texel> = texels.iter().filter(|t| boundary == Boundary::Box || t.face >= 4).copied().collect();
        let (a, _) = render(&geo().with_light(Box::new(UniformLight(k))), &med, &texels, 0, &opts);
        let (b, _) = render(&geo().with_light(Box::new(env.clone())), &med, &texels, 0, &opts);
        for (x, y) in a.iter().zip(&b) {
            assert_eq!(x.mean, y.mean);
            assert_eq!(x.var_mean, y.var_mean);
        }
    }
}

#[test]
fn packets_match_the_scalar_trace_under_a_directional_map() {
    // Every escape, on every face, looks the map up in the world frame: a map bright in one direction per channel
    // (red from above, green from +x, blue from -y) makes the faces differ strongly; the packets against the
    // scalar `trace`, per texel and channel within 4.5 standard errors (~200 comparisons).
    let n = [7, 6, 5];
    let med = heterogeneous(210);
    let env = map_of(16, 0.0, |i, j, c| {
        let d = dir((i as f32 + 0.5) * PI / 16.0, (j as f32 + 0.5) * PI / 16.0);
        let lobe = [d[2], d[0], -d[1]][c].max(0.0);
        0.05 + 3.0 * lobe * lobe
    });
    for boundary in [Boundary::Box, Boundary::PeriodicXY] {
        let geo = Geometry::new(n, [0.08, 0.05, 0.1], boundary, 1.5, 0.4).unwrap().with_light(Box::new(env.clone()));
        let faces: &[u8] = if boundary == Boundary::Box { &[0, 1, 2, 3, 4, 5] } else { &[4, 5] };
        let texels = box_texels(n, faces);
        let spp = 2000u32;
        let (packed, _) = render(&geo, &med, &texels, 0, &RenderOptions { spp, seed: 31, include_specular: true });
        for (i, (tex, x)) in texels.iter().zip(&packed).enumerate() {
            for c in 0..3 {
                let (m, var_mean, _) = super::samplers::scalar_estimate(&geo, &med, tex, i as u64, c, spp, 32, true);
                let se = (x.var_mean[c] as f64 + var_mean).sqrt();
                assert!(
                    (x.mean[c] as f64 - m).abs() < 4.5 * se + 1e-6,
                    "{boundary:?} texel {i} face {} c {c}: {} vs {m} (se {se})",
                    tex.face,
                    x.mean[c]
                );
            }
        }
    }
}
