//! `nbrdf info` and `nbrdf tabulate`: MERL-format tables.

use super::with_threads;
use crate::error::Result;
use crate::merl::{self, MerlTable, TableStats};
use crate::network::Nbrdf;
use std::fmt;
use std::path::{Path, PathBuf};
use std::time::Instant;

/// What `info` prints: a valid table's statistics.
#[derive(Clone, Debug, PartialEq)]
pub struct TableInfo {
    pub path: PathBuf,
    pub stats: TableStats,
}

impl fmt::Display for TableInfo {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        let stats = &self.stats;
        writeln!(
            f,
            "{}: valid MERL table (90 x 90 x 180 cells, {} bytes)",
            self.path.display(),
            merl::FILE_SIZE
        )?;
        writeln!(
            f,
            "cells: {} valid, {} invalid (not measured) of {}",
            stats.valid_cells,
            stats.invalid_cells,
            merl::CELLS
        )?;
        writeln!(f, "reflectance over valid cells (1/sr):")?;
        writeln!(
            f,
            "  {:<7}{:>14}{:>14}{:>14}",
            "channel", "min", "max", "mean"
        )?;
        for (c, channel) in ["red", "green", "blue"].iter().enumerate() {
            writeln!(
                f,
                "  {:<7}{:>14.6e}{:>14.6e}{:>14.6e}",
                channel, stats.min[c], stats.max[c], stats.mean[c]
            )?;
        }
        Ok(())
    }
}

/// Reads and validates the table at `path`.
pub fn info(path: &Path) -> Result<TableInfo> {
    let table = MerlTable::read(path)?;
    Ok(TableInfo {
        path: path.to_path_buf(),
        stats: table.stats(),
    })
}

/// What `tabulate` wrote.
#[derive(Clone, Debug, PartialEq)]
pub struct TabulateReport {
    pub output: PathBuf,
    pub network: String,
    pub invalid_cells: usize,
    pub seconds: f64,
}

impl fmt::Display for TabulateReport {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        writeln!(
            f,
            "wrote {} (network {}, {} cells below the horizon marked invalid) in {:.2} s",
            self.output.display(),
            self.network,
            self.invalid_cells,
            self.seconds
        )
    }
}

/// Tabulates the network at `network` on the MERL grid into `output`, by default
/// `NAME.binary` in the current directory.
pub fn tabulate(
    network: &Path,
    output: Option<&Path>,
    threads: Option<usize>,
) -> Result<TabulateReport> {
    let net = Nbrdf::load(network)?;
    net.require_no_base("tabulating it")?;
    let output = output.map_or_else(
        || PathBuf::from(format!("{}.binary", net.name)),
        Path::to_path_buf,
    );
    let start = Instant::now();
    let table = with_threads(threads, || net.tabulate())?;
    table.write(&output)?;
    Ok(TabulateReport {
        output,
        invalid_cells: table.stats().invalid_cells,
        network: net.name,
        seconds: start.elapsed().as_secs_f64(),
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn info_of_a_missing_file_names_it() {
        let path = std::env::temp_dir().join("nbrdf-no-such-file.binary");
        assert!(info(&path)
            .unwrap_err()
            .to_string()
            .contains("nbrdf-no-such-file.binary"));
    }

    #[test]
    fn info_report_lists_channels() {
        let mut stored = vec![1500.0; 3 * merl::CELLS];
        stored[0] = -1.0;
        let table = MerlTable::from_stored(stored).unwrap();
        let report = TableInfo {
            path: PathBuf::from("t.binary"),
            stats: table.stats(),
        }
        .to_string();
        assert!(report.contains("1457999 valid, 1 invalid"), "{report}");
        assert!(
            report.contains("red") && report.contains("1.000000e0"),
            "{report}"
        );
    }

    #[test]
    fn a_network_on_an_analytic_base_is_not_tabulated() {
        let mut net = Nbrdf::random("on-base", 4, 1);
        net.base = Some(serde_json::json!({"type": "roughconductor", "alpha": 0.2}));
        let dir = std::env::temp_dir().join(format!("nbrdf-base-tab-{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        let path = dir.join("on-base.nbrdf.json");
        net.save(&path).unwrap();
        let output = dir.join("on-base.binary");
        let err = tabulate(&path, Some(&output), Some(1))
            .unwrap_err()
            .to_string();
        assert!(err.contains("analytic base (\"roughconductor\")"), "{err}");
        assert!(!output.exists());
        std::fs::remove_dir_all(&dir).ok();
    }
}
