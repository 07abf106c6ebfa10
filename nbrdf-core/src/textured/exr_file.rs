//! Latent textures in OpenEXR files (the pure-Rust `exr` crate): one part, float16 or float32
//! channels, looked up by name. The header is checked before any pixel is decoded, so a file of
//! the wrong size or channels is refused without reading it.

use super::texture::{size_problem, LatentTexture};
use crate::error::{NbrdfError, Result};
use exr::prelude as ex;
use exr::prelude::traits::{ReadChannels as _, ReadLayers as _, WritableImage as _};
use std::path::Path;

/// The largest EXR file read: a texture of [`super::texture::MAX_TEXTURE_VALUES`] float32
/// values uncompressed, and room for its headers and offset tables.
pub const MAX_EXR_BYTES: u64 = 5 << 28;

/// The precision of the values in a written file.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum TexturePrecision {
    /// float16, the format's usual one (values round to 11 significant bits; beyond 65504, inf).
    Half,
    /// float32, exact.
    Float,
}

/// What the file says about its size and channels: the one part's, or why it is refused.
fn header_problem(
    meta: &ex::MetaData,
    channel_names: &[String],
    width: usize,
    height: usize,
) -> Option<String> {
    if meta.headers.len() != 1 {
        return Some(format!(
            "{} parts (layers); a latent texture has one",
            meta.headers.len()
        ));
    }
    let header = &meta.headers[0];
    if header.deep {
        return Some("deep data; a latent texture is flat".into());
    }
    let size = header.layer_size;
    if (size.width(), size.height()) != (width, height) {
        return Some(format!(
            "{} x {} texels, but latent.width x latent.height is {width} x {height}",
            size.width(),
            size.height()
        ));
    }
    let found: Vec<String> = header
        .channels
        .list
        .iter()
        .map(|c| c.name.to_string())
        .collect();
    let channels_found = || found.join(", ");
    if let Some(missing) = channel_names.iter().find(|name| !found.contains(name)) {
        return Some(format!(
            "no channel '{missing}' (expected {}; the file has {})",
            channel_names.join(", "),
            channels_found()
        ));
    }
    if let Some(extra) = found.iter().find(|name| !channel_names.contains(name)) {
        return Some(format!(
            "unexpected channel '{extra}' (expected exactly {}; the file has {})",
            channel_names.join(", "),
            channels_found()
        ));
    }
    for channel in &header.channels.list {
        if channel.sample_type == ex::SampleType::U32 {
            return Some(format!(
                "channel '{}' holds 32-bit integers; latent channels are float16 or float32",
                channel.name
            ));
        }
        if channel.sampling != ex::Vec2(1, 1) {
            return Some(format!(
                "channel '{}' is subsampled; latent channels have one value per texel",
                channel.name
            ));
        }
    }
    None
}

impl LatentTexture {
    /// Reads the `width x height` texture at `path` whose channels are exactly `channel_names`
    /// (in any order in the file; in this order in the texture). Errors name the file and what
    /// is wrong: missing or unreadable, another size, a missing, extra or integer channel.
    pub fn read_exr(
        path: &Path,
        channel_names: &[String],
        width: usize,
        height: usize,
    ) -> Result<Self> {
        let fail = |message: String| NbrdfError::format(path, message);
        if let Some(problem) = size_problem(width, height, channel_names.len()) {
            return Err(fail(problem));
        }
        crate::error::regular_file_size(path, MAX_EXR_BYTES, "a latent texture (OpenEXR)")?;
        let meta = ex::MetaData::read_from_file(path, false)
            .map_err(|e| fail(format!("not a readable OpenEXR file: {e}")))?;
        if let Some(problem) = header_problem(&meta, channel_names, width, height) {
            return Err(fail(problem));
        }
        // The decoder is not known to panic on damaged files; if it does, that is a bad file too.
        let image = std::panic::catch_unwind(|| {
            ex::read()
                .no_deep_data()
                .largest_resolution_level()
                .all_channels()
                .first_valid_layer()
                .all_attributes()
                .non_parallel()
                .from_file(path)
        })
        .map_err(|_| fail("the OpenEXR decoder failed on this file".into()))?
        .map_err(|e| fail(format!("not a readable OpenEXR file: {e}")))?;
        let channels = &image.layer_data.channel_data.list;
        let count = channel_names.len();
        let mut texels = vec![0.0f32; width * height * count];
        for (k, name) in channel_names.iter().enumerate() {
            let channel = channels
                .iter()
                .find(|c| c.name.to_string() == *name)
                .ok_or_else(|| fail(format!("no channel '{name}'")))?;
            let values: Vec<f32> = match &channel.sample_data {
                ex::FlatSamples::F16(v) => v.iter().map(|h| h.to_f32()).collect(),
                ex::FlatSamples::F32(v) => v.clone(),
                ex::FlatSamples::U32(_) => {
                    return Err(fail(format!("channel '{name}' holds 32-bit integers")))
                }
            };
            if values.len() != width * height {
                return Err(fail(format!(
                    "channel '{name}' has {} values, expected {width} x {height}",
                    values.len()
                )));
            }
            for (texel, value) in values.into_iter().enumerate() {
                texels[texel * count + k] = value;
            }
        }
        LatentTexture::new(width, height, channel_names.to_vec(), texels)
            .map_err(|e| fail(e.to_string()))
    }

    /// Writes the texture as a one-part, ZIP-compressed OpenEXR file at `precision`, channels
    /// by name in the format's alphabetical order.
    pub fn write_exr(&self, path: &Path, precision: TexturePrecision) -> Result<()> {
        let fail = |message: String| NbrdfError::format(path, message);
        let count = self.channel_count();
        let mut list = ex::SmallVec::<[ex::AnyChannel<ex::FlatSamples>; 4]>::new();
        for (k, name) in self.channel_names().iter().enumerate() {
            let text = ex::Text::new_or_none(name).ok_or_else(|| {
                fail(format!(
                    "channel name '{name}' has characters OpenEXR cannot store"
                ))
            })?;
            let values = self.texels().iter().skip(k).step_by(count).copied();
            let samples = match precision {
                TexturePrecision::Half => {
                    ex::FlatSamples::F16(values.map(ex::f16::from_f32).collect())
                }
                TexturePrecision::Float => ex::FlatSamples::F32(values.collect()),
            };
            list.push(ex::AnyChannel::new(text, samples));
        }
        let layer = ex::Layer::new(
            (self.width(), self.height()),
            ex::LayerAttributes::default(),
            ex::Encoding::SMALL_LOSSLESS,
            ex::AnyChannels::sort(list),
        );
        ex::Image::from_layer(layer)
            .write()
            .to_file(path)
            .map_err(|e| match e {
                ex::Error::Io(source) => NbrdfError::io(path, source),
                other => fail(format!("writing the OpenEXR file: {other}")),
            })
    }
}
