//! The training samples of a spatially varying material, as the caller gives them (the source
//! evaluated at random texels and directions: [`TexturedSamples`]) and as the trainer reads
//! them ([`Rows`]: network inputs, source parameters and log-space targets).

use crate::brdf::Directions;
use crate::coords::network_input_for;
use crate::error::{NbrdfError, Result};
use crate::network::{INPUTS, OUTPUTS};
use crate::train::spectral::{SpectralTarget, SPECTRAL_OUTPUTS};
use glam::Vec3;

/// What the targets of [`TexturedSamples`] are.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub enum TargetKind {
    /// `f_r cos(theta_light)`, what Mitsuba's `BSDF.eval` returns.
    #[default]
    BrdfCos,
    /// `f_r`.
    Brdf,
}

/// The source's values of [`TexturedSamples`]: RGB, or spectra (a spectral material).
#[derive(Clone, Copy, Debug)]
pub enum TargetValues<'a> {
    /// One slice per channel.
    Rgb([&'a [f32]; 3]),
    /// Spectra sampled at `wavelengths` (nm; finite, strictly increasing, overlapping the
    /// default spectral basis' 360-830 nm): sample `i`'s value at wavelength `j` is
    /// `values[j n + i]`. The decoder learns the coefficients of the default basis, each
    /// sample's target the least-squares fit of its piecewise-linear spectrum, negative
    /// coefficients clamped to 0 ([`SpectralTarget`], as spectral networks are trained).
    Spectral {
        wavelengths: &'a [f32],
        values: &'a [f32],
    },
}

impl TargetValues<'_> {
    /// Values per sample: 3, or the wavelengths.
    fn channels(&self) -> usize {
        match self {
            TargetValues::Rgb(_) => OUTPUTS,
            TargetValues::Spectral { wavelengths, .. } => wavelengths.len(),
        }
    }

    /// Sample `i`'s values (of `n`) into `out` (`channels` long), in float64.
    fn values_of(&self, i: usize, n: usize, out: &mut [f64]) {
        match self {
            TargetValues::Rgb(planes) => {
                for (o, plane) in out.iter_mut().zip(planes) {
                    *o = f64::from(plane[i]);
                }
            }
            TargetValues::Spectral { values, .. } => {
                for (j, o) in out.iter_mut().enumerate() {
                    *o = f64::from(values[j * n + i]);
                }
            }
        }
    }
}

/// Samples of a textured source, structure-of-arrays, one lane per sample: the source's `P`
/// parameters at the sample's texel (`params[k][i]`: parameter `k` of sample `i`), the view and
/// light directions (shading frame, z = normal), and the source's value there (RGB or spectra).
#[derive(Clone, Copy, Debug)]
pub struct TexturedSamples<'a> {
    pub params: &'a [&'a [f32]],
    pub view: Directions<'a>,
    pub light: Directions<'a>,
    pub target: TargetValues<'a>,
    pub target_kind: TargetKind,
}

impl TexturedSamples<'_> {
    /// `P`, the parameters per sample.
    pub fn parameter_count(&self) -> usize {
        self.params.len()
    }

    /// The sample count, after checking that every slice has it.
    pub fn len(&self) -> Result<usize> {
        let n = self.view.x.len();
        let mut slices: Vec<(String, usize)> = vec![
            ("view.y".into(), self.view.y.len()),
            ("view.z".into(), self.view.z.len()),
            ("light.x".into(), self.light.x.len()),
            ("light.y".into(), self.light.y.len()),
            ("light.z".into(), self.light.z.len()),
        ];
        match self.target {
            TargetValues::Rgb(planes) => {
                for (c, t) in ["r", "g", "b"].iter().zip(planes) {
                    slices.push((format!("target.{c}"), t.len()));
                }
            }
            TargetValues::Spectral {
                wavelengths,
                values,
            } => {
                let m = wavelengths.len();
                if Some(values.len()) != m.checked_mul(n) {
                    return Err(NbrdfError::InvalidArgument(format!(
                        "textured samples: {} spectral values for {n} samples and {m} wavelengths \
                         (expected m n)",
                        values.len()
                    )));
                }
            }
        }
        for (k, p) in self.params.iter().enumerate() {
            slices.push((format!("params[{k}]"), p.len()));
        }
        match slices.iter().find(|(_, len)| *len != n) {
            Some((name, len)) => Err(NbrdfError::InvalidArgument(format!(
                "textured samples: {name} has {len} values, view.x has {n}"
            ))),
            None => Ok(n),
        }
    }

    /// The decoder's outputs these samples train: 3, or the default spectral basis' count.
    pub fn output_count(&self) -> usize {
        match self.target {
            TargetValues::Rgb(_) => OUTPUTS,
            TargetValues::Spectral { .. } => SPECTRAL_OUTPUTS,
        }
    }

    pub fn is_empty(&self) -> bool {
        self.view.x.is_empty()
    }
}

/// The error for a source without parameters.
pub(crate) fn no_textures() -> NbrdfError {
    NbrdfError::InvalidArgument(
        "the source has no textures (0 parameters per texel): a homogeneous material needs no \
         latent texture; train an NBRDF network instead"
            .into(),
    )
}

/// The samples the trainer reads: per sample its network input, its parameters (`P` a row),
/// `ln(1 + f_r cos)` per output (`outputs` a row: RGB, or a spectrum's coefficients) and
/// `cos(theta_light)`.
#[derive(Clone, Debug, Default)]
pub(crate) struct Rows {
    pub parameters: usize,
    pub outputs: usize,
    pub inputs: Vec<[f32; INPUTS]>,
    pub params: Vec<f32>,
    pub log_targets: Vec<f32>,
    pub cos_light: Vec<f32>,
    /// Samples dropped: a direction at or below the horizon, or a target not finite and >= 0.
    pub below_horizon: u64,
    pub invalid: u64,
}

impl Rows {
    pub fn len(&self) -> usize {
        self.cos_light.len()
    }

    /// The rows of `samples` in order, dropping what cannot be learnt; a non-finite parameter
    /// is an error naming the sample.
    pub fn from_samples(samples: &TexturedSamples<'_>, anisotropic: bool) -> Result<Self> {
        let n = samples.len()?;
        let parameters = samples.parameter_count();
        if parameters == 0 {
            return Err(no_textures());
        }
        let spectral = match samples.target {
            TargetValues::Spectral { wavelengths, .. } => Some(SpectralTarget::new(wavelengths)?),
            TargetValues::Rgb(_) => None,
        };
        let mut rows = Rows {
            parameters,
            outputs: samples.output_count(),
            ..Rows::default()
        };
        let mut value = vec![0.0f64; samples.target.channels()];
        for i in 0..n {
            if let Some(k) = samples.params.iter().position(|p| !p[i].is_finite()) {
                return Err(NbrdfError::InvalidArgument(format!(
                    "textured samples: parameter {k} of sample {i} is {}",
                    samples.params[k][i]
                )));
            }
            let unit = |d: Vec3| d.as_dvec3().try_normalize().map(|d| d.as_vec3());
            let (view, light) = match (unit(samples.view.get(i)), unit(samples.light.get(i))) {
                (Some(v), Some(l)) if v.z > 0.0 && l.z > 0.0 => (v, l),
                _ => {
                    rows.below_horizon += 1;
                    continue;
                }
            };
            samples.target.values_of(i, n, &mut value);
            if !value.iter().all(|v| v.is_finite() && *v >= 0.0) {
                rows.invalid += 1;
                continue;
            }
            let cos = light.z;
            if samples.target_kind == TargetKind::Brdf {
                value.iter_mut().for_each(|v| *v *= f64::from(cos));
            }
            rows.inputs
                .push(network_input_for(anisotropic, view, light));
            rows.params.extend(samples.params.iter().map(|p| p[i]));
            match &spectral {
                None => rows
                    .log_targets
                    .extend(value.iter().map(|v| v.ln_1p() as f32)),
                Some(target) => {
                    let coefficients = target.coefficients(&value);
                    rows.log_targets
                        .extend(coefficients.iter().map(|c| c.ln_1p() as f32));
                }
            }
            rows.cos_light.push(cos);
        }
        Ok(rows)
    }

    /// The parameters of row `i`.
    pub fn params_of(&self, i: usize) -> &[f32] {
        &self.params[i * self.parameters..(i + 1) * self.parameters]
    }

    /// The log-space targets of row `i`.
    pub fn log_targets_of(&self, i: usize) -> &[f32] {
        &self.log_targets[i * self.outputs..(i + 1) * self.outputs]
    }

    /// The rows `indices` of `self`, in that order.
    pub fn subset(&self, indices: &[u32]) -> Rows {
        let mut out = Rows {
            parameters: self.parameters,
            outputs: self.outputs,
            ..Rows::default()
        };
        for &i in indices {
            let i = i as usize;
            out.inputs.push(self.inputs[i]);
            out.params.extend_from_slice(self.params_of(i));
            out.log_targets.extend_from_slice(self.log_targets_of(i));
            out.cos_light.push(self.cos_light[i]);
        }
        out
    }
}
