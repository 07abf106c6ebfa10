//! What the C-ABI tests share: status codes, the last error, a small config and the trainer's
//! own directions, each called as a C caller calls them.

#![allow(dead_code)] // each test file uses its own subset

use glam::Vec3;
use nbrdf_train::*;
use std::ffi::CStr;

pub const OK: i32 = NbrdfTrainStatus::NBRDF_TRAIN_OK as i32;
pub const NULL: i32 = NbrdfTrainStatus::NBRDF_TRAIN_ERROR_NULL_POINTER as i32;
pub const INVALID: i32 = NbrdfTrainStatus::NBRDF_TRAIN_ERROR_INVALID_ARGUMENT as i32;

pub fn last_error() -> String {
    // SAFETY: the library returns a valid NUL-terminated string.
    unsafe { CStr::from_ptr(nbrdf_train_last_error()) }
        .to_string_lossy()
        .into_owned()
}

/// The defaults shrunk to a run of a fraction of a second on one thread.
pub fn small_config() -> NbrdfTrainConfig {
    let mut config = std::mem::MaybeUninit::<NbrdfTrainConfig>::uninit();
    // SAFETY: a writable config.
    assert_eq!(
        unsafe { nbrdf_train_config_default(config.as_mut_ptr()) },
        OK
    );
    // SAFETY: initialised by the call above.
    let mut config = unsafe { config.assume_init() };
    config.samples = 2000;
    config.max_epochs = 3;
    config.hidden = 8;
    config.batch = 128;
    config.threads = 1;
    config
}

/// The trainer's planar view and light directions for `config` (`3 n` floats each) with `n`
/// and the validation count, from `nbrdf_train_sample_counts` and `nbrdf_train_directions`
/// (for the as-given fold).
pub fn directions(config: &NbrdfTrainConfig) -> (Vec<f32>, Vec<f32>, usize, usize) {
    directions_for(config, NbrdfTrainFold::NBRDF_TRAIN_FOLD_AS_GIVEN as i32)
}

/// [`directions`] for the `NbrdfTrainFold` value `fold`.
pub fn directions_for(config: &NbrdfTrainConfig, fold: i32) -> (Vec<f32>, Vec<f32>, usize, usize) {
    let (mut n_train, mut n_validation) = (0, 0);
    // SAFETY: valid pointers.
    let status = unsafe { nbrdf_train_sample_counts(config, &mut n_train, &mut n_validation) };
    assert_eq!(status, OK, "{}", last_error());
    let n = n_train + n_validation;
    let (mut view, mut light) = (vec![0.0; 3 * n], vec![0.0; 3 * n]);
    // SAFETY: 3 n floats each.
    let status =
        unsafe { nbrdf_train_directions(config, fold, n, view.as_mut_ptr(), light.as_mut_ptr()) };
    assert_eq!(status, OK, "{}", last_error());
    (view, light, n, n_validation)
}

/// The first `n` pairs of planar direction arrays (`3 n` floats each, as the C calls take and
/// give them) as `(view, light)` vectors.
pub fn planar_pairs(view: &[f32], light: &[f32], n: usize) -> Vec<(Vec3, Vec3)> {
    let at = |d: &[f32], i: usize| Vec3::new(d[i], d[n + i], d[2 * n + i]);
    (0..n).map(|i| (at(view, i), at(light, i))).collect()
}
