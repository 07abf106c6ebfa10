//! Looking a table up: nearest cell (MERL's own reader) and trilinear interpolation between
//! cell centres, from angles or from a view/light pair.

use super::{
    cell_index, continuous_index_folded, lerp_clamped, lerp_wrapped, nearest_clamped,
    nearest_wrapped, unit, Interpolation, MerlTable, PhiFold, N_PHI_D, N_THETA_D, N_THETA_H,
};
use crate::coords::{self, RusinkiewiczAngles};
use glam::DVec3;

/// [`coords::to_rusinkiewicz`] without `phi_h` (an isotropic table ignores it; its `atan2` is a
/// measurable share of a lookup).
fn isotropic_angles(view: DVec3, light: DVec3) -> RusinkiewiczAngles {
    let coords::HalfDiff { half, diff } = coords::half_diff(view, light);
    RusinkiewiczAngles {
        theta_h: half.z.clamp(-1.0, 1.0).acos(),
        phi_h: 0.0,
        theta_d: diff.z.clamp(-1.0, 1.0).acos(),
        phi_d: diff.y.atan2(diff.x),
    }
}

impl MerlTable {
    /// Lower cell, upper cell and weight of the upper one on the `phi_d` axis.
    fn lerp_phi(&self, t: f64) -> (usize, usize, f64) {
        match self.phi_fold {
            PhiFold::Reciprocal => lerp_wrapped(t, N_PHI_D),
            PhiFold::Mirror => lerp_clamped(t, N_PHI_D),
        }
    }

    pub fn lookup(&self, angles: &RusinkiewiczAngles, interpolation: Interpolation) -> [f64; 3] {
        let index = continuous_index_folded(angles, self.phi_fold);
        if index.iter().any(|x| !x.is_finite()) {
            return [0.0; 3];
        }
        match interpolation {
            Interpolation::Nearest => self.nearest(index),
            Interpolation::Trilinear => self.trilinear(index),
        }
    }

    pub(super) fn nearest(&self, index: [f64; 3]) -> [f64; 3] {
        let cell = cell_index(
            nearest_clamped(index[0], N_THETA_H),
            nearest_clamped(index[1], N_THETA_D),
            match self.phi_fold {
                PhiFold::Reciprocal => nearest_wrapped(index[2], N_PHI_D),
                PhiFold::Mirror => nearest_clamped(index[2], N_PHI_D),
            },
        );
        self.cell(cell).unwrap_or([0.0; 3])
    }

    pub(super) fn trilinear(&self, index: [f64; 3]) -> [f64; 3] {
        let (h0, h1, wh) = lerp_clamped(index[0] - 0.5, N_THETA_H);
        let (d0, d1, wd) = lerp_clamped(index[1] - 0.5, N_THETA_D);
        let (p0, p1, wp) = self.lerp_phi(index[2] - 0.5);
        let mut sum = [0.0; 3];
        let mut weight_sum = 0.0;
        for (ih, w_h) in [(h0, 1.0 - wh), (h1, wh)] {
            for (id, w_d) in [(d0, 1.0 - wd), (d1, wd)] {
                for (ip, w_p) in [(p0, 1.0 - wp), (p1, wp)] {
                    let w = w_h * w_d * w_p;
                    // Zero-weight corners are skipped so that a valid but irrelevant neighbour
                    // cannot resurrect an invalid cell the point sits exactly on.
                    if w <= 0.0 {
                        continue;
                    }
                    if let Some(rgb) = self.cell(cell_index(ih, id, ip)) {
                        for c in 0..3 {
                            sum[c] += w * rgb[c];
                        }
                        weight_sum += w;
                    }
                }
            }
        }
        if weight_sum > 0.0 {
            sum.map(|s| s / weight_sum)
        } else {
            [0.0; 3]
        }
    }

    /// Trilinear [`MerlTable::lookup`] that tells unmeasured data apart: `None` where no
    /// neighbour cell with a positive interpolation weight is valid (a cell is invalid when any
    /// of its channels is not measured), where `lookup` would return 0. Training uses it so that
    /// unmeasured regions never become targets.
    pub fn lookup_valid(&self, angles: &RusinkiewiczAngles) -> Option<[f64; 3]> {
        let index = continuous_index_folded(angles, self.phi_fold);
        if index.iter().any(|x| !x.is_finite()) {
            return None;
        }
        let (h0, h1, wh) = lerp_clamped(index[0] - 0.5, N_THETA_H);
        let (d0, d1, wd) = lerp_clamped(index[1] - 0.5, N_THETA_D);
        let (p0, p1, wp) = self.lerp_phi(index[2] - 0.5);
        let any_valid = [(h0, 1.0 - wh), (h1, wh)].iter().any(|&(ih, w_h)| {
            [(d0, 1.0 - wd), (d1, wd)].iter().any(|&(id, w_d)| {
                [(p0, 1.0 - wp), (p1, wp)].iter().any(|&(ip, w_p)| {
                    w_h * w_d * w_p > 0.0 && self.cell(cell_index(ih, id, ip)).is_some()
                })
            })
        });
        any_valid.then(|| self.trilinear(index))
    }

    /// `f_r(view, light)`, zero at or below the horizon.
    pub fn eval_f64(
        &self,
        view: glam::DVec3,
        light: glam::DVec3,
        interpolation: Interpolation,
    ) -> [f64; 3] {
        match (unit(light), unit(view)) {
            (Some(l), Some(v)) if l.z > 0.0 && v.z > 0.0 => {
                self.lookup(&isotropic_angles(v, l), interpolation)
            }
            _ => [0.0; 3],
        }
    }
}
