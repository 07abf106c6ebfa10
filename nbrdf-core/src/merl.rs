//! MERL-format BRDF tables (DESIGN.md section 3): I/O, validation and lookup.
//!
//! Grid convention: cell `i` covers the continuous index interval `[i, i + 1)`, so its value is
//! the BRDF at the cell centre, continuous index `i + 0.5` ("cell-centre angles", see
//! [`cell_centre_angles`]). Nearest lookup floors the continuous index (MERL's own reader);
//! trilinear lookup interpolates between cell centres (continuous index minus one half), clamped
//! at the theta borders and wrapping in phi_d, so it returns stored values exactly at centres.

use crate::brdf::Brdf;
use crate::coords::RusinkiewiczAngles;
use crate::error::Result;
use glam::Vec3;
use std::path::Path;

pub const N_THETA_H: usize = 90;
pub const N_THETA_D: usize = 90;
pub const N_PHI_D: usize = 180;
pub const CELLS: usize = N_THETA_H * N_THETA_D * N_PHI_D;
/// Size of a valid file: 3 int32 header values and 3 channels of float64.
pub const FILE_SIZE: usize = 12 + 3 * CELLS * 8;
/// Stored value times scale = reflectance, per channel.
pub const SCALE: [f64; 3] = [1.0 / 1500.0, 1.15 / 1500.0, 1.66 / 1500.0];

/// How a table is read between cell centres.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Default)]
pub enum Interpolation {
    Nearest,
    #[default]
    Trilinear,
}

/// A MERL-format table. Values are kept as stored in the file (unscaled float64; negative =
/// not measured), so a read/write round trip is exact.
#[derive(Clone)]
pub struct MerlTable {
    stored: Vec<f64>,
}

/// Flat index of a cell (channel 0): `i_phi_d + 180 (i_theta_d + 90 i_theta_h)`.
pub fn cell_index(i_theta_h: usize, i_theta_d: usize, i_phi_d: usize) -> usize {
    i_phi_d + N_PHI_D * (i_theta_d + N_THETA_D * i_theta_h)
}

/// Angles at the centre of a cell: continuous index `i + 0.5` on each axis, `phi_h = 0`.
pub fn cell_centre_angles(i_theta_h: usize, i_theta_d: usize, i_phi_d: usize) -> RusinkiewiczAngles {
    todo!()
}

/// Continuous (unfloored) indices `[theta_h, theta_d, phi_d]` of a set of angles, phi_d folded
/// into `[0, pi)` by reciprocity.
pub fn continuous_index(angles: &RusinkiewiczAngles) -> [f64; 3] {
    todo!()
}

impl MerlTable {
    /// Parses the bytes of a MERL file; `origin` names the file in errors.
    pub fn from_bytes(bytes: &[u8], origin: &Path) -> Result<Self> {
        todo!()
    }

    pub fn read(path: impl AsRef<Path>) -> Result<Self> {
        todo!()
    }

    pub fn to_bytes(&self) -> Vec<u8> {
        todo!()
    }

    pub fn write(&self, path: impl AsRef<Path>) -> Result<()> {
        todo!()
    }

    /// Builds a table from stored (unscaled) values, channel-major, `3 * CELLS` long.
    pub fn from_stored(stored: Vec<f64>) -> Result<Self> {
        todo!()
    }

    /// Tabulates a reflectance function (`f_r`, linear RGB) at every cell centre, in parallel.
    pub fn tabulate(f: impl Fn(&RusinkiewiczAngles) -> [f64; 3] + Sync) -> Self {
        todo!()
    }

    pub fn stored(&self) -> &[f64] {
        &self.stored
    }

    /// Reflectance of one cell, or `None` when any channel is marked not measured.
    pub fn cell(&self, index: usize) -> Option<[f64; 3]> {
        todo!()
    }

    pub fn lookup(&self, angles: &RusinkiewiczAngles, interpolation: Interpolation) -> [f64; 3] {
        todo!()
    }

    /// `f_r(light, view)`, zero at or below the horizon.
    pub fn eval_f64(&self, light: glam::DVec3, view: glam::DVec3, interpolation: Interpolation) -> [f64; 3] {
        todo!()
    }
}

impl Brdf for MerlTable {
    fn eval(&self, light: Vec3, view: Vec3) -> [f32; 3] {
        todo!()
    }
}
