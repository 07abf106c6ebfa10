//! What each `nbrdf` command does: one function per command, taking the command's settings and
//! returning a report (`#[derive(Serialize)]` for the commands that print JSON, [`Display`] for
//! their text), so that the command-line tool only parses, calls and prints.
//!
//! * `list-materials`, `synth`: [`catalogue`].
//! * `info`, `tabulate`: [`table`].
//! * `train`: [`train_network`]; the distiller of Mitsuba BSDFs (through the C ABI): [`distill`].
//! * `fit-phong`: [`fit_phong`].
//! * `compare`: [`compare`].
//! * `ae train|encode|decode|eval`, `interpolate`: [`autoencoder`].
//! * `predictor train|eval`, `predict-phong`: [`predictor`].
//!
//! [`limits`] holds the ranges of their size settings, checked before anything is allocated.
//!
//! [`Display`]: std::fmt::Display

pub mod autoencoder;
pub mod catalogue;
pub mod compare;
pub mod distill;
pub mod fit_phong;
pub mod limits;
pub mod predictor;
pub mod table;
pub mod train_network;

use crate::error::{NbrdfError, Result};
use crate::network::Nbrdf;
use serde::Serialize;
use std::path::Path;

/// Runs `f` on a pool of `threads` workers, or on the global pool (one per core).
pub fn with_threads<T: Send>(threads: Option<usize>, f: impl FnOnce() -> T + Send) -> Result<T> {
    match threads {
        None => Ok(f()),
        Some(0) => Err(NbrdfError::Usage("--threads must be at least 1".into())),
        Some(n) => {
            let pool = rayon::ThreadPoolBuilder::new()
                .num_threads(n)
                .build()
                .map_err(|e| {
                    NbrdfError::InvalidArgument(format!("cannot start {n} threads: {e}"))
                })?;
            Ok(pool.install(f))
        }
    }
}

/// The file name without its extensions: `gold.binary` and `gold.nbrdf.json` give `gold`.
pub fn file_stem(path: &Path) -> String {
    let name = path
        .file_name()
        .map(|n| n.to_string_lossy().into_owned())
        .unwrap_or_default();
    let stem = name.split('.').next().unwrap_or_default();
    if stem.is_empty() {
        "nbrdf".to_string()
    } else {
        stem.to_string()
    }
}

/// A report as indented JSON with a final newline. It goes through [`serde_json::Value`], whose
/// maps are sorted by key, so the output does not depend on the order of a struct's fields.
pub fn to_json_pretty<T: Serialize>(report: &T) -> Result<String> {
    let text = serde_json::to_value(report)
        .and_then(|value| serde_json::to_string_pretty(&value))
        .map_err(|e| NbrdfError::InvalidArgument(format!("cannot format JSON: {e}")))?;
    Ok(format!("{text}\n"))
}

/// Puts the file the data came from in front of an error about the data ("no valid
/// directions"), which the numerical code raising it cannot name; other errors name their
/// file already.
pub(crate) fn about_data(source: &str) -> impl Fn(NbrdfError) -> NbrdfError + '_ {
    move |error| match error {
        NbrdfError::InvalidArgument(message) => {
            NbrdfError::InvalidArgument(format!("{source}: {message}"))
        }
        other => other,
    }
}

fn invalid(message: String) -> NbrdfError {
    NbrdfError::InvalidArgument(message)
}

/// The `NAME.nbrdf.json` networks of a directory, sorted by name: the training and test
/// networks of the latent commands, so isotropic ([`crate::latent::require_isotropic`]).
pub fn read_nbrdf_dir(dir: &Path) -> Result<Vec<(String, Nbrdf)>> {
    let entries = std::fs::read_dir(dir).map_err(|e| invalid(format!("{}: {e}", dir.display())))?;
    let mut out = Vec::new();
    for entry in entries {
        let path = entry
            .map_err(|e| invalid(format!("{}: {e}", dir.display())))?
            .path();
        let Some(file) = path.file_name().and_then(|f| f.to_str()) else {
            continue;
        };
        if let Some(name) = file.strip_suffix(".nbrdf.json") {
            let net = Nbrdf::load(&path)?;
            net.require_no_base("the latent commands")?;
            if let Some(message) = crate::latent::anisotropy_problem(&net) {
                return Err(NbrdfError::Format { path, message });
            }
            out.push((name.to_string(), net));
        }
    }
    if out.is_empty() {
        return Err(invalid(format!("no *.nbrdf.json in {}", dir.display())));
    }
    out.sort_by(|a, b| a.0.cmp(&b.0));
    Ok(out)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn default_names_drop_every_extension() {
        assert_eq!(file_stem(Path::new("/x/gold-paint.binary")), "gold-paint");
        assert_eq!(file_stem(Path::new("net.nbrdf.json")), "net");
        assert_eq!(file_stem(Path::new("/")), "nbrdf");
    }

    #[test]
    fn a_directory_with_an_anisotropic_network_is_refused_naming_it() {
        let dir = std::env::temp_dir().join(format!("nbrdf-ops-aniso-{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        Nbrdf::random("plain", 4, 1)
            .save(dir.join("plain.nbrdf.json"))
            .unwrap();
        assert_eq!(read_nbrdf_dir(&dir).unwrap().len(), 1);
        let mut brushed = Nbrdf::random("brushed", 4, 2);
        brushed.anisotropic = true;
        brushed.save(dir.join("brushed.nbrdf.json")).unwrap();
        let message = read_nbrdf_dir(&dir).unwrap_err().to_string();
        std::fs::remove_dir_all(&dir).unwrap();
        assert!(message.contains("brushed.nbrdf.json"), "{message}");
        assert!(message.contains("is anisotropic"), "{message}");
    }

    #[test]
    fn zero_threads_is_an_error() {
        assert!(with_threads(Some(0), || ()).is_err());
        assert_eq!(
            with_threads(Some(1), rayon::current_num_threads).unwrap(),
            1
        );
    }

    #[test]
    fn json_reports_have_sorted_keys() {
        #[derive(Serialize)]
        struct Report {
            zeta: u8,
            alpha: f32,
        }
        let text = to_json_pretty(&Report {
            zeta: 1,
            alpha: 0.5,
        })
        .unwrap();
        assert_eq!(text, "{\n  \"alpha\": 0.5,\n  \"zeta\": 1\n}\n");
    }
}
