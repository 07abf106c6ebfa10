//! MERL-format BRDF tables (DESIGN.md section 3): I/O, validation and lookup.
//!
//! Grid convention: cell `i` covers the continuous index interval `[i, i + 1)`, so its value is
//! the BRDF at the cell centre, continuous index `i + 0.5` ("cell-centre angles", see
//! [`cell_centre_angles`]). Nearest lookup floors the continuous index (MERL's own reader);
//! trilinear lookup interpolates between cell centres (continuous index minus one half), clamped
//! at the theta borders and wrapping in phi_d, so it returns stored values exactly at centres.

use crate::brdf::{Brdf, Directions, RgbMut};
use crate::coords::{self, RusinkiewiczAngles};
use crate::error::{NbrdfError, Result};
use glam::{DVec3, Vec3};
use rayon::prelude::*;
use std::f64::consts::{FRAC_PI_2, PI};
use std::fmt;
use std::io::Read;
use std::path::Path;
use std::sync::OnceLock;

pub const N_THETA_H: usize = 90;
pub const N_THETA_D: usize = 90;
pub const N_PHI_D: usize = 180;
pub const CELLS: usize = N_THETA_H * N_THETA_D * N_PHI_D;
/// Size of a valid file: 3 int32 header values and 3 channels of float64.
pub const FILE_SIZE: usize = 12 + 3 * CELLS * 8;
/// Stored value times scale = reflectance, per channel.
pub const SCALE: [f64; 3] = [1.0 / 1500.0, 1.15 / 1500.0, 1.66 / 1500.0];
/// The stored value [`MerlTable::tabulate`] writes for cells it cannot fill (MERL's own marker).
pub const NOT_MEASURED: f64 = -1.0;

const HEADER: [i32; 3] = [N_THETA_H as i32, N_THETA_D as i32, N_PHI_D as i32];
const HEADER_SIZE: usize = 12;
/// Work items per rayon task in batched evaluation: large enough to amortise scheduling, small
/// enough to balance a few thousand directions over all cores.
const BATCH_CHUNK: usize = 1024;

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
/// instead of one per channel (lookups at random directions are memory-bound; this layout made
/// nearest lookups about 2x and trilinear ones about 1.5x faster). The file's channel-major
/// layout is built on demand by
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
fn mirror_phi_d(phi_d: f64) -> f64 {
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
fn fold_phi_d(phi_d: f64) -> f64 {
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
fn nearest_clamped(index: f64, n: usize) -> usize {
    // `as usize` saturates: negative indices land on cell 0.
    (index.floor() as usize).min(n - 1)
}

/// Nearest cell on a wrapping axis of `n` cells.
fn nearest_wrapped(index: f64, n: usize) -> usize {
    (index.floor() as i64).rem_euclid(n as i64) as usize
}

/// Lower cell, upper cell and weight of the upper one for a position `t` between cell centres
/// (`t = continuous index - 0.5`), clamped to the first and last centre.
fn lerp_clamped(t: f64, n: usize) -> (usize, usize, f64) {
    let t = t.clamp(0.0, (n - 1) as f64);
    let i0 = (t.floor() as usize).min(n - 2);
    (i0, i0 + 1, t - i0 as f64)
}

/// As [`lerp_clamped`] on a periodic axis: centre `n - 1` blends into centre 0.
fn lerp_wrapped(t: f64, n: usize) -> (usize, usize, f64) {
    let floor = t.floor();
    let i0 = (floor as i64).rem_euclid(n as i64) as usize;
    (i0, (i0 + 1) % n, t - floor)
}

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
    let n = [view.x, view.y, view.z, light.x, light.y, light.z]
        .iter()
        .map(|s| s.len())
        .chain([out.r.len(), out.g.len(), out.b.len()])
        .min()
        .unwrap_or(0);
    let RgbMut { r, g, b } = out;
    r[..n]
        .par_chunks_mut(BATCH_CHUNK)
        .zip(g[..n].par_chunks_mut(BATCH_CHUNK))
        .zip(b[..n].par_chunks_mut(BATCH_CHUNK))
        .enumerate()
        .for_each(|(chunk, ((r, g), b))| {
            let start = chunk * BATCH_CHUNK;
            for j in 0..r.len() {
                let i = start + j;
                let l = DVec3::new(light.x[i] as f64, light.y[i] as f64, light.z[i] as f64);
                let v = DVec3::new(view.x[i] as f64, view.y[i] as f64, view.z[i] as f64);
                let cos = unit(l).map_or(0.0, |l| l.z.max(0.0));
                let rgb = to_f32_rgb(f(v, l).map(|x| x * cos));
                r[j] = rgb[0];
                g[j] = rgb[1];
                b[j] = rgb[2];
            }
        });
}

/// A human-readable description of where a flat stored index points.
fn describe_position(flat: usize) -> String {
    let channel = ["red", "green", "blue"]
        .get(flat / CELLS)
        .copied()
        .unwrap_or("?");
    let (th, td, pd) = cell_coordinates(flat % CELLS);
    format!("{channel} channel, cell (theta_h {th}, theta_d {td}, phi_d {pd})")
}

impl MerlTable {
    /// Parses the bytes of a MERL file; `origin` names the file in errors.
    pub fn from_bytes(bytes: &[u8], origin: &Path) -> Result<Self> {
        Self::parse(bytes, bytes.len() as u64, origin)
    }

    /// `bytes` may be a prefix of the file (reading stops one byte past a valid size);
    /// `file_size` is the real size, for the message.
    fn parse(bytes: &[u8], file_size: u64, origin: &Path) -> Result<Self> {
        let fail = |message: String| Err(NbrdfError::format(origin, message));
        if bytes.len() < HEADER_SIZE {
            return fail(format!(
                "truncated: {file_size} bytes, a MERL table has {FILE_SIZE} (not even the 12-byte header)"
            ));
        }
        let header: [i32; 3] = std::array::from_fn(|k| {
            let b = &bytes[4 * k..4 * k + 4];
            i32::from_le_bytes([b[0], b[1], b[2], b[3]])
        });
        if header != HEADER {
            return fail(format!(
                "header is ({}, {}, {}), a MERL table has (90, 90, 180) (theta_h, theta_d, phi_d)",
                header[0], header[1], header[2]
            ));
        }
        if file_size < FILE_SIZE as u64 {
            return fail(format!(
                "truncated: {file_size} bytes, a MERL table has {FILE_SIZE}"
            ));
        }
        if file_size > FILE_SIZE as u64 || bytes.len() != FILE_SIZE {
            return fail(format!(
                "{file_size} bytes, a MERL table has exactly {FILE_SIZE} (trailing data after the last value)"
            ));
        }
        let mut cells = vec![[0.0; 3]; CELLS];
        for (k, chunk) in bytes[HEADER_SIZE..].chunks_exact(8).enumerate() {
            let mut raw = [0u8; 8];
            raw.copy_from_slice(chunk);
            let value = f64::from_le_bytes(raw);
            if !value.is_finite() {
                return fail(format!(
                    "non-finite value {value} at byte offset {} ({})",
                    HEADER_SIZE + 8 * k,
                    describe_position(k)
                ));
            }
            cells[k % CELLS][k / CELLS] = value;
        }
        Ok(MerlTable {
            cells,
            channel_major: OnceLock::new(),
            phi_fold: PhiFold::Reciprocal,
        })
    }

    /// The same table read with another `phi_d` fold ([`PhiFold::Reciprocal`] unless set).
    pub fn with_phi_fold(mut self, fold: PhiFold) -> Self {
        self.phi_fold = fold;
        self
    }

    pub fn phi_fold(&self) -> PhiFold {
        self.phi_fold
    }

    /// Lower cell, upper cell and weight of the upper one on the `phi_d` axis.
    fn lerp_phi(&self, t: f64) -> (usize, usize, f64) {
        match self.phi_fold {
            PhiFold::Reciprocal => lerp_wrapped(t, N_PHI_D),
            PhiFold::Mirror => lerp_clamped(t, N_PHI_D),
        }
    }

    pub fn read(path: impl AsRef<Path>) -> Result<Self> {
        let path = path.as_ref();
        let io = |e| NbrdfError::io(path, e);
        let file = std::fs::File::open(path).map_err(io)?;
        let file_size = file.metadata().map_err(io)?.len();
        // Bounded read: a huge file given by mistake is rejected without loading it whole.
        let mut bytes = Vec::with_capacity(FILE_SIZE.min(file_size as usize) + 1);
        file.take(FILE_SIZE as u64 + 1)
            .read_to_end(&mut bytes)
            .map_err(io)?;
        Self::parse(&bytes, file_size.max(bytes.len() as u64), path)
    }

    pub fn to_bytes(&self) -> Vec<u8> {
        let mut bytes = Vec::with_capacity(FILE_SIZE);
        for h in HEADER {
            bytes.extend_from_slice(&h.to_le_bytes());
        }
        for c in 0..3 {
            for cell in &self.cells {
                bytes.extend_from_slice(&cell[c].to_le_bytes());
            }
        }
        bytes
    }

    pub fn write(&self, path: impl AsRef<Path>) -> Result<()> {
        let path = path.as_ref();
        std::fs::write(path, self.to_bytes()).map_err(|e| NbrdfError::io(path, e))
    }

    /// Builds a table from stored (unscaled) values, channel-major, `3 * CELLS` long.
    pub fn from_stored(stored: Vec<f64>) -> Result<Self> {
        if stored.len() != 3 * CELLS {
            return Err(NbrdfError::InvalidArgument(format!(
                "a MERL table holds {} stored values (3 x 90 x 90 x 180), got {}",
                3 * CELLS,
                stored.len()
            )));
        }
        if let Some(k) = stored.iter().position(|x| !x.is_finite()) {
            return Err(NbrdfError::InvalidArgument(format!(
                "non-finite stored value {} at index {k} ({})",
                stored[k],
                describe_position(k)
            )));
        }
        let cells = (0..CELLS)
            .map(|i| [stored[i], stored[CELLS + i], stored[2 * CELLS + i]])
            .collect();
        Ok(MerlTable {
            cells,
            channel_major: OnceLock::from(stored),
            phi_fold: PhiFold::Reciprocal,
        })
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

    fn nearest(&self, index: [f64; 3]) -> [f64; 3] {
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

    fn trilinear(&self, index: [f64; 3]) -> [f64; 3] {
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

#[cfg(test)]
mod tests {
    use super::*;
    use proptest::prelude::*;

    /// A table whose stored value is `f(channel, i_theta_h, i_theta_d, i_phi_d)`.
    fn table_from(f: impl Fn(usize, usize, usize, usize) -> f64) -> MerlTable {
        let mut stored = vec![0.0; 3 * CELLS];
        for (k, s) in stored.iter_mut().enumerate() {
            let (h, d, p) = cell_coordinates(k % CELLS);
            *s = f(k / CELLS, h, d, p);
        }
        MerlTable::from_stored(stored).expect("test table is valid")
    }

    /// Irregular but deterministic values, so no interpolation can be right by accident.
    fn hashed(c: usize, h: usize, d: usize, p: usize) -> f64 {
        let x = (c * 7919 + h * 104_729 + d * 1_299_709 + p * 15_485_863) as u64;
        ((x.wrapping_mul(0x9E37_79B9_7F4A_7C15) >> 40) % 1000) as f64 + 1.0
    }

    /// Stored value of a cell, scaled to reflectance.
    fn refl(t: &MerlTable, c: usize, h: usize, d: usize, p: usize) -> f64 {
        t.stored()[c * CELLS + cell_index(h, d, p)] * SCALE[c]
    }

    fn temp_path(name: &str) -> std::path::PathBuf {
        std::env::temp_dir().join(format!("nbrdf-merl-test-{}-{name}", std::process::id()))
    }

    fn close(a: f64, b: f64) -> bool {
        (a - b).abs() <= 1e-9 * (1.0 + a.abs().max(b.abs()))
    }

    fn hemisphere(theta: f64, phi: f64) -> DVec3 {
        DVec3::new(
            theta.sin() * phi.cos(),
            theta.sin() * phi.sin(),
            theta.cos(),
        )
    }

    #[test]
    fn cell_index_layout() {
        assert_eq!(cell_index(0, 0, 1), 1);
        assert_eq!(cell_index(0, 1, 0), 180);
        assert_eq!(cell_index(1, 0, 0), 16_200);
        assert_eq!(cell_index(89, 89, 179), CELLS - 1);
        assert_eq!(cell_coordinates(cell_index(12, 34, 56)), (12, 34, 56));
        assert_eq!(FILE_SIZE, 34_992_012);
    }

    #[test]
    fn index_maps_match_the_format() {
        let a = RusinkiewiczAngles {
            theta_h: PI / 8.0,
            phi_h: 0.3,
            theta_d: PI / 4.0,
            phi_d: PI / 2.0,
        };
        let i = continuous_index(&a);
        // theta_h: 90 sqrt((pi/8) / (pi/2)) = 90 * 0.5.
        assert!(
            close(i[0], 45.0) && close(i[1], 45.0) && close(i[2], 90.0),
            "{i:?}"
        );
        let fold = |phi_d| continuous_index(&RusinkiewiczAngles { phi_d, ..a })[2];
        assert!(close(fold(-PI / 4.0), 135.0));
        assert_eq!(fold(0.0), 0.0);
        assert_eq!(fold(PI), 0.0);
        assert!(close(fold(1.5 * PI), 90.0));
        assert!(close(fold(-3.0 * PI + 0.1), 18.0 / PI * 0.1 * 10.0));
        let c = cell_centre_angles(0, 0, 0);
        assert!(close(c.theta_h, (0.5f64 / 90.0).powi(2) * FRAC_PI_2));
        assert!(close(c.theta_d, 0.5 / 90.0 * FRAC_PI_2));
        assert!(close(c.phi_d, 0.5 / 180.0 * PI));
        assert_eq!(c.phi_h, 0.0);
    }

    proptest! {
        #[test]
        fn centre_angles_invert_the_index_maps(h in 0usize..90, d in 0usize..90, p in 0usize..180) {
            let i = continuous_index(&cell_centre_angles(h, d, p));
            prop_assert!(close(i[0], h as f64 + 0.5) && close(i[1], d as f64 + 0.5));
            prop_assert!(close(i[2], p as f64 + 0.5), "{i:?}");
        }
    }

    #[test]
    fn write_read_round_trip_is_bit_exact() {
        let mut stored: Vec<f64> = (0..3 * CELLS)
            .map(|k| hashed(k % 3, k, k / 7, k / 13) / 3.0)
            .collect();
        // Markers and awkward values must survive too.
        stored[0] = NOT_MEASURED;
        stored[1] = -0.0;
        stored[2] = f64::MIN_POSITIVE / 4.0;
        stored[3 * CELLS - 1] = 1e300;
        let table = MerlTable::from_stored(stored).unwrap();
        let bytes = table.to_bytes();
        assert_eq!(bytes.len(), FILE_SIZE);
        assert_eq!(&bytes[..12], &[90, 0, 0, 0, 90, 0, 0, 0, 180, 0, 0, 0]);
        assert_eq!(&bytes[12..20], &NOT_MEASURED.to_le_bytes());
        let path = temp_path("roundtrip.binary");
        table.write(&path).unwrap();
        let back = MerlTable::read(&path);
        let _ = std::fs::remove_file(&path);
        let back = back.unwrap();
        assert!(table
            .stored()
            .iter()
            .zip(back.stored())
            .all(|(a, b)| a.to_bits() == b.to_bits()));
    }

    /// Writes `bytes` to a temp file, reads it, returns the error message.
    fn read_error(name: &str, bytes: &[u8]) -> String {
        let path = temp_path(name);
        std::fs::write(&path, bytes).unwrap();
        let result = MerlTable::read(&path);
        let _ = std::fs::remove_file(&path);
        let err = result.expect_err("must be rejected");
        assert!(matches!(err, NbrdfError::Format { .. }), "{err:?}");
        let message = err.to_string();
        assert!(
            message.contains(name),
            "message must name the file: {message}"
        );
        message
    }

    #[test]
    fn malformed_files_are_rejected_with_the_file_named() {
        let good = shared_table().to_bytes();
        let m = read_error("truncated.binary", &good[..1234]);
        assert!(
            m.contains("truncated: 1234 bytes, a MERL table has 34992012"),
            "{m}"
        );
        let m = read_error("tiny.binary", &good[..5]);
        assert!(m.contains("truncated: 5 bytes"), "{m}");
        let m = read_error("short-by-one.binary", &good[..FILE_SIZE - 1]);
        assert!(m.contains("truncated: 34992011 bytes"), "{m}");
        let mut long = good.clone();
        long.extend_from_slice(&[0; 8]);
        let m = read_error("long.binary", &long);
        assert!(
            m.contains("34992020 bytes") && m.contains("exactly 34992012"),
            "{m}"
        );
        let mut header = good.clone();
        header[8..12].copy_from_slice(&360i32.to_le_bytes());
        let m = read_error("header.binary", &header);
        assert!(m.contains("header is (90, 90, 360)"), "{m}");
        let mut nan = good.clone();
        let at = 12 + 8 * (CELLS + cell_index(1, 2, 3));
        nan[at..at + 8].copy_from_slice(&f64::NAN.to_le_bytes());
        let m = read_error("nan.binary", &nan);
        assert!(
            m.contains("NaN") && m.contains("green") && m.contains("theta_h 1, theta_d 2, phi_d 3"),
            "{m}"
        );
        let mut inf = good;
        inf[12..20].copy_from_slice(&f64::NEG_INFINITY.to_le_bytes());
        assert!(read_error("inf.binary", &inf).contains("-inf"));
    }

    #[test]
    fn missing_file_is_an_io_error_naming_it() {
        let path = temp_path("does-not-exist.binary");
        let err = MerlTable::read(&path).unwrap_err();
        assert!(matches!(err, NbrdfError::Io { .. }));
        assert!(err.to_string().contains("does-not-exist.binary"));
    }

    #[test]
    fn from_stored_validates() {
        assert!(MerlTable::from_stored(vec![0.0; 10]).is_err());
        let mut v = vec![0.0; 3 * CELLS];
        v[17] = f64::NAN;
        assert!(matches!(
            MerlTable::from_stored(v),
            Err(NbrdfError::InvalidArgument(_))
        ));
    }

    #[test]
    fn lookups_at_cell_centres_return_stored_values() {
        let t = shared_table();
        for (h, d, p) in [
            (0, 0, 0),
            (89, 89, 179),
            (0, 89, 90),
            (45, 12, 179),
            (17, 60, 1),
            (89, 0, 0),
        ] {
            let a = cell_centre_angles(h, d, p);
            let expect: [f64; 3] = std::array::from_fn(|c| refl(t, c, h, d, p));
            assert_eq!(t.lookup(&a, Interpolation::Nearest), expect);
            let tri = t.lookup(&a, Interpolation::Trilinear);
            assert!(
                (0..3).all(|c| close(tri[c], expect[c])),
                "{h} {d} {p}: {tri:?} vs {expect:?}"
            );
        }
    }

    #[test]
    fn nearest_floors_the_continuous_index() {
        let t = shared_table();
        let a = angles_at_index([10.99, 20.01, 30.7]);
        assert_eq!(
            t.lookup(&a, Interpolation::Nearest)[1],
            refl(t, 1, 10, 20, 30)
        );
        // Beyond the theta range: clamped to the last cell.
        let a = RusinkiewiczAngles {
            theta_h: 2.0,
            phi_h: 0.0,
            theta_d: 3.0,
            phi_d: 0.1,
        };
        assert_eq!(
            t.lookup(&a, Interpolation::Nearest)[0],
            refl(t, 0, 89, 89, 5)
        );
    }

    #[test]
    fn trilinear_blends_linearly_between_centres() {
        let t = shared_table();
        // Along phi_d: continuous index 30.75 is a quarter of the way from centre 30 to 31.
        let a = angles_at_index([10.5, 20.5, 30.75]);
        let expect = 0.75 * refl(t, 2, 10, 20, 30) + 0.25 * refl(t, 2, 10, 20, 31);
        assert!(close(t.lookup(&a, Interpolation::Trilinear)[2], expect));
        // Along all three axes at once: the full trilinear formula, written out.
        let a = angles_at_index([10.8, 20.6, 30.9]);
        let (wh, wd, wp) = (0.3, 0.1, 0.4);
        let mut expect = 0.0;
        for (h, fh) in [(10, 1.0 - wh), (11, wh)] {
            for (d, fd) in [(20, 1.0 - wd), (21, wd)] {
                for (p, fp) in [(30, 1.0 - wp), (31, wp)] {
                    expect += fh * fd * fp * refl(t, 0, h, d, p);
                }
            }
        }
        assert!(close(t.lookup(&a, Interpolation::Trilinear)[0], expect));
    }

    #[test]
    fn trilinear_reproduces_a_linear_field() {
        // A field linear in the cell indices is reproduced exactly away from the borders.
        let t = &table_from(|c, h, d, p| {
            1.0 + c as f64 + 2.0 * h as f64 + 3.0 * d as f64 + 0.5 * p as f64
        });
        for idx in [[3.2, 4.7, 5.9], [70.1, 0.6, 178.2], [88.4, 88.9, 1.0]] {
            let got = t.lookup(&angles_at_index(idx), Interpolation::Trilinear)[1];
            let t_idx = idx.map(|x| x - 0.5);
            let expect = (2.0 + 2.0 * t_idx[0] + 3.0 * t_idx[1] + 0.5 * t_idx[2]) * SCALE[1];
            assert!(close(got, expect), "{idx:?}: {got} vs {expect}");
        }
    }

    #[test]
    fn trilinear_clamps_at_theta_borders() {
        let t = shared_table();
        // theta_h index 0.2 is before the first centre: clamped onto it.
        let got = t.lookup(
            &angles_at_index([0.2, 89.9, 40.5]),
            Interpolation::Trilinear,
        );
        assert!(close(got[0], refl(t, 0, 0, 89, 40)));
        let a = RusinkiewiczAngles {
            theta_h: 1.7,
            phi_h: 0.0,
            theta_d: 1.6,
            phi_d: PI * 40.5 / 180.0,
        };
        assert!(close(
            t.lookup(&a, Interpolation::Trilinear)[2],
            refl(t, 2, 89, 89, 40)
        ));
    }

    #[test]
    fn trilinear_wraps_in_phi_d() {
        let t = shared_table();
        // Continuous index 0.2 (t = -0.3): 0.3 of centre 179 and 0.7 of centre 0.
        let expect = 0.3 * refl(t, 0, 5, 6, 179) + 0.7 * refl(t, 0, 5, 6, 0);
        let got = t.lookup(&angles_at_index([5.5, 6.5, 0.2]), Interpolation::Trilinear)[0];
        assert!(close(got, expect), "{got} vs {expect}");
        // Continuous index 179.8 (t = 179.3): 0.7 of centre 179 and 0.3 of centre 0.
        let expect = 0.7 * refl(t, 0, 5, 6, 179) + 0.3 * refl(t, 0, 5, 6, 0);
        let got = t.lookup(
            &angles_at_index([5.5, 6.5, 179.8]),
            Interpolation::Trilinear,
        )[0];
        assert!(close(got, expect));
        // phi_d just below 0 folds to just below pi: the same point as index 179.8.
        let mut a = angles_at_index([5.5, 6.5, 179.8]);
        a.phi_d -= PI;
        assert!(close(t.lookup(&a, Interpolation::Trilinear)[0], expect));
    }

    #[test]
    fn mirror_fold_reflects_phi_d_and_clamps() {
        let t = shared_table().clone().with_phi_fold(PhiFold::Mirror);
        assert_eq!(t.phi_fold(), PhiFold::Mirror);
        // Stored centres come back as they are, whatever the fold.
        let centre = cell_centre_angles(5, 6, 40);
        assert!(close(
            t.lookup(&centre, Interpolation::Trilinear)[1],
            refl(&t, 1, 5, 6, 40)
        ));
        // phi_d + pi is the mirror image of pi - phi_d (cell 139), not cell 40 as by reciprocity.
        let swapped = RusinkiewiczAngles {
            phi_d: centre.phi_d + PI,
            ..centre
        };
        for interpolation in [Interpolation::Nearest, Interpolation::Trilinear] {
            let got = t.lookup(&swapped, interpolation)[1];
            assert!(close(got, refl(&t, 1, 5, 6, 139)), "{got}");
            let negative = RusinkiewiczAngles {
                phi_d: -centre.phi_d,
                ..centre
            };
            assert!(close(
                t.lookup(&negative, interpolation)[1],
                refl(&t, 1, 5, 6, 40)
            ));
        }
        // Near the mirror planes 0 and pi the lookup clamps instead of wrapping around.
        for (index, cell) in [(0.2, 0), (179.8, 179)] {
            let got = t.lookup(
                &angles_at_index([5.5, 6.5, index]),
                Interpolation::Trilinear,
            )[0];
            assert!(close(got, refl(&t, 0, 5, 6, cell)), "{index}: {got}");
        }
        let i = continuous_index_folded(
            &RusinkiewiczAngles {
                phi_d: 1.5 * PI,
                ..centre
            },
            PhiFold::Mirror,
        );
        assert!(close(i[2], 90.0), "{i:?}");
        // lookup_valid folds the same way.
        assert_eq!(
            t.lookup_valid(&swapped),
            Some(t.lookup(&swapped, Interpolation::Trilinear))
        );
    }

    proptest! {
        #![proptest_config(ProptestConfig::with_cases(64))]
        #[test]
        fn mirror_fold_is_mirror_symmetric_and_rotation_invariant(
            tl in 0.0..FRAC_PI_2, pl in -PI..PI, tv in 0.0..FRAC_PI_2, pv in -PI..PI
        ) {
            let t = shared_table().clone().with_phi_fold(PhiFold::Mirror);
            let (l, v) = (hemisphere(tl, pl), hemisphere(tv, pv));
            let flip = DVec3::new(1.0, -1.0, 1.0);
            let a = t.eval_f64(v, l, Interpolation::Trilinear);
            let b = t.eval_f64(v * flip, l * flip, Interpolation::Trilinear);
            let rot = glam::DMat3::from_rotation_z(0.77);
            let c = t.eval_f64(rot * v, rot * l, Interpolation::Trilinear);
            prop_assert!((0..3).all(|k| (a[k] - b[k]).abs() <= 1e-6 * (1.0 + a[k])), "{a:?} vs {b:?}");
            prop_assert!((0..3).all(|k| (a[k] - c[k]).abs() <= 1e-6 * (1.0 + a[k])), "{a:?} vs {c:?}");
        }
    }

    #[test]
    fn invalid_neighbours_are_left_out() {
        let t = &table_from(|c, h, d, p| match (h, d, p) {
            (10, 20, 31) => NOT_MEASURED,
            (10, 21, 30) if c == 2 => NOT_MEASURED, // one channel is enough to invalidate
            (40, _, _) => NOT_MEASURED,
            _ => hashed(c, h, d, p),
        });
        assert_eq!(t.cell(cell_index(10, 20, 31)), None);
        assert_eq!(t.cell(cell_index(10, 21, 30)), None);
        assert_eq!(t.cell(CELLS), None);
        // Two corners along phi_d, one of them invalid: the valid one alone.
        let got = t.lookup(
            &angles_at_index([10.5, 20.5, 30.75]),
            Interpolation::Trilinear,
        );
        assert!(close(got[0], refl(t, 0, 10, 20, 30)));
        // Four corners in (theta_d, phi_d), two invalid: the other two, renormalised.
        let got = t.lookup(
            &angles_at_index([10.5, 20.75, 30.6]),
            Interpolation::Trilinear,
        )[1];
        let (w_a, w_b) = (0.75 * 0.9, 0.25 * 0.1); // (20, 30) and (21, 31)
        let expect = (w_a * refl(t, 1, 10, 20, 30) + w_b * refl(t, 1, 10, 21, 31)) / (w_a + w_b);
        assert!(close(got, expect), "{got} vs {expect}");
        // Every weighted corner invalid: 0; nearest on an invalid cell: 0.
        assert_eq!(
            t.lookup(&angles_at_index([40.5, 3.3, 7.7]), Interpolation::Trilinear),
            [0.0; 3]
        );
        assert_eq!(
            t.lookup(&angles_at_index([10.5, 20.5, 31.2]), Interpolation::Nearest),
            [0.0; 3]
        );
        // Exactly on an invalid centre: zero-weight valid neighbours do not count.
        assert_eq!(
            t.lookup(
                &angles_at_index([40.5, 20.5, 31.5]),
                Interpolation::Trilinear
            ),
            [0.0; 3]
        );
    }

    #[test]
    fn eval_is_zero_below_the_horizon_and_total() {
        let t = shared_table();
        let up = hemisphere(0.4, 0.3);
        let cases = [
            (DVec3::new(1.0, 0.0, 0.0), up),
            (up, DVec3::new(0.3, 0.1, -0.2)),
            (DVec3::new(0.0, 0.0, -1.0), up),
            (DVec3::ZERO, up),
            (up, DVec3::new(f64::NAN, 0.0, 1.0)),
            (DVec3::new(f64::INFINITY, 0.0, 1.0), up),
        ];
        for (l, v) in cases {
            assert_eq!(
                t.eval_f64(v, l, Interpolation::Trilinear),
                [0.0; 3],
                "{l} {v}"
            );
            assert_eq!(t.eval_f64(v, l, Interpolation::Nearest), [0.0; 3]);
            assert_eq!(t.eval(v.as_vec3(), l.as_vec3()), [0.0; 3]);
        }
        // Grazing but above, and l = v (phi_d undefined): finite.
        for (l, v) in [
            (DVec3::new(1.0, 0.0, 1e-12), up),
            (up, up),
            (DVec3::Z, DVec3::Z),
        ] {
            let f = t.eval_f64(v, l, Interpolation::Trilinear);
            assert!(f.iter().all(|x| x.is_finite() && *x >= 0.0));
        }
        // Non-unit input: the same as unit input.
        for (l, v) in [
            (DVec3::new(1.0, 0.0, 1e-3), up),
            (up, hemisphere(1.0, -2.0)),
        ] {
            let (a, b) = (
                t.eval_f64(0.5 * v, 3.0 * l, Interpolation::Trilinear),
                t.eval_f64(v, l, Interpolation::Trilinear),
            );
            assert!((0..3).all(|c| close(a[c], b[c])), "{a:?} vs {b:?}");
        }
    }

    #[test]
    fn eval_matches_lookup_of_the_angles() {
        let t = shared_table();
        let (l, v) = (hemisphere(0.5, 0.2), hemisphere(1.1, 2.9));
        let a = coords::to_rusinkiewicz(v, l);
        for mode in [Interpolation::Nearest, Interpolation::Trilinear] {
            assert_eq!(t.eval_f64(v, l, mode), t.lookup(&a, mode));
        }
        // Rotating both directions about the normal changes nothing for an isotropic table.
        let rot = glam::DMat3::from_rotation_z(1.234);
        let a = t.eval_f64(v, l, Interpolation::Trilinear);
        let b = t.eval_f64(rot * v, rot * l, Interpolation::Trilinear);
        assert!((0..3).all(|c| close(a[c], b[c])));
    }

    #[test]
    fn nearest_is_reciprocal_on_generic_directions() {
        let t = shared_table();
        for (tl, pl, tv, pv) in [
            (0.3, 0.1, 1.2, 2.0),
            (1.4, -2.0, 0.2, 0.5),
            (0.9, 3.0, 0.7, -1.0),
        ] {
            let (l, v) = (hemisphere(tl, pl), hemisphere(tv, pv));
            assert_eq!(
                t.eval_f64(v, l, Interpolation::Nearest),
                t.eval_f64(l, v, Interpolation::Nearest)
            );
        }
    }

    proptest! {
        #![proptest_config(ProptestConfig::with_cases(64))]
        #[test]
        fn trilinear_is_reciprocal_and_finite(
            tl in 0.0..FRAC_PI_2, pl in -PI..PI, tv in 0.0..FRAC_PI_2, pv in -PI..PI
        ) {
            let t = shared_table();
            let (l, v) = (hemisphere(tl, pl), hemisphere(tv, pv));
            let a = t.eval_f64(v, l, Interpolation::Trilinear);
            let b = t.eval_f64(l, v, Interpolation::Trilinear);
            prop_assert!((0..3).all(|c| close(a[c], b[c])), "{a:?} vs {b:?}");
            prop_assert!(a.iter().all(|x| x.is_finite() && *x >= 0.0));
        }
    }

    /// One table for the property tests, built once.
    fn shared_table() -> &'static MerlTable {
        static TABLE: std::sync::OnceLock<MerlTable> = std::sync::OnceLock::new();
        TABLE.get_or_init(|| table_from(hashed))
    }

    #[test]
    fn batch_matches_single_evaluation() {
        let t = shared_table();
        let n = 3000;
        let mut light = vec![0.0f32; 3 * n];
        let mut view = vec![0.0f32; 3 * n];
        for i in 0..n {
            let l = hemisphere(1.7 * (i as f64 / n as f64) - 0.05, i as f64);
            let v = hemisphere(1.5 * ((i * 7 % n) as f64 / n as f64), -(i as f64) * 0.3);
            for k in 0..3 {
                light[k * n + i] = l[k] as f32;
                view[k * n + i] = v[k] as f32;
            }
        }
        let mut out = vec![-1.0f32; 3 * n];
        t.eval_cos_batch(
            Directions::from_planar(&view).unwrap(),
            Directions::from_planar(&light).unwrap(),
            RgbMut::from_planar(&mut out).unwrap(),
        );
        for i in 0..n {
            let (l, v) = (
                Vec3::new(light[i], light[n + i], light[2 * n + i]),
                Vec3::new(view[i], view[n + i], view[2 * n + i]),
            );
            let f = t.eval(v, l);
            let cos = crate::brdf::cos_theta_light(l);
            for c in 0..3 {
                let expect = f[c] * cos;
                assert!(
                    (out[c * n + i] - expect).abs() <= 1e-6 * (1.0 + expect.abs()),
                    "{i} {c}"
                );
            }
        }
        // Mismatched lengths: the common prefix only, no panic.
        let mut short = vec![7.0f32; 3 * 10];
        let before = short.clone();
        let out = RgbMut::from_planar(&mut short).unwrap();
        t.eval_cos_batch(
            Directions::from_planar(&view).unwrap(),
            Directions::from_planar(&light[..3 * 4]).unwrap(),
            out,
        );
        assert_eq!(&short[4..10], &before[4..10]);
    }

    #[test]
    fn tabulate_stores_scaled_values_at_cell_centres() {
        let t = MerlTable::tabulate(|a| {
            if a.theta_d > 1.5 {
                [f64::NAN, 1.0, -2.0]
            } else {
                [a.theta_h, a.theta_d, a.phi_d]
            }
        });
        for (h, d, p) in [(0, 0, 0), (89, 10, 179), (33, 44, 55)] {
            let a = cell_centre_angles(h, d, p);
            let i = cell_index(h, d, p);
            assert_eq!(t.stored()[i], a.theta_h / SCALE[0]);
            assert_eq!(t.stored()[CELLS + i], a.theta_d / SCALE[1]);
            assert_eq!(t.stored()[2 * CELLS + i], a.phi_d / SCALE[2]);
        }
        // theta_d index 86 is the first centre past 1.5 rad.
        let i = cell_index(3, 86, 4);
        assert_eq!(
            [
                t.stored()[i],
                t.stored()[CELLS + i],
                t.stored()[2 * CELLS + i]
            ],
            [NOT_MEASURED, 1.0 / SCALE[1], 0.0]
        );
        let stats = t.stats();
        assert_eq!(stats.invalid_cells, 90 * 4 * 180);
        assert_eq!(stats.valid_cells, CELLS - 90 * 4 * 180);
    }

    #[test]
    fn stats_of_a_known_table() {
        let t = &table_from(|c, h, _, _| {
            if h == 0 {
                NOT_MEASURED
            } else {
                (c + 1) as f64 * if h == 1 { 2.0 } else { 1.0 }
            }
        });
        let s = t.stats();
        assert_eq!(s.invalid_cells, 90 * 180);
        assert_eq!(s.valid_cells, 89 * 90 * 180);
        assert!(close(s.min[2], 3.0 * SCALE[2]) && close(s.max[2], 6.0 * SCALE[2]));
        assert!(close(s.mean[0], (88.0 + 2.0) / 89.0 * SCALE[0]));
    }
}
