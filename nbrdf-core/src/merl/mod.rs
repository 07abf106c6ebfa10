//! MERL-format BRDF tables (docs/design.md section 3).
//!
//! Grid convention: cell `i` covers the continuous index interval `[i, i + 1)`, so its value is
//! the BRDF at the cell centre, continuous index `i + 0.5` ("cell-centre angles", see
//! [`cell_centre_angles`]). Nearest lookup floors the continuous index (MERL's own reader);
//! trilinear lookup interpolates between cell centres (continuous index minus one half), clamped
//! at the theta borders and wrapping in phi_d, so it returns stored values exactly at centres.
//!
//! * this file: the [`MerlTable`] type, tabulation, statistics and the [`Brdf`] implementation;
//! * [`grid`]: grid dimensions, [`SCALE`], cell indices and angles;
//! * [`io`]: reading, validating and writing files;
//! * `lookup.rs`: nearest and trilinear lookup ([`MerlTable::lookup`], [`MerlTable::eval_f64`]).

pub mod grid;
pub mod io;
mod lookup;
#[cfg(test)]
mod tests;

pub use grid::*;
pub use io::FILE_SIZE;

use crate::brdf::{par_eval_pairs, Brdf, Directions, RgbMut};
use crate::coords::RusinkiewiczAngles;
use glam::{DVec3, Vec3};
use rayon::prelude::*;
use std::fmt;
use std::sync::OnceLock;

/// How a table is read between cell centres.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Default)]
pub enum Interpolation {
    Nearest,
    #[default]
    Trilinear,
}

/// A MERL-format table. Values are kept as stored in the file (unscaled float64; negative =
/// not measured), so a read/write round trip is exact.
///
/// The three channels of a cell are kept side by side: a lookup then touches a few cache lines
/// instead of one per channel (lookups at random directions are memory-bound; lookup rates in
/// docs/results/performance.md). The file's channel-major layout is built on demand by
/// [`MerlTable::stored`].
#[derive(Clone)]
pub struct MerlTable {
    cells: Vec<[f64; 3]>,
    channel_major: OnceLock<Vec<f64>>,
    phi_fold: PhiFold,
}

/// How a lookup maps `phi_d` in `[0, 2 pi)` onto the stored half `[0, pi)`.
///
/// A MERL file does not say which; the format's convention is [`PhiFold::Reciprocal`].
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub enum PhiFold {
    /// `phi_d -> phi_d - pi`: swapping light and view (reciprocity) turns `phi_d` into
    /// `phi_d + pi`. MERL's convention; the lookup wraps around in `phi_d`.
    #[default]
    Reciprocal,
    /// `phi_d -> 2 pi - phi_d`: mirroring both directions in the plane of the half vector and the
    /// normal, a symmetry of every isotropic material, reciprocal or not. For tables of measured
    /// data that are not reciprocal (Mitsuba's `measured` BSDF, with the light as `wo`), tabulated
    /// with `nbrdf_mitsuba.tabulate_rgl --phi-fold mirror`; the lookup is clamped in `phi_d`
    /// (0 and pi are mirror planes). Such tables only make sense to tools told so
    /// (`nbrdf train --phi-fold mirror`); the `merl` BSDF reads every table as reciprocal.
    Mirror,
}

impl PhiFold {
    pub fn as_str(self) -> &'static str {
        match self {
            PhiFold::Reciprocal => "reciprocal",
            PhiFold::Mirror => "mirror",
        }
    }
}

/// Summary of a table for reports: reflectance statistics over the valid cells.
#[derive(Clone, Debug, PartialEq)]
pub struct TableStats {
    /// Per-channel minimum, maximum and mean reflectance over valid cells (0 when none is valid).
    pub min: [f64; 3],
    pub max: [f64; 3],
    pub mean: [f64; 3],
    pub valid_cells: usize,
    /// Cells where at least one channel is marked not measured.
    pub invalid_cells: usize,
}

/// Unit vector of `v`, or `None` for zero-length and non-finite input.
fn unit(v: DVec3) -> Option<DVec3> {
    let len = v.length();
    (len > 0.0 && len.is_finite()).then(|| v / len)
}

/// Narrows a reflectance to f32 without producing infinities from huge stored values.
pub(crate) fn to_f32_rgb(f: [f64; 3]) -> [f32; 3] {
    f.map(|x| {
        if x.is_finite() {
            x.clamp(0.0, f32::MAX as f64) as f32
        } else {
            0.0
        }
    })
}

/// Shared rayon loop behind the `eval_cos_batch` overrides: `f(view, light) * cos(theta_l)` for
/// every pair. Mismatched slice lengths are not a reason to panic in a renderer callback: only
/// the common prefix is evaluated.
pub(crate) fn parallel_eval_cos<F>(
    view: Directions<'_>,
    light: Directions<'_>,
    out: RgbMut<'_>,
    f: F,
) where
    F: Fn(DVec3, DVec3) -> [f64; 3] + Sync,
{
    par_eval_pairs(view, light, out, |v, l| {
        let (v, l) = (v.as_dvec3(), l.as_dvec3());
        let cos = unit(l).map_or(0.0, |l| l.z.max(0.0));
        to_f32_rgb(f(v, l).map(|x| x * cos))
    });
}

impl MerlTable {
    /// The same table read with another `phi_d` fold ([`PhiFold::Reciprocal`] unless set).
    pub fn with_phi_fold(mut self, fold: PhiFold) -> Self {
        self.phi_fold = fold;
        self
    }

    pub fn phi_fold(&self) -> PhiFold {
        self.phi_fold
    }

    /// Tabulates a reflectance function (`f_r`, linear RGB) at every cell centre, in parallel.
    ///
    /// A non-finite value is stored as [`NOT_MEASURED`] (the table stays valid and the lookup
    /// skips it); a negative one as 0, since a negative store would mean "not measured".
    pub fn tabulate(f: impl Fn(&RusinkiewiczAngles) -> [f64; 3] + Sync) -> Self {
        const SLAB: usize = N_THETA_D * N_PHI_D;
        let mut cells = vec![[0.0; 3]; CELLS];
        cells
            .par_chunks_mut(SLAB)
            .enumerate()
            .for_each(|(i_theta_h, slab)| {
                for (j, cell) in slab.iter_mut().enumerate() {
                    let rgb = f(&cell_centre_angles(i_theta_h, j / N_PHI_D, j % N_PHI_D));
                    *cell = std::array::from_fn(|c| {
                        let x = rgb[c] / SCALE[c];
                        if x.is_finite() {
                            x.max(0.0)
                        } else {
                            NOT_MEASURED
                        }
                    });
                }
            });
        MerlTable {
            cells,
            channel_major: OnceLock::new(),
            phi_fold: PhiFold::Reciprocal,
        }
    }

    /// The stored (unscaled) values in the file's channel-major order, `3 * CELLS` long.
    /// Built on first use (35 MB) and kept.
    pub fn stored(&self) -> &[f64] {
        self.channel_major.get_or_init(|| {
            (0..3)
                .flat_map(|c| self.cells.iter().map(move |cell| cell[c]))
                .collect()
        })
    }

    /// Reflectance of one cell, or `None` when any channel is marked not measured.
    pub fn cell(&self, index: usize) -> Option<[f64; 3]> {
        let stored = self.cells.get(index)?;
        if stored.iter().any(|x| *x < 0.0) {
            return None;
        }
        Some([
            stored[0] * SCALE[0],
            stored[1] * SCALE[1],
            stored[2] * SCALE[2],
        ])
    }

    /// Reflectance statistics over the valid cells and the count of invalid ones.
    pub fn stats(&self) -> TableStats {
        let mut min = [f64::INFINITY; 3];
        let mut max = [0.0f64; 3];
        let mut sum = [0.0; 3];
        let mut valid = 0usize;
        for rgb in (0..CELLS).filter_map(|i| self.cell(i)) {
            for c in 0..3 {
                min[c] = min[c].min(rgb[c]);
                max[c] = max[c].max(rgb[c]);
                sum[c] += rgb[c];
            }
            valid += 1;
        }
        if valid == 0 {
            min = [0.0; 3];
        }
        let mean = sum.map(|s| if valid > 0 { s / valid as f64 } else { 0.0 });
        TableStats {
            min,
            max,
            mean,
            valid_cells: valid,
            invalid_cells: CELLS - valid,
        }
    }
}

impl fmt::Debug for MerlTable {
    // 4.4 million values are not a useful debug print.
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.debug_struct("MerlTable")
            .field("cells", &self.cells.len())
            .finish_non_exhaustive()
    }
}

impl Brdf for MerlTable {
    fn eval(&self, view: Vec3, light: Vec3) -> [f32; 3] {
        to_f32_rgb(self.eval_f64(view.as_dvec3(), light.as_dvec3(), Interpolation::Trilinear))
    }

    fn eval_cos_batch(&self, view: Directions<'_>, light: Directions<'_>, out: RgbMut<'_>) {
        parallel_eval_cos(view, light, out, |v, l| {
            self.eval_f64(v, l, Interpolation::Trilinear)
        });
    }
}
