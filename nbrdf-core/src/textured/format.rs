//! The `*.nbrdf.json` file of a spatially varying material (format version
//! [`FORMAT_VERSION_TEXTURED`], docs/formats.md) and [`NeuralMaterial`], which loads a file of
//! either kind by its version. Every refusal names the file and the field.

use super::lobes::{EXPONENT_ENCODING, LOBE_MODEL, MAX_LOBES};
use super::texture::size_problem;
use super::{
    lobe_name_problem, Decoder, FilterMode, LatentTexture, LobeChannels, SamplingChannels,
    TexturePrecision, TexturedNbrdf, UvMapping, UvTransform, WrapMode,
};
use crate::error::{NbrdfError, Result};
use crate::network::{
    describe_json_error, file_version, Layer, Nbrdf, Spectral, FORMAT_NAME, FORMAT_VERSION_TEXTURED,
};
use crate::spectral_basis::SpectralBasis;
use serde::de::DeserializeOwned;
use serde::Serialize;
use serde_json::{Map, Value};
use std::path::{Path, PathBuf};

/// A material file of either kind, as [`NeuralMaterial::load`] found it.
// Loaded once per material, so the variants' sizes do not matter.
#[allow(clippy::large_enum_variant)]
#[derive(Clone, Debug, PartialEq)]
pub enum NeuralMaterial {
    /// A homogeneous network, versions 1 to 3.
    Homogeneous(Nbrdf),
    /// A spatially varying material, version [`FORMAT_VERSION_TEXTURED`].
    Textured(TexturedNbrdf),
}

impl NeuralMaterial {
    /// Loads a `*.nbrdf.json` file of either kind: a spatially varying material by its version,
    /// anything else as [`Nbrdf::load`] does (with its errors).
    pub fn load(path: impl AsRef<Path>) -> Result<Self> {
        let path = path.as_ref();
        let text = read_text(path)?;
        let root = serde_json::from_str::<Value>(&text).ok();
        match root {
            Some(root) if file_version(&root) == Ok(FORMAT_VERSION_TEXTURED) => {
                TexturedNbrdf::from_json_value(root, path).map(NeuralMaterial::Textured)
            }
            _ => Nbrdf::load(path).map(NeuralMaterial::Homogeneous),
        }
    }
}

/// The text of a JSON file, with the size and kind checks of the network loader.
fn read_text(path: &Path) -> Result<String> {
    crate::error::regular_file_size(
        path,
        crate::error::MAX_JSON_BYTES,
        "an NBRDF material (.nbrdf.json)",
    )?;
    let bytes = std::fs::read(path).map_err(|e| NbrdfError::io(path, e))?;
    String::from_utf8(bytes).map_err(|e| {
        NbrdfError::format(
            path,
            format!("not text ({e}): an NBRDF material is a JSON file (*.nbrdf.json)"),
        )
    })
}

/// Field `key` of `object` (named `at` in errors), `None` when absent.
fn field<T: DeserializeOwned>(
    object: &Map<String, Value>,
    key: &str,
    at: &str,
) -> std::result::Result<Option<T>, String> {
    object
        .get(key)
        .map(|value| T::deserialize(value).map_err(|e| format!("{at}: {e}")))
        .transpose()
}

/// Field `key` of `object`, required.
fn required<T: DeserializeOwned>(
    object: &Map<String, Value>,
    key: &str,
    at: &str,
) -> std::result::Result<T, String> {
    field(object, key, at)?.ok_or_else(|| format!("missing field \"{at}\""))
}

/// The object `key` of `object`, `None` when absent.
fn section<'a>(
    object: &'a Map<String, Value>,
    key: &str,
) -> std::result::Result<Option<&'a Map<String, Value>>, String> {
    match object.get(key) {
        None => Ok(None),
        Some(Value::Object(inner)) => Ok(Some(inner)),
        Some(other) => Err(format!("{key} is {other}, expected an object")),
    }
}

/// The `latent` section before the texture is read.
struct LatentSection {
    path: String,
    width: usize,
    height: usize,
    channels: usize,
    mapping: UvMapping,
}

fn latent_section(root: &Map<String, Value>) -> std::result::Result<LatentSection, String> {
    let latent = section(root, "latent")?.ok_or("missing field \"latent\"")?;
    let path: String = required(latent, "path", "latent.path")?;
    if path.is_empty() {
        return Err("latent.path is empty".into());
    }
    let wrap = match field::<String>(latent, "wrap", "latent.wrap")? {
        None => WrapMode::Repeat,
        Some(name) => WrapMode::parse(&name).ok_or_else(|| {
            format!("latent.wrap \"{name}\": expected \"repeat\", \"mirror\" or \"clamp\"")
        })?,
    };
    let filter = match field::<String>(latent, "filter", "latent.filter")? {
        None => FilterMode::Bilinear,
        Some(name) => FilterMode::parse(&name).ok_or_else(|| {
            format!("latent.filter \"{name}\": expected \"bilinear\" or \"nearest\"")
        })?,
    };
    let to_uv = match field::<Vec<Vec<f64>>>(latent, "to_uv", "latent.to_uv")? {
        None => UvTransform::IDENTITY,
        Some(rows) => uv_transform(&rows)?,
    };
    if let Some(problem) = to_uv.problem() {
        return Err(format!("latent.{problem}"));
    }
    Ok(LatentSection {
        path,
        width: required(latent, "width", "latent.width")?,
        height: required(latent, "height", "latent.height")?,
        channels: required(latent, "channels", "latent.channels")?,
        mapping: UvMapping {
            to_uv,
            wrap,
            filter,
        },
    })
}

/// A `to_uv` matrix from 3 rows of 3 numbers, each finite in float32.
fn uv_transform(rows: &[Vec<f64>]) -> std::result::Result<UvTransform, String> {
    if rows.len() != 3 || rows.iter().any(|row| row.len() != 3) {
        return Err("latent.to_uv must be 3 rows of 3 numbers (Mitsuba's to_uv)".into());
    }
    let mut matrix = [[0.0f32; 3]; 3];
    for (out, row) in matrix.iter_mut().zip(rows) {
        for (m, &x) in out.iter_mut().zip(row) {
            *m = x as f32;
        }
    }
    Ok(UvTransform { matrix })
}

/// The optional `spectral` object: the decoder's outputs are the coefficients of this basis
/// (as a version-3 network's), else RGB.
fn spectral_section(root: &Map<String, Value>) -> std::result::Result<Option<Spectral>, String> {
    let Some(basis) = field::<SpectralBasis>(root, "spectral", "spectral")? else {
        return Ok(None);
    };
    Spectral::new(basis).map(Some).map_err(invalid_message)
}

fn sampling_section(root: &Map<String, Value>) -> std::result::Result<SamplingChannels, String> {
    let Some(sampling) = section(root, "sampling")? else {
        return Ok(SamplingChannels::cosine());
    };
    let model: String = required(sampling, "model", "sampling.model")?;
    if model != LOBE_MODEL {
        return Err(format!(
            "sampling.model \"{model}\": only \"{LOBE_MODEL}\" is defined"
        ));
    }
    let encoding: String = required(sampling, "exponent_encoding", "sampling.exponent_encoding")?;
    if encoding != EXPONENT_ENCODING {
        return Err(format!(
            "sampling.exponent_encoding \"{encoding}\": only \"{EXPONENT_ENCODING}\" (the \
             exponent n stored as ln(1 + n)) is defined"
        ));
    }
    let lobes: Vec<LobeChannels> = required(sampling, "lobes", "sampling.lobes")?;
    let count = lobes.len();
    SamplingChannels::new(lobes)
        .ok_or_else(|| format!("sampling.lobes has {count} lobes, at most {MAX_LOBES}"))
}

/// Where the texture named `relative` in the file at `origin` is.
fn texture_location(origin: &Path, relative: &str) -> PathBuf {
    origin
        .parent()
        .unwrap_or_else(|| Path::new(""))
        .join(relative)
}

impl TexturedNbrdf {
    /// Loads a spatially varying material and its latent texture.
    pub fn load(path: impl AsRef<Path>) -> Result<Self> {
        let path = path.as_ref();
        Self::from_json_str(&read_text(path)?, path)
    }

    /// Parses the JSON text of a material; `origin` names it in errors and its folder is where
    /// the texture's relative path starts.
    pub fn from_json_str(text: &str, origin: &Path) -> Result<Self> {
        let root: Value = serde_json::from_str(text)
            .map_err(|e| NbrdfError::format(origin, describe_json_error(text, &e)))?;
        Self::from_json_value(root, origin)
    }

    fn from_json_value(root: Value, origin: &Path) -> Result<Self> {
        let fail = |message: String| NbrdfError::format(origin, message);
        let version = file_version(&root).map_err(fail)?;
        if version != FORMAT_VERSION_TEXTURED {
            return Err(fail(format!(
                "this is a homogeneous NBRDF network (format version {version}), not a \
                 spatially varying material (version {FORMAT_VERSION_TEXTURED}); the network \
                 loaders and the nbrdf BSDF read it"
            )));
        }
        let Value::Object(root) = root else {
            return Err(fail("the top level is not a JSON object".into()));
        };
        let name: String = required(&root, "name", "name").map_err(fail)?;
        let anisotropic: bool = field(&root, "anisotropic", "anisotropic")
            .map_err(fail)?
            .unwrap_or(false);
        let layers: Vec<Layer> = required(&root, "layers", "layers").map_err(fail)?;
        let spectral = spectral_section(&root).map_err(fail)?;
        let latent = latent_section(&root).map_err(fail)?;
        let sampling = sampling_section(&root).map_err(fail)?;
        let decoder = Decoder::new(layers, latent.channels, anisotropic, spectral)
            .map_err(|e| fail(invalid_message(e)))?;
        if let Some(problem) = lobe_name_problem(&sampling, latent.channels) {
            return Err(fail(problem));
        }
        let names = Self::channel_names_for(latent.channels, &sampling);
        if let Some(problem) = size_problem(latent.width, latent.height, names.len()) {
            return Err(fail(format!("latent.width, latent.height: {problem}")));
        }
        let location = texture_location(origin, &latent.path);
        let texture = LatentTexture::read_exr(&location, &names, latent.width, latent.height)
            .map_err(|e| fail(format!("latent.path \"{}\": {}", latent.path, e)))?;
        let provenance = root.get("provenance").cloned().unwrap_or(Value::Null);
        let material = TexturedNbrdf::new(
            name,
            decoder,
            texture,
            latent.mapping,
            sampling,
            latent.path,
        )
        .map_err(|e| fail(invalid_message(e)))?;
        Ok(match provenance {
            Value::Null => material,
            provenance => material.with_provenance(provenance),
        })
    }

    /// The JSON text of the material (the texture is written by [`TexturedNbrdf::save`]).
    pub fn to_json_string(&self) -> String {
        let lobes = self.sampling_channels().lobes();
        let out = FileOut {
            format: FORMAT_NAME,
            version: FORMAT_VERSION_TEXTURED,
            name: self.name(),
            anisotropic: self.decoder().anisotropic(),
            spectral: self.decoder().spectral().map(Spectral::basis),
            layers: self.decoder().layers(),
            latent: LatentOut {
                path: self.texture_path(),
                width: self.texture().width(),
                height: self.texture().height(),
                channels: self.decoder().latent_channels(),
                wrap: self.mapping().wrap.name(),
                filter: self.mapping().filter.name(),
                to_uv: self.mapping().to_uv.matrix,
            },
            sampling: (!lobes.is_empty()).then_some(SamplingOut {
                model: LOBE_MODEL,
                exponent_encoding: EXPONENT_ENCODING,
                lobes,
            }),
            provenance: self.provenance(),
        };
        // Plain structs and a JSON value with string keys: serde_json cannot fail on these.
        serde_json::to_string_pretty(&out).expect("serialising a material cannot fail")
    }

    /// Writes the texture at `precision` to the material's texture path (relative to `path`'s
    /// folder), then the JSON file at `path`.
    pub fn save(&self, path: impl AsRef<Path>, precision: TexturePrecision) -> Result<()> {
        let path = path.as_ref();
        let location = texture_location(path, self.texture_path());
        self.texture().write_exr(&location, precision)?;
        std::fs::write(path, self.to_json_string()).map_err(|e| NbrdfError::io(path, e))
    }
}

/// The message of a validation error, without the "invalid argument" prefix.
fn invalid_message(error: NbrdfError) -> String {
    match error {
        NbrdfError::InvalidArgument(message) => message,
        other => other.to_string(),
    }
}

#[derive(Serialize)]
struct FileOut<'a> {
    format: &'a str,
    version: u32,
    name: &'a str,
    anisotropic: bool,
    #[serde(skip_serializing_if = "Option::is_none")]
    spectral: Option<&'a SpectralBasis>,
    layers: &'a [Layer],
    latent: LatentOut<'a>,
    #[serde(skip_serializing_if = "Option::is_none")]
    sampling: Option<SamplingOut<'a>>,
    provenance: &'a Value,
}

#[derive(Serialize)]
struct LatentOut<'a> {
    path: &'a str,
    width: usize,
    height: usize,
    channels: usize,
    wrap: &'a str,
    filter: &'a str,
    to_uv: [[f32; 3]; 3],
}

#[derive(Serialize)]
struct SamplingOut<'a> {
    model: &'a str,
    exponent_encoding: &'a str,
    lobes: &'a [LobeChannels],
}
