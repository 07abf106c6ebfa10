//! Spatially varying neural materials (Zeltner et al. 2023, "Real-Time Neural Appearance
//! Models"; Kuznetsov et al. 2021, NeuMIP): one decoder MLP per material reads a latent code of
//! `C` channels, looked up in a texture at the hit's UV, together with the six direction
//! features of the homogeneous network, and gives `f_r` in RGB, or the coefficients of its
//! spectrum in a spectral basis (a spectral material: its RGB value is their sRGB projection,
//! as for a spectral network). Sampling reads Blinn-Phong lobe parameters baked into extra
//! channels of the same texture (docs/textured.md; the files: docs/formats.md).
//!
//! * `texture.rs`: the texture ([`LatentTexture`]) and its lookup ([`UvMapping`]: `to_uv`,
//!   wrap mode, nearest or bilinear filtering, as Mitsuba's `bitmap`);
//! * `exr_file.rs`: reading and writing the texture as an OpenEXR file;
//! * `decoder.rs`: the [`Decoder`] and its forward pass;
//! * `lobes.rs`: the lobe channels ([`SamplingChannels`]) and the strategy they give;
//! * `spectral.rs`: a spectral material's value per wavelength;
//! * `format.rs`: the `*.nbrdf.json` file (version [`FORMAT_VERSION_TEXTURED`]) and
//!   [`NeuralMaterial`], which loads either kind of file;
//! * this file: [`TexturedNbrdf`], its evaluation and sampling, one hit or a batch.
//!
//! Conventions are the crate's: view first, then light, both in the shading frame (z = normal);
//! `eval_cos` is `f_r cos(theta_light)`, what Mitsuba's `BSDF.eval` returns. A hit whose UV maps
//! to a non-finite position, or whose footprint holds a non-finite latent value, is a bad
//! texel: the material is 0 there and samples the cosine lobe.

mod decoder;
mod exr_file;
#[cfg(test)]
mod file_tests;
mod format;
mod lobes;
#[cfg(test)]
pub(crate) mod sampling_tests;
mod spectral;
#[cfg(test)]
mod spectral_tests;
#[cfg(test)]
mod tests;
mod texture;

pub use decoder::{Decoder, MAX_DECODER_LAYERS, MAX_DECODER_WIDTH, MAX_LATENT_CHANNELS};
pub use exr_file::{TexturePrecision, MAX_EXR_BYTES};
pub use format::NeuralMaterial;
pub use lobes::{
    decode_exponent, encode_exponent, strategy_of, LobeChannels, SamplingChannels,
    EXPONENT_ENCODING, FILTER_SLACK, LOBE_MODEL, MAX_LOBES,
};
pub use texture::{
    FilterMode, Footprint, LatentTexture, UvMapping, UvTransform, WrapMode, MAX_TEXTURE_SIDE,
    MAX_TEXTURE_VALUES,
};

pub use crate::network::FORMAT_VERSION_TEXTURED;

use crate::brdf::{common_len, cos_theta_light, Directions, DirectionsMut, RgbMut};
use crate::coords::network_input_for;
use crate::error::{NbrdfError, Result};
#[cfg(any(target_arch = "x86", target_arch = "x86_64"))]
use crate::fastmath::Fused;
use crate::fastmath::{MulAdd, Unfused};
use crate::sampling::{
    sample_tasks, sample_weight, split_chunks, DirectionSample, SampleOut, SamplingStrategy,
};
use glam::Vec3;
use rayon::prelude::*;

/// Lanes per rayon task of the batched entry points.
const TASK_LANES: usize = 1024;

/// UVs of a batch, one slice per coordinate.
#[derive(Clone, Copy, Debug)]
pub struct Uvs<'a> {
    pub u: &'a [f32],
    pub v: &'a [f32],
}

impl<'a> Uvs<'a> {
    /// The lanes both slices have.
    pub fn min_len(&self) -> usize {
        self.u.len().min(self.v.len())
    }

    pub fn get(&self, i: usize) -> [f32; 2] {
        [self.u[i], self.v[i]]
    }
}

/// The name of latent channel `k` in the texture, `latent.k`.
pub fn latent_channel_name(k: usize) -> String {
    format!("latent.{k}")
}

/// A spatially varying material: decoder, latent texture, how the texture is mapped, and which
/// of its channels hold the sampling lobes.
#[derive(Clone, Debug, PartialEq)]
pub struct TexturedNbrdf {
    name: String,
    decoder: Decoder,
    texture: LatentTexture,
    mapping: UvMapping,
    sampling: SamplingChannels,
    texture_path: String,
    provenance: serde_json::Value,
}

impl TexturedNbrdf {
    /// A material from its parts. The texture's channels must be, in this order,
    /// `latent.0 .. latent.{C-1}` then each lobe's exponent and weight channel
    /// ([`TexturedNbrdf::channel_names_for`]); `texture_path` is where [`TexturedNbrdf::save`]
    /// writes the texture, relative to the JSON file's folder.
    pub fn new(
        name: impl Into<String>,
        decoder: Decoder,
        texture: LatentTexture,
        mapping: UvMapping,
        sampling: SamplingChannels,
        texture_path: impl Into<String>,
    ) -> Result<Self> {
        let texture_path = texture_path.into();
        let invalid = |message: String| Err(NbrdfError::InvalidArgument(message));
        if texture_path.is_empty() {
            return invalid("latent.path is empty".into());
        }
        if let Some(problem) = mapping.to_uv.problem() {
            return invalid(format!("latent.{problem}"));
        }
        if let Some(problem) = lobe_name_problem(&sampling, decoder.latent_channels()) {
            return invalid(problem);
        }
        let expected = Self::channel_names_for(decoder.latent_channels(), &sampling);
        if texture.channel_names() != expected.as_slice() {
            return invalid(format!(
                "the latent texture's channels are {}, expected {}",
                texture.channel_names().join(", "),
                expected.join(", ")
            ));
        }
        Ok(TexturedNbrdf {
            name: name.into(),
            decoder,
            texture,
            mapping,
            sampling,
            texture_path,
            provenance: serde_json::Value::Object(serde_json::Map::new()),
        })
    }

    /// The texture channels of a material with `latent_channels` latent channels and these
    /// lobes, in texture order.
    pub fn channel_names_for(latent_channels: usize, sampling: &SamplingChannels) -> Vec<String> {
        (0..latent_channels)
            .map(latent_channel_name)
            .chain(sampling.channel_names())
            .collect()
    }

    /// The same material with this free-form provenance record.
    pub fn with_provenance(mut self, provenance: serde_json::Value) -> Self {
        self.provenance = provenance;
        self
    }

    pub fn name(&self) -> &str {
        &self.name
    }

    pub fn decoder(&self) -> &Decoder {
        &self.decoder
    }

    pub fn texture(&self) -> &LatentTexture {
        &self.texture
    }

    pub fn mapping(&self) -> &UvMapping {
        &self.mapping
    }

    pub fn sampling_channels(&self) -> &SamplingChannels {
        &self.sampling
    }

    /// The texture's file, relative to the JSON file's folder, as the file names it.
    pub fn texture_path(&self) -> &str {
        &self.texture_path
    }

    pub fn provenance(&self) -> &serde_json::Value {
        &self.provenance
    }

    /// The texels the hit at `uv` reads, or `None` for a bad texel.
    pub fn footprint(&self, uv: [f32; 2]) -> Option<Footprint> {
        let (width, height) = (self.texture.width(), self.texture.height());
        self.mapping.footprint(width, height, uv)
    }

    /// `f_r(view, light) cos(theta_light)` at the hit `uv`: 0 at or below the horizon, for
    /// non-finite or zero directions and at bad texels; finite and non-negative always.
    pub fn eval_cos(&self, uv: [f32; 2], view: Vec3, light: Vec3) -> [f32; 3] {
        let footprint = self.footprint(uv);
        #[cfg(any(target_arch = "x86", target_arch = "x86_64"))]
        if crate::network::has_avx2_fma() {
            // SAFETY: the CPU has AVX2 and FMA (checked just above), all `eval_avx2` requires.
            return unsafe { self.eval_avx2(footprint.as_ref(), view, light) };
        }
        self.eval_at::<Unfused>(footprint.as_ref(), view, light)
    }

    /// [`TexturedNbrdf::eval_cos`] for a batch, a UV per lane, on all cores; lanes past the
    /// common length of the slices are left as they are.
    pub fn eval_cos_batch(
        &self,
        uv: Uvs<'_>,
        view: Directions<'_>,
        light: Directions<'_>,
        out: RgbMut<'_>,
    ) {
        let n = common_len(&[uv.min_len(), view.min_len(), light.min_len(), out.min_len()]);
        let RgbMut { r, g, b } = out;
        split_chunks([&mut r[..n], &mut g[..n], &mut b[..n]], TASK_LANES)
            .into_par_iter()
            .enumerate()
            .for_each(|(k, [r, g, b])| {
                let lanes = Lanes::new(k * TASK_LANES, uv, view);
                self.eval_chunk(lanes, light, RgbMut { r, g, b });
            });
    }

    /// The sampling strategy at the hit `uv`: its lobes' filtered parameters, cosine without
    /// lobes, at bad texels and where they are out of range ([`strategy_of`]).
    pub fn sampling_strategy(&self, uv: [f32; 2]) -> SamplingStrategy {
        self.strategy_at(self.footprint(uv).as_ref())
    }

    /// A light direction for `view` at the hit `uv` from uniforms `u` (see
    /// [`SamplingStrategy::sample`]), with the pdf [`TexturedNbrdf::pdf`] gives it.
    pub fn sample(&self, uv: [f32; 2], view: Vec3, u: [f32; 3]) -> DirectionSample {
        self.sampling_strategy(uv).sample(view, u)
    }

    /// The density of [`TexturedNbrdf::sample`] per unit solid angle of `light`.
    pub fn pdf(&self, uv: [f32; 2], view: Vec3, light: Vec3) -> f32 {
        self.sampling_strategy(uv).pdf(view, light)
    }

    /// Batched sampling: per lane a light direction, its pdf, and the weight
    /// `f_r cos / pdf` (0 for invalid samples), on all cores; lanes past the common length of
    /// the slices are left as they are.
    pub fn sample_batch(
        &self,
        uv: Uvs<'_>,
        view: Directions<'_>,
        u: Directions<'_>,
        light: DirectionsMut<'_>,
        weight: RgbMut<'_>,
        pdf: &mut [f32],
    ) {
        let n = common_len(&[
            uv.min_len(),
            view.min_len(),
            u.min_len(),
            light.min_len(),
            weight.min_len(),
            pdf.len(),
        ]);
        sample_tasks(light, weight, pdf, n, TASK_LANES)
            .into_par_iter()
            .enumerate()
            .for_each(|(k, out)| {
                self.sample_chunk(Lanes::new(k * TASK_LANES, uv, view), u, out);
            });
    }

    /// Batched [`TexturedNbrdf::pdf`].
    pub fn pdf_batch(
        &self,
        uv: Uvs<'_>,
        view: Directions<'_>,
        light: Directions<'_>,
        pdf: &mut [f32],
    ) {
        let n = common_len(&[uv.min_len(), view.min_len(), light.min_len(), pdf.len()]);
        pdf[..n]
            .par_chunks_mut(TASK_LANES)
            .enumerate()
            .for_each(|(k, p)| {
                for (i, out) in p.iter_mut().enumerate() {
                    let j = k * TASK_LANES + i;
                    *out = self.pdf(uv.get(j), view.get(j), light.get(j));
                }
            });
    }

    /// `f_r cos` in RGB at a footprint (`None`: a bad texel) with `M`'s arithmetic: a spectral
    /// material's projection `M (c cos)`.
    #[inline(always)]
    fn eval_at<M: MulAdd>(
        &self,
        footprint: Option<&Footprint>,
        view: Vec3,
        light: Vec3,
    ) -> [f32; 3] {
        self.outputs_cos_at::<M, _>(footprint, view, light, |f_cos| self.decoder.rgb_of(f_cos))
            .unwrap_or([0.0; 3])
    }

    /// `finish` of the decoder's outputs times `cos(theta_light)` (RGB `f_r cos`, or the
    /// coefficients of its spectrum) at a footprint with `M`'s arithmetic; `None` where the
    /// material is 0: a bad texel (`None` footprint or a non-finite code), at or below the
    /// horizon, for zero or non-finite directions.
    #[inline(always)]
    fn outputs_cos_at<M: MulAdd, R>(
        &self,
        footprint: Option<&Footprint>,
        view: Vec3,
        light: Vec3,
        finish: impl FnOnce(&mut [f32]) -> R,
    ) -> Option<R> {
        let footprint = footprint?;
        let mut code = [0.0f32; MAX_LATENT_CHANNELS];
        let code = &mut code[..self.decoder.latent_channels()];
        self.texture.filter_into::<M>(footprint, 0, code);
        // Normalised in float64, so that very long or short vectors keep their direction; the
        // horizon test in float32, as the homogeneous network's.
        let unit = |d: Vec3| d.as_dvec3().try_normalize().map(|d| d.as_vec3());
        let (v, l) = (unit(view)?, unit(light)?);
        if v.z <= 0.0 || l.z <= 0.0 || !code.iter().all(|c| c.is_finite()) {
            return None;
        }
        let features = network_input_for(self.decoder.anisotropic(), v, l);
        let cos = cos_theta_light(l);
        Some(self.decoder.forward_with::<M, _>(&features, code, |f| {
            f.iter_mut().for_each(|v| *v *= cos);
            finish(f)
        }))
    }

    /// The strategy at a footprint: the lobe channels filtered with portable arithmetic, so that
    /// every caller on every CPU builds the same one.
    fn strategy_at(&self, footprint: Option<&Footprint>) -> SamplingStrategy {
        let lobes = self.sampling.channel_count();
        let Some(footprint) = footprint.filter(|_| lobes > 0) else {
            return SamplingStrategy::Cosine;
        };
        let mut values = [0.0f32; 2 * MAX_LOBES];
        let values = &mut values[..lobes];
        let first = self.decoder.latent_channels();
        self.texture
            .filter_into::<Unfused>(footprint, first, values);
        strategy_of(values)
    }

    #[cfg(any(target_arch = "x86", target_arch = "x86_64"))]
    #[target_feature(enable = "avx2,fma")]
    unsafe fn eval_avx2(&self, footprint: Option<&Footprint>, view: Vec3, light: Vec3) -> [f32; 3] {
        self.eval_at::<Fused>(footprint, view, light)
    }

    /// One task of [`TexturedNbrdf::eval_cos_batch`] with the kernel for this CPU.
    fn eval_chunk(&self, lanes: Lanes<'_>, light: Directions<'_>, out: RgbMut<'_>) {
        #[cfg(any(target_arch = "x86", target_arch = "x86_64"))]
        if crate::network::has_avx2_fma() {
            // SAFETY: the CPU has AVX2 and FMA (checked just above), all it requires.
            return unsafe { self.eval_chunk_avx2(lanes, light, out) };
        }
        self.eval_chunk_with::<Unfused>(lanes, light, out)
    }

    #[cfg(any(target_arch = "x86", target_arch = "x86_64"))]
    #[target_feature(enable = "avx2,fma")]
    unsafe fn eval_chunk_avx2(&self, lanes: Lanes<'_>, light: Directions<'_>, out: RgbMut<'_>) {
        self.eval_chunk_with::<Fused>(lanes, light, out)
    }

    #[inline(always)]
    fn eval_chunk_with<M: MulAdd>(
        &self,
        lanes: Lanes<'_>,
        light: Directions<'_>,
        mut out: RgbMut<'_>,
    ) {
        for i in 0..out.r.len() {
            let j = lanes.start + i;
            let footprint = self.footprint(lanes.uv.get(j));
            out.set(
                i,
                self.eval_at::<M>(footprint.as_ref(), lanes.view.get(j), light.get(j)),
            );
        }
    }

    /// One task of [`TexturedNbrdf::sample_batch`] with the kernel for this CPU.
    fn sample_chunk(&self, lanes: Lanes<'_>, u: Directions<'_>, out: SampleOut<'_>) {
        #[cfg(any(target_arch = "x86", target_arch = "x86_64"))]
        if crate::network::has_avx2_fma() {
            // SAFETY: the CPU has AVX2 and FMA (checked just above), all it requires.
            return unsafe { self.sample_chunk_avx2(lanes, u, out) };
        }
        self.sample_chunk_with::<Unfused>(lanes, u, out)
    }

    #[cfg(any(target_arch = "x86", target_arch = "x86_64"))]
    #[target_feature(enable = "avx2,fma")]
    unsafe fn sample_chunk_avx2(&self, lanes: Lanes<'_>, u: Directions<'_>, out: SampleOut<'_>) {
        self.sample_chunk_with::<Fused>(lanes, u, out)
    }

    /// Each lane's footprint is found once and serves both the strategy and the weight.
    #[inline(always)]
    fn sample_chunk_with<M: MulAdd>(
        &self,
        lanes: Lanes<'_>,
        u: Directions<'_>,
        out: SampleOut<'_>,
    ) {
        let SampleOut {
            mut light,
            mut weight,
            pdf,
        } = out;
        for (i, pdf) in pdf.iter_mut().enumerate() {
            let j = lanes.start + i;
            let (view, uniforms) = (lanes.view.get(j), u.get(j));
            let footprint = self.footprint(lanes.uv.get(j));
            let sample = self
                .strategy_at(footprint.as_ref())
                .sample(view, uniforms.to_array());
            let f_cos = self.eval_at::<M>(footprint.as_ref(), view, sample.light);
            light.set(i, sample.light);
            weight.set(i, f_cos.map(|f| sample_weight(f, sample.pdf)));
            *pdf = sample.pdf;
        }
    }
}

/// The inputs every lane of a task reads, from lane `start` of the batch on.
#[derive(Clone, Copy)]
struct Lanes<'a> {
    start: usize,
    uv: Uvs<'a>,
    view: Directions<'a>,
}

impl<'a> Lanes<'a> {
    fn new(start: usize, uv: Uvs<'a>, view: Directions<'a>) -> Self {
        Lanes { start, uv, view }
    }
}

/// Why the lobes' channel names are unusable, if they are: empty, not printable ASCII, a latent
/// channel's name or repeated. Each problem names the field.
pub(super) fn lobe_name_problem(
    sampling: &SamplingChannels,
    latent_channels: usize,
) -> Option<String> {
    let mut seen: Vec<String> = (0..latent_channels).map(latent_channel_name).collect();
    for (k, lobe) in sampling.lobes().iter().enumerate() {
        for (field, name) in [("exponent", &lobe.exponent), ("weight", &lobe.weight)] {
            let at = format!("sampling.lobes[{k}].{field}");
            if name.is_empty() || name.len() > 255 || !name.bytes().all(|b| b.is_ascii_graphic()) {
                return Some(format!(
                    "{at} '{name}' must be 1 to 255 printable ASCII characters without spaces"
                ));
            }
            if seen.contains(name) {
                return Some(format!(
                    "{at} '{name}' is already a latent or lobe channel's name"
                ));
            }
            seen.push(name.clone());
        }
    }
    None
}
