//! Training spectral networks (file format version 3, docs/design.md section 9): the network's
//! outputs are the coefficients `c_k` of the default [`SpectralBasis`] (16 clamped cubic
//! B-splines over 360-830 nm), `f_r(lambda) = sum_k c_k B_k(lambda)`.
//!
//! The target of a pair is the least-squares fit of the piecewise-linear spectrum through its
//! values at the source's wavelengths ([`SpectralBasis::least_squares`], one `count x m` matrix
//! per wavelength set), negative coefficients clamped to 0. The loss is the RGB networks', per
//! coefficient: `|ln(1 + c_k cos) - ln(1 + y_k cos)|` averaged over samples and coefficients,
//! with the same sampling, early stopping and validation ([`super::train_on_samples`]). Since
//! the basis is local and sums to 1, a coefficient is about the spectrum's value near its knot,
//! so the per-coefficient log error is about a per-wavelength one.
//!
//! Values come from a [`SpectralSource`]: arrays a caller sampled at the trainer's directions
//! ([`SampledSpectra`], the C ABI's `nbrdf_train_spectral_from_arrays`) or a spectral RGL
//! measurement evaluated there (`nbrdf train X_spec.bsdf`, in `crate::ops`). Folding,
//! horizon and finiteness are the RGB arrays' ([`super::arrays::fold_pair`]).

use super::arrays::{fold_pair, Folded};
use super::mlp_grad::TrainingSample;
use super::{train_on_samples, EpochStats, SampleSets, TrainConfig, TrainOutcome};
use crate::error::{NbrdfError, Result};
use crate::network::{Spectral, INPUTS};
use crate::source::RglFold;
use crate::spectral_basis::{SpectralBasis, DEFAULT_COUNT};
use glam::Vec3;
use rayon::prelude::*;
use std::ops::Range;
use std::time::Instant;

/// Outputs of the spectral networks the trainer writes: the default basis' coefficients.
pub const SPECTRAL_OUTPUTS: usize = DEFAULT_COUNT;

/// One spectral training sample: a [`super::dataset::Sample`] with a target per coefficient.
#[derive(Clone, Copy, Debug, PartialEq)]
#[repr(C)]
pub struct SpectralSample {
    pub x: [f32; INPUTS],
    /// `ln(1 + c_k cos_light)` per coefficient.
    pub log_target: [f32; SPECTRAL_OUTPUTS],
    pub cos_light: f32,
}

impl Default for SpectralSample {
    fn default() -> Self {
        SpectralSample {
            x: [0.0; INPUTS],
            log_target: [0.0; SPECTRAL_OUTPUTS],
            cos_light: 0.0,
        }
    }
}

impl TrainingSample for SpectralSample {
    const OUTPUTS: usize = SPECTRAL_OUTPUTS;

    #[inline(always)]
    fn input(&self) -> &[f32; INPUTS] {
        &self.x
    }

    #[inline(always)]
    fn log_targets(&self) -> &[f32] {
        &self.log_target
    }

    #[inline(always)]
    fn cos_light(&self) -> f32 {
        self.cos_light
    }

    fn gather(samples: &[Self], order: &[u32], out: &mut Vec<Self>) {
        // Pieces of about the RGB samples' bytes: a spectral sample is about 4x larger.
        super::dataset::gather(samples, order, out, 1 << 12)
    }
}

/// The least-squares projection of spectra sampled at one set of wavelengths onto the default
/// basis.
#[derive(Clone, Debug)]
pub struct SpectralTarget {
    /// `count x m`, row-major.
    projection: Vec<f64>,
    m: usize,
}

impl SpectralTarget {
    /// For spectra sampled at `wavelengths` (nm): finite, strictly increasing and overlapping
    /// 360-830 nm, else an error naming the problem.
    pub fn new(wavelengths: &[f32]) -> Result<Self> {
        let wavelengths: Vec<f64> = wavelengths.iter().map(|&l| f64::from(l)).collect();
        let projection = SpectralBasis::default().least_squares(&wavelengths)?;
        Ok(SpectralTarget {
            projection,
            m: wavelengths.len(),
        })
    }

    /// Number of wavelengths.
    pub fn wavelength_count(&self) -> usize {
        self.m
    }

    /// The clamped coefficients of spectrum `values` (`m` of them).
    pub fn coefficients(&self, values: &[f64]) -> [f64; SPECTRAL_OUTPUTS] {
        std::array::from_fn(|k| {
            let row = &self.projection[k * self.m..(k + 1) * self.m];
            let c: f64 = row.iter().zip(values).map(|(p, v)| p * v).sum();
            c.max(0.0)
        })
    }

    /// The sample of a kept pair whose folded `f_r cos_light` spectrum is `f_cos`.
    pub fn sample(
        &self,
        anisotropic: bool,
        view: Vec3,
        light: Vec3,
        f_cos: &[f64],
    ) -> SpectralSample {
        SpectralSample {
            x: crate::coords::network_input_for(anisotropic, view, light),
            log_target: self.coefficients(f_cos).map(|c| c.ln_1p() as f32),
            cos_light: light.z,
        }
    }
}

/// Spectral values at view/light pairs: what a spectral network is trained on.
pub trait SpectralSource: Sync {
    /// Number of pairs.
    fn pairs(&self) -> usize;
    /// The wavelengths (nm) every pair is sampled at.
    fn wavelengths(&self) -> &[f32];
    /// Pair `i`'s `(view, light)`.
    fn directions(&self, i: usize) -> (Vec3, Vec3);
    /// Pair `i`'s `f_r(view, light) cos_light` per wavelength into `a`, and with `b` the
    /// swapped values `f_r(light, view) cos_view`.
    fn values(&self, i: usize, a: &mut [f32], b: Option<&mut [f32]>) -> Result<()>;
    /// Whether swapped values exist (the reciprocal mean needs them).
    fn has_swapped(&self) -> bool;
}

/// Spectral reflectance sampled at view/light pairs.
#[derive(Clone, Copy, Debug)]
pub struct SampledSpectra<'a> {
    pub view: &'a [Vec3],
    pub light: &'a [Vec3],
    /// `m` wavelengths in nm.
    pub wavelengths: &'a [f32],
    /// `f_r(view, light, lambda_j) cos_light` of pair `i` at `[j n + i]`.
    pub eval_cos: &'a [f32],
    /// The same with view and light swapped, needed by [`RglFold::ReciprocalMean`] only.
    pub swapped_eval_cos: Option<&'a [f32]>,
    /// The last `validation` pairs are the validation set.
    pub validation: usize,
}

impl SampledSpectra<'_> {
    /// The first length mismatch, naming the arrays.
    fn check(&self) -> Result<()> {
        let (n, m) = (self.view.len(), self.wavelengths.len());
        let bad = |message: String| Err(NbrdfError::InvalidArgument(message));
        if self.light.len() != n {
            return bad(format!("{n} views and {} lights", self.light.len()));
        }
        for (values, what) in [
            (Some(self.eval_cos), "values"),
            (self.swapped_eval_cos, "swapped values"),
        ] {
            match values {
                Some(v) if Some(v.len()) != m.checked_mul(n) => {
                    return bad(format!(
                        "{} {what} for {n} pairs and {m} wavelengths",
                        v.len()
                    ))
                }
                _ => {}
            }
        }
        Ok(())
    }
}

impl SpectralSource for SampledSpectra<'_> {
    fn pairs(&self) -> usize {
        self.view.len()
    }

    fn wavelengths(&self) -> &[f32] {
        self.wavelengths
    }

    fn directions(&self, i: usize) -> (Vec3, Vec3) {
        (self.view[i], self.light[i])
    }

    fn values(&self, i: usize, a: &mut [f32], b: Option<&mut [f32]>) -> Result<()> {
        let n = self.view.len();
        for (j, v) in a.iter_mut().enumerate() {
            *v = self.eval_cos[j * n + i];
        }
        if let (Some(b), Some(swapped)) = (b, self.swapped_eval_cos) {
            for (j, v) in b.iter_mut().enumerate() {
                *v = swapped[j * n + i];
            }
        }
        Ok(())
    }

    fn has_swapped(&self) -> bool {
        self.swapped_eval_cos.is_some()
    }
}

/// The provenance entry `"spectral_target"` of a network trained on spectra sampled at
/// `wavelengths`.
pub fn provenance_entry(wavelengths: &[f32]) -> serde_json::Value {
    serde_json::json!({
        "target": "least-squares coefficients of the piecewise-linear spectrum, clamped at 0",
        "wavelengths": wavelengths.len(),
        "min_nm": wavelengths.first().copied().map(f64::from),
        "max_nm": wavelengths.last().copied().map(f64::from),
    })
}

/// Spectral samples of a range of pairs and what was dropped.
#[derive(Clone, Debug, Default)]
struct SpectralSet {
    samples: Vec<SpectralSample>,
    below_horizon: u64,
    invalid: u64,
}

impl SpectralSet {
    fn append(&mut self, mut other: SpectralSet) {
        self.samples.append(&mut other.samples);
        self.below_horizon += other.below_horizon;
        self.invalid += other.invalid;
    }
}

/// Pairs a block of [`spectral_set`] handles: blocks run in parallel and merge in order.
const BLOCK: usize = 2048;

/// The samples of pairs `range` of `source`, folded as `fold` says.
fn spectral_set(
    source: &dyn SpectralSource,
    target: &SpectralTarget,
    range: Range<usize>,
    fold: RglFold,
    anisotropic: bool,
) -> Result<SpectralSet> {
    let blocks: Vec<Result<SpectralSet>> = range
        .clone()
        .step_by(BLOCK)
        .collect::<Vec<_>>()
        .into_par_iter()
        .map(|start| {
            let block = start..(start + BLOCK).min(range.end);
            spectral_block(source, target, block, fold, anisotropic)
        })
        .collect();
    let mut set = SpectralSet::default();
    for block in blocks {
        set.append(block?);
    }
    Ok(set)
}

fn spectral_block(
    source: &dyn SpectralSource,
    target: &SpectralTarget,
    block: Range<usize>,
    fold: RglFold,
    anisotropic: bool,
) -> Result<SpectralSet> {
    let m = target.wavelength_count();
    let swapped = fold == RglFold::ReciprocalMean;
    let (mut a, mut b, mut f_cos) = (vec![0.0f32; m], vec![0.0f32; m], vec![0.0f64; m]);
    let mut set = SpectralSet::default();
    for i in block {
        source.values(i, &mut a, swapped.then_some(&mut b[..]))?;
        let b = swapped.then_some(&b[..]);
        match fold_pair(i, source.directions(i), fold, &a, b, &mut f_cos)? {
            Folded::BelowHorizon => set.below_horizon += 1,
            Folded::Grazing => set.invalid += 1,
            Folded::Kept(view, light) => {
                set.samples
                    .push(target.sample(anisotropic, view, light, &f_cos))
            }
        }
    }
    Ok(set)
}

/// Trains a spectral network named `name` on `source`, whose last `validation` pairs are the
/// validation set, calling `on_epoch` after every epoch. `config.samples` and
/// `config.validation_fraction` are not read: the source's pairs are the samples.
pub fn train_spectral(
    source: &dyn SpectralSource,
    validation: usize,
    fold: RglFold,
    config: &TrainConfig,
    name: &str,
    on_epoch: &mut dyn FnMut(&EpochStats),
) -> Result<TrainOutcome> {
    let start = Instant::now();
    let n = source.pairs();
    if validation == 0 || validation >= n {
        return Err(NbrdfError::InvalidArgument(format!(
            "{n} pairs with {validation} for validation: at least one pair each for training \
             and validation is needed"
        )));
    }
    if fold == RglFold::ReciprocalMean && !source.has_swapped() {
        return Err(NbrdfError::InvalidArgument(
            "the reciprocal mean needs the swapped values".into(),
        ));
    }
    let target = SpectralTarget::new(source.wavelengths())?;
    let split = n - validation;
    let train = spectral_set(source, &target, 0..split, fold, config.anisotropic)?;
    let valid = spectral_set(source, &target, split..n, fold, config.anisotropic)?;
    if train.samples.is_empty() || valid.samples.is_empty() {
        return Err(NbrdfError::InvalidArgument(
            "no pair is above the horizon in the training or the validation set".into(),
        ));
    }
    let sets = SampleSets {
        train: &train.samples,
        validation: &valid.samples,
        dropped_below_horizon: train.below_horizon,
        dropped_invalid: train.invalid,
    };
    let spectral = Spectral::new(SpectralBasis::default())?;
    train_on_samples(&sets, config, name, Some(spectral), start, on_epoch)
}

/// [`train_spectral`] on arrays, after checking their lengths.
pub fn train_spectral_arrays(
    arrays: &SampledSpectra<'_>,
    fold: RglFold,
    config: &TrainConfig,
    name: &str,
    on_epoch: &mut dyn FnMut(&EpochStats),
) -> Result<TrainOutcome> {
    arrays.check()?;
    train_spectral(arrays, arrays.validation, fold, config, name, on_epoch)
}

#[cfg(test)]
mod tests;
