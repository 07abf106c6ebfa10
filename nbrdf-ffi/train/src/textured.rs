//! The C ABI of textured distillation (`nbrdf_core::distillation`, docs/textured.md): an
//! encoder and a decoder trained on samples of a textured source, baked over the source's
//! parameter image into a spatially varying material (a version 4 `*.nbrdf.json` and its
//! latent texture), written to disk.

use crate::{guard, read_details, read_str, Callback, NbrdfEpochCallback};
use nbrdf_core::brdf::Directions;
use nbrdf_core::distillation::{
    bake, train_textured, BakeConfig, BakeStage, ParameterImage, TargetKind, TargetValues,
    TexturedSamples, TexturedTrainConfig, MAX_REPRESENTATIVES,
};
use nbrdf_core::textured::{SamplingChannels, TexturePrecision};
use nbrdf_core::train::adam::AdamConfig;
use nbrdf_core::train::spectral::provenance_entry;
use nbrdf_core::train::EpochStats;
use nbrdf_ffi_common::{array_len, check_pointer, input, Failure, FfiResult};
use std::ffi::{c_char, c_void};
use std::path::Path;

/// Settings of `nbrdf_train_textured`; `nbrdf_train_textured_config_default` fills in the
/// defaults.
#[repr(C)]
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct NbrdfTexturedConfig {
    /// `C`, the latent channels per texel, in [1, 32].
    pub channels: usize,
    /// Width of the encoder's two hidden layers (parameters -> code).
    pub encoder_hidden: usize,
    /// Width of the decoder's two hidden layers (directions and code -> RGB or spectral
    /// coefficients).
    pub decoder_hidden: usize,
    pub epochs: usize,
    pub batch: usize,
    pub learning_rate: f32,
    /// Samples held out to pick the best epoch, as a fraction of the valid samples, in (0, 1).
    pub validation_fraction: f64,
    pub seed: u64,
    /// Worker threads; 0: one per core.
    pub threads: usize,
    /// Sampling lobes stored per texel: 0 (cosine sampling), 1 or 2.
    pub lobes: usize,
    /// The most representative codes whose lobes are fitted, in [1, 256].
    pub representatives: usize,
    /// 1: an anisotropic decoder (its input carries the half vector's azimuth); 0: isotropic.
    pub anisotropic: i32,
    /// 1: the texture in float32; 0: float16, the format's usual precision.
    pub float_texture: i32,
}

/// What the baking is doing (`NbrdfBakeProgress.stage`).
#[repr(C)]
#[allow(non_camel_case_types)]
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum NbrdfBakeStage {
    /// Every texel's code is computed (`done` = `total` = texels).
    NBRDF_BAKE_ENCODED = 0,
    /// A k-means iteration over the codes (`done` of at most `total`; they may stop early).
    NBRDF_BAKE_CLUSTERING = 1,
    /// Lobes fitted for `done` of `total` representative codes.
    NBRDF_BAKE_FITTING_LOBES = 2,
}

/// Progress of the baking, passed to the `NbrdfBakeCallback`.
#[repr(C)]
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct NbrdfBakeProgress {
    /// An `NbrdfBakeStage` value.
    pub stage: i32,
    pub done: usize,
    pub total: usize,
}

/// Called during the baking with the caller's `user` pointer, on a thread of the library's
/// pool; `progress` is valid during the call only.
pub type NbrdfBakeCallback =
    Option<unsafe extern "C" fn(user: *mut c_void, progress: *const NbrdfBakeProgress)>;

fn defaults() -> NbrdfTexturedConfig {
    let train = TexturedTrainConfig::default();
    let bake = BakeConfig::new("");
    NbrdfTexturedConfig {
        channels: train.channels,
        encoder_hidden: train.encoder_hidden[0],
        decoder_hidden: train.decoder_hidden[0],
        epochs: train.epochs,
        batch: train.batch,
        learning_rate: train.adam.learning_rate,
        validation_fraction: train.validation_fraction,
        seed: train.seed,
        threads: 0,
        lobes: bake.sampling.lobes().len(),
        representatives: bake.representatives,
        anisotropic: 0,
        float_texture: 0,
    }
}

/// The settings of a C config: training, baking (without names), texture precision, threads.
struct Settings {
    train: TexturedTrainConfig,
    bake: BakeConfig,
    precision: TexturePrecision,
    threads: Option<usize>,
}

fn flag(value: i32, field: &str) -> FfiResult<bool> {
    match value {
        0 => Ok(false),
        1 => Ok(true),
        other => Err(Failure::invalid(format!(
            "config.{field} is {other} (expected 0 or 1)"
        ))),
    }
}

/// # Safety
/// A non-null `config` points to a live `NbrdfTexturedConfig`.
unsafe fn read_config(config: *const NbrdfTexturedConfig) -> FfiResult<Settings> {
    check_pointer(config, "config")?;
    // SAFETY: non-null and aligned (checked), initialised by contract; plain numbers only.
    let c = unsafe { config.read() };
    let base = TexturedTrainConfig::default();
    let train = TexturedTrainConfig {
        channels: c.channels,
        encoder_hidden: vec![c.encoder_hidden; base.encoder_hidden.len()],
        decoder_hidden: vec![c.decoder_hidden; base.decoder_hidden.len()],
        anisotropic: flag(c.anisotropic, "anisotropic")?,
        epochs: c.epochs,
        batch: c.batch,
        adam: AdamConfig {
            learning_rate: c.learning_rate,
            ..base.adam
        },
        validation_fraction: c.validation_fraction,
        seed: c.seed,
        ..base
    };
    let sampling = match c.lobes {
        0 => SamplingChannels::cosine(),
        1 => SamplingChannels::one_lobe(),
        2 => SamplingChannels::two_lobes(),
        other => {
            return Err(Failure::invalid(format!(
                "config.lobes is {other} (expected 0, 1 or 2)"
            )))
        }
    };
    if !(1..=MAX_REPRESENTATIVES).contains(&c.representatives) {
        return Err(Failure::invalid(format!(
            "config.representatives is {} (expected 1 to {MAX_REPRESENTATIVES})",
            c.representatives
        )));
    }
    let bake = BakeConfig {
        sampling,
        representatives: c.representatives,
        ..BakeConfig::new("")
    };
    let precision = if flag(c.float_texture, "float_texture")? {
        TexturePrecision::Float
    } else {
        TexturePrecision::Half
    };
    Ok(Settings {
        train,
        bake,
        precision,
        threads: (c.threads > 0).then_some(c.threads),
    })
}

/// The bake callback and its user pointer, handed to the library's threads.
struct BakeReporter {
    function: unsafe extern "C" fn(*mut c_void, *const NbrdfBakeProgress),
    user: *mut c_void,
}

// SAFETY: as `Callback`: the caller accepts that the callback runs on the library's threads
// (documented); the pointer is only handed back to it, one call at a time.
unsafe impl Send for BakeReporter {}

impl BakeReporter {
    fn call(&self, stage: BakeStage) {
        let (stage, done, total) = match stage {
            BakeStage::Encoded { texels } => (NbrdfBakeStage::NBRDF_BAKE_ENCODED, texels, texels),
            BakeStage::Clustering {
                iteration,
                iterations,
            } => (NbrdfBakeStage::NBRDF_BAKE_CLUSTERING, iteration, iterations),
            BakeStage::FittingLobes { done, total } => {
                (NbrdfBakeStage::NBRDF_BAKE_FITTING_LOBES, done, total)
            }
        };
        let progress = NbrdfBakeProgress {
            stage: stage as i32,
            done,
            total,
        };
        // SAFETY: the caller's function and pointer, called as documented.
        unsafe { (self.function)(self.user, &progress) }
    }
}

/// The samples of `nbrdf_train_textured`, borrowed from the caller's buffers.
struct SampleArrays<'a> {
    params: Vec<&'a [f32]>,
    directions: [&'a [f32]; 2],
    /// The wavelengths of spectral values; empty for RGB.
    wavelengths: &'a [f32],
    eval_cos: &'a [f32],
    n: usize,
}

impl SampleArrays<'_> {
    fn samples(&self) -> TexturedSamples<'_> {
        let n = self.n;
        let ([vx, vy, vz], [lx, ly, lz]) =
            (planes(self.directions[0], n), planes(self.directions[1], n));
        let target = if self.wavelengths.is_empty() {
            TargetValues::Rgb(planes(self.eval_cos, n))
        } else {
            TargetValues::Spectral {
                wavelengths: self.wavelengths,
                values: self.eval_cos,
            }
        };
        TexturedSamples {
            params: &self.params,
            view: Directions {
                x: vx,
                y: vy,
                z: vz,
            },
            light: Directions {
                x: lx,
                y: ly,
                z: lz,
            },
            target,
            target_kind: TargetKind::BrdfCos,
        }
    }
}

/// The three planes of `3 n` planar floats.
fn planes(planar: &[f32], n: usize) -> [&[f32]; 3] {
    [0, 1, 2].map(|a| &planar[a * n..(a + 1) * n])
}

/// Borrows `params` (`parameters n` floats, parameter-major), the planar `view` and `light`
/// (`3 n` floats each), the `m` `wavelengths` (none for RGB: null with `m` 0) and `eval_cos`
/// (`3 n` floats, or `m n` for spectra).
///
/// # Safety
/// Each pointer is valid for its size above (`params` may be null when `parameters` is 0).
unsafe fn read_samples<'a>(
    (params, parameters): (*const f32, usize),
    [view, light]: [*const f32; 2],
    (wavelengths, m): (*const f32, usize),
    eval_cos: *const f32,
    n: usize,
) -> FfiResult<SampleArrays<'a>> {
    let len = array_len(n, 3)?;
    for (ptr, argument) in [(view, "view"), (light, "light"), (eval_cos, "eval_cos")] {
        check_pointer(ptr, argument)?;
    }
    let wavelengths = if m == 0 {
        &[][..]
    } else {
        check_pointer(wavelengths, "wavelengths")?;
        // SAFETY: checked; `m` floats by contract.
        unsafe { input(wavelengths, m) }
    };
    let values = if m == 0 { len } else { array_len(n, m)? };
    let params = if parameters == 0 {
        Vec::new()
    } else {
        check_pointer(params, "params")?;
        array_len(n, parameters)?;
        // SAFETY: checked; `parameters n` floats by contract.
        let all = unsafe { input(params, parameters * n) };
        (0..parameters).map(|k| &all[k * n..(k + 1) * n]).collect()
    };
    // SAFETY: checked; `3 n` floats each by contract.
    let directions = unsafe { [input(view, len), input(light, len)] };
    Ok(SampleArrays {
        params,
        directions,
        wavelengths,
        // SAFETY: as above, `values` floats.
        eval_cos: unsafe { input(eval_cos, values) },
        n,
    })
}

/// Borrows the parameter image: `width height parameters` floats, texel-major.
///
/// # Safety
/// `image` is valid for that many floats (or null when it is 0).
unsafe fn read_image<'a>(
    image: *const f32,
    [width, height, parameters]: [usize; 3],
) -> FfiResult<ParameterImage<'a>> {
    let texels = width
        .checked_mul(height)
        .ok_or_else(|| Failure::invalid(format!("a {width} x {height} image is too large")))?;
    let len = array_len(texels, parameters)?;
    let values = if len == 0 {
        &[][..]
    } else {
        check_pointer(image, "image")?;
        // SAFETY: checked; `len` floats by contract.
        unsafe { input(image, len) }
    };
    Ok(ParameterImage {
        width,
        height,
        channels: parameters,
        values,
    })
}

/// Fills `*out` with the defaults of `nbrdf_train_textured`: 8 latent channels, encoder and
/// decoder of two hidden layers of 32, 40 epochs of batches of 512, one sampling lobe per texel
/// from 64 representatives, a float16 texture, `threads` 0.
///
/// # Safety
/// `out` points to a writable `NbrdfTexturedConfig`.
#[no_mangle]
pub unsafe extern "C" fn nbrdf_train_textured_config_default(out: *mut NbrdfTexturedConfig) -> i32 {
    guard("nbrdf_train_textured_config_default", || {
        check_pointer(out, "out")?;
        // SAFETY: non-null, aligned, writable by contract.
        unsafe { out.write(defaults()) };
        Ok(())
    })
}

/// Trains an encoder (a texel's parameters -> its latent code) and a decoder on `n` samples of a
/// textured source, bakes them over the source's parameter image and writes the spatially
/// varying material (an `*.nbrdf.json` of format version 4) to `path`, its latent texture
/// beside it (`<stem>.latent.exr`, `stem` the file name up to its first dot).
///
/// * `params`: `parameters n` floats, parameter-major: `params[k n + i]` is parameter `k` of
///   the texel of sample `i` (whatever describes the source at a texel, the same for every
///   texel; all finite). `parameters` 0 is an error saying that the source has no textures.
/// * `view`, `light`: planar `3 n` floats; `eval_cos`: `f_r(view, light) cos(theta_light)` of
///   the source at the sample's texel (Mitsuba's `BSDF.eval`), planar RGB `3 n` floats when `m`
///   is 0 (`wavelengths` may be null), else `m n` floats, sample `i`'s value at wavelength `j`
///   at `eval_cos[j n + i]` (a spectral variant's `BSDF.eval`). Pairs at or below the horizon
///   and values that are not finite and `>= 0` are dropped; a fraction
///   `config.validation_fraction` of the rest picks the best epoch.
/// * `wavelengths`: `m` wavelengths in nm, finite, strictly increasing and overlapping
///   360-830 nm (anything else is `NBRDF_TRAIN_ERROR_INVALID_ARGUMENT` naming the problem):
///   the material is spectral, its decoder giving 16 cubic B-spline coefficients over 360-830
///   nm (the file's `spectral` object), each sample's target the least-squares fit of its
///   piecewise-linear spectrum, negative coefficients clamped to 0, as
///   `nbrdf_train_spectral_from_arrays` trains; the loss is the RGB one per coefficient, and
///   the lobes are fitted to the decoder's sRGB projection. `m` 0: an RGB material.
/// * `image`: `width height parameters` floats, texel-major (`image[(y width + x) parameters +
///   k]`), row `y` = 0 at `v` = 0 as Mitsuba's `bitmap` reads an image: the parameters at the
///   centre of every texel of the latent texture.
/// * `name`: the material's name; `source`: what the values came from and `details_json` (null
///   or a JSON text): stored in the provenance.
/// * `on_epoch` (null or called after every epoch) and `on_bake` (null or called as the baking
///   proceeds) get `user`.
///
/// The result depends on the seed only, not on the thread count. Files that cannot be written
/// are `NBRDF_TRAIN_ERROR_IO`.
///
/// # Safety
/// Pointers are null where allowed above, or valid for the sizes above; strings are
/// NUL-terminated.
#[no_mangle]
pub unsafe extern "C" fn nbrdf_train_textured(
    config: *const NbrdfTexturedConfig,
    params: *const f32,
    parameters: usize,
    view: *const f32,
    light: *const f32,
    wavelengths: *const f32,
    m: usize,
    eval_cos: *const f32,
    n: usize,
    image: *const f32,
    width: usize,
    height: usize,
    path: *const c_char,
    name: *const c_char,
    source: *const c_char,
    details_json: *const c_char,
    on_epoch: NbrdfEpochCallback,
    on_bake: NbrdfBakeCallback,
    user: *mut c_void,
) -> i32 {
    guard("nbrdf_train_textured", || {
        // SAFETY: forwarded contract.
        let settings = unsafe { read_config(config)? };
        // SAFETY: forwarded contract.
        let (path, name, source, details) = unsafe {
            (
                read_str(path, "path")?,
                read_str(name, "name")?,
                read_str(source, "source")?,
                read_details(details_json)?,
            )
        };
        // SAFETY: forwarded contract.
        let arrays = unsafe {
            read_samples(
                (params, parameters),
                [view, light],
                (wavelengths, m),
                eval_cos,
                n,
            )?
        };
        let spectral_target =
            (!arrays.wavelengths.is_empty()).then(|| provenance_entry(arrays.wavelengths));
        // SAFETY: forwarded contract.
        let image = unsafe { read_image(image, [width, height, parameters])? };
        let path = Path::new(&path);
        let bake_config = BakeConfig {
            name,
            texture_path: format!("{}.latent.exr", nbrdf_core::ops::file_stem(path)),
            ..settings.bake
        };
        let epoch = on_epoch.map(|function| Callback { function, user });
        let baking = on_bake.map(|function| BakeReporter { function, user });
        let (train_config, threads) = (settings.train, settings.threads);
        let material = nbrdf_core::ops::with_threads(threads, move || {
            let model = train_textured(&arrays.samples(), &train_config, &mut |e: &EpochStats| {
                if let Some(callback) = &epoch {
                    callback.call(e);
                }
            })?;
            bake(&model, &image, &bake_config, &mut |stage| {
                if let Some(callback) = &baking {
                    callback.call(stage);
                }
            })
        })??;
        let mut provenance = material.provenance().clone();
        if let Some(fields) = provenance.as_object_mut() {
            fields.insert("source".into(), source.into());
            if let Some(details) = details {
                fields.insert("distilled_from".into(), details);
            }
            if let Some(target) = spectral_target {
                fields.insert("spectral_target".into(), target);
            }
        }
        let material = material.with_provenance(provenance);
        material.save(path, settings.precision)?;
        Ok(())
    })
}
