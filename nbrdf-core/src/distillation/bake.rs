//! Baking a trained model into a [`TexturedNbrdf`]: the latent channels of every texel are the
//! encoder's code of that texel's source parameters, the lobe channels its representative's
//! lobe ([`super::representatives`]).

use super::representatives::{assign, fit_lobes, representatives, MAX_REPRESENTATIVES};
use super::samples::no_textures;
use super::trainer::TexturedModel;
use crate::error::{NbrdfError, Result};
use crate::textured::{
    encode_exponent, LatentTexture, SamplingChannels, TexturedNbrdf, UvMapping, MAX_TEXTURE_SIDE,
};

/// The source's parameters at every texel: `width x height` texels of `channels` values,
/// texel-major (`values[(y * width + x) * channels + k]`), row `y = 0` at `v = 0` like the
/// latent texture it becomes.
#[derive(Clone, Copy, Debug)]
pub struct ParameterImage<'a> {
    pub width: usize,
    pub height: usize,
    pub channels: usize,
    pub values: &'a [f32],
}

impl ParameterImage<'_> {
    /// Why the image cannot be baked with an encoder of `parameters` inputs, if it cannot.
    fn check(&self, parameters: usize) -> Result<()> {
        let bad = |m: String| Err(NbrdfError::InvalidArgument(m));
        if self.channels == 0 {
            return Err(no_textures());
        }
        if !(1..=MAX_TEXTURE_SIDE).contains(&self.width)
            || !(1..=MAX_TEXTURE_SIDE).contains(&self.height)
        {
            return bad(format!(
                "parameter image of {} x {} texels: width and height must be in [1, \
                 {MAX_TEXTURE_SIDE}]",
                self.width, self.height
            ));
        }
        if self.channels != parameters {
            return bad(format!(
                "the parameter image has {} channels, the encoder reads {parameters} parameters",
                self.channels
            ));
        }
        let expected = self.width * self.height * self.channels;
        if self.values.len() != expected {
            return bad(format!(
                "parameter image of {} x {} texels and {} channels needs {expected} values, got {}",
                self.width,
                self.height,
                self.channels,
                self.values.len()
            ));
        }
        if let Some(at) = self.values.iter().position(|v| !v.is_finite()) {
            let (texel, k) = (at / self.channels, at % self.channels);
            return bad(format!(
                "parameter image: parameter {k} of texel (x {}, y {}) is {}",
                texel % self.width,
                texel / self.width,
                self.values[at]
            ));
        }
        Ok(())
    }
}

/// How a model is baked.
#[derive(Clone, Debug, PartialEq)]
pub struct BakeConfig {
    pub name: String,
    /// Where [`TexturedNbrdf::save`] writes the texture, relative to the JSON file's folder.
    pub texture_path: String,
    pub mapping: UvMapping,
    /// The lobe channels: none (cosine sampling), one lobe or two.
    pub sampling: SamplingChannels,
    /// The most representative codes whose lobes are fitted (at most
    /// [`MAX_REPRESENTATIVES`]).
    pub representatives: usize,
    pub lobe_fit: crate::fit::lobes::LobeFitConfig,
}

impl BakeConfig {
    /// A material `name` with its texture `name.exr`, Mitsuba's default mapping, one lobe and
    /// 64 representatives.
    pub fn new(name: &str) -> Self {
        BakeConfig {
            name: name.to_string(),
            texture_path: format!("{name}.exr"),
            mapping: UvMapping::default(),
            sampling: SamplingChannels::one_lobe(),
            representatives: 64,
            lobe_fit: Default::default(),
        }
    }
}

/// What [`bake`] is doing, for progress reports.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum BakeStage {
    /// The codes of all texels are computed.
    Encoded { texels: usize },
    /// A k-means iteration over the codes (they may stop before the last).
    Clustering { iteration: usize, iterations: usize },
    /// Lobes fitted for `done` of `total` representatives.
    FittingLobes { done: usize, total: usize },
}

/// Bakes `model` over `image` into a material.
pub fn bake(
    model: &TexturedModel,
    image: &ParameterImage<'_>,
    config: &BakeConfig,
    progress: &mut dyn FnMut(BakeStage),
) -> Result<TexturedNbrdf> {
    image.check(model.parameter_count())?;
    if !(1..=MAX_REPRESENTATIVES).contains(&config.representatives) {
        return Err(NbrdfError::InvalidArgument(format!(
            "representatives {} must be in [1, {MAX_REPRESENTATIVES}]",
            config.representatives
        )));
    }
    let channels = model.decoder.latent_channels();
    let codes = super::joint::encode(&model.weights(), image.values, image.channels);
    let texels = image.width * image.height;
    progress(BakeStage::Encoded { texels });
    let lobe_values = config.sampling.channel_count();
    let lobe_channels = if lobe_values == 0 {
        vec![Vec::new(); texels]
    } else {
        let centres = representatives(&codes, channels, config.representatives, &mut |i, n| {
            progress(BakeStage::Clustering {
                iteration: i,
                iterations: n,
            })
        });
        let mut lobes = Vec::with_capacity(centres.len());
        for (done, centre) in centres.iter().enumerate() {
            let fitted = fit_lobes(&model.decoder, centre, lobe_values / 2, &config.lobe_fit)?;
            lobes.push(stored_lobes(&fitted));
            progress(BakeStage::FittingLobes {
                done: done + 1,
                total: centres.len(),
            });
        }
        let points: Vec<&[f32]> = codes.chunks_exact(channels).collect();
        assign(&points, &centres)
            .into_iter()
            .map(|c| lobes[c].clone())
            .collect()
    };
    let mut values = Vec::with_capacity(texels * (channels + lobe_values));
    for (code, lobes) in codes.chunks_exact(channels).zip(&lobe_channels) {
        values.extend_from_slice(code);
        values.extend_from_slice(lobes);
    }
    let names = TexturedNbrdf::channel_names_for(channels, &config.sampling);
    let texture = LatentTexture::new(image.width, image.height, names, values)?;
    let material = TexturedNbrdf::new(
        config.name.clone(),
        model.decoder.clone(),
        texture,
        config.mapping,
        config.sampling.clone(),
        config.texture_path.clone(),
    )?;
    Ok(material.with_provenance(provenance(model, config, image)))
}

/// Fitted lobes `[n, w, ...]` as the texture stores them (exponents encoded).
fn stored_lobes(fitted: &[f64]) -> Vec<f32> {
    fitted
        .chunks(2)
        .flat_map(|lobe| [encode_exponent(lobe[0]), lobe[1] as f32])
        .collect()
}

fn provenance(
    model: &TexturedModel,
    config: &BakeConfig,
    image: &ParameterImage<'_>,
) -> serde_json::Value {
    let report = &model.report;
    serde_json::json!({
        "trainer": crate::train::TRAINER_VERSION,
        "distillation": "encoder of the source's texture parameters, baked per texel",
        "parameters": image.channels,
        "encoder_widths": std::iter::once(model.parameter_count())
            .chain(model.encoder.iter().map(|l| l.outputs))
            .collect::<Vec<_>>(),
        "representatives": config.representatives,
        "samples": report.train_samples,
        "validation_samples": report.validation_samples,
        "epochs": report.epochs_run,
        "best_epoch": report.best_epoch,
        "best_validation_loss": report.best_validation_loss,
        "loss": "mean |ln(1 + f cos) - ln(1 + f_net cos)| over samples and channels",
        "seconds": (report.seconds * 1000.0).round() / 1000.0,
    })
}
