//! `nbrdf compare`: sphere images and the log-space error of two materials.

use super::with_threads;
use crate::error::Result;
use crate::merl::PhiFold;
use crate::metrics::{self, Comparison, ImageErrors, Material};
use serde::Serialize;
use std::fmt;
use std::path::Path;

/// The comparison of `test` against `reference` (file names as given).
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct CompareReport {
    pub reference: String,
    pub test: String,
    pub comparison: Comparison,
}

impl fmt::Display for CompareReport {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        let c = &self.comparison;
        writeln!(
            f,
            "{} vs {} (reference first), {}x{} spheres:\n  {:>9}{:>12}{:>12}{:>9}{:>8}",
            self.reference,
            self.test,
            c.resolution,
            c.resolution,
            "theta_l",
            "MAE",
            "RMSE",
            "PSNR",
            "SSIM"
        )?;
        let row = |f: &mut fmt::Formatter<'_>, label: String, e: &ImageErrors| {
            writeln!(
                f,
                "  {label:>9}{:>12.4e}{:>12.4e}{:>9.2}{:>8.4}",
                e.mae, e.rmse, e.psnr_peak_reference, e.ssim
            )
        };
        for (deg, e) in &c.per_light {
            row(f, format!("{deg:.0} deg"), e)?;
        }
        row(f, "mean".to_string(), &c.mean)?;
        writeln!(
            f,
            "log-space BRDF error |ln(1+fA cos) - ln(1+fB cos)|: adaptive {:.4e}, uniform {:.4e}",
            c.log_error_adaptive, c.log_error_uniform
        )
    }
}

/// Compares the materials (tables or networks) at `reference` and `test`: spheres of
/// `resolution` pixels, `samples` directions for the log-space error.
pub fn compare(
    reference: &Path,
    test: &Path,
    fold: PhiFold,
    resolution: usize,
    samples: usize,
    threads: Option<usize>,
) -> Result<CompareReport> {
    super::limits::check_compare(resolution, samples)?;
    let a = Material::read_folded(reference, fold)?;
    let b = Material::read_folded(test, fold)?;
    let pair = format!("{} vs {}", reference.display(), test.display());
    let comparison = with_threads(threads, || metrics::compare(&a, &b, resolution, samples))?
        .map_err(super::about_data(&pair))?;
    Ok(CompareReport {
        reference: reference.display().to_string(),
        test: test.display().to_string(),
        comparison,
    })
}
