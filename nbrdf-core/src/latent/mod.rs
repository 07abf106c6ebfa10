//! The latent space of materials (docs/design.md section 7): an autoencoder over flattened NBRDFs
//! trained with an image loss, a predictor of the Blinn-Phong sampling parameters from the
//! code, and the PCA baseline of Nielsen et al. 2015.

pub mod autoencoder;
pub mod family;
pub mod mlp;
pub mod pca;
pub mod predictor;
pub mod sphere;

use crate::error::{NbrdfError, Result};
use crate::network::Nbrdf;
use serde::de::DeserializeOwned;
use serde::Serialize;
use std::path::Path;

/// The latent models (autoencoders, predictors, the pretrained ones) are learnt from isotropic
/// RGB networks: an anisotropic network's first layer reads the half vector's azimuth, and a
/// spectral network's last layer has another meaning (and count), so their weights mean
/// something else and their code (or a relearnt stand-in) would be silently wrong. Every latent
/// operation refuses one with this error.
pub fn require_isotropic(net: &Nbrdf) -> Result<()> {
    anisotropy_problem(net).map_or(Ok(()), |m| Err(NbrdfError::InvalidArgument(m)))
}

/// [`require_isotropic`]'s message, when `net` is anisotropic or spectral.
pub fn anisotropy_problem(net: &Nbrdf) -> Option<String> {
    if net.spectral.is_some() {
        return Some(format!(
            "network '{}' is a spectral network: the autoencoder and the predictors take RGB \
             networks only; train one with --output rgb",
            net.name
        ));
    }
    net.anisotropic.then(|| {
        format!(
            "network '{}' is anisotropic: the autoencoder and the predictors take isotropic networks \
             only (the pretrained models are isotropic); train one with --anisotropy off",
            net.name
        )
    })
}

/// Per-column mean and standard deviation (population, accumulated in f64) of equally long
/// rows; each deviation is at least `floor`, so that standardising never divides by ~0.
fn column_mean_std<R: AsRef<[f32]>>(rows: &[R], floor: f32) -> (Vec<f32>, Vec<f32>) {
    let dims = rows.first().map_or(0, |r| r.as_ref().len());
    let n = rows.len() as f64;
    (0..dims)
        .map(|d| {
            let m = rows.iter().map(|r| r.as_ref()[d] as f64).sum::<f64>() / n;
            let v = rows
                .iter()
                .map(|r| (r.as_ref()[d] as f64 - m).powi(2))
                .sum::<f64>()
                / n;
            (m as f32, (v.sqrt() as f32).max(floor))
        })
        .unzip()
}

/// Reads a JSON model file (autoencoder, predictor); errors name the file.
fn read_json<T: DeserializeOwned>(path: &Path) -> Result<T> {
    crate::error::regular_file_size(path, crate::error::MAX_JSON_BYTES, "a JSON model")?;
    let text = std::fs::read_to_string(path)
        .map_err(|e| NbrdfError::InvalidArgument(format!("{}: {e}", path.display())))?;
    parse_json(&text, &path.display().to_string())
}

/// Parses a JSON model (a file's text, or a model embedded in a program); errors name `origin`.
fn parse_json<T: DeserializeOwned>(text: &str, origin: &str) -> Result<T> {
    serde_json::from_str(text).map_err(|e| NbrdfError::InvalidArgument(format!("{origin}: {e}")))
}

/// Writes a JSON model file; errors name the file.
fn write_json<T: Serialize>(value: &T, path: &Path) -> Result<()> {
    let text =
        serde_json::to_string(value).map_err(|e| NbrdfError::InvalidArgument(e.to_string()))?;
    std::fs::write(path, text)
        .map_err(|e| NbrdfError::InvalidArgument(format!("{}: {e}", path.display())))
}

#[cfg(test)]
mod spectral_refusal_tests {
    // Here, not in network/: the rendering layer must not refer to the training layer.
    #[test]
    fn latent_models_refuse_spectral_networks() {
        let net = crate::network::spectral::tests::spectral_net(6, 1);
        let message = super::require_isotropic(&net).unwrap_err().to_string();
        assert!(message.contains("spectral"), "{message}");
    }
}
