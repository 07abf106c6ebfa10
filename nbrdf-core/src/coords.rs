//! Rusinkiewicz's half/difference parameterisation (docs/design.md section 2).
//!
//! Directions come in Mitsuba's order, view then light (see the crate's conventions).
//! `h = normalize(l + v)`, `d = R_y(-theta_h) R_z(-phi_h) l`. Every function here is total: unit
//! length is not assumed, and the degenerate configurations (`l = v`, `theta_h = 0`, `l + v = 0`,
//! zero vectors) give finite angles instead of NaN.

use glam::{DVec3, Vec3};

/// Below this `sin(theta_h)` the azimuth of the half vector is undefined and taken as 0.
const SIN_THETA_H_EPS: f64 = 1e-12;
const SIN_THETA_H_EPS_F32: f32 = 1e-7;

/// The four Rusinkiewicz angles, radians: `theta_h, theta_d` in `[0, pi]`,
/// `phi_h, phi_d` in `(-pi, pi]`.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct RusinkiewiczAngles {
    pub theta_h: f64,
    pub phi_h: f64,
    pub theta_d: f64,
    pub phi_d: f64,
}

/// Half vector and difference vector, both unit length.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct HalfDiff {
    pub half: DVec3,
    pub diff: DVec3,
}

/// Normalises `v`, or returns the normal `+z` for zero-length and non-finite input.
fn normalize_or_normal(v: DVec3) -> DVec3 {
    let len = v.length();
    if len > 0.0 && len.is_finite() {
        v / len
    } else {
        DVec3::Z
    }
}

/// The half and difference vectors of a view/light pair.
pub fn half_diff(view: DVec3, light: DVec3) -> HalfDiff {
    let l = normalize_or_normal(light);
    let v = normalize_or_normal(view);
    // l + v = 0 only happens with one direction below the horizon, where every BRDF is 0; the
    // normal is as good a half vector as any there.
    let half = normalize_or_normal(l + v);
    let sin_theta_h = (half.x * half.x + half.y * half.y).sqrt();
    let (cos_phi, sin_phi) = if sin_theta_h > SIN_THETA_H_EPS {
        (half.x / sin_theta_h, half.y / sin_theta_h)
    } else {
        (1.0, 0.0)
    };
    let cos_theta_h = half.z;
    // t = R_z(-phi_h) l, then d = R_y(-theta_h) t.
    let tx = cos_phi * l.x + sin_phi * l.y;
    let ty = -sin_phi * l.x + cos_phi * l.y;
    let tz = l.z;
    let diff = DVec3::new(
        cos_theta_h * tx - sin_theta_h * tz,
        ty,
        sin_theta_h * tx + cos_theta_h * tz,
    );
    HalfDiff { half, diff }
}

/// Rusinkiewicz angles of a view/light pair.
pub fn to_rusinkiewicz(view: DVec3, light: DVec3) -> RusinkiewiczAngles {
    let HalfDiff { half, diff } = half_diff(view, light);
    let sin_theta_h = (half.x * half.x + half.y * half.y).sqrt();
    let phi_h = if sin_theta_h > SIN_THETA_H_EPS {
        half.y.atan2(half.x)
    } else {
        0.0
    };
    RusinkiewiczAngles {
        theta_h: half.z.clamp(-1.0, 1.0).acos(),
        phi_h,
        theta_d: diff.z.clamp(-1.0, 1.0).acos(),
        phi_d: diff.y.atan2(diff.x),
    }
}

/// View and light directions of a set of angles, in that order: `l = R_z(phi_h) R_y(theta_h) d`,
/// `v = 2 (l . h) h - l`.
pub fn from_rusinkiewicz(angles: &RusinkiewiczAngles) -> (DVec3, DVec3) {
    let (sin_td, cos_td) = angles.theta_d.sin_cos();
    let (sin_pd, cos_pd) = angles.phi_d.sin_cos();
    let (sin_th, cos_th) = angles.theta_h.sin_cos();
    let (sin_ph, cos_ph) = angles.phi_h.sin_cos();
    let d = DVec3::new(sin_td * cos_pd, sin_td * sin_pd, cos_td);
    // R_y(theta_h) d
    let t = DVec3::new(
        cos_th * d.x + sin_th * d.z,
        d.y,
        -sin_th * d.x + cos_th * d.z,
    );
    // R_z(phi_h) t
    let light = DVec3::new(
        cos_ph * t.x - sin_ph * t.y,
        sin_ph * t.x + cos_ph * t.y,
        t.z,
    );
    let half = DVec3::new(sin_th * cos_ph, sin_th * sin_ph, cos_th);
    let view = 2.0 * light.dot(half) * half - light;
    (view, light)
}

/// The unit direction at polar angle `theta` (radians from the normal) and azimuth `phi`.
pub fn spherical_direction(theta: f64, phi: f64) -> DVec3 {
    let (sin_t, cos_t) = theta.sin_cos();
    let (sin_p, cos_p) = phi.sin_cos();
    DVec3::new(sin_t * cos_p, sin_t * sin_p, cos_t)
}

/// `cos(theta_l)` from the angles: `cos td cos th - sin td cos pd sin th`.
pub fn cos_theta_light(angles: &RusinkiewiczAngles) -> f64 {
    angles.theta_d.cos() * angles.theta_h.cos()
        - angles.theta_d.sin() * angles.phi_d.cos() * angles.theta_h.sin()
}

/// The isotropic network input `[sin th, 0, cos th, d.x, d.y, d.z]` of one view/light pair, from
/// scalar components so that batched loops over structure-of-arrays data vectorise (square roots
/// and selects only, no trigonometry, no branches the compiler cannot turn into blends).
#[inline(always)]
pub fn network_input_components(vx: f32, vy: f32, vz: f32, lx: f32, ly: f32, lz: f32) -> [f32; 6] {
    network_input_components_for(false, vx, vy, vz, lx, ly, lz)
}

/// The network input of one view/light pair for an isotropic (`anisotropic = false`,
/// [`network_input_components`]) or an anisotropic network: the anisotropic input is the full
/// half vector and the difference vector, `[sin th cos ph, sin th sin ph, cos th, d.x, d.y, d.z]`
/// (docs/design.md section 4); the isotropic one is the same with `phi_h = 0`. The difference
/// vector is the same in both (it is measured in the half vector's own frame). Twin:
/// `jit/network.py` `network_input` (held together by `tests/test_backends.py`).
#[allow(clippy::too_many_arguments)]
#[inline(always)]
pub fn network_input_components_for(
    anisotropic: bool,
    vx: f32,
    vy: f32,
    vz: f32,
    lx: f32,
    ly: f32,
    lz: f32,
) -> [f32; 6] {
    let (lx, ly, lz) = normalize_or_normal_f32(lx, ly, lz);
    let (vx, vy, vz) = normalize_or_normal_f32(vx, vy, vz);
    let (hx, hy, hz) = (lx + vx, ly + vy, lz + vz);
    let h_len2 = hx * hx + hy * hy + hz * hz;
    let degenerate = h_len2 <= 0.0;
    let h_inv = if degenerate { 0.0 } else { 1.0 / h_len2.sqrt() };
    let (hx, hy) = (hx * h_inv, hy * h_inv);
    let hz = if degenerate { 1.0 } else { hz * h_inv };
    let sin_th = (hx * hx + hy * hy).sqrt();
    let has_azimuth = sin_th > SIN_THETA_H_EPS_F32;
    let s_inv = if has_azimuth { 1.0 / sin_th } else { 0.0 };
    let cos_ph = if has_azimuth { hx * s_inv } else { 1.0 };
    let sin_ph = hy * s_inv;
    let tx = cos_ph * lx + sin_ph * ly;
    let ty = -sin_ph * lx + cos_ph * ly;
    let dx = hz * tx - sin_th * lz;
    let dz = sin_th * tx + hz * lz;
    if anisotropic {
        [sin_th * cos_ph, sin_th * sin_ph, hz, dx, ty, dz]
    } else {
        [sin_th, 0.0, hz, dx, ty, dz]
    }
}

/// The isotropic network input straight from Rusinkiewicz angles (`phi_h` is dropped):
/// `[sin theta_h, 0, cos theta_h, d]` with `d = (sin theta_d cos phi_d, sin theta_d sin phi_d,
/// cos theta_d)`. Unlike [`network_input`] of `f32` directions it stays exact where `theta_h`
/// is tiny (the first rows of the MERL grid), where `phi_h` recomputed from the directions is
/// rounding noise.
pub fn network_input_from_angles(angles: &RusinkiewiczAngles) -> [f32; 6] {
    network_input_from_angles_for(false, angles)
}

/// [`network_input_from_angles`] for an isotropic or (with `phi_h`) an anisotropic network.
pub fn network_input_from_angles_for(anisotropic: bool, angles: &RusinkiewiczAngles) -> [f32; 6] {
    let (sin_th, cos_th) = angles.theta_h.sin_cos();
    let (sin_td, cos_td) = angles.theta_d.sin_cos();
    let (sin_pd, cos_pd) = angles.phi_d.sin_cos();
    let (sin_ph, cos_ph) = if anisotropic {
        angles.phi_h.sin_cos()
    } else {
        (0.0, 1.0)
    };
    [
        (sin_th * cos_ph) as f32,
        (sin_th * sin_ph) as f32,
        cos_th as f32,
        (sin_td * cos_pd) as f32,
        (sin_td * sin_pd) as f32,
        cos_td as f32,
    ]
}

/// Unit vector, or the normal `+z` for zero-length, infinite or NaN input (selects only).
#[inline(always)]
fn normalize_or_normal_f32(x: f32, y: f32, z: f32) -> (f32, f32, f32) {
    let len2 = x * x + y * y + z * z;
    // False for NaN as well as for 0 and infinity.
    let usable = len2 > 0.0 && len2 < f32::INFINITY;
    let inv = if usable { 1.0 / len2.sqrt() } else { 0.0 };
    if usable {
        (x * inv, y * inv, z * inv)
    } else {
        (0.0, 0.0, 1.0)
    }
}

/// [`network_input_components`] for `glam` vectors.
#[inline]
pub fn network_input(view: Vec3, light: Vec3) -> [f32; 6] {
    network_input_components(view.x, view.y, view.z, light.x, light.y, light.z)
}

/// [`network_input_components_for`] for `glam` vectors.
#[inline]
pub fn network_input_for(anisotropic: bool, view: Vec3, light: Vec3) -> [f32; 6] {
    network_input_components_for(
        anisotropic,
        view.x,
        view.y,
        view.z,
        light.x,
        light.y,
        light.z,
    )
}

#[cfg(test)]
mod tests {
    use super::*;
    use proptest::prelude::*;
    use std::f64::consts::{FRAC_PI_2, PI};

    proptest! {
        #[test]
        fn roundtrip_recovers_directions(
            tl in 0.0..FRAC_PI_2, pl in -PI..PI, tv in 0.0..FRAC_PI_2, pv in -PI..PI
        ) {
            let (l, v) = (spherical_direction(tl, pl), spherical_direction(tv, pv));
            let angles = to_rusinkiewicz(v, l);
            let (v2, l2) = from_rusinkiewicz(&angles);
            prop_assert!((l - l2).length() < 1e-9, "{l} vs {l2}");
            prop_assert!((v - v2).length() < 1e-9, "{v} vs {v2}");
            prop_assert!((cos_theta_light(&angles) - l.z).abs() < 1e-9);
        }

        #[test]
        fn f32_input_matches_f64_angles(
            tl in 0.0..FRAC_PI_2, pl in -PI..PI, tv in 0.0..FRAC_PI_2, pv in -PI..PI
        ) {
            let (l, v) = (spherical_direction(tl, pl), spherical_direction(tv, pv));
            let hd = half_diff(v, l);
            let x = network_input(v.as_vec3(), l.as_vec3());
            let sin_th = (hd.half.x.powi(2) + hd.half.y.powi(2)).sqrt();
            let expect = [sin_th, 0.0, hd.half.z, hd.diff.x, hd.diff.y, hd.diff.z];
            for k in 0..6 {
                prop_assert!((x[k] as f64 - expect[k]).abs() < 1e-4, "{k}: {x:?} vs {expect:?}");
            }
        }

        #[test]
        fn anisotropic_input_is_the_half_and_difference_vector(
            tl in 0.0..FRAC_PI_2, pl in -PI..PI, tv in 0.0..FRAC_PI_2, pv in -PI..PI
        ) {
            let (l, v) = (spherical_direction(tl, pl), spherical_direction(tv, pv));
            let hd = half_diff(v, l);
            let x = network_input_for(true, v.as_vec3(), l.as_vec3());
            let expect = [hd.half.x, hd.half.y, hd.half.z, hd.diff.x, hd.diff.y, hd.diff.z];
            for k in 0..6 {
                prop_assert!((x[k] as f64 - expect[k]).abs() < 1e-4, "{k}: {x:?} vs {expect:?}");
            }
            let a = to_rusinkiewicz(v, l);
            let y = network_input_from_angles_for(true, &a);
            for k in 0..6 {
                prop_assert!((y[k] as f64 - expect[k]).abs() < 1e-5, "{k}: {y:?} vs {expect:?}");
            }
        }

        #[test]
        fn any_input_gives_finite_angles(
            l in proptest::array::uniform3(-2.0f64..2.0), v in proptest::array::uniform3(-2.0f64..2.0)
        ) {
            let a = to_rusinkiewicz(DVec3::from(v), DVec3::from(l));
            prop_assert!(a.theta_h.is_finite() && a.phi_h.is_finite());
            prop_assert!(a.theta_d.is_finite() && a.phi_d.is_finite());
            let x = network_input(DVec3::from(v).as_vec3(), DVec3::from(l).as_vec3());
            prop_assert!(x.iter().all(|c| c.is_finite()));
        }
    }

    #[test]
    fn degenerate_cases_are_finite() {
        let cases = [
            (DVec3::Z, DVec3::Z), // l = v = n: theta_h = theta_d = 0
            (spherical_direction(0.3, 0.2), spherical_direction(0.3, 0.2)), // l = v
            (DVec3::X, -DVec3::X), // l + v = 0
            (DVec3::ZERO, DVec3::Z), // zero vector
            (DVec3::new(0.0, 0.0, 3.0), DVec3::new(1.0, 0.0, 1.0)), // not unit length
            (DVec3::new(f64::NAN, 0.0, 1.0), DVec3::Z),
        ];
        for (l, v) in cases {
            let a = to_rusinkiewicz(v, l);
            assert!(
                [a.theta_h, a.phi_h, a.theta_d, a.phi_d]
                    .iter()
                    .all(|x| x.is_finite()),
                "{l} {v} -> {a:?}"
            );
            let x = network_input(v.as_vec3(), l.as_vec3());
            assert!(x.iter().all(|c| c.is_finite()), "{l} {v} -> {x:?}");
        }
        let a = to_rusinkiewicz(DVec3::Z, DVec3::Z);
        assert_eq!((a.theta_h, a.theta_d, a.phi_h), (0.0, 0.0, 0.0));
    }

    #[test]
    fn mirror_configuration_has_zero_theta_h() {
        let l = spherical_direction(0.7, 1.0);
        let v = DVec3::new(-l.x, -l.y, l.z);
        let a = to_rusinkiewicz(v, l);
        assert!(a.theta_h.abs() < 1e-7);
        assert!((a.theta_d - 0.7).abs() < 1e-9);
    }
}
