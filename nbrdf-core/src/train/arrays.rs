//! Training from sampled arrays: reflectance that a caller computed at the trainer's own sample
//! directions ([`sample_directions`]), as `python -m nbrdf_mitsuba.distill` does with any
//! Mitsuba 3 BSDF. The optimisation is [`super::train_on_sets`], the one of every source.
//!
//! Loss decisions, as for RGL measurements ([`crate::source`]):
//! * Values are `f_r(view, light) cos_light`, what Mitsuba's `BSDF::eval(si.wi = view,
//!   wo = light)` returns. The loss compares `ln(1 + f cos_light)`, so it is taken from them as
//!   they are and the `1 / cos` of `f` never reaches the loss: no blow-up at the horizon.
//! * Reciprocity: [`RglFold::AsMeasured`] learns the values as given, what a scene with the
//!   BSDF renders. [`RglFold::ReciprocalMean`] also needs the swapped values `eval(wi = light,
//!   wo = view) = f(light, view) cos_view` and learns `(f(v, l) + f(l, v)) / 2 cos_light =
//!   (a + b cos_light / cos_view) / 2`; that ratio grows without bound at grazing views, so pairs
//!   with either cosine below [`GRAZING_COS`](crate::source::GRAZING_COS) are dropped, as for RGL measurements
//!   ([`sample_directions_for`] with that fold draws none, replacing them by the next candidates).
//! * Out-of-gamut values (slightly negative) are clamped to 0. A value that is not finite is an
//!   error naming the pair: a BSDF returning NaN is broken, and dropping its samples would hide it.
//! * Pairs at or below the horizon (either `z <= 0`) are dropped, as the trainer drops them.

use super::dataset::{self, DataSet};
use super::{train_on_sets, EpochStats, TrainConfig, TrainOutcome};
use crate::error::{NbrdfError, Result};
use crate::rng::Stream;
use crate::source::RglFold;
use glam::Vec3;
use std::time::Instant;

/// The trainer's sample directions for `config`: `config.samples` training pairs followed by
/// the validation pairs (`config.validation_fraction` of them, at least 1), each
/// `(view, light)` in the local frame (z up), above the horizon. These are the directions
/// [`super::train`] draws for a target valid everywhere, from the same random streams.
pub fn sample_directions(config: &TrainConfig) -> Result<(Vec<(Vec3, Vec3)>, usize)> {
    sample_directions_for(config, RglFold::AsMeasured)
}

/// [`sample_directions`] for a target folded as `fold` says: pairs the fold leaves out
/// ([`RglFold::trains_on`]) are replaced by the next candidates, as [`super::train`] replaces
/// them for an RGL measurement, so that `config.samples` pairs are trained on.
pub fn sample_directions_for(
    config: &TrainConfig,
    fold: RglFold,
) -> Result<(Vec<(Vec3, Vec3)>, usize)> {
    config.validate()?;
    let validation = config.validation_samples();
    let keep = |v: Vec3, l: Vec3| fold.trains_on(f64::from(v.z), f64::from(l.z));
    let draw = |count, stream| {
        dataset::draw_directions_where(
            config.sampling,
            config.anisotropic,
            count,
            config.seed,
            stream,
            keep,
        )
    };
    let mut pairs = draw(config.samples, Stream::TrainSamples);
    pairs.extend(draw(validation, Stream::ValidationSamples));
    Ok((pairs, validation))
}

/// Reflectance sampled at view/light pairs; the last `validation` pairs are the validation set.
#[derive(Clone, Copy, Debug)]
pub struct SampledArrays<'a> {
    pub view: &'a [Vec3],
    pub light: &'a [Vec3],
    /// `f_r(view, light) cos_light` per pair, linear RGB.
    pub eval_cos: &'a [[f32; 3]],
    /// `f_r(light, view) cos_view` per pair (Mitsuba's eval with the two swapped), needed by
    /// [`RglFold::ReciprocalMean`] only.
    pub swapped_eval_cos: Option<&'a [[f32; 3]]>,
    pub validation: usize,
}

impl SampledArrays<'_> {
    fn check(&self, fold: RglFold) -> Result<()> {
        let n = self.view.len();
        let bad = |message: String| Err(NbrdfError::InvalidArgument(message));
        if self.light.len() != n || self.eval_cos.len() != n {
            return bad(format!(
                "the arrays differ in length: {n} views, {} lights, {} values",
                self.light.len(),
                self.eval_cos.len()
            ));
        }
        match (fold, self.swapped_eval_cos) {
            (RglFold::ReciprocalMean, None) => {
                return bad("the reciprocal mean needs the swapped values".into())
            }
            (_, Some(swapped)) if swapped.len() != n => {
                return bad(format!("{} swapped values for {n} pairs", swapped.len()))
            }
            _ => {}
        }
        if self.validation == 0 || self.validation >= n {
            return bad(format!(
                "{n} pairs with {} for validation: at least one pair each for training and \
                 validation is needed",
                self.validation
            ));
        }
        Ok(())
    }

    /// Training and validation samples, folded as `fold` says, with the network input of an
    /// isotropic or `anisotropic` network.
    pub fn data_sets(&self, fold: RglFold, anisotropic: bool) -> Result<(DataSet, DataSet)> {
        self.check(fold)?;
        let split = self.view.len() - self.validation;
        Ok((
            self.data_set(0..split, fold, anisotropic)?,
            self.data_set(split..self.view.len(), fold, anisotropic)?,
        ))
    }

    fn data_set(
        &self,
        range: std::ops::Range<usize>,
        fold: RglFold,
        anisotropic: bool,
    ) -> Result<DataSet> {
        let mut set = DataSet {
            samples: Vec::with_capacity(range.len()),
            ..DataSet::default()
        };
        let mut f_cos = [0.0f64; 3];
        for i in range {
            set.candidates += 1;
            let (a, b) = (&self.eval_cos[i], self.swapped_eval_cos.map(|s| &s[i][..]));
            let pair = (self.view[i], self.light[i]);
            match fold_pair(i, pair, fold, a, b, &mut f_cos)? {
                Folded::BelowHorizon => set.below_horizon += 1,
                Folded::Grazing => set.invalid += 1,
                Folded::Kept(view, light) => {
                    set.samples
                        .push(dataset::sample(anisotropic, view, light, f_cos))
                }
            }
        }
        Ok(set)
    }
}

/// What a pair of [`fold_pair`] became.
#[derive(Clone, Copy, Debug, PartialEq)]
pub(crate) enum Folded {
    BelowHorizon,
    /// A cosine below [`GRAZING_COS`](crate::source::GRAZING_COS) under the reciprocal mean.
    Grazing,
    /// Kept, with its unit directions.
    Kept(Vec3, Vec3),
}

/// The target values `f_cos` (one per channel or wavelength, `>= 0`) of pair `i` from its values
/// `a` and swapped values `b`, folded as `fold` says; an error naming the pair for a value or a
/// direction that is not finite. `f_cos` is written only for a kept pair.
pub(crate) fn fold_pair(
    i: usize,
    (view, light): (Vec3, Vec3),
    fold: RglFold,
    a: &[f32],
    b: Option<&[f32]>,
    f_cos: &mut [f64],
) -> Result<Folded> {
    if let Some(bad) = a
        .iter()
        .chain(b.iter().copied().flatten())
        .find(|c| !c.is_finite())
    {
        return Err(NbrdfError::InvalidArgument(format!(
            "the value at pair {i} (view {view}, light {light}) is {bad}: the source \
             returned a value that is not a finite number"
        )));
    }
    if !(view.is_finite() && light.is_finite()) {
        return Err(NbrdfError::InvalidArgument(format!(
            "pair {i} has a direction that is not finite (view {view}, light {light})"
        )));
    }
    if view.z <= 0.0 || light.z <= 0.0 {
        return Ok(Folded::BelowHorizon);
    }
    let (view, light) = (unit(view), unit(light));
    let (cos_view, cos_light) = (f64::from(view.z), f64::from(light.z));
    if !fold.trains_on(cos_view, cos_light) {
        return Ok(Folded::Grazing);
    }
    match fold {
        RglFold::AsMeasured => {
            for (f, &a) in f_cos.iter_mut().zip(a) {
                *f = f64::from(a).max(0.0);
            }
        }
        RglFold::ReciprocalMean => {
            let b = b.expect("checked: the reciprocal mean has swapped values");
            for ((f, &a), &b) in f_cos.iter_mut().zip(a).zip(b) {
                *f = (0.5 * (f64::from(a) + f64::from(b) * cos_light / cos_view)).max(0.0);
            }
        }
    }
    Ok(Folded::Kept(view, light))
}

/// `d` normalised, unless it is a unit vector already: the trainer's own directions are kept
/// bit for bit, so that their samples are those [`super::train`] would make.
fn unit(d: Vec3) -> Vec3 {
    if (d.length_squared() - 1.0).abs() <= 1e-6 {
        d
    } else {
        d.normalize()
    }
}

/// Trains a network named `name` on `arrays`, calling `on_epoch` after every epoch.
/// `config.samples` and `config.validation_fraction` are not read: the arrays are the samples.
pub fn train_arrays(
    arrays: &SampledArrays<'_>,
    fold: RglFold,
    config: &TrainConfig,
    name: &str,
    on_epoch: &mut dyn FnMut(&EpochStats),
) -> Result<TrainOutcome> {
    let start = Instant::now();
    let (train_set, validation) = arrays.data_sets(fold, config.anisotropic)?;
    if train_set.samples.is_empty() || validation.samples.is_empty() {
        return Err(NbrdfError::InvalidArgument(format!(
            "no pair is above the horizon in the {} set",
            if train_set.samples.is_empty() {
                "training"
            } else {
                "validation"
            }
        )));
    }
    train_on_sets(&train_set, &validation, config, name, start, on_epoch)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::coords::RusinkiewiczAngles;
    use crate::fit::phong::PhongParams;
    use crate::source::GRAZING_COS;
    use crate::train::adam::AdamConfig;
    use crate::train::dataset::AngularSampling;
    use crate::train::Trainer;

    const PHONG: PhongParams = PhongParams {
        kd: [0.5, 0.3, 0.2],
        ks: [0.3, 0.3, 0.3],
        exponent: 8.0,
    };

    /// The closed-form oracle by angles, for the trainer's own draws.
    fn phong_by_angles(a: &RusinkiewiczAngles) -> Option<[f64; 3]> {
        Some(PHONG.eval(a.theta_h.cos()))
    }

    /// The same by directions, as a caller of the arrays sees it.
    fn phong(view: Vec3, light: Vec3) -> [f64; 3] {
        let h = (view.as_dvec3() + light.as_dvec3()).normalize();
        PHONG.eval(h.z)
    }

    use crate::train::tests::{log_error_on_fresh_directions, small_config};

    struct Owned {
        view: Vec<Vec3>,
        light: Vec<Vec3>,
        eval_cos: Vec<[f32; 3]>,
        swapped: Vec<[f32; 3]>,
        validation: usize,
    }

    impl Owned {
        fn arrays(&self, swapped: bool) -> SampledArrays<'_> {
            SampledArrays {
                view: &self.view,
                light: &self.light,
                eval_cos: &self.eval_cos,
                swapped_eval_cos: swapped.then_some(&self.swapped[..]),
                validation: self.validation,
            }
        }
    }

    /// `f(view, light) cos_light` (and swapped) at the trainer's directions for `config`.
    fn sampled(config: &TrainConfig, f: impl Fn(Vec3, Vec3) -> [f64; 3]) -> Owned {
        let (pairs, validation) = sample_directions(config).unwrap();
        let eval = |v: Vec3, l: Vec3| f(v, l).map(|c| (c * f64::from(l.z)) as f32);
        Owned {
            view: pairs.iter().map(|p| p.0).collect(),
            light: pairs.iter().map(|p| p.1).collect(),
            eval_cos: pairs.iter().map(|&(v, l)| eval(v, l)).collect(),
            swapped: pairs.iter().map(|&(v, l)| eval(l, v)).collect(),
            validation,
        }
    }

    #[test]
    fn sample_directions_are_those_the_trainer_draws() {
        for sampling in [AngularSampling::Adaptive, AngularSampling::Uniform] {
            for anisotropic in [false, true] {
                let config = TrainConfig {
                    sampling,
                    samples: 3000,
                    anisotropic,
                    ..small_config()
                };
                let (pairs, validation) = sample_directions(&config).unwrap();
                assert_eq!((pairs.len(), validation), (3300, 300));
                let (train, valid) = crate::train::draw_sets(&|_| Some([0.0; 3]), &config).unwrap();
                let drawn = train.samples.iter().chain(&valid.samples);
                for (&(v, l), s) in pairs.iter().zip(drawn) {
                    assert_eq!(crate::coords::network_input_for(anisotropic, v, l), s.x);
                    assert_eq!(l.z, s.cos_light);
                    assert!(v.z > 0.0 && (v.length() - 1.0).abs() < 1e-6);
                }
                // Adaptive sampling draws phi_h only for anisotropic networks: their half
                // vectors leave the x-z plane.
                let off_plane = pairs
                    .iter()
                    .filter(|(v, l)| (*v + *l).normalize().y.abs() > 0.1)
                    .count();
                if sampling == AngularSampling::Adaptive && !anisotropic {
                    assert_eq!(off_plane, 0);
                } else {
                    assert!(off_plane > 1000, "{sampling} {anisotropic} {off_plane}");
                }
            }
        }
    }

    /// The reciprocal mean's directions replace the grazing pairs it leaves out, so that the
    /// spectral trainer gets `config.samples` pairs, those the RGB trainer keeps for a target
    /// that is `None` at grazing angles (as `source::rgl_target` is).
    #[test]
    fn reciprocal_mean_directions_replace_grazing_pairs_as_the_trainer_does() {
        for sampling in [AngularSampling::Adaptive, AngularSampling::Uniform] {
            let config = TrainConfig {
                sampling,
                samples: 3000,
                ..small_config()
            };
            let (pairs, validation) =
                sample_directions_for(&config, RglFold::ReciprocalMean).unwrap();
            assert_eq!((pairs.len(), validation), (3300, 300));
            let grazing =
                |v: Vec3, l: Vec3| (v.z as f64) < GRAZING_COS || (l.z as f64) < GRAZING_COS;
            assert!(pairs.iter().all(|&(v, l)| !grazing(v, l)));
            let (all, _) = sample_directions(&config).unwrap();
            assert!(all.iter().any(|&(v, l)| grazing(v, l)), "{sampling}");
            let target = |a: &RusinkiewiczAngles| {
                let (v, l) = crate::coords::from_rusinkiewicz(a);
                (!grazing(v.as_vec3(), l.as_vec3())).then_some([0.0; 3])
            };
            let (train, valid) = crate::train::draw_sets(&target, &config).unwrap();
            let drawn: Vec<_> = train.samples.iter().chain(&valid.samples).collect();
            assert_eq!(drawn.len(), pairs.len());
            for (&(v, l), s) in pairs.iter().zip(&drawn) {
                assert_eq!(crate::coords::network_input_for(false, v, l), s.x);
                assert_eq!(l.z, s.cos_light);
            }
        }
    }

    /// An elliptical highlight, narrow along x and wide along y (in the half vector's slopes).
    fn elliptical(view: Vec3, light: Vec3) -> [f64; 3] {
        let h = (view.as_dvec3() + light.as_dvec3()).normalize();
        let (sx, sy) = (h.x / h.z, h.y / h.z);
        let k = 0.1 + 2.0 * (-(sx / 0.15).powi(2) - (sy / 0.6).powi(2)).exp();
        [k, k, k]
    }

    #[test]
    fn anisotropic_arrays_train_a_network_that_follows_phi_h() {
        let config = TrainConfig {
            samples: 8000,
            max_epochs: 40,
            ..small_config()
        };
        let error = |anisotropic: bool| {
            let config = TrainConfig {
                anisotropic,
                ..config.clone()
            };
            let owned = sampled(&config, elliptical);
            let outcome = train_arrays(
                &owned.arrays(false),
                RglFold::AsMeasured,
                &config,
                "e",
                &mut |_| {},
            )
            .unwrap();
            assert_eq!(outcome.network.anisotropic, anisotropic);
            // Log-space error on fresh uniform pairs, computed here from the directions.
            let test = sampled(
                &TrainConfig {
                    sampling: AngularSampling::Uniform,
                    samples: 3000,
                    seed: 77,
                    ..config.clone()
                },
                elliptical,
            );
            let (set, _) = test
                .arrays(false)
                .data_sets(RglFold::AsMeasured, anisotropic)
                .unwrap();
            let trainer = Trainer::from_layers(&outcome.network.layers, 64, AdamConfig::default());
            trainer.validation_loss(&set.samples)
        };
        let (aniso, iso) = (error(true), error(false));
        assert!(aniso < 0.5 * iso, "anisotropic {aniso} vs isotropic {iso}");
    }

    #[test]
    fn arrays_of_a_closed_form_train_a_network_that_matches_it() {
        let config = small_config();
        let owned = sampled(&config, phong);
        let outcome = train_arrays(
            &owned.arrays(false),
            RglFold::AsMeasured,
            &config,
            "p",
            &mut |_| {},
        )
        .unwrap();
        assert_eq!(outcome.report.train_samples, 4000);
        assert_eq!(outcome.report.validation_samples, 400);
        // Log-space error against the closed form on fresh directions, drawn by the trainer
        // from the angles (an independent path to the same reflectance).
        let error = log_error_on_fresh_directions(&phong_by_angles, &outcome.network.layers);
        assert!(error < 5e-3, "{error} {:?}", outcome.report.history);
        // A caller that passed f instead of f cos_light trains a network that is far off.
        let f_only = Owned {
            eval_cos: owned
                .view
                .iter()
                .zip(&owned.light)
                .map(|(&v, &l)| phong(v, l).map(|c| c as f32))
                .collect(),
            ..sampled(&config, phong)
        };
        let wrong = train_arrays(
            &f_only.arrays(false),
            RglFold::AsMeasured,
            &config,
            "p",
            &mut |_| {},
        )
        .unwrap();
        let wrong_error = log_error_on_fresh_directions(&phong_by_angles, &wrong.network.layers);
        assert!(wrong_error > 10.0 * error.max(1e-3));
    }

    /// Not reciprocal: brighter towards a high light than a high viewer.
    fn lopsided(view: Vec3, light: Vec3) -> [f64; 3] {
        let k = 0.2 + 0.3 * f64::from(light.z) + 0.1 * f64::from(view.x).abs();
        [k, 0.5 * k, 0.25 * k]
    }

    #[test]
    fn the_reciprocal_mean_averages_both_orders_and_skips_grazing_pairs() {
        let config = TrainConfig {
            samples: 20_000,
            sampling: AngularSampling::Uniform,
            ..small_config()
        };
        let owned = sampled(&config, lopsided);
        let (as_given, _) = owned
            .arrays(true)
            .data_sets(RglFold::AsMeasured, false)
            .unwrap();
        let (mean, _) = owned
            .arrays(true)
            .data_sets(RglFold::ReciprocalMean, false)
            .unwrap();
        assert_eq!(as_given.samples.len(), 20_000);
        // Uniform cosines: about 2 % of the pairs have one below 0.01.
        assert!((200..600).contains(&mean.invalid), "{}", mean.invalid);
        assert_eq!(mean.samples.len() as u64 + mean.invalid, 20_000);
        let kept = (0..20_000).filter(|&i| {
            owned.view[i].z as f64 >= GRAZING_COS && owned.light[i].z as f64 >= GRAZING_COS
        });
        for (i, s) in kept.zip(&mean.samples) {
            let (v, l) = (owned.view[i], owned.light[i]);
            let f = 0.5 * (lopsided(v, l)[0] + lopsided(l, v)[0]);
            let expect = (f * f64::from(l.z)).ln_1p();
            assert!((f64::from(s.log_target[0]) - expect).abs() < 1e-6, "{i}");
            let given = (lopsided(v, l)[0] * f64::from(l.z)).ln_1p();
            assert!((f64::from(as_given.samples[i].log_target[0]) - given).abs() < 1e-6);
        }
        assert!(owned
            .arrays(false)
            .data_sets(RglFold::ReciprocalMean, false)
            .is_err());
    }

    #[test]
    fn bad_arrays_are_errors_and_low_pairs_are_dropped() {
        let config = TrainConfig {
            samples: 100,
            ..small_config()
        };
        let owned = sampled(&config, phong);
        let error = |owned: &Owned| {
            owned
                .arrays(false)
                .data_sets(RglFold::AsMeasured, false)
                .unwrap_err()
                .to_string()
        };
        let mut nan = sampled(&config, phong);
        nan.eval_cos[7][1] = f32::NAN;
        assert!(error(&nan).contains("pair 7"), "{}", error(&nan));
        let mut short = sampled(&config, phong);
        short.light.pop();
        assert!(error(&short).contains("differ in length"));
        for validation in [0, owned.view.len()] {
            let split = Owned {
                validation,
                ..sampled(&config, phong)
            };
            assert!(error(&split).contains("validation"));
        }
        let mut low = sampled(&config, phong);
        low.view[3].z = -0.5;
        low.light[4] = Vec3::ZERO;
        low.eval_cos[5] = [-1e-4, 0.0, 0.1];
        let (train, _) = low
            .arrays(false)
            .data_sets(RglFold::AsMeasured, false)
            .unwrap();
        assert_eq!((train.below_horizon, train.samples.len()), (2, 98));
        assert_eq!(train.samples[3].log_target[0], 0.0);
    }
}
