//! A MERL file described structurally: a header near (90, 90, 180), a size near the valid one,
//! a whole-table fill and a few patched values. Byte-level mutation of a 35 MB input rarely keeps
//! the header and size intact; this target always gets that far, so every input reaches the
//! value checks, and most of them the lookup (with fuzzer-chosen directions).

#![no_main]

use arbitrary::Arbitrary;
use libfuzzer_sys::fuzz_target;
use nbrdf_core::merl::MerlTable;
use nbrdf_core_fuzz::{
    assert_acceptable_merl, check_error_names_origin, check_evaluations, fixed_pairs,
    pairs_from_components, MERL_CELLS, MERL_FILE_SIZE, MERL_HEADER,
};
use std::cell::RefCell;
use std::path::Path;

const ORIGIN: &str = "fuzz/structured.binary";

#[derive(Arbitrary, Debug)]
enum HeaderField {
    Valid,
    Offset(i8),
    Raw(i32),
}

#[derive(Arbitrary, Debug)]
enum Length {
    Exact,
    Shorter(u16),
    Longer(u16),
    /// Only the first `n` bytes (a header at most, with n < 256).
    Prefix(u8),
}

#[derive(Arbitrary, Debug)]
enum Fill {
    Constant(f64),
    /// `base + amplitude * u` with `u` in [0, 1) varying from cell to cell.
    Varying {
        base: f64,
        amplitude: f64,
    },
    NotMeasured,
}

#[derive(Arbitrary, Debug)]
enum Value {
    Raw(f64),
    Bits(u64),
    NotMeasured,
    Huge,
    Tiny,
}

#[derive(Arbitrary, Debug)]
struct Patch {
    /// Index of a stored value (modulo the 3 * 1458000 values).
    position: u32,
    /// How many consecutive values get it (at most 255), e.g. a whole `phi_d` row.
    run: u8,
    value: Value,
}

#[derive(Arbitrary, Debug)]
struct Input {
    header: [HeaderField; 3],
    length: Length,
    fill: Fill,
    patches: Vec<Patch>,
    directions: Vec<[f32; 6]>,
}

impl Value {
    fn get(&self) -> f64 {
        match *self {
            Value::Raw(x) => x,
            Value::Bits(bits) => f64::from_bits(bits),
            Value::NotMeasured => -1.0,
            Value::Huge => f64::MAX,
            Value::Tiny => f64::from_bits(1),
        }
    }
}

/// Values of the `Varying` fill repeat with this period (a prime, so that the pattern does not
/// line up with the grid's axes); the rest of the table is copied, not computed.
const PERIOD: usize = 1021;

/// Writes the file `input` describes into `bytes` (reused between runs: a fresh 35 MB buffer per
/// input costs more than the reader itself).
fn build(input: &Input, bytes: &mut Vec<u8>) {
    bytes.clear();
    for (field, valid) in input.header.iter().zip(MERL_HEADER) {
        let h = match *field {
            HeaderField::Valid => valid,
            HeaderField::Offset(d) => valid.wrapping_add(i32::from(d)),
            HeaderField::Raw(x) => x,
        };
        bytes.extend_from_slice(&h.to_le_bytes());
    }
    let values = 3 * MERL_CELLS;
    for k in 0..PERIOD {
        let v = match input.fill {
            Fill::Constant(x) => x,
            Fill::Varying { base, amplitude } => {
                let u = ((k as u64).wrapping_mul(0x9E37_79B9_7F4A_7C15) >> 11) as f64
                    / (1u64 << 53) as f64;
                base + amplitude * u
            }
            Fill::NotMeasured => -1.0,
        };
        bytes.extend_from_slice(&v.to_le_bytes());
    }
    bytes.resize(MERL_FILE_SIZE, 0);
    // Doubling copies of the first period: memcpy speed.
    let mut filled = 8 * PERIOD;
    while filled < 8 * values {
        let n = filled.min(8 * values - filled);
        bytes.copy_within(12..12 + n, 12 + filled);
        filled += n;
    }
    for patch in input.patches.iter().take(64) {
        let start = patch.position as usize % values;
        let end = (start + usize::from(patch.run).max(1)).min(values);
        let v = patch.value.get().to_le_bytes();
        for k in start..end {
            bytes[12 + 8 * k..20 + 8 * k].copy_from_slice(&v);
        }
    }
    match input.length {
        Length::Exact => {}
        Length::Shorter(n) => bytes.truncate(MERL_FILE_SIZE - usize::from(n).max(1)),
        Length::Longer(n) => bytes.resize(MERL_FILE_SIZE + usize::from(n).max(1), 0),
        Length::Prefix(n) => bytes.truncate(usize::from(n)),
    }
}

thread_local! {
    static BUFFER: RefCell<Vec<u8>> = RefCell::new(Vec::with_capacity(MERL_FILE_SIZE + 65536));
}

fuzz_target!(|input: Input| {
    BUFFER.with_borrow_mut(|bytes| {
        build(&input, bytes);
        check(&input, bytes);
    });
});

fn check(input: &Input, bytes: &[u8]) {
    match MerlTable::from_bytes(bytes, Path::new(ORIGIN)) {
        Ok(table) => {
            let bound = assert_acceptable_merl(bytes);
            let mut pairs = fixed_pairs();
            pairs.extend(pairs_from_components(
                &input.directions[..input.directions.len().min(16)],
            ));
            check_evaluations(&table, &pairs, Some(bound));
        }
        Err(error) => check_error_names_origin(&error, ORIGIN),
    }
}
