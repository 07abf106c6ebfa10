//! C ABI of nbrdf's trainer for distillation (`libnbrdf_train`): the trainer's sample
//! directions, and a network trained from reflectance values a caller computed there
//! (`python -m nbrdf_mitsuba.distill` evaluates a Mitsuba 3 BSDF); and a spatially varying
//! material trained from a textured source's values and written to disk (`textured.rs`,
//! `python -m nbrdf_mitsuba.distill --spatial`). A library of its own so that the rendering
//! library `libnbrdf_ffi` never links the training stack.
//!
//! The header `include/nbrdf_train.h` is generated from these files by cbindgen
//! (`NBRDF_BLESS=1 cargo test -p nbrdf-train-ffi --test header` regenerates it). The crate is a
//! thin shell around `nbrdf_core::ops::distill` and `nbrdf_core::distillation`: it checks pointers and lengths, turns errors
//! and panics into status codes with a thread-local message, and converts planar arrays. The
//! error plumbing (failures, last error, panic guard, pointer checks) is nbrdf-ffi-common's,
//! shared with nbrdf-ffi.
//!
//! Conventions, those of nbrdf-ffi: planar arrays (`3 n` floats `[x.., y.., z..]` for
//! directions, `[r.., g.., b..]` for colours), local shading frame with z the normal, `view`
//! towards the viewer (Mitsuba's `si.wi`), `light` towards the light (Mitsuba's `wo`). Values
//! are `f_r(view, light) cos(theta_light)`, what Mitsuba's `BSDF.eval` returns.

#![deny(unsafe_op_in_unsafe_fn)]

mod textured;
pub use textured::*;

use glam::Vec3;
use nbrdf_core::ops::distill::{self, DistillArrays, DistillRequest};
use nbrdf_core::source::RglFold;
use nbrdf_core::train::adam::AdamConfig;
use nbrdf_core::train::arrays::SampledArrays;
use nbrdf_core::train::dataset::AngularSampling;
use nbrdf_core::train::spectral::SampledSpectra;
use nbrdf_core::train::{EpochStats, TrainConfig};
use nbrdf_ffi_common::{array_len, check_pointer, input, Failure, FailureKind, FfiResult, Status};
use std::ffi::{c_char, c_void, CStr, CString};

/// Status code returned (as `int32_t`) by every fallible function; the values are those of
/// nbrdf-ffi's `NbrdfStatus`. On any value other than `NBRDF_TRAIN_OK`,
/// `nbrdf_train_last_error()` describes the failure.
#[repr(C)]
#[allow(non_camel_case_types)]
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum NbrdfTrainStatus {
    /// Success.
    NBRDF_TRAIN_OK = 0,
    /// A required pointer argument was null; the message names the argument.
    NBRDF_TRAIN_ERROR_NULL_POINTER = 1,
    /// An argument is outside its domain: settings, lengths, values that are not finite.
    NBRDF_TRAIN_ERROR_INVALID_ARGUMENT = 2,
    /// A file could not be written (`nbrdf_train_textured`); the message names it.
    NBRDF_TRAIN_ERROR_IO = 3,
    /// The library caught an internal panic (a bug); the message carries the panic message.
    NBRDF_TRAIN_ERROR_PANIC = 5,
}

/// How the trainer draws view/light pairs (`NbrdfTrainConfig.sampling`).
#[repr(C)]
#[allow(non_camel_case_types)]
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum NbrdfTrainSampling {
    /// Uniform in the Rusinkiewicz angles theta_h, theta_d, phi_d: dense at the specular peak.
    NBRDF_TRAIN_SAMPLING_ADAPTIVE = 0,
    /// Light and view each uniform over the hemisphere.
    NBRDF_TRAIN_SAMPLING_UNIFORM = 1,
}

/// How a non-reciprocal source enters the training target (`nbrdf_train_directions`,
/// `nbrdf_train_from_arrays`, `nbrdf_train_spectral_from_arrays`).
#[repr(C)]
#[allow(non_camel_case_types)]
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum NbrdfTrainFold {
    /// `f(view, light)` as given: what a scene with the source renders.
    NBRDF_TRAIN_FOLD_AS_GIVEN = 0,
    /// `(f(view, light) + f(light, view)) / 2`, from the values and the swapped values. Pairs
    /// with a cosine below 0.01 are left out (the swapped term divides by `cos_view`):
    /// `nbrdf_train_directions` draws the next candidates in their place, and the
    /// `*_from_arrays` functions drop any they are given.
    NBRDF_TRAIN_FOLD_RECIPROCAL_MEAN = 1,
}

/// Training settings; `nbrdf_train_config_default` fills in the trainer's adaptive defaults
/// (those of `nbrdf train`). `samples` and `validation_fraction` decide the number of
/// directions of `nbrdf_train_directions`; `nbrdf_train_from_arrays` trains on the arrays it is
/// given instead.
#[repr(C)]
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct NbrdfTrainConfig {
    /// An `NbrdfTrainSampling` value.
    pub sampling: i32,
    /// Training pairs.
    pub samples: usize,
    /// Validation pairs as a fraction of `samples` (in (0, 1]; at least one pair).
    pub validation_fraction: f64,
    pub max_epochs: usize,
    /// Width of the two hidden layers (21: the paper's).
    pub hidden: usize,
    pub batch: usize,
    pub learning_rate: f32,
    /// Epochs without a relative validation improvement of `min_improvement` before the
    /// learning rate drops (`lr_decays` times, by `lr_decay_factor`) or training stops, but not
    /// before `min_epochs`.
    pub patience: usize,
    pub min_improvement: f64,
    pub min_epochs: usize,
    pub lr_decays: usize,
    pub lr_decay_factor: f32,
    /// Stop once the validation loss is at most this (0: off).
    pub target_loss: f64,
    pub seed: u64,
    /// Worker threads; 0: one per core.
    pub threads: usize,
    /// 1: an anisotropic network (its input carries the half vector's azimuth `phi_h`, and
    /// `nbrdf_train_directions` draws `phi_h` too); 0: isotropic. Other values are errors.
    /// `nbrdf_train_config_for_anisotropy` sets it with the trainer's default sample scaling.
    pub anisotropic: i32,
}

/// Progress after one epoch, passed to the `NbrdfEpochCallback`.
#[repr(C)]
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct NbrdfEpochStats {
    /// 1-based.
    pub epoch: usize,
    pub max_epochs: usize,
    pub train_loss: f64,
    pub validation_loss: f64,
    pub best_validation_loss: f64,
    pub best_epoch: usize,
    /// Since training began.
    pub seconds: f64,
}

/// Called after every epoch with the caller's `user` pointer, on a thread of the library's
/// pool; `stats` is valid during the call only.
pub type NbrdfEpochCallback =
    Option<unsafe extern "C" fn(user: *mut c_void, stats: *const NbrdfEpochStats)>;

// ---------------------------------------------------------------------------------------------
// Errors (the plumbing is nbrdf-ffi-common's, shared with nbrdf-ffi).

impl Status for NbrdfTrainStatus {
    const OK: i32 = NbrdfTrainStatus::NBRDF_TRAIN_OK as i32;

    /// The trainer reads no files: what the core reports as a file's content is an argument's.
    fn code(kind: FailureKind) -> i32 {
        (match kind {
            FailureKind::NullPointer => NbrdfTrainStatus::NBRDF_TRAIN_ERROR_NULL_POINTER,
            FailureKind::InvalidArgument | FailureKind::Format => {
                NbrdfTrainStatus::NBRDF_TRAIN_ERROR_INVALID_ARGUMENT
            }
            FailureKind::Io => NbrdfTrainStatus::NBRDF_TRAIN_ERROR_IO,
            FailureKind::Panic => NbrdfTrainStatus::NBRDF_TRAIN_ERROR_PANIC,
        }) as i32
    }
}

/// Runs `body`, catching panics; returns the status code and records the message of a failure
/// (prefixed with `function`) for `nbrdf_train_last_error`.
fn guard(function: &str, body: impl FnOnce() -> FfiResult<()>) -> i32 {
    nbrdf_ffi_common::guard::<NbrdfTrainStatus>(function, body)
}

// ---------------------------------------------------------------------------------------------
// Arguments.

fn planar_vectors(planar: &[f32]) -> Vec<Vec3> {
    let n = planar.len() / 3;
    (0..n)
        .map(|i| Vec3::new(planar[i], planar[n + i], planar[2 * n + i]))
        .collect()
}

fn planar_colours(planar: &[f32]) -> Vec<[f32; 3]> {
    planar_vectors(planar)
        .into_iter()
        .map(|c| c.to_array())
        .collect()
}

/// A NUL-terminated UTF-8 string argument.
///
/// # Safety
/// A non-null `ptr` points to a NUL-terminated string.
unsafe fn read_str(ptr: *const c_char, argument: &str) -> FfiResult<String> {
    if ptr.is_null() {
        return Err(Failure::null(argument));
    }
    // SAFETY: non-null, NUL-terminated by contract.
    let bytes = unsafe { CStr::from_ptr(ptr) }.to_bytes();
    String::from_utf8(bytes.to_vec())
        .map_err(|_| Failure::invalid(format!("argument `{argument}` is not valid UTF-8")))
}

fn to_c(config: &TrainConfig, threads: usize) -> NbrdfTrainConfig {
    NbrdfTrainConfig {
        sampling: match config.sampling {
            AngularSampling::Adaptive => NbrdfTrainSampling::NBRDF_TRAIN_SAMPLING_ADAPTIVE as i32,
            AngularSampling::Uniform => NbrdfTrainSampling::NBRDF_TRAIN_SAMPLING_UNIFORM as i32,
        },
        samples: config.samples,
        validation_fraction: config.validation_fraction,
        max_epochs: config.max_epochs,
        hidden: config.hidden,
        batch: config.batch,
        learning_rate: config.adam.learning_rate,
        patience: config.patience,
        min_improvement: config.min_improvement,
        min_epochs: config.min_epochs,
        lr_decays: config.lr_decays,
        lr_decay_factor: config.lr_decay_factor,
        target_loss: config.target_loss,
        seed: config.seed,
        threads,
        anisotropic: i32::from(config.anisotropic),
    }
}

/// The core's settings of a C config (ranges are checked by the core) and the thread count.
///
/// # Safety
/// A non-null `config` points to a live `NbrdfTrainConfig`.
unsafe fn read_config(config: *const NbrdfTrainConfig) -> FfiResult<(TrainConfig, Option<usize>)> {
    check_pointer(config, "config")?;
    // SAFETY: non-null and aligned (checked), initialised by contract; every field is a plain
    // number (the sampling is an int, not a Rust enum).
    let c = unsafe { config.read() };
    let sampling = match c.sampling {
        0 => AngularSampling::Adaptive,
        1 => AngularSampling::Uniform,
        other => {
            return Err(Failure::invalid(format!(
                "unknown sampling {other} (expected 0 = adaptive, 1 = uniform)"
            )))
        }
    };
    let anisotropic = match c.anisotropic {
        0 => false,
        1 => true,
        other => {
            return Err(Failure::invalid(format!(
                "anisotropic is {other} (expected 0 = isotropic, 1 = anisotropic)"
            )))
        }
    };
    let defaults = TrainConfig::default();
    let config = TrainConfig {
        sampling,
        samples: c.samples,
        validation_fraction: c.validation_fraction,
        max_epochs: c.max_epochs,
        hidden: c.hidden,
        batch: c.batch,
        adam: AdamConfig {
            learning_rate: c.learning_rate,
            ..defaults.adam
        },
        patience: c.patience,
        min_improvement: c.min_improvement,
        min_epochs: c.min_epochs,
        lr_decays: c.lr_decays,
        lr_decay_factor: c.lr_decay_factor,
        // Not in the C struct (its layout stays): the defaults' schedule.
        lr_schedule: defaults.lr_schedule,
        target_loss: c.target_loss,
        seed: c.seed,
        anisotropic,
    };
    Ok((config, (c.threads > 0).then_some(c.threads)))
}

/// The epoch callback and its user pointer, handed to the trainer's threads.
struct Callback {
    function: unsafe extern "C" fn(*mut c_void, *const NbrdfEpochStats),
    user: *mut c_void,
}

// SAFETY: the caller of `nbrdf_train_from_arrays` accepts that the callback runs on the
// library's threads (documented); the pointer is only handed back to it, one call at a time.
unsafe impl Send for Callback {}

impl Callback {
    fn call(&self, e: &EpochStats) {
        let stats = NbrdfEpochStats {
            epoch: e.epoch,
            max_epochs: e.max_epochs,
            train_loss: e.train_loss,
            validation_loss: e.validation_loss,
            best_validation_loss: e.best_validation_loss,
            best_epoch: e.best_epoch,
            seconds: e.seconds,
        };
        // SAFETY: the caller's function and pointer, called as documented.
        unsafe { (self.function)(self.user, &stats) }
    }
}

// ---------------------------------------------------------------------------------------------
// Exported functions.

/// Message of the last failed call on this thread, prefixed with the name of the function that
/// failed; an empty string when no call has failed on this thread. The pointer stays valid until
/// the next call into this library on the same thread.
#[no_mangle]
pub extern "C" fn nbrdf_train_last_error() -> *const c_char {
    nbrdf_ffi_common::last_error()
}

/// Version of the library (the crate version, e.g. "0.1.0"); a static string.
#[no_mangle]
pub extern "C" fn nbrdf_train_version() -> *const c_char {
    concat!(env!("CARGO_PKG_VERSION"), "\0").as_ptr().cast()
}

/// Fills `*out` with the trainer's defaults (those of `nbrdf train`: adaptive sampling, 800,000
/// pairs, up to 300 epochs, early stopping), `threads` 0.
///
/// # Safety
/// `out` points to a writable `NbrdfTrainConfig`.
#[no_mangle]
pub unsafe extern "C" fn nbrdf_train_config_default(out: *mut NbrdfTrainConfig) -> i32 {
    guard("nbrdf_train_config_default", || {
        check_pointer(out, "out")?;
        // SAFETY: non-null, aligned, writable by contract.
        unsafe { out.write(to_c(&TrainConfig::default(), 0)) };
        Ok(())
    })
}

/// Makes `*config` a configuration for an isotropic (`anisotropic` 0) or anisotropic (1)
/// network, as `nbrdf train --anisotropy` does: with `scale_samples` 1, an anisotropic network
/// gets the trainer's default factor (5) times `samples` (for a sample count that is the
/// default rather than the user's); 0 keeps `samples`.
///
/// # Safety
/// `config` points to a readable and writable `NbrdfTrainConfig`.
#[no_mangle]
pub unsafe extern "C" fn nbrdf_train_config_for_anisotropy(
    config: *mut NbrdfTrainConfig,
    anisotropic: i32,
    scale_samples: i32,
) -> i32 {
    guard("nbrdf_train_config_for_anisotropy", || {
        let flag = |value: i32, argument: &str| match value {
            0 => Ok(false),
            1 => Ok(true),
            other => Err(Failure::invalid(format!(
                "argument `{argument}` is {other} (expected 0 or 1)"
            ))),
        };
        let (anisotropic, scale) = (
            flag(anisotropic, "anisotropic")?,
            flag(scale_samples, "scale_samples")?,
        );
        // SAFETY: forwarded contract.
        let (core, threads) = unsafe { read_config(config)? };
        let core = core.for_anisotropy(anisotropic, scale);
        // SAFETY: non-null, aligned (read_config), writable by contract.
        unsafe { config.write(to_c(&core, threads.unwrap_or(0))) };
        Ok(())
    })
}

/// Stores the number of training and validation pairs of `config` (what
/// `nbrdf_train_directions` writes with either fold, training pairs first) after checking its
/// settings.
///
/// # Safety
/// `config` points to an `NbrdfTrainConfig`; the outputs point to writable `size_t`s.
#[no_mangle]
pub unsafe extern "C" fn nbrdf_train_sample_counts(
    config: *const NbrdfTrainConfig,
    out_train: *mut usize,
    out_validation: *mut usize,
) -> i32 {
    guard("nbrdf_train_sample_counts", || {
        // SAFETY: forwarded contract.
        let (config, _) = unsafe { read_config(config)? };
        check_pointer(out_train, "out_train")?;
        check_pointer(out_validation, "out_validation")?;
        let (train, validation) = distill::sample_counts(&config)?;
        // SAFETY: non-null, aligned, writable by contract.
        unsafe {
            out_train.write(train);
            out_validation.write(validation);
        }
        Ok(())
    })
}

/// Writes the trainer's `n` view/light pairs for `config` (planar `3 n` floats each, unit
/// vectors above the horizon): the training pairs, then the validation pairs, as
/// `nbrdf_train_sample_counts` counts them; `n` must be their sum. Directions are full 3D
/// vectors: a caller must not assume any symmetry of them. With `config.anisotropic` the
/// adaptive pairs cover the half vector's azimuth too (the same config must then train).
/// `fold` (an `NbrdfTrainFold`) is the one the pairs will train with: under
/// `NBRDF_TRAIN_FOLD_RECIPROCAL_MEAN` pairs with a cosine below 0.01 are replaced by the next
/// candidates, so that every pair is trained on, as `nbrdf train --rgl-fold reciprocal-mean`
/// draws them.
///
/// # Safety
/// `config` points to an `NbrdfTrainConfig`; `out_view` and `out_light` hold `3 n` writable
/// floats each and do not overlap.
#[no_mangle]
pub unsafe extern "C" fn nbrdf_train_directions(
    config: *const NbrdfTrainConfig,
    fold: i32,
    n: usize,
    out_view: *mut f32,
    out_light: *mut f32,
) -> i32 {
    guard("nbrdf_train_directions", || {
        // SAFETY: forwarded contract.
        let (config, threads) = unsafe { read_config(config)? };
        let fold = read_fold(fold)?;
        check_pointer(out_view, "out_view")?;
        check_pointer(out_light, "out_light")?;
        let len = array_len(n, 3)?;
        let (pairs, _) =
            nbrdf_core::ops::with_threads(threads, || distill::sample_directions(&config, fold))??;
        if pairs.len() != n {
            return Err(Failure::invalid(format!(
                "n = {n}, but the config has {} pairs (nbrdf_train_sample_counts)",
                pairs.len()
            )));
        }
        // SAFETY: `len` writable floats each by contract, not overlapping.
        let (view, light) = unsafe {
            (
                std::slice::from_raw_parts_mut(out_view, len),
                std::slice::from_raw_parts_mut(out_light, len),
            )
        };
        for (i, (v, l)) in pairs.iter().enumerate() {
            for axis in 0..3 {
                view[axis * n + i] = v[axis];
                light[axis * n + i] = l[axis];
            }
        }
        Ok(())
    })
}

/// The fold of a `fold` argument (an `NbrdfTrainFold`).
fn read_fold(fold: i32) -> FfiResult<RglFold> {
    match fold {
        0 => Ok(RglFold::AsMeasured),
        1 => Ok(RglFold::ReciprocalMean),
        other => Err(Failure::invalid(format!(
            "unknown fold {other} (expected 0 = as given, 1 = reciprocal mean)"
        ))),
    }
}

/// The arrays of `nbrdf_train_from_arrays`, copied out of the caller's planar buffers.
struct OwnedArrays {
    view: Vec<Vec3>,
    light: Vec<Vec3>,
    eval_cos: Vec<[f32; 3]>,
    swapped_eval_cos: Option<Vec<[f32; 3]>>,
}

/// Reads `[view, light, eval_cos, swapped_eval_cos]`, planar `3 n` floats each; the swapped
/// values only for the reciprocal-mean fold.
///
/// # Safety
/// The first three pointers are null or valid for `3 n` floats, and so is the fourth under
/// `RglFold::ReciprocalMean`.
unsafe fn read_arrays(
    fold: RglFold,
    pointers: [*const f32; 4],
    n: usize,
) -> FfiResult<OwnedArrays> {
    let [view, light, eval_cos, swapped_eval_cos] = pointers;
    let len = array_len(n, 3)?;
    for (ptr, argument) in [(view, "view"), (light, "light"), (eval_cos, "eval_cos")] {
        check_pointer(ptr, argument)?;
    }
    let swapped_eval_cos = match fold {
        RglFold::ReciprocalMean => {
            check_pointer(swapped_eval_cos, "swapped_eval_cos")?;
            // SAFETY: checked; `3 n` floats by contract.
            Some(planar_colours(unsafe { input(swapped_eval_cos, len) }))
        }
        RglFold::AsMeasured => None,
    };
    // SAFETY: checked; `3 n` floats each by contract.
    let (view, light, eval_cos) = unsafe {
        (
            planar_vectors(input(view, len)),
            planar_vectors(input(light, len)),
            planar_colours(input(eval_cos, len)),
        )
    };
    Ok(OwnedArrays {
        view,
        light,
        eval_cos,
        swapped_eval_cos,
    })
}

/// The provenance details of `nbrdf_train_from_arrays`: none for a null `details_json`, else its
/// JSON value.
///
/// # Safety
/// `details_json` is null or a NUL-terminated string.
unsafe fn read_details(details_json: *const c_char) -> FfiResult<Option<serde_json::Value>> {
    if details_json.is_null() {
        return Ok(None);
    }
    // SAFETY: non-null, NUL-terminated by contract.
    let text = unsafe { read_str(details_json, "details_json")? };
    serde_json::from_str(&text)
        .map(Some)
        .map_err(|e| Failure::invalid(format!("argument `details_json` is not JSON: {e}")))
}

/// Trains a network named `name` on `n` pairs and stores its JSON text (an `*.nbrdf.json` file's
/// content, as `nbrdf train` writes it) in `*out_json`; free it with `nbrdf_train_string_free`.
///
/// * `view`, `light`: planar `3 n` floats; `eval_cos`: planar RGB `3 n` floats,
///   `f_r(view, light) cos(theta_light)` (Mitsuba's `BSDF.eval` with `si.wi = view`,
///   `wo = light`). Negative values are clamped to 0; a value that is not finite is an error.
///   Pairs at or below the horizon are dropped.
/// * `swapped_eval_cos`: the same with view and light swapped (`f_r(light, view) cos(theta_view)`),
///   read only by `NBRDF_TRAIN_FOLD_RECIPROCAL_MEAN` (`fold`, an `NbrdfTrainFold`); may be null
///   otherwise.
/// * The last `n_validation` pairs are the validation set (at least 1, fewer than `n`).
/// * `config`: the training settings (its `samples` and `validation_fraction` are not read);
///   `config.anisotropic` makes an anisotropic network (file format version 2).
/// * `source`: what the values came from, stored in the provenance; `details_json`: null or a
///   JSON text stored in the provenance under "distilled_from".
/// * `on_epoch`: null or called after every epoch with `user`.
///
/// # Safety
/// Pointers are null where allowed above, or valid for the sizes above; strings are
/// NUL-terminated; `out_json` points to writable storage for one pointer.
#[no_mangle]
pub unsafe extern "C" fn nbrdf_train_from_arrays(
    config: *const NbrdfTrainConfig,
    fold: i32,
    view: *const f32,
    light: *const f32,
    eval_cos: *const f32,
    swapped_eval_cos: *const f32,
    n: usize,
    n_validation: usize,
    name: *const c_char,
    source: *const c_char,
    details_json: *const c_char,
    on_epoch: NbrdfEpochCallback,
    user: *mut c_void,
    out_json: *mut *mut c_char,
) -> i32 {
    guard("nbrdf_train_from_arrays", || {
        // SAFETY: forwarded contract.
        let common = unsafe { read_common(out_json, config, fold, [name, source, details_json])? };
        // SAFETY: forwarded contract.
        let arrays =
            unsafe { read_arrays(common.fold, [view, light, eval_cos, swapped_eval_cos], n)? };
        let request = common.request(DistillArrays::Rgb(SampledArrays {
            view: &arrays.view,
            light: &arrays.light,
            eval_cos: &arrays.eval_cos,
            swapped_eval_cos: arrays.swapped_eval_cos.as_deref(),
            validation: n_validation,
        }));
        // SAFETY: writable by contract.
        unsafe { distil_into(&request, on_epoch, user, out_json) }
    })
}

/// What both `*_from_arrays` functions read besides their arrays.
struct Common {
    config: TrainConfig,
    threads: Option<usize>,
    fold: RglFold,
    name: String,
    source: String,
    source_details: Option<serde_json::Value>,
}

impl Common {
    fn request<'a>(self, arrays: DistillArrays<'a>) -> DistillRequest<'a> {
        DistillRequest {
            arrays,
            fold: self.fold,
            name: self.name,
            source: self.source,
            source_details: self.source_details,
            config: self.config,
            threads: self.threads,
        }
    }
}

/// Clears `*out_json` (null until a network is made) and reads the settings, the fold and the
/// strings `[name, source, details_json]` of a `*_from_arrays` call.
///
/// # Safety
/// As the `*_from_arrays` functions' contract: `out_json` points to writable storage for one
/// pointer, `config` to an `NbrdfTrainConfig`, the strings are NUL-terminated (`details_json`
/// may be null).
unsafe fn read_common(
    out_json: *mut *mut c_char,
    config: *const NbrdfTrainConfig,
    fold: i32,
    [name, source, details_json]: [*const c_char; 3],
) -> FfiResult<Common> {
    check_pointer(out_json, "out_json")?;
    // SAFETY: writable by contract.
    unsafe { out_json.write(std::ptr::null_mut()) };
    // SAFETY: forwarded contract.
    let (config, threads) = unsafe { read_config(config)? };
    let fold = read_fold(fold)?;
    // SAFETY: forwarded contract.
    unsafe {
        Ok(Common {
            config,
            threads,
            fold,
            name: read_str(name, "name")?,
            source: read_str(source, "source")?,
            source_details: read_details(details_json)?,
        })
    }
}

/// Distils `request`, calling `on_epoch` with `user`, and stores the network's JSON text in
/// `*out_json`.
///
/// # Safety
/// `out_json` points to writable storage for one pointer.
unsafe fn distil_into(
    request: &DistillRequest<'_>,
    on_epoch: NbrdfEpochCallback,
    user: *mut c_void,
    out_json: *mut *mut c_char,
) -> FfiResult<()> {
    let callback = on_epoch.map(|function| Callback { function, user });
    let (network, _) = distill::distill(request, &mut move |e: &EpochStats| {
        if let Some(callback) = &callback {
            callback.call(e);
        }
    })?;
    let text = CString::new(network.to_json_string())
        .map_err(|_| Failure::invalid("the network's JSON holds a NUL byte"))?;
    // SAFETY: writable by contract.
    unsafe { out_json.write(text.into_raw()) };
    Ok(())
}

/// The spectral arrays of `nbrdf_train_spectral_from_arrays`, copied out of the caller's buffers.
struct OwnedSpectra {
    view: Vec<Vec3>,
    light: Vec<Vec3>,
    wavelengths: Vec<f32>,
    eval_cos: Vec<f32>,
    swapped_eval_cos: Option<Vec<f32>>,
}

/// Reads `[view, light]` (planar `3 n` floats), `wavelengths` (`m`) and `[eval_cos,
/// swapped_eval_cos]` (`m n` floats each, the swapped values only for the reciprocal mean).
///
/// # Safety
/// Each pointer is null or valid for its size above (the swapped values under
/// `RglFold::ReciprocalMean` only).
unsafe fn read_spectra(
    fold: RglFold,
    [view, light]: [*const f32; 2],
    (wavelengths, m): (*const f32, usize),
    [eval_cos, swapped_eval_cos]: [*const f32; 2],
    n: usize,
) -> FfiResult<OwnedSpectra> {
    let len = array_len(n, 3)?;
    let values = array_len(n, m)?;
    array_len(m, 1)?;
    for (ptr, argument) in [
        (view, "view"),
        (light, "light"),
        (wavelengths, "wavelengths"),
        (eval_cos, "eval_cos"),
    ] {
        check_pointer(ptr, argument)?;
    }
    if m == 0 {
        return Err(Failure::invalid(
            "m = 0 wavelengths: a spectrum needs at least 2",
        ));
    }
    let swapped_eval_cos = match fold {
        RglFold::ReciprocalMean => {
            check_pointer(swapped_eval_cos, "swapped_eval_cos")?;
            // SAFETY: checked; `m n` floats by contract.
            Some(unsafe { input(swapped_eval_cos, values) }.to_vec())
        }
        RglFold::AsMeasured => None,
    };
    // SAFETY: checked; the sizes above by contract.
    unsafe {
        Ok(OwnedSpectra {
            view: planar_vectors(input(view, len)),
            light: planar_vectors(input(light, len)),
            wavelengths: input(wavelengths, m).to_vec(),
            eval_cos: input(eval_cos, values).to_vec(),
            swapped_eval_cos,
        })
    }
}

/// `nbrdf_train_from_arrays` for spectral values: trains a spectral network (file format
/// version 3: 16 cubic B-spline coefficients over 360-830 nm) and stores its JSON text in
/// `*out_json` (free it with `nbrdf_train_string_free`).
///
/// * `wavelengths`: `m` wavelengths in nm, finite, strictly increasing and overlapping
///   360-830 nm; anything else is `NBRDF_TRAIN_ERROR_INVALID_ARGUMENT` naming the problem.
/// * `eval_cos`: `m n` floats, `eval_cos[j n + i]` = `f_r(view_i, light_i, wavelength_j)
///   cos(theta_light)` (Mitsuba's `BSDF.eval` in a spectral variant); `swapped_eval_cos` the
///   same with view and light swapped, read only by `NBRDF_TRAIN_FOLD_RECIPROCAL_MEAN`.
///   Negative values are clamped to 0; a value that is not finite is an error.
/// * The training target of a pair is the least-squares fit of the piecewise-linear spectrum
///   through its values, negative coefficients clamped to 0; the loss is the RGB one per
///   coefficient.
/// * Everything else as `nbrdf_train_from_arrays`.
///
/// # Safety
/// Pointers are null where allowed above, or valid for the sizes above; strings are
/// NUL-terminated; `out_json` points to writable storage for one pointer.
#[no_mangle]
pub unsafe extern "C" fn nbrdf_train_spectral_from_arrays(
    config: *const NbrdfTrainConfig,
    fold: i32,
    view: *const f32,
    light: *const f32,
    wavelengths: *const f32,
    m: usize,
    eval_cos: *const f32,
    swapped_eval_cos: *const f32,
    n: usize,
    n_validation: usize,
    name: *const c_char,
    source: *const c_char,
    details_json: *const c_char,
    on_epoch: NbrdfEpochCallback,
    user: *mut c_void,
    out_json: *mut *mut c_char,
) -> i32 {
    guard("nbrdf_train_spectral_from_arrays", || {
        // SAFETY: forwarded contract.
        let common = unsafe { read_common(out_json, config, fold, [name, source, details_json])? };
        // SAFETY: forwarded contract.
        let spectra = unsafe {
            read_spectra(
                common.fold,
                [view, light],
                (wavelengths, m),
                [eval_cos, swapped_eval_cos],
                n,
            )?
        };
        let request = common.request(DistillArrays::Spectral(SampledSpectra {
            view: &spectra.view,
            light: &spectra.light,
            wavelengths: &spectra.wavelengths,
            eval_cos: &spectra.eval_cos,
            swapped_eval_cos: spectra.swapped_eval_cos.as_deref(),
            validation: n_validation,
        }));
        // SAFETY: writable by contract.
        unsafe { distil_into(&request, on_epoch, user, out_json) }
    })
}

/// Frees a string returned by this library; null is accepted and ignored.
///
/// # Safety
/// `text` is null or a string from `nbrdf_train_from_arrays` that was not freed yet.
#[no_mangle]
pub unsafe extern "C" fn nbrdf_train_string_free(text: *mut c_char) {
    if !text.is_null() {
        // SAFETY: made by `CString::into_raw` in this library, freed once by contract.
        drop(unsafe { CString::from_raw(text) });
    }
}
