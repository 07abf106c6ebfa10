//! The MERL grid: its dimensions and channel scale factors, cell indices, cell-centre angles
//! and the continuous index of a set of angles (with the `phi_d` folds), and the per-axis
//! nearest and interpolation weights the lookups use.

use super::PhiFold;
use crate::coords::RusinkiewiczAngles;
use std::f64::consts::{FRAC_PI_2, PI};

pub const N_THETA_H: usize = 90;
pub const N_THETA_D: usize = 90;
pub const N_PHI_D: usize = 180;
pub const CELLS: usize = N_THETA_H * N_THETA_D * N_PHI_D;
/// Stored value times scale = reflectance, per channel.
pub const SCALE: [f64; 3] = [1.0 / 1500.0, 1.15 / 1500.0, 1.66 / 1500.0];
/// The stored value [`super::MerlTable::tabulate`] writes for cells it cannot fill (MERL's own marker).
pub const NOT_MEASURED: f64 = -1.0;

/// Flat index of a cell (channel 0): `i_phi_d + 180 (i_theta_d + 90 i_theta_h)`.
pub fn cell_index(i_theta_h: usize, i_theta_d: usize, i_phi_d: usize) -> usize {
    i_phi_d + N_PHI_D * (i_theta_d + N_THETA_D * i_theta_h)
}

/// The `(i_theta_h, i_theta_d, i_phi_d)` of a flat cell index (inverse of [`cell_index`]).
pub fn cell_coordinates(index: usize) -> (usize, usize, usize) {
    let i_phi_d = index % N_PHI_D;
    let rest = index / N_PHI_D;
    (rest / N_THETA_D, rest % N_THETA_D, i_phi_d)
}

/// Angles at the centre of a cell: continuous index `i + 0.5` on each axis, `phi_h = 0`.
pub fn cell_centre_angles(
    i_theta_h: usize,
    i_theta_d: usize,
    i_phi_d: usize,
) -> RusinkiewiczAngles {
    angles_at_index([
        i_theta_h as f64 + 0.5,
        i_theta_d as f64 + 0.5,
        i_phi_d as f64 + 0.5,
    ])
}

/// Inverse of [`continuous_index`] (for indices inside the grid): the angles, `phi_h = 0`, whose
/// continuous indices are `index`.
pub fn angles_at_index(index: [f64; 3]) -> RusinkiewiczAngles {
    let u = index[0] / N_THETA_H as f64;
    RusinkiewiczAngles {
        theta_h: u * u * FRAC_PI_2,
        phi_h: 0.0,
        theta_d: index[1] / N_THETA_D as f64 * FRAC_PI_2,
        phi_d: index[2] / N_PHI_D as f64 * PI,
    }
}

/// Continuous (unfloored) indices `[theta_h, theta_d, phi_d]` of a set of angles, phi_d folded
/// into `[0, pi)` by reciprocity.
pub fn continuous_index(angles: &RusinkiewiczAngles) -> [f64; 3] {
    continuous_index_folded(angles, PhiFold::Reciprocal)
}

/// [`continuous_index`] with phi_d folded by `fold` (into `[0, pi]` for [`PhiFold::Mirror`]).
pub fn continuous_index_folded(angles: &RusinkiewiczAngles, fold: PhiFold) -> [f64; 3] {
    // sqrt of a negative would be NaN; a negative theta_h is the border cell anyway.
    let theta_h = angles.theta_h.max(0.0);
    let phi_d = match fold {
        PhiFold::Reciprocal => fold_phi_d(angles.phi_d),
        PhiFold::Mirror => mirror_phi_d(angles.phi_d),
    };
    [
        N_THETA_H as f64 * (theta_h / FRAC_PI_2).sqrt(),
        N_THETA_D as f64 * angles.theta_d / FRAC_PI_2,
        N_PHI_D as f64 * phi_d / PI,
    ]
}

/// Mirror symmetry of an isotropic BRDF (`phi_d -> -phi_d`): any angle onto `[0, pi]`.
pub(super) fn mirror_phi_d(phi_d: f64) -> f64 {
    if !phi_d.is_finite() {
        return phi_d;
    }
    let phi = phi_d.rem_euclid(2.0 * PI);
    if phi > PI {
        2.0 * PI - phi
    } else {
        phi
    }
}

/// Reciprocity (swapping light and view) turns phi_d into phi_d + pi, so an isotropic table
/// only stores `[0, pi)`.
pub(super) fn fold_phi_d(phi_d: f64) -> f64 {
    let mut phi = phi_d;
    if phi < 0.0 {
        phi += PI;
    }
    if phi >= PI {
        phi -= PI;
    }
    // Angles outside (-pi, 2 pi) (not produced by atan2, but callers may pass any number).
    if !(0.0..PI).contains(&phi) && phi.is_finite() {
        phi = phi.rem_euclid(PI);
    }
    phi
}

/// Nearest cell on a clamped axis of `n` cells.
pub(super) fn nearest_clamped(index: f64, n: usize) -> usize {
    // `as usize` saturates: negative indices land on cell 0.
    (index.floor() as usize).min(n - 1)
}

/// Nearest cell on a wrapping axis of `n` cells.
pub(super) fn nearest_wrapped(index: f64, n: usize) -> usize {
    (index.floor() as i64).rem_euclid(n as i64) as usize
}

/// Lower cell, upper cell and weight of the upper one for a position `t` between cell centres
/// (`t = continuous index - 0.5`), clamped to the first and last centre.
pub(super) fn lerp_clamped(t: f64, n: usize) -> (usize, usize, f64) {
    let t = t.clamp(0.0, (n - 1) as f64);
    let i0 = (t.floor() as usize).min(n - 2);
    (i0, i0 + 1, t - i0 as f64)
}

/// As [`lerp_clamped`] on a periodic axis: centre `n - 1` blends into centre 0.
pub(super) fn lerp_wrapped(t: f64, n: usize) -> (usize, usize, f64) {
    let floor = t.floor();
    let i0 = (floor as i64).rem_euclid(n as i64) as usize;
    (i0, (i0 + 1) % n, t - floor)
}
