//! The versioned `*.nbrdf.json` file format of a network: reading with the checks that make a
//! bad file an error naming the file and the problem, writing, and in-memory validation.

use super::{empty_object, Layer, Nbrdf, SamplingParams, Spectral, INPUTS, OUTPUTS};
use crate::error::{NbrdfError, Result};
use crate::spectral_basis::SpectralBasis;
use serde::{Deserialize, Serialize};
use std::path::Path;

pub const FORMAT_NAME: &str = "nbrdf";
/// The newest version of a homogeneous network this build reads and writes. Version 2 adds
/// `anisotropic` (default false); an isotropic network is still written as version 1, which every
/// reader understands and which loads and evaluates as before (docs/design.md section 4).
/// Version 3 adds `spectral`: the outputs are the coefficients of a spectral basis
/// (docs/formats.md), written only for spectral networks.
pub const FORMAT_VERSION: u32 = 3;
/// The version of anisotropic RGB networks.
pub const FORMAT_VERSION_ANISOTROPIC: u32 = 2;
/// The version of files without version-2 features.
pub const FORMAT_VERSION_ISOTROPIC: u32 = 1;
/// The version of spatially varying materials: a decoder reading a latent texture
/// (`nbrdf_core::textured`, docs/formats.md). Not a homogeneous network: [`Nbrdf::load`] refuses
/// it, naming the kind.
pub const FORMAT_VERSION_TEXTURED: u32 = 4;

/// What a serde_json syntax error means to the user: non-finite numbers (`NaN`, `Infinity`,
/// which Python's json module writes) are named, the rest reported as corrupt JSON.
pub(crate) fn describe_json_error(text: &str, error: &serde_json::Error) -> String {
    let (line, column) = (error.line(), error.column());
    let near = text
        .lines()
        .nth(line.saturating_sub(1))
        .map(|l| {
            let chars: Vec<char> = l.chars().collect();
            let at = column.saturating_sub(1).min(chars.len());
            chars[at.saturating_sub(2)..(at + 10).min(chars.len())]
                .iter()
                .collect::<String>()
        })
        .unwrap_or_default();
    for token in ["NaN", "Infinity"] {
        if near.contains(token) {
            return format!(
                "{token} is not valid JSON (line {line} column {column}): network parameters \
                 must be finite numbers"
            );
        }
    }
    format!("not valid JSON (truncated or corrupt?): {error}")
}

/// What is read from a file once `format` and `version` have been checked.
#[derive(Deserialize)]
struct FileIn {
    name: String,
    layers: Vec<Layer>,
    #[serde(default)]
    anisotropic: bool,
    #[serde(default)]
    spectral: Option<SpectralBasis>,
    #[serde(default)]
    sampling: Option<SamplingParams>,
    #[serde(default)]
    base: Option<serde_json::Value>,
    #[serde(default)]
    provenance: serde_json::Value,
}

#[derive(Serialize)]
struct FileOut<'a> {
    format: &'a str,
    version: u32,
    name: &'a str,
    layers: &'a [Layer; 3],
    /// Written (as true) only by version 2.
    #[serde(skip_serializing_if = "std::ops::Not::not")]
    anisotropic: bool,
    /// Written only by version 3.
    #[serde(skip_serializing_if = "Option::is_none")]
    spectral: Option<&'a SpectralBasis>,
    #[serde(skip_serializing_if = "Option::is_none")]
    sampling: &'a Option<SamplingParams>,
    #[serde(skip_serializing_if = "Option::is_none")]
    base: &'a Option<serde_json::Value>,
    provenance: &'a serde_json::Value,
}

/// Checks the `format` and `version` fields of a homogeneous network before anything else, so
/// that a file of another kind or version is reported as such rather than as a missing field
/// further in; returns the version.
fn check_header(root: &serde_json::Value) -> std::result::Result<u32, String> {
    let version = file_version(root)?;
    if version == FORMAT_VERSION_TEXTURED {
        return Err(format!(
            "unsupported version {version} for a homogeneous network: version \
             {FORMAT_VERSION_TEXTURED} is a spatially varying material (a decoder reading a latent \
             texture); load it as a textured material"
        ));
    }
    Ok(version)
}

/// The `format` and `version` fields of any `*.nbrdf.json` file, homogeneous network (versions
/// 1 to [`FORMAT_VERSION`]) or spatially varying material ([`FORMAT_VERSION_TEXTURED`]):
/// the version, or what is wrong with them.
pub(crate) fn file_version(root: &serde_json::Value) -> std::result::Result<u32, String> {
    let object = root
        .as_object()
        .ok_or("the top level is not a JSON object")?;
    match object.get("format") {
        None => {
            return Err(format!(
                "missing field \"format\" (expected \"{FORMAT_NAME}\")"
            ))
        }
        Some(serde_json::Value::String(s)) if s == FORMAT_NAME => {}
        Some(other) => return Err(format!("format is {other}, expected \"{FORMAT_NAME}\"")),
    }
    match object.get("version") {
        None => Err("missing field \"version\"".to_string()),
        Some(v) => match v.as_u64() {
            Some(n) if (1..=u64::from(FORMAT_VERSION_TEXTURED)).contains(&n) => Ok(n as u32),
            _ => Err(format!(
                "unsupported version {v} (this build reads versions 1 to {FORMAT_VERSION}, \
                 networks, and {FORMAT_VERSION_TEXTURED}, spatially varying materials)"
            )),
        },
    }
}

/// The first structural problem of a layer stack (counts, dimensions, lengths) whose last layer
/// must have `outputs` outputs (3, RGB, or a spectral network's count), if any.
pub(super) fn shape_problem(layers: &[Layer], outputs: usize) -> Option<String> {
    if layers.len() != 3 {
        return Some(format!("expected 3 layers, found {}", layers.len()));
    }
    if layers[0].inputs != INPUTS {
        return Some(format!(
            "layer 1 has {} inputs, expected {INPUTS} (the Rusinkiewicz input)",
            layers[0].inputs
        ));
    }
    if layers[2].outputs != outputs {
        let what = if outputs == OUTPUTS {
            "RGB"
        } else {
            "the spectral count"
        };
        return Some(format!(
            "layer 3 has {} outputs, expected {outputs} ({what})",
            layers[2].outputs
        ));
    }
    for k in 1..3 {
        if layers[k].inputs != layers[k - 1].outputs {
            return Some(format!(
                "layer dimensions do not chain: layer {} has {} outputs but layer {} has {} inputs",
                k,
                layers[k - 1].outputs,
                k + 1,
                layers[k].inputs
            ));
        }
    }
    for (k, layer) in layers.iter().enumerate() {
        if layer.outputs == 0 {
            return Some(format!("layer {} has 0 outputs", k + 1));
        }
        let expected = layer.inputs.checked_mul(layer.outputs);
        if expected != Some(layer.weights.len()) {
            return Some(format!(
                "layer {} has {} weights, expected inputs * outputs = {} * {}",
                k + 1,
                layer.weights.len(),
                layer.inputs,
                layer.outputs
            ));
        }
        if layer.bias.len() != layer.outputs {
            return Some(format!(
                "layer {} has {} bias values, expected {} (its outputs)",
                k + 1,
                layer.bias.len(),
                layer.outputs
            ));
        }
    }
    None
}

/// The first non-finite parameter, if any.
pub(crate) fn value_problem(layers: &[Layer]) -> Option<String> {
    for (k, layer) in layers.iter().enumerate() {
        if let Some(i) = layer.weights.iter().position(|w| !w.is_finite()) {
            return Some(format!(
                "layer {} weight {} is not finite ({}); values must fit in float32",
                k + 1,
                i,
                layer.weights[i]
            ));
        }
        if let Some(i) = layer.bias.iter().position(|b| !b.is_finite()) {
            return Some(format!(
                "layer {} bias {} is not finite ({}); values must fit in float32",
                k + 1,
                i,
                layer.bias[i]
            ));
        }
    }
    None
}

impl Nbrdf {
    /// Loads and validates an `*.nbrdf.json` file.
    pub fn load(path: impl AsRef<Path>) -> Result<Self> {
        let path = path.as_ref();
        crate::error::regular_file_size(
            path,
            crate::error::MAX_JSON_BYTES,
            "an NBRDF network (.nbrdf.json)",
        )?;
        let bytes = std::fs::read(path).map_err(|e| NbrdfError::io(path, e))?;
        if crate::merl::io::has_merl_header(&bytes) {
            return Err(NbrdfError::format(
                path,
                "this is a MERL table (binary), not an NBRDF network JSON; the nbrdf BSDF and \
                 the network commands read *.nbrdf.json (the merl BSDF reads tables)",
            ));
        }
        let text = String::from_utf8(bytes).map_err(|e| {
            NbrdfError::format(
                path,
                format!("not text ({e}): an NBRDF network is a JSON file (*.nbrdf.json)"),
            )
        })?;
        Self::from_json_str(&text, path)
    }

    /// Parses and validates the JSON text of a network; `origin` names the source in errors.
    pub fn from_json_str(text: &str, origin: &Path) -> Result<Self> {
        let fail = |message: String| NbrdfError::format(origin, message);
        let root: serde_json::Value =
            serde_json::from_str(text).map_err(|e| fail(describe_json_error(text, &e)))?;
        let version = check_header(&root).map_err(fail)?;
        let file: FileIn = serde_json::from_value(root)
            .map_err(|e| fail(format!("not a valid NBRDF network: {e}")))?;
        if file.anisotropic && version < 2 {
            // A version-1 reader would ignore the flag and evaluate the network wrongly.
            return Err(fail(
                "\"anisotropic\": true needs format version 2 (version 1 networks are isotropic)"
                    .to_string(),
            ));
        }
        let spectral = spectral_of(version, file.spectral).map_err(fail)?;
        let outputs = spectral.as_ref().map_or(OUTPUTS, Spectral::count);
        if let Some(message) = shape_problem(&file.layers, outputs) {
            return Err(fail(message));
        }
        if let Some(message) = file.sampling.as_ref().and_then(SamplingParams::problem) {
            return Err(fail(message));
        }
        if let Some(message) = anisotropy_problem(file.anisotropic, file.sampling.as_ref()) {
            return Err(fail(message));
        }
        if let Some(message) = file.base.as_ref().and_then(base_problem) {
            return Err(fail(message));
        }
        let layers: [Layer; 3] = file
            .layers
            .try_into()
            .map_err(|_| fail("expected 3 layers".to_string()))?;
        let net = Nbrdf {
            name: file.name,
            layers,
            anisotropic: file.anisotropic,
            spectral,
            sampling: file.sampling,
            base: file.base,
            provenance: if file.provenance.is_null() {
                empty_object()
            } else {
                file.provenance
            },
        };
        if let Some(message) = value_problem(&net.layers) {
            return Err(fail(message));
        }
        Ok(net)
    }

    pub fn to_json_string(&self) -> String {
        let out = FileOut {
            format: FORMAT_NAME,
            version: if self.spectral.is_some() {
                FORMAT_VERSION
            } else if self.anisotropic {
                FORMAT_VERSION_ANISOTROPIC
            } else {
                FORMAT_VERSION_ISOTROPIC
            },
            name: &self.name,
            layers: &self.layers,
            anisotropic: self.anisotropic,
            spectral: self.spectral.as_ref().map(Spectral::basis),
            sampling: &self.sampling,
            base: &self.base,
            provenance: &self.provenance,
        };
        // Plain structs and a JSON value with string keys: serde_json cannot fail on these.
        serde_json::to_string_pretty(&out).expect("serialising an NBRDF cannot fail")
    }

    pub fn save(&self, path: impl AsRef<Path>) -> Result<()> {
        let path = path.as_ref();
        std::fs::write(path, self.to_json_string()).map_err(|e| NbrdfError::io(path, e))
    }

    /// An error where the network is a residual on an analytic `base`, which the library does not
    /// evaluate: `what` (e.g. "tabulating it") would see the residual alone, a silently wrong
    /// material.
    pub fn require_no_base(&self, what: &str) -> Result<()> {
        match &self.base {
            None => Ok(()),
            Some(base) => Err(NbrdfError::InvalidArgument(format!(
                "network '{}' is a residual on an analytic base ({}), which this library does \
                 not evaluate: {what} would see the residual alone (render it with the nbrdf \
                 BSDF in Mitsuba, which adds the base)",
                self.name, base["type"]
            ))),
        }
    }

    /// Checks an in-memory network (shapes, finite values, sampling parameters), e.g. after
    /// training or decoding; files are checked by [`Nbrdf::load`] already.
    pub fn validate(&self) -> Result<()> {
        let problem = shape_problem(&self.layers, self.output_count())
            .or_else(|| value_problem(&self.layers))
            .or_else(|| self.sampling.as_ref().and_then(SamplingParams::problem))
            .or_else(|| anisotropy_problem(self.anisotropic, self.sampling.as_ref()))
            .or_else(|| self.base.as_ref().and_then(base_problem));
        match problem {
            Some(message) => Err(NbrdfError::InvalidArgument(format!(
                "network '{}': {message}",
                self.name
            ))),
            None => Ok(()),
        }
    }
}

/// The spectral output of a file: version 3 and only version 3 has one, and it must be usable.
fn spectral_of(
    version: u32,
    basis: Option<SpectralBasis>,
) -> std::result::Result<Option<Spectral>, String> {
    match (version, basis) {
        (3, None) => {
            Err("missing field \"spectral\" (version 3 is the format of spectral networks)".into())
        }
        (3, Some(basis)) => Spectral::new(basis).map(Some).map_err(|e| match e {
            NbrdfError::InvalidArgument(message) => message,
            other => other.to_string(),
        }),
        (_, Some(_)) => {
            Err("\"spectral\" needs format version 3 (older versions are RGB networks)".into())
        }
        (_, None) => Ok(None),
    }
}

/// An anisotropic sampling lobe on an isotropic network: its orientation would be meaningless
/// (the network does not see the tangent).
fn anisotropy_problem(anisotropic: bool, sampling: Option<&SamplingParams>) -> Option<String> {
    match sampling {
        Some(s) if s.exponent_v.is_some() && !anisotropic => Some(
            "sampling exponent_v (an anisotropic lobe) needs an anisotropic network".to_string(),
        ),
        _ => None,
    }
}

/// What is wrong with a `base`, if anything: the library does not evaluate it, but a renderer
/// needs a dictionary naming a BSDF plugin (Mitsuba's `mi.load_dict`).
fn base_problem(base: &serde_json::Value) -> Option<String> {
    match base.as_object().map(|object| object.get("type")) {
        None => Some(format!(
            "\"base\" must be a BSDF dictionary (a JSON object with a \"type\"), got {base}"
        )),
        Some(Some(serde_json::Value::String(kind))) if !kind.is_empty() => None,
        Some(_) => Some(
            "\"base\" must name its BSDF plugin in a string \"type\" (e.g. \"roughconductor\")"
                .to_string(),
        ),
    }
}
