//! Importance sampling of a spatially varying material: per texel, Blinn-Phong lobe parameters
//! baked into extra texture channels (docs/textured.md). At a hit they are filtered
//! like the latent code, into one [`SamplingStrategy`] (a Blinn-Phong or two-lobe mixture with
//! cosine) that both `sample` and `pdf` use, so the pdf is that strategy's exact density.
//! Parameters outside their range, beyond float32 rounding, give cosine sampling.

use crate::sampling::{exponent_in_range, SamplingStrategy, MAX_EXPONENT};
use serde::{Deserialize, Serialize};

/// The only lobe model of the format.
pub const LOBE_MODEL: &str = "blinn-phong";
/// How a lobe's exponent `n` is stored: `ln(1 + n)`, which float16 holds to 0.4 % relative
/// error for every `n` in `[0, 1e6]`.
pub const EXPONENT_ENCODING: &str = "log1p";
/// The most lobes per texel (a two-lobe mixture).
pub const MAX_LOBES: usize = 2;
/// How far filtered parameters may pass their range and still be clamped into it: the float32
/// rounding of a bilinear sum of in-range values, with room to spare.
pub const FILTER_SLACK: f64 = 1e-5;

/// The texture channels of one lobe: its encoded exponent and its weight in the mixture.
#[derive(Clone, Debug, PartialEq, Eq, Serialize, Deserialize)]
pub struct LobeChannels {
    pub exponent: String,
    pub weight: String,
}

/// Which channels hold the lobes: none (cosine sampling everywhere), one or two.
#[derive(Clone, Debug, Default, PartialEq, Eq)]
pub struct SamplingChannels {
    lobes: Vec<LobeChannels>,
}

impl SamplingChannels {
    /// Cosine sampling everywhere.
    pub fn cosine() -> Self {
        SamplingChannels::default()
    }

    /// One lobe in the channels `lobe.n` (exponent) and `lobe.w` (weight).
    pub fn one_lobe() -> Self {
        SamplingChannels {
            lobes: vec![LobeChannels {
                exponent: "lobe.n".into(),
                weight: "lobe.w".into(),
            }],
        }
    }

    /// Two lobes in `lobe.n1`, `lobe.w1`, `lobe.n2`, `lobe.w2`.
    pub fn two_lobes() -> Self {
        let lobe = |k: usize| LobeChannels {
            exponent: format!("lobe.n{k}"),
            weight: format!("lobe.w{k}"),
        };
        SamplingChannels {
            lobes: vec![lobe(1), lobe(2)],
        }
    }

    /// Lobes in the given channels; at most [`MAX_LOBES`], names checked by the material.
    pub fn new(lobes: Vec<LobeChannels>) -> Option<Self> {
        (lobes.len() <= MAX_LOBES).then_some(SamplingChannels { lobes })
    }

    pub fn lobes(&self) -> &[LobeChannels] {
        &self.lobes
    }

    /// The channel names in texture order: each lobe's exponent, then its weight.
    pub fn channel_names(&self) -> Vec<String> {
        self.lobes
            .iter()
            .flat_map(|lobe| [lobe.exponent.clone(), lobe.weight.clone()])
            .collect()
    }

    /// The channel count, two per lobe.
    pub fn channel_count(&self) -> usize {
        2 * self.lobes.len()
    }
}

/// The stored code of exponent `n`, `ln(1 + n)` with `n` clamped into `[0, MAX_EXPONENT]`
/// (NaN to 0). Writers round it to float16 themselves or through
/// [`super::TexturePrecision::Half`].
pub fn encode_exponent(n: f64) -> f32 {
    let n = if n > 0.0 { n.min(MAX_EXPONENT) } else { 0.0 };
    n.ln_1p() as f32
}

/// The exponent of a stored code, `exp(code) - 1`.
pub fn decode_exponent(code: f64) -> f64 {
    code.exp_m1()
}

/// `x` clamped into `[lo, hi]` when within `FILTER_SLACK` (relative to the range's size) of
/// it; `None` beyond, and for NaN.
fn within(x: f64, lo: f64, hi: f64) -> Option<f64> {
    let slack = FILTER_SLACK * (hi - lo);
    (x >= lo - slack && x <= hi + slack).then(|| x.clamp(lo, hi))
}

/// An exponent from its filtered code, or `None` out of range (the range and its slack are
/// those of the code, `[0, ln(1 + MAX_EXPONENT)]`).
fn exponent(code: f32) -> Option<f64> {
    let code = within(f64::from(code), 0.0, MAX_EXPONENT.ln_1p())?;
    let n = decode_exponent(code).min(MAX_EXPONENT);
    exponent_in_range(n).then_some(n)
}

/// The strategy of filtered lobe values in texture order (`[n1, w1]` or `[n1, w1, n2, w2]`,
/// exponents encoded): Blinn-Phong or two-lobe with cosine; cosine without lobes or where a
/// value is non-finite or out of range (beyond [`FILTER_SLACK`]). Two weights summing to just
/// over 1 by rounding are scaled to sum to 1.
pub fn strategy_of(values: &[f32]) -> SamplingStrategy {
    lobe_strategy(values).unwrap_or(SamplingStrategy::Cosine)
}

fn lobe_strategy(values: &[f32]) -> Option<SamplingStrategy> {
    match *values {
        [n, w] => Some(SamplingStrategy::Phong {
            exponent: exponent(n)?,
            specular_weight: within(f64::from(w), 0.0, 1.0)?,
        }),
        [n1, w1, n2, w2] => {
            let (w1, w2) = (
                within(f64::from(w1), 0.0, 1.0)?,
                within(f64::from(w2), 0.0, 1.0)?,
            );
            let sum = within(w1 + w2, 0.0, 1.0)?;
            let scale = if w1 + w2 > 1.0 { sum / (w1 + w2) } else { 1.0 };
            Some(SamplingStrategy::TwoLobe {
                exponent1: exponent(n1)?,
                weight1: w1 * scale,
                exponent2: exponent(n2)?,
                weight2: w2 * scale,
            })
        }
        _ => None,
    }
}
