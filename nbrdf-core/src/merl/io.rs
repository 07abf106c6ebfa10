//! Reading, validating and writing MERL-format files (a 12-byte header, then three channels of
//! float64 cell values, channel-major).

use super::{cell_coordinates, MerlTable, PhiFold, CELLS, N_PHI_D, N_THETA_D, N_THETA_H, SCALE};
use crate::error::{regular_file_size, NbrdfError, Result};
use std::io::Read;
use std::path::Path;
use std::sync::OnceLock;

/// Size of a valid file: 3 int32 header values and 3 channels of float64.
pub const FILE_SIZE: usize = 12 + 3 * CELLS * 8;
const HEADER: [i32; 3] = [N_THETA_H as i32, N_THETA_D as i32, N_PHI_D as i32];
const HEADER_SIZE: usize = 12;

/// A human-readable description of where a flat stored index points.
fn describe_position(flat: usize) -> String {
    let channel = ["red", "green", "blue"]
        .get(flat / CELLS)
        .copied()
        .unwrap_or("?");
    let (th, td, pd) = cell_coordinates(flat % CELLS);
    format!("{channel} channel, cell (theta_h {th}, theta_d {td}, phi_d {pd})")
}

/// Whether bytes start with the header of a MERL table (90, 90, 180).
pub(crate) fn has_merl_header(bytes: &[u8]) -> bool {
    bytes.len() >= HEADER_SIZE
        && HEADER
            .iter()
            .enumerate()
            .all(|(k, h)| bytes[4 * k..4 * k + 4] == h.to_le_bytes())
}

/// Whether bytes look like the start of a JSON document (an NBRDF network given by mistake).
pub(crate) fn looks_like_json(bytes: &[u8]) -> bool {
    matches!(
        bytes.iter().find(|b| !b.is_ascii_whitespace()),
        Some(b'{') | Some(b'[')
    )
}

/// The first reason stored values (channel-major, `3 * CELLS`, finite) cannot be rendered:
/// a value whose reflectance (stored x [`SCALE`]) overflows float32, the precision the
/// renderer reads it in, or a table without a single cell valid in all three channels.
fn value_problem(stored_at: impl Fn(usize) -> f64) -> Option<String> {
    for (c, scale) in SCALE.iter().enumerate() {
        for i in 0..CELLS {
            let flat = c * CELLS + i;
            let value = stored_at(flat);
            if value * scale > f64::from(f32::MAX) {
                return Some(format!(
                    "value {value:e} at byte offset {} ({}) is {:e} once scaled, beyond the \
                     float32 range (3.4e38) the table is rendered in",
                    HEADER_SIZE + 8 * flat,
                    describe_position(flat),
                    value * scale
                ));
            }
        }
    }
    let any_valid = (0..CELLS).any(|i| (0..3).all(|c| stored_at(c * CELLS + i) >= 0.0));
    if !any_valid {
        return Some(
            "no valid cell: every cell has a channel marked not measured (negative), \
             so the table would render black"
                .to_string(),
        );
    }
    None
}

impl MerlTable {
    /// Parses the bytes of a MERL file; `origin` names the file in errors.
    pub fn from_bytes(bytes: &[u8], origin: &Path) -> Result<Self> {
        Self::parse(bytes, bytes.len() as u64, origin)
    }

    /// `bytes` may be a prefix of the file (reading stops one byte past a valid size);
    /// `file_size` is the real size, for the message.
    fn parse(bytes: &[u8], file_size: u64, origin: &Path) -> Result<Self> {
        let fail = |message: String| Err(NbrdfError::format(origin, message));
        if !has_merl_header(bytes) && looks_like_json(bytes) {
            return fail(
                "this is JSON (an NBRDF network?), not a MERL table (.binary); networks are \
                 read by the nbrdf BSDF and the commands that take NAME.nbrdf.json"
                    .to_string(),
            );
        }
        if bytes.len() < HEADER_SIZE {
            return fail(format!(
                "truncated: {file_size} bytes, a MERL table has {FILE_SIZE} (not even the 12-byte header)"
            ));
        }
        let header: [i32; 3] = std::array::from_fn(|k| {
            let b = &bytes[4 * k..4 * k + 4];
            i32::from_le_bytes([b[0], b[1], b[2], b[3]])
        });
        if header != HEADER {
            return fail(format!(
                "header is ({}, {}, {}), a MERL table has (90, 90, 180) (theta_h, theta_d, phi_d)",
                header[0], header[1], header[2]
            ));
        }
        if file_size < FILE_SIZE as u64 {
            return fail(format!(
                "truncated: {file_size} bytes, a MERL table has {FILE_SIZE}"
            ));
        }
        if file_size > FILE_SIZE as u64 || bytes.len() != FILE_SIZE {
            return fail(format!(
                "{file_size} bytes, a MERL table has exactly {FILE_SIZE} (trailing data after the last value)"
            ));
        }
        let mut cells = vec![[0.0; 3]; CELLS];
        for (k, chunk) in bytes[HEADER_SIZE..].chunks_exact(8).enumerate() {
            let mut raw = [0u8; 8];
            raw.copy_from_slice(chunk);
            let value = f64::from_le_bytes(raw);
            if !value.is_finite() {
                return fail(format!(
                    "non-finite value {value} at byte offset {} ({})",
                    HEADER_SIZE + 8 * k,
                    describe_position(k)
                ));
            }
            cells[k % CELLS][k / CELLS] = value;
        }
        if let Some(problem) = value_problem(|flat| cells[flat % CELLS][flat / CELLS]) {
            return fail(problem);
        }
        Ok(MerlTable {
            cells,
            channel_major: OnceLock::new(),
            phi_fold: PhiFold::Reciprocal,
        })
    }

    pub fn read(path: impl AsRef<Path>) -> Result<Self> {
        let path = path.as_ref();
        let io = |e| NbrdfError::io(path, e);
        // Before opening: a FIFO would block the open, a device would never end.
        regular_file_size(path, u64::MAX, "a MERL table (.binary)")?;
        let file = std::fs::File::open(path).map_err(io)?;
        let file_size = file.metadata().map_err(io)?.len();
        // Bounded read: a huge file given by mistake is rejected without loading it whole.
        let mut bytes = Vec::with_capacity(FILE_SIZE.min(file_size as usize) + 1);
        file.take(FILE_SIZE as u64 + 1)
            .read_to_end(&mut bytes)
            .map_err(io)?;
        Self::parse(&bytes, file_size.max(bytes.len() as u64), path)
    }

    pub fn to_bytes(&self) -> Vec<u8> {
        let mut bytes = Vec::with_capacity(FILE_SIZE);
        for h in HEADER {
            bytes.extend_from_slice(&h.to_le_bytes());
        }
        for c in 0..3 {
            for cell in &self.cells {
                bytes.extend_from_slice(&cell[c].to_le_bytes());
            }
        }
        bytes
    }

    pub fn write(&self, path: impl AsRef<Path>) -> Result<()> {
        let path = path.as_ref();
        std::fs::write(path, self.to_bytes()).map_err(|e| NbrdfError::io(path, e))
    }

    /// Builds a table from stored (unscaled) values, channel-major, `3 * CELLS` long.
    pub fn from_stored(stored: Vec<f64>) -> Result<Self> {
        if stored.len() != 3 * CELLS {
            return Err(NbrdfError::InvalidArgument(format!(
                "a MERL table holds {} stored values (3 x 90 x 90 x 180), got {}",
                3 * CELLS,
                stored.len()
            )));
        }
        if let Some(k) = stored.iter().position(|x| !x.is_finite()) {
            return Err(NbrdfError::InvalidArgument(format!(
                "non-finite stored value {} at index {k} ({})",
                stored[k],
                describe_position(k)
            )));
        }
        if let Some(problem) = value_problem(|flat| stored[flat]) {
            return Err(NbrdfError::InvalidArgument(problem));
        }
        let cells = (0..CELLS)
            .map(|i| [stored[i], stored[CELLS + i], stored[2 * CELLS + i]])
            .collect();
        Ok(MerlTable {
            cells,
            channel_major: OnceLock::from(stored),
            phi_fold: PhiFold::Reciprocal,
        })
    }
}
