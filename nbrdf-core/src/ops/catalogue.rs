//! `nbrdf list-materials` and `nbrdf synth`: the embedded fits of the MERL materials.

use crate::analytic::{catalogue, AnalyticBrdf, ModelKind};
use crate::error::Result;
use crate::merl;
use serde::Serialize;
use std::fmt;
use std::path::{Path, PathBuf};
use std::time::Instant;

/// A material of the catalogue.
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct MaterialEntry {
    pub name: &'static str,
    pub alias: Option<&'static str>,
}

/// The 100 MERL materials, sorted by name.
pub fn list_materials() -> Vec<MaterialEntry> {
    catalogue::material_names()
        .into_iter()
        .map(|name| MaterialEntry {
            name,
            alias: catalogue::alias(name),
        })
        .collect()
}

/// What `synth` wrote.
#[derive(Clone, Debug, PartialEq)]
pub struct SynthReport {
    pub output: PathBuf,
    pub model: ModelKind,
    /// The canonical material name.
    pub material: String,
    pub invalid_cells: usize,
    pub seconds: f64,
}

impl fmt::Display for SynthReport {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        writeln!(
            f,
            "wrote {} ({} fit of {}, {} bytes{}) in {:.2} s",
            self.output.display(),
            self.model.name().to_uppercase(),
            self.material,
            merl::FILE_SIZE,
            if self.invalid_cells > 0 {
                format!(
                    ", {} cells not finite and marked invalid",
                    self.invalid_cells
                )
            } else {
                String::new()
            },
            self.seconds,
        )
    }
}

/// Tabulates the `model` fit of `material` (a name or alias) into `output`, by default
/// `NAME.binary` in the current directory.
pub fn synth(model: ModelKind, material: &str, output: Option<&Path>) -> Result<SynthReport> {
    let brdf = AnalyticBrdf::from_catalogue(model, material)?;
    // from_catalogue succeeded, so the name resolves; the canonical one makes the file name.
    let name = catalogue::canonical_name(material).unwrap_or(material);
    let output = output.map_or_else(
        || PathBuf::from(format!("{name}.binary")),
        Path::to_path_buf,
    );
    let start = Instant::now();
    let table = brdf.tabulate();
    table.write(&output)?;
    let seconds = start.elapsed().as_secs_f64();
    Ok(SynthReport {
        output,
        model,
        material: name.to_string(),
        invalid_cells: table.stats().invalid_cells,
        seconds,
    })
}
