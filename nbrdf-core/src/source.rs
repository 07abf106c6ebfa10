//! What a network is trained from: a MERL-format table or an RGL `.bsdf` measurement, told apart
//! by the file's content (its first bytes), not its name.
//!
//! An RGL measurement is learnt from [`RglMeasurement::eval`] at the trainer's own sample
//! directions, with no MERL grid in between. Loss decisions (docs/results/rgl-training.md):
//! * Reciprocity: RGL data is not reciprocal, and Mitsuba's `measured` plugin (what a scene with
//!   the measurement renders) evaluates `f(view, light)` as measured. [`RglFold::AsMeasured`]
//!   learns exactly that; [`RglFold::ReciprocalMean`] learns `(f(v, l) + f(l, v)) / 2`, as
//!   `tabulate_rgl --phi-fold reciprocal` did.
//! * Horizon: the loss compares `ln(1 + f cos_light)`, and `f cos_light` is what the measurement
//!   stores (`eval_cos_f32`), so the `1 / cos` of `f` never reaches the loss for the light.
//!   The reciprocal mean's swapped term carries `cos_light / cos_view`, which grows without bound
//!   at grazing views; samples with either cosine below [`GRAZING_COS`] are dropped there.
//! * Out-of-gamut RGB values (slightly negative) are clamped to 0, as the `Brdf` impl does.
//! * A spectral measurement (`*_spec.bsdf`) gives a spectral network by default, learnt from its
//!   spectra (`crate::ops::train_network`, `crate::train::spectral`); [`rgl_target`] of such a
//!   file is its linear sRGB projection under D65 (`RglMeasurement::eval`; docs/design.md
//!   section 9), what an RGB network of it (`--output-kind rgb`) learns.

use crate::coords::{from_rusinkiewicz, RusinkiewiczAngles};
use crate::error::{NbrdfError, Result};
use crate::merl::MerlTable;
use crate::rgl::RglMeasurement;
use std::io::Read;
use std::path::{Path, PathBuf};

/// Below this cosine (about 89.4 degrees) the reciprocal mean is not trained on.
pub const GRAZING_COS: f64 = 0.01;

/// How an RGL measurement's lack of reciprocity enters the training target.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub enum RglFold {
    /// `f(view, light)` as Mitsuba's `measured` evaluates it.
    #[default]
    AsMeasured,
    /// `(f(view, light) + f(light, view)) / 2`: a reciprocal network.
    ReciprocalMean,
}

impl RglFold {
    pub fn as_str(self) -> &'static str {
        match self {
            RglFold::AsMeasured => "as-measured",
            RglFold::ReciprocalMean => "reciprocal-mean",
        }
    }

    /// Whether a pair with these cosines is trained on: the reciprocal mean's swapped term
    /// carries `cos_light / cos_view`, so it leaves out pairs with either cosine below
    /// [`GRAZING_COS`]; the measurement as measured keeps every pair above the horizon.
    pub fn trains_on(self, cos_view: f64, cos_light: f64) -> bool {
        match self {
            RglFold::AsMeasured => true,
            RglFold::ReciprocalMean => cos_view >= GRAZING_COS && cos_light >= GRAZING_COS,
        }
    }
}

/// A training source read from a file.
pub enum TrainingSource {
    Table { path: PathBuf, table: MerlTable },
    Rgl(Box<RglMeasurement>),
}

const TENSOR_MAGIC: &[u8] = b"tensor_file\0";
/// The MERL header: three little-endian i32 resolutions (90, 90, 180).
const MERL_HEADER: [u8; 12] = [90, 0, 0, 0, 90, 0, 0, 0, 180, 0, 0, 0];

impl TrainingSource {
    /// Opens `path`, deciding from its first 12 bytes whether it is an RGL tensor file or a MERL
    /// table; anything else is an error naming the file and the formats accepted.
    pub fn open(path: impl AsRef<Path>) -> Result<TrainingSource> {
        let path = path.as_ref();
        let mut head = Vec::with_capacity(12);
        std::fs::File::open(path)
            .and_then(|f| f.take(12).read_to_end(&mut head))
            .map_err(|e| NbrdfError::io(path, e))?;
        if head.as_slice() == TENSOR_MAGIC {
            Ok(TrainingSource::Rgl(Box::new(RglMeasurement::load(path)?)))
        } else if head.as_slice() == MERL_HEADER {
            Ok(TrainingSource::Table {
                path: path.to_path_buf(),
                table: MerlTable::read(path)?,
            })
        } else {
            let what = if head.first().is_some_and(|b| matches!(b, b'{' | b'[')) {
                " (it looks like JSON: a network file? `nbrdf train` learns from measurements)"
            } else if head.is_empty() {
                " (the file is empty)"
            } else {
                ""
            };
            Err(NbrdfError::format(
                path,
                format!(
                    "not a training source{what}: expected an RGL .bsdf measurement (starting \
                     with \"tensor_file\") or a MERL-format table (header 90 90 180)"
                ),
            ))
        }
    }

    /// `"merl-table"`, `"rgl-measurement"` or `"rgl-spectral-measurement"`, for provenance.
    pub fn kind(&self) -> &'static str {
        match self {
            TrainingSource::Table { .. } => "merl-table",
            TrainingSource::Rgl(m) if m.spectra().is_some() => "rgl-spectral-measurement",
            TrainingSource::Rgl(_) => "rgl-measurement",
        }
    }

    /// Whether the source is isotropic: MERL tables are by construction, RGL measurements say
    /// so in their header ([`RglMeasurement::is_isotropic`]).
    pub fn is_isotropic(&self) -> bool {
        match self {
            TrainingSource::Table { .. } => true,
            TrainingSource::Rgl(m) => m.is_isotropic(),
        }
    }

    pub fn path(&self) -> &Path {
        match self {
            TrainingSource::Table { path, .. } => path,
            TrainingSource::Rgl(m) => m.path(),
        }
    }
}

/// The training target of an RGL measurement: `f_r(view, light)` at the sample's angles, folded
/// as `fold` says, negative values clamped to 0; `None` (no sample) for grazing directions of the
/// reciprocal mean.
pub fn rgl_target(
    measurement: &RglMeasurement,
    fold: RglFold,
) -> impl Fn(&RusinkiewiczAngles) -> Option<[f64; 3]> + Sync + '_ {
    move |angles| {
        let (view, light) = from_rusinkiewicz(angles);
        let (v, l) = (view.as_vec3(), light.as_vec3());
        if !fold.trains_on(v.z as f64, l.z as f64) {
            return None;
        }
        let f = measurement.eval(v, l);
        let f = match fold {
            RglFold::AsMeasured => f,
            RglFold::ReciprocalMean => {
                let g = measurement.eval(l, v);
                std::array::from_fn(|c| 0.5 * (f[c] + g[c]))
            }
        };
        Some(f.map(|c| if c.is_finite() { c.max(0.0) } else { 0.0 }))
    }
}
