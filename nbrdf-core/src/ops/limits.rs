//! The documented ranges of the commands' size settings (docs/hardening.md) and the memory
//! estimate checked before anything is allocated: a setting out of range is an
//! [`NbrdfError::Usage`] naming the option and its limit (exit status 2 in the CLI), never
//! an allocation failure or a process killed for memory. The checks live here, in the library,
//! so that every caller of [`crate::ops`] gets them; the CLI also declares the ranges to clap.

use crate::error::{NbrdfError, Result};
use crate::train::TrainConfig;

/// Widest hidden layer trained (the paper's is 21; the traced Mitsuba backend is already slow
/// at a few hundred).
pub const MAX_HIDDEN: usize = 4096;
/// Largest mini-batch.
pub const MAX_BATCH: usize = 1 << 20;
/// Most training or fitting samples (each is a few dozen bytes; the memory cap applies too).
pub const MAX_SAMPLES: usize = 100_000_000;
/// Most epochs (each keeps a line of history).
pub const MAX_EPOCHS: usize = 1_000_000;
/// Widest comparison sphere image, pixels.
pub const MAX_RESOLUTION: usize = 4096;
/// Most code-refinement iterations, interpolation steps, seeds or mixup examples.
pub const MAX_ITERATIONS: usize = 1_000_000;
/// Memory a command may plan to use.
pub const MAX_MEMORY_BYTES: u64 = 8 << 30;

/// `value` within `[min, max]`, or an error naming `option` and the range.
pub fn check_range(option: &str, value: usize, min: usize, max: usize) -> Result<()> {
    if (min..=max).contains(&value) {
        Ok(())
    } else {
        Err(NbrdfError::Usage(format!(
            "{option} {value} is out of range: it must be in [{min}, {max}] (docs/hardening.md)"
        )))
    }
}

/// An estimate of `bytes` for `what` within [`MAX_MEMORY_BYTES`]; `None` (an overflow) fails.
pub fn check_memory(what: &str, bytes: Option<u64>) -> Result<()> {
    match bytes {
        Some(b) if b <= MAX_MEMORY_BYTES => Ok(()),
        _ => Err(NbrdfError::Usage(format!(
            "{what} would need about {} of memory, more than the {} GiB limit; use smaller sizes",
            bytes.map_or("more than 16 EiB".to_string(), |b| format!(
                "{:.1} GiB",
                b as f64 / f64::from(1u32 << 30)
            )),
            MAX_MEMORY_BYTES >> 30
        ))),
    }
}

/// Bytes of one drawn training sample with its bookkeeping (inputs, target, weight, spare).
const SAMPLE_BYTES: u64 = 64;

/// The training settings' ranges and the memory they plan: the samples (with validation), and
/// for the network about eight copies of its parameters (weights, gradients per worker chunk,
/// Adam moments, the best so far) plus the activations of a batch.
pub fn check_train(config: &TrainConfig) -> Result<()> {
    check_range("--hidden", config.hidden, 1, MAX_HIDDEN)?;
    check_range("--batch", config.batch, 1, MAX_BATCH)?;
    check_range("--samples", config.samples, 1, MAX_SAMPLES)?;
    check_range("--epochs", config.max_epochs, 1, MAX_EPOCHS)?;
    let h = config.hidden as u64;
    let samples = (config.samples as f64 * (1.0 + config.validation_fraction.max(0.0))) as u64;
    let parameters = h * h + 11 * h + 3;
    let threads = rayon::current_num_threads() as u64;
    let bytes = samples
        .checked_mul(SAMPLE_BYTES)
        .and_then(|s| s.checked_add(parameters * 4 * (8 + threads)))
        .and_then(|s| s.checked_add(config.batch as u64 * h * 4 * 4));
    check_memory("training", bytes)
}

/// Samples of a Blinn-Phong fit (`fit-phong --samples`).
pub fn check_fit_samples(samples: usize) -> Result<()> {
    check_range("--samples", samples, 1, MAX_SAMPLES)?;
    check_memory(
        "the fit's samples",
        (samples as u64).checked_mul(SAMPLE_BYTES),
    )
}

/// `compare`: spheres of `resolution` pixels (two views and two lights buffers of three floats
/// per pixel, two images per light) and `samples` directions (no storage, but time).
pub fn check_compare(resolution: usize, samples: usize) -> Result<()> {
    check_range("--resolution", resolution, 1, MAX_RESOLUTION)?;
    check_range("--samples", samples, 1, MAX_SAMPLES)?;
    let pixels = (resolution as u64).pow(2);
    check_memory(
        "the comparison images",
        pixels.checked_mul(4 * 3 * 4 + 2 * 3 * 8),
    )
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn ranges_name_the_option_and_the_limit() {
        assert!(check_range("--hidden", 21, 1, MAX_HIDDEN).is_ok());
        let e = check_range("--hidden", 100_000, 1, MAX_HIDDEN).unwrap_err();
        assert!(matches!(e, NbrdfError::Usage(_)));
        assert!(e.to_string().contains("--hidden 100000"), "{e}");
        assert!(e.to_string().contains("4096"), "{e}");
        assert!(check_range("--batch", 0, 1, MAX_BATCH).is_err());
    }

    #[test]
    fn memory_is_estimated_before_allocating() {
        let default = TrainConfig::default();
        assert!(check_train(&default).is_ok());
        // Within every range, but together beyond the memory cap: width 4096 with a batch of a
        // million is 64 GiB of activations.
        let wide = TrainConfig {
            hidden: MAX_HIDDEN,
            batch: MAX_BATCH,
            ..TrainConfig::default()
        };
        let e = check_train(&wide).unwrap_err();
        assert!(e.to_string().contains("GiB limit"), "{e}");
        for bad in [
            TrainConfig {
                hidden: 100_000,
                ..TrainConfig::default()
            },
            TrainConfig {
                batch: 100_000_000,
                ..TrainConfig::default()
            },
            TrainConfig {
                samples: usize::MAX,
                ..TrainConfig::default()
            },
            TrainConfig {
                max_epochs: usize::MAX,
                ..TrainConfig::default()
            },
        ] {
            assert!(matches!(check_train(&bad), Err(NbrdfError::Usage(_))));
        }
        assert!(check_memory("x", None).is_err());
        assert!(check_compare(128, 100_000).is_ok());
        assert!(check_compare(100_000, 100_000).is_err());
        assert!(check_fit_samples(10_000_000_000).is_err());
        assert!(check_fit_samples(200_000).is_ok());
    }
}
