//! C ABI of nbrdf: load, evaluate, sample and pdf of NBRDFs and MERL tables, batched.
//!
//! The header `include/nbrdf.h` is generated from this file by cbindgen (see `cbindgen.toml`;
//! `NBRDF_BLESS=1 cargo test -p nbrdf-ffi --test header` regenerates it). The crate is a thin
//! shell around `nbrdf-core`: it checks pointers and lengths, turns errors and panics into status
//! codes with a thread-local message, and hands planar slices to the core.
//!
//! Conventions: every array is planar (structure of arrays): a batch of `n` directions is `3 n`
//! floats `[x0..x(n-1), y0..y(n-1), z0..z(n-1)]`, uniforms are `[u0.., u1.., u2..]`, colours are
//! `[r.., g.., b..]`, pdfs are `n` floats. Directions live in the local shading frame (z = normal);
//! `view` points towards the viewer (Mitsuba's `si.wi`), `light` towards the light (Mitsuba's
//! `wo`). Output arrays must not overlap the inputs.

#![deny(unsafe_op_in_unsafe_fn)]

use nbrdf_core::brdf::{Brdf, Directions, DirectionsMut, RgbMut};
use nbrdf_core::network::parameter_count_for;
use nbrdf_core::sampling::tabulated::{TableConfig, TabulatedSampler};
use nbrdf_core::sampling::{self, SamplingStrategy};
use nbrdf_core::{MerlTable, Nbrdf, NbrdfError};
use nbrdf_ffi_common::{
    array_len, check_pointer, input, output, reference, Failure, FailureKind, FfiResult, Status,
};
use std::ffi::{c_char, CStr, CString};
use std::panic::{catch_unwind, AssertUnwindSafe};
use std::path::PathBuf;
use std::sync::Arc;

/// Status code returned (as `int32_t`) by every fallible function. On any value other than
/// `NBRDF_OK`, `nbrdf_last_error()` describes the failure.
#[repr(C)]
#[allow(non_camel_case_types)]
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum NbrdfStatus {
    /// Success.
    NBRDF_OK = 0,
    /// A required pointer argument was null; the message names the argument.
    NBRDF_ERROR_NULL_POINTER = 1,
    /// An argument is outside its domain (sampler parameters, misaligned arrays, sizes).
    NBRDF_ERROR_INVALID_ARGUMENT = 2,
    /// A file could not be opened or read; the message names the file.
    NBRDF_ERROR_IO = 3,
    /// A file was read but is not a valid network or MERL table; the message names the file.
    NBRDF_ERROR_FORMAT = 4,
    /// The library caught an internal panic (a bug); the message carries the panic message.
    NBRDF_ERROR_PANIC = 5,
}

/// Importance-sampling strategy of an `NbrdfSampler`.
#[repr(C)]
#[allow(non_camel_case_types)]
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum NbrdfSamplingKind {
    /// Uniform over the upper hemisphere.
    NBRDF_SAMPLING_UNIFORM = 0,
    /// Cosine-weighted over the upper hemisphere.
    NBRDF_SAMPLING_COSINE = 1,
    /// Mixture of a Blinn-Phong lobe (`exponent`, weight `specular_weight`) and a cosine lobe.
    NBRDF_SAMPLING_PHONG = 2,
    /// Mixture of two Blinn-Phong lobes (`exponent`, `specular_weight`; `exponent2`,
    /// `specular_weight2`) and a cosine lobe of weight `1 - specular_weight - specular_weight2`.
    /// Only in an `NbrdfMixtureSampler` (the `*_mixture` functions).
    NBRDF_SAMPLING_TWO_LOBE = 3,
    /// The material's data-driven table (an `NbrdfTable` and the `*_table` functions); not
    /// accepted in an `NbrdfSampler` or `NbrdfMixtureSampler`.
    NBRDF_SAMPLING_TABULATED = 4,
    /// Anisotropic Blinn-Phong lobe (Ashikhmin-Shirley: `exponent` = `n_u` along the tangent x,
    /// `exponent2` = `n_v` across it, weight `specular_weight`) mixed with a cosine lobe; for
    /// anisotropic networks, whose directions are in the shading frame. Only in an
    /// `NbrdfMixtureSampler`; `specular_weight2` is not read.
    NBRDF_SAMPLING_ANISOTROPIC_PHONG = 5,
}

/// An importance-sampling strategy. `exponent` (in [0, 1e6], `MAX_EXPONENT`) and `specular_weight` (in [0, 1])
/// are read only for `NBRDF_SAMPLING_PHONG`.
#[repr(C)]
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct NbrdfSampler {
    pub kind: NbrdfSamplingKind,
    pub exponent: f32,
    pub specular_weight: f32,
}

/// An importance-sampling strategy with up to two Blinn-Phong lobes, for the `*_mixture`
/// functions: any kind of `NbrdfSamplingKind`. The first three fields are those of
/// `NbrdfSampler`; `exponent2` and `specular_weight2` are read only for
/// `NBRDF_SAMPLING_TWO_LOBE`, which takes exponents finite in [0, 1e6], weights in [0, 1] with
/// `specular_weight + specular_weight2 <= 1`; `NBRDF_SAMPLING_ANISOTROPIC_PHONG` reads
/// `exponent2` as `n_v` (finite in [0, 1e6]).
#[repr(C)]
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct NbrdfMixtureSampler {
    pub kind: NbrdfSamplingKind,
    pub exponent: f32,
    pub specular_weight: f32,
    pub exponent2: f32,
    pub specular_weight2: f32,
}

/// Summary of a loaded network.
#[repr(C)]
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct NbrdfNetworkInfo {
    /// Width of the two hidden layers (21 for the paper's networks).
    pub hidden_width: u32,
    /// Number of weights and biases (675 for width 21).
    pub parameter_count: u32,
    /// 1 when the file carries Blinn-Phong sampling parameters, else 0.
    pub has_sampling: u32,
    /// Blinn-Phong exponent stored with the network (0 when `has_sampling` is 0); of the first
    /// lobe when the file stores two (see `nbrdf_network_stored_sampler`).
    pub exponent: f32,
    /// Blinn-Phong specular weight stored with the network (0 when `has_sampling` is 0).
    pub specular_weight: f32,
}

/// A neural BRDF loaded from an `*.nbrdf.json` file. Immutable: one handle may be used by many
/// threads at once.
pub struct NbrdfNetwork {
    network: Nbrdf,
    /// What eval, sample and tables evaluate: the same BRDF without the hidden units that no
    /// pair of directions above the horizon activates (`Nbrdf::without_inactive_units`).
    renderer: Nbrdf,
    name: CString,
}

/// A MERL-format BRDF table loaded from a `.binary` file. Immutable: one handle may be used by
/// many threads at once.
pub struct NbrdfMerl {
    table: MerlTable,
}

/// The data-driven sampler of a material (`sampling` = `tabulated`): per band of view elevation,
/// a piecewise-constant half-vector density tabulated from the material, mixed with cosine
/// (nbrdf-core `tabulated`). Built by `nbrdf_network_build_table` or `nbrdf_merl_build_table`;
/// immutable, so one handle may be used by many threads at once.
pub struct NbrdfTable {
    sampler: Arc<TabulatedSampler>,
}

/// Shape of an `NbrdfTable` (`nbrdf_table_info`): `mass` (each bin's probability, row-major
/// `[row][theta bin][phi bin]`; the `phi_bins` span `|phi_h - phi_v|` over `[0, pi]`, each bin
/// standing for itself and its mirror image across the plane of incidence, so a bin's mass is
/// spread over both), `alias_probability` and `alias` (per row, Walker's alias table
/// over the row's bins: a bin `k` drawn uniformly is kept with probability
/// `alias_probability[k]`, else replaced by the bin `alias[k]`, an index within the row) each
/// have `rows * theta_bins * phi_bins` values (`nbrdf_table_arrays`).
#[repr(C)]
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct NbrdfTableInfo {
    pub rows: u32,
    pub theta_bins: u32,
    pub phi_bins: u32,
    /// Weight of the defensive cosine component of the mixture.
    pub cosine_weight: f32,
}

// ---------------------------------------------------------------------------------------------
// Errors (the plumbing is nbrdf-ffi-common's, shared with libnbrdf_train).

impl Status for NbrdfStatus {
    const OK: i32 = NbrdfStatus::NBRDF_OK as i32;

    fn code(kind: FailureKind) -> i32 {
        (match kind {
            FailureKind::NullPointer => NbrdfStatus::NBRDF_ERROR_NULL_POINTER,
            FailureKind::InvalidArgument => NbrdfStatus::NBRDF_ERROR_INVALID_ARGUMENT,
            FailureKind::Io => NbrdfStatus::NBRDF_ERROR_IO,
            FailureKind::Format => NbrdfStatus::NBRDF_ERROR_FORMAT,
            FailureKind::Panic => NbrdfStatus::NBRDF_ERROR_PANIC,
        }) as i32
    }
}

/// Runs `body`, catching panics; returns the status code and records the message of a failure
/// (prefixed with `function`) for `nbrdf_last_error`.
fn guard(function: &str, body: impl FnOnce() -> FfiResult<()>) -> i32 {
    nbrdf_ffi_common::guard::<NbrdfStatus>(function, body)
}

fn directions(buffer: &[f32]) -> Directions<'_> {
    Directions::from_planar(buffer).expect("planar buffers have length 3 n")
}

/// The fields of a sampler struct passed by C, the kind as a plain integer.
struct SamplerFields {
    kind: i32,
    exponent: f32,
    specular_weight: f32,
    /// `exponent2` and `specular_weight2` of an `NbrdfMixtureSampler`; `None` for an
    /// `NbrdfSampler`, which refuses the kinds that read them.
    second: Option<(f32, f32)>,
}

impl SamplerFields {
    /// The strategy the fields describe, validated by the core.
    fn strategy(&self) -> FfiResult<SamplingStrategy> {
        let (exponent, specular_weight) =
            (f64::from(self.exponent), f64::from(self.specular_weight));
        let strategy = match (self.kind, self.second) {
            (0, _) => SamplingStrategy::Uniform,
            (1, _) => SamplingStrategy::Cosine,
            (2, _) => SamplingStrategy::Phong {
                exponent,
                specular_weight,
            },
            (3, Some((exponent2, weight2))) => SamplingStrategy::TwoLobe {
                exponent1: exponent,
                weight1: specular_weight,
                exponent2: f64::from(exponent2),
                weight2: f64::from(weight2),
            },
            (5, Some((exponent_v, _))) => {
                SamplingStrategy::anisotropic(exponent, f64::from(exponent_v), specular_weight)
            }
            (kind @ (3 | 5), None) => {
                return Err(Failure::invalid(format!(
                    "sampling kind {kind} ({}) needs an NbrdfMixtureSampler and the *_mixture functions",
                    if kind == 3 { "two-lobe" } else { "anisotropic phong" }
                )))
            }
            (4, _) => {
                return Err(Failure::invalid(
                    "sampling kind 4 (tabulated) needs an NbrdfTable and the *_table functions",
                ))
            }
            (other, None) => {
                return Err(Failure::invalid(format!(
                    "unknown sampling kind {other} (expected 0 = uniform, 1 = cosine, 2 = phong)"
                )))
            }
            (other, Some(_)) => {
                return Err(Failure::invalid(format!(
                    "unknown sampling kind {other} (expected 0 = uniform, 1 = cosine, 2 = phong, 3 = two-lobe, 5 = anisotropic phong; 4 = tabulated needs an NbrdfTable)"
                )))
            }
        };
        Ok(strategy.validated()?)
    }
}

/// A sampler argument of the exported functions: `NbrdfSampler`, `NbrdfMixtureSampler` or
/// `NbrdfTable`.
trait SamplerArg {
    /// The name of the argument in the C signatures and error messages.
    const ARGUMENT: &'static str = "sampler";
    /// # Safety
    /// A non-null pointer must point to a live value of the type.
    unsafe fn strategy(sampler: *const Self) -> FfiResult<SamplingStrategy>;
}

impl SamplerArg for NbrdfSampler {
    unsafe fn strategy(sampler: *const Self) -> FfiResult<SamplingStrategy> {
        check_pointer(sampler, Self::ARGUMENT)?;
        // Read the fields through the raw pointer and the kind as a plain integer: C may store
        // any int there, and materialising an out-of-range Rust enum would be undefined
        // behaviour.
        // SAFETY: non-null and aligned (checked), initialised by contract; `NbrdfSamplingKind`
        // is a repr(C) fieldless enum, laid out as a C int.
        let fields = unsafe {
            SamplerFields {
                kind: std::ptr::addr_of!((*sampler).kind).cast::<i32>().read(),
                exponent: std::ptr::addr_of!((*sampler).exponent).read(),
                specular_weight: std::ptr::addr_of!((*sampler).specular_weight).read(),
                second: None,
            }
        };
        fields.strategy()
    }
}

impl SamplerArg for NbrdfTable {
    const ARGUMENT: &'static str = "table";

    unsafe fn strategy(sampler: *const Self) -> FfiResult<SamplingStrategy> {
        // SAFETY: forwarded contract.
        let table = unsafe { reference(sampler, Self::ARGUMENT)? };
        Ok(SamplingStrategy::Tabulated(Arc::clone(&table.sampler)))
    }
}

impl SamplerArg for NbrdfMixtureSampler {
    unsafe fn strategy(sampler: *const Self) -> FfiResult<SamplingStrategy> {
        check_pointer(sampler, Self::ARGUMENT)?;
        // SAFETY: as for `NbrdfSampler`; the kind is read as a plain C int.
        let fields = unsafe {
            SamplerFields {
                kind: std::ptr::addr_of!((*sampler).kind).cast::<i32>().read(),
                exponent: std::ptr::addr_of!((*sampler).exponent).read(),
                specular_weight: std::ptr::addr_of!((*sampler).specular_weight).read(),
                second: Some((
                    std::ptr::addr_of!((*sampler).exponent2).read(),
                    std::ptr::addr_of!((*sampler).specular_weight2).read(),
                )),
            }
        };
        fields.strategy()
    }
}

/// A path argument: bytes on Unix (any encoding), UTF-8 elsewhere.
///
/// # Safety
/// A non-null `path` must point to a NUL-terminated string.
unsafe fn read_path(path: *const c_char) -> FfiResult<PathBuf> {
    if path.is_null() {
        return Err(Failure::null("path"));
    }
    // SAFETY: non-null, NUL-terminated by contract.
    let bytes = unsafe { CStr::from_ptr(path) }.to_bytes();
    #[cfg(unix)]
    {
        use std::os::unix::ffi::OsStrExt;
        Ok(PathBuf::from(std::ffi::OsStr::from_bytes(bytes)))
    }
    #[cfg(not(unix))]
    {
        std::str::from_utf8(bytes)
            .map(PathBuf::from)
            .map_err(|_| Failure::invalid("path is not valid UTF-8"))
    }
}

// ---------------------------------------------------------------------------------------------
// Generic implementations shared by networks and tables.

/// What the batched entry points need from a handle.
trait BrdfHandle: Sized {
    /// The name of the handle argument in error messages.
    const ARGUMENT: &'static str;
    fn brdf(&self) -> &dyn Brdf;
    /// How to tabulate it for `sampling` = `tabulated`.
    fn table_config(&self) -> TableConfig {
        TableConfig::default()
    }
}

impl BrdfHandle for NbrdfNetwork {
    const ARGUMENT: &'static str = "network";
    fn brdf(&self) -> &dyn Brdf {
        &self.renderer
    }
    /// With the cosine weight `nbrdf fit-phong` stored, if any.
    fn table_config(&self) -> TableConfig {
        self.network.table_config()
    }
}

impl BrdfHandle for NbrdfMerl {
    const ARGUMENT: &'static str = "merl";
    fn brdf(&self) -> &dyn Brdf {
        &self.table
    }
}

/// # Safety
/// See the exported `*_load` functions.
unsafe fn load_impl<H>(
    function: &str,
    path: *const c_char,
    out: *mut *mut H,
    load: impl FnOnce(PathBuf) -> Result<H, NbrdfError>,
) -> i32 {
    guard(function, || {
        if out.is_null() {
            return Err(Failure::null("out"));
        }
        // SAFETY: `out` is non-null and writable by contract; cleared first so that it never
        // holds a stale pointer after a failure.
        unsafe { out.write(std::ptr::null_mut()) };
        // SAFETY: forwarded contract.
        let path = unsafe { read_path(path)? };
        let handle = load(path)?;
        // SAFETY: as above.
        unsafe { out.write(Box::into_raw(Box::new(handle))) };
        Ok(())
    })
}

/// # Safety
/// `handle` is null or came from the matching `*_load` and was not freed yet.
unsafe fn free_impl<H>(handle: *mut H) {
    if !handle.is_null() {
        // Dropping plain data cannot panic, but no unwind may ever cross the boundary.
        // SAFETY: ownership returns from C, by contract.
        let _ = catch_unwind(AssertUnwindSafe(|| drop(unsafe { Box::from_raw(handle) })));
    }
}

/// # Safety
/// See the exported `*_eval` functions.
unsafe fn eval_impl<H: BrdfHandle>(
    function: &str,
    handle: *const H,
    view: *const f32,
    light: *const f32,
    n: usize,
    out_rgb: *mut f32,
) -> i32 {
    guard(function, || {
        // SAFETY: forwarded contract.
        let handle = unsafe { reference(handle, H::ARGUMENT)? };
        check_pointer(view, "view")?;
        check_pointer(light, "light")?;
        check_pointer(out_rgb, "out_rgb")?;
        let len = array_len(n, 3)?;
        if n == 0 {
            return Ok(());
        }
        // SAFETY: checked above; sizes and aliasing are the caller's contract.
        let (view, light, rgb) =
            unsafe { (input(view, len), input(light, len), output(out_rgb, len)) };
        let rgb = RgbMut::from_planar(rgb).expect("planar buffers have length 3 n");
        handle
            .brdf()
            .eval_cos_batch(directions(view), directions(light), rgb);
        Ok(())
    })
}

/// # Safety
/// See the exported `*_sample` functions.
#[allow(clippy::too_many_arguments)]
unsafe fn sample_impl<H: BrdfHandle, S: SamplerArg>(
    function: &str,
    handle: *const H,
    sampler: *const S,
    view: *const f32,
    u: *const f32,
    n: usize,
    out_light: *mut f32,
    out_weight: *mut f32,
    out_pdf: *mut f32,
) -> i32 {
    guard(function, || {
        // SAFETY: forwarded contract.
        let handle = unsafe { reference(handle, H::ARGUMENT)? };
        check_pointer(sampler, S::ARGUMENT)?;
        check_pointer(view, "view")?;
        check_pointer(u, "u")?;
        check_pointer(out_light, "out_light")?;
        check_pointer(out_weight, "out_weight")?;
        check_pointer(out_pdf, "out_pdf")?;
        // SAFETY: forwarded contract.
        let strategy = unsafe { S::strategy(sampler)? };
        let len = array_len(n, 3)?;
        if n == 0 {
            return Ok(());
        }
        // SAFETY: checked above; sizes and aliasing are the caller's contract.
        let (view, u, light, weight, pdf) = unsafe {
            (
                input(view, len),
                input(u, len),
                output(out_light, len),
                output(out_weight, len),
                output(out_pdf, n),
            )
        };
        sampling::sample_batch(
            &strategy,
            handle.brdf(),
            directions(view),
            directions(u),
            DirectionsMut::from_planar(light).expect("planar buffers have length 3 n"),
            RgbMut::from_planar(weight).expect("planar buffers have length 3 n"),
            pdf,
        );
        Ok(())
    })
}

// ---------------------------------------------------------------------------------------------
// Exported functions.

/// Message of the last failed call on this thread, prefixed with the name of the function that
/// failed; an empty string when no call has failed on this thread. Successful calls leave it
/// unchanged. The pointer stays valid until the next call into this library on the same thread.
#[no_mangle]
pub extern "C" fn nbrdf_last_error() -> *const c_char {
    nbrdf_ffi_common::last_error()
}

/// Version of the library (the crate version, e.g. "0.1.0"); a static string.
#[no_mangle]
pub extern "C" fn nbrdf_version() -> *const c_char {
    concat!(env!("CARGO_PKG_VERSION"), "\0").as_ptr().cast()
}

/// Loads a network from an `*.nbrdf.json` file and stores a new handle in `*out` (null on
/// failure). Free it with `nbrdf_network_free`.
///
/// # Safety
/// `path` is a NUL-terminated string; `out` points to writable storage for one pointer.
#[no_mangle]
pub unsafe extern "C" fn nbrdf_network_load(
    path: *const c_char,
    out: *mut *mut NbrdfNetwork,
) -> i32 {
    // SAFETY: forwarded contract.
    unsafe {
        load_impl("nbrdf_network_load", path, out, |path| {
            let network = Nbrdf::load(&path)?;
            let name = CString::new(network.name.replace('\0', "")).unwrap_or_default();
            let renderer = network.without_inactive_units();
            Ok(NbrdfNetwork {
                network,
                renderer,
                name,
            })
        })
    }
}

/// Frees a network handle; null is accepted and ignored.
///
/// # Safety
/// `network` is null or a handle from `nbrdf_network_load` that was not freed yet.
#[no_mangle]
pub unsafe extern "C" fn nbrdf_network_free(network: *mut NbrdfNetwork) {
    // SAFETY: forwarded contract.
    unsafe { free_impl(network) }
}

/// Fills `*out` with the hidden width, parameter count and stored sampling parameters.
///
/// # Safety
/// `network` is a live handle; `out` points to a writable `NbrdfNetworkInfo`.
#[no_mangle]
pub unsafe extern "C" fn nbrdf_network_info(
    network: *const NbrdfNetwork,
    out: *mut NbrdfNetworkInfo,
) -> i32 {
    guard("nbrdf_network_info", || {
        // SAFETY: forwarded contract.
        let network = &unsafe { reference(network, "network")? }.network;
        check_pointer(out, "out")?;
        let to_u32 = |value: usize| u32::try_from(value).unwrap_or(u32::MAX);
        let sampling = network.sampling.as_ref();
        let info = NbrdfNetworkInfo {
            hidden_width: to_u32(network.hidden_width()),
            parameter_count: to_u32(network.parameter_count()),
            has_sampling: u32::from(sampling.is_some()),
            exponent: sampling.map_or(0.0, |s| s.exponent),
            specular_weight: sampling.map_or(0.0, |s| s.specular_weight),
        };
        // SAFETY: non-null, aligned, writable by contract.
        unsafe { out.write(info) };
        Ok(())
    })
}

/// Stores in `*out` 1 when the network is anisotropic (file format version 2, input with the half
/// vector's azimuth `phi_h` in the local frame whose x axis is the tangent), else 0. A separate
/// call rather than a field of `NbrdfNetworkInfo`, whose layout stays that of version 0.1.
///
/// # Safety
/// `network` is a live handle; `out` points to a writable `uint32_t`.
#[no_mangle]
pub unsafe extern "C" fn nbrdf_network_is_anisotropic(
    network: *const NbrdfNetwork,
    out: *mut u32,
) -> i32 {
    guard("nbrdf_network_is_anisotropic", || {
        // SAFETY: forwarded contract.
        let network = &unsafe { reference(network, "network")? }.network;
        check_pointer(out, "out")?;
        // SAFETY: non-null, aligned, writable by contract.
        unsafe { out.write(u32::from(network.anisotropic)) };
        Ok(())
    })
}

/// Stores in `*out_name` the network's name (UTF-8, NUL-terminated, possibly empty). The string
/// belongs to the handle and stays valid until `nbrdf_network_free`.
///
/// # Safety
/// `network` is a live handle; `out_name` points to writable storage for one pointer.
#[no_mangle]
pub unsafe extern "C" fn nbrdf_network_name(
    network: *const NbrdfNetwork,
    out_name: *mut *const c_char,
) -> i32 {
    guard("nbrdf_network_name", || {
        // SAFETY: forwarded contract.
        let network = unsafe { reference(network, "network")? };
        check_pointer(out_name, "out_name")?;
        // SAFETY: non-null, aligned, writable by contract.
        unsafe { out_name.write(network.name.as_ptr()) };
        Ok(())
    })
}

/// Which hidden units of a `6 -> hidden -> hidden -> 3` network, given as its flat parameters
/// `W1, b1, W2, b2, W3, b3` (`count` floats, `hidden * hidden + 11 * hidden + 3` of them, all
/// finite), some pair of directions above the horizon may activate. Writes `2 hidden` bytes to
/// `out_active` (`out_len` must be that): the first hidden layer's units, then the second's, 1
/// for a unit that may fire, 0 for one proved never to. A 0 unit outputs exactly 0 on every
/// direction pair the BRDF is evaluated at, so an evaluator that leaves it out computes the same
/// values with fewer multiply-adds (the network handles do so; the Mitsuba plugin's traced
/// kernels ask here). `anisotropic` is 1 for a network that sees the half vector's azimuth.
/// Takes milliseconds (a bounded interval-arithmetic proof over the hemisphere).
///
/// # Safety
/// `params` points to `count` readable floats; `out_active` to `out_len` writable bytes.
#[no_mangle]
pub unsafe extern "C" fn nbrdf_network_active_units(
    params: *const f32,
    count: usize,
    hidden: usize,
    anisotropic: u32,
    out_active: *mut u8,
    out_len: usize,
) -> i32 {
    guard("nbrdf_network_active_units", || {
        check_pointer(params, "params")?;
        check_pointer(out_active, "out_active")?;
        let expected = hidden
            .checked_mul(2)
            .filter(|&len| len == out_len)
            .ok_or_else(|| {
                Failure::invalid(format!(
                    "out_len is {out_len}, expected 2 hidden = 2 x {hidden}"
                ))
            })?;
        if parameter_count_for(hidden) != count {
            return Err(Failure::invalid(format!(
                "count is {count}, but a network of hidden width {hidden} has \
                 hidden * hidden + 11 * hidden + 3 parameters"
            )));
        }
        let count = array_len(count, 1)?;
        // SAFETY: non-null, `count` readable floats by contract.
        let params = unsafe { input(params, count) };
        let mut network = Nbrdf::from_flat("parameters", hidden, params)?;
        network.anisotropic = anisotropic != 0;
        let active = network.active_units();
        // SAFETY: non-null, `out_len` writable bytes by contract.
        let out = unsafe { std::slice::from_raw_parts_mut(out_active, expected) };
        for (byte, &flag) in out
            .iter_mut()
            .zip(active.hidden1.iter().chain(&active.hidden2))
        {
            *byte = u8::from(flag);
        }
        Ok(())
    })
}

/// Evaluates `f_r(view, light) * cos(theta_light)` (what Mitsuba's `BSDF.eval` returns) for `n`
/// direction pairs: `view` and `light` are planar `3 n` floats, `out_rgb` receives planar
/// `3 n` floats `[r.., g.., b..]`. Zero when either direction is at or below the horizon.
///
/// # Safety
/// `network` is a live handle; the arrays hold `3 n` floats each and `out_rgb` overlaps neither
/// input.
#[no_mangle]
pub unsafe extern "C" fn nbrdf_network_eval(
    network: *const NbrdfNetwork,
    view: *const f32,
    light: *const f32,
    n: usize,
    out_rgb: *mut f32,
) -> i32 {
    // SAFETY: forwarded contract.
    unsafe { eval_impl("nbrdf_network_eval", network, view, light, n, out_rgb) }
}

/// Importance-samples `n` light directions for the planar `view` directions from the planar
/// uniforms `u = [u0.., u1.., u2..]` (in [0, 1]; `u0` picks the lobe of the Blinn-Phong mixture).
/// Writes the planar light directions `out_light` (3 n), the weights
/// `f_r * cos(theta_light) / pdf` as planar RGB `out_weight` (3 n) and the solid-angle pdfs
/// `out_pdf` (n). Invalid samples (below the horizon) have pdf 0 and weight 0.
///
/// # Safety
/// `network` is a live handle, `sampler` points to an `NbrdfSampler`; the arrays have the sizes
/// above and the outputs overlap neither each other nor the inputs.
#[no_mangle]
pub unsafe extern "C" fn nbrdf_network_sample(
    network: *const NbrdfNetwork,
    sampler: *const NbrdfSampler,
    view: *const f32,
    u: *const f32,
    n: usize,
    out_light: *mut f32,
    out_weight: *mut f32,
    out_pdf: *mut f32,
) -> i32 {
    // SAFETY: forwarded contract.
    unsafe {
        sample_impl(
            "nbrdf_network_sample",
            network,
            sampler,
            view,
            u,
            n,
            out_light,
            out_weight,
            out_pdf,
        )
    }
}

/// Loads a MERL-format table (a `.binary` file of 34,992,012 bytes) and stores a new handle in
/// `*out` (null on failure). Free it with `nbrdf_merl_free`.
///
/// # Safety
/// `path` is a NUL-terminated string; `out` points to writable storage for one pointer.
#[no_mangle]
pub unsafe extern "C" fn nbrdf_merl_load(path: *const c_char, out: *mut *mut NbrdfMerl) -> i32 {
    // SAFETY: forwarded contract.
    unsafe {
        load_impl("nbrdf_merl_load", path, out, |path| {
            Ok(NbrdfMerl {
                table: MerlTable::read(&path)?,
            })
        })
    }
}

/// Frees a table handle; null is accepted and ignored.
///
/// # Safety
/// `merl` is null or a handle from `nbrdf_merl_load` that was not freed yet.
#[no_mangle]
pub unsafe extern "C" fn nbrdf_merl_free(merl: *mut NbrdfMerl) {
    // SAFETY: forwarded contract.
    unsafe { free_impl(merl) }
}

/// Evaluates `f_r(view, light) * cos(theta_light)` of a table (trilinear lookup) for `n`
/// direction pairs; the layout is that of `nbrdf_network_eval`.
///
/// # Safety
/// As `nbrdf_network_eval`, with a live table handle.
#[no_mangle]
pub unsafe extern "C" fn nbrdf_merl_eval(
    merl: *const NbrdfMerl,
    view: *const f32,
    light: *const f32,
    n: usize,
    out_rgb: *mut f32,
) -> i32 {
    // SAFETY: forwarded contract.
    unsafe { eval_impl("nbrdf_merl_eval", merl, view, light, n, out_rgb) }
}

/// Importance-samples light directions for a table; the layout is that of
/// `nbrdf_network_sample`.
///
/// # Safety
/// As `nbrdf_network_sample`, with a live table handle.
#[no_mangle]
pub unsafe extern "C" fn nbrdf_merl_sample(
    merl: *const NbrdfMerl,
    sampler: *const NbrdfSampler,
    view: *const f32,
    u: *const f32,
    n: usize,
    out_light: *mut f32,
    out_weight: *mut f32,
    out_pdf: *mut f32,
) -> i32 {
    // SAFETY: forwarded contract.
    unsafe {
        sample_impl(
            "nbrdf_merl_sample",
            merl,
            sampler,
            view,
            u,
            n,
            out_light,
            out_weight,
            out_pdf,
        )
    }
}

/// Solid-angle pdf with which `sampler` draws each planar `light` direction given the planar
/// `view` direction (`3 n` floats each); writes `n` floats to `out_pdf` (0 at or below the
/// horizon).
///
/// # Safety
/// `sampler` points to an `NbrdfSampler`; the arrays have the sizes above and `out_pdf` overlaps
/// neither input.
#[no_mangle]
pub unsafe extern "C" fn nbrdf_sampler_pdf(
    sampler: *const NbrdfSampler,
    view: *const f32,
    light: *const f32,
    n: usize,
    out_pdf: *mut f32,
) -> i32 {
    // SAFETY: forwarded contract.
    unsafe { pdf_impl("nbrdf_sampler_pdf", sampler, view, light, n, out_pdf) }
}

/// # Safety
/// See the exported `*_pdf` functions.
unsafe fn pdf_impl<S: SamplerArg>(
    function: &str,
    sampler: *const S,
    view: *const f32,
    light: *const f32,
    n: usize,
    out_pdf: *mut f32,
) -> i32 {
    guard(function, || {
        check_pointer(sampler, S::ARGUMENT)?;
        check_pointer(view, "view")?;
        check_pointer(light, "light")?;
        check_pointer(out_pdf, "out_pdf")?;
        // SAFETY: forwarded contract.
        let strategy = unsafe { S::strategy(sampler)? };
        let len = array_len(n, 3)?;
        if n == 0 {
            return Ok(());
        }
        // SAFETY: checked above; sizes and aliasing are the caller's contract.
        let (view, light, pdf) =
            unsafe { (input(view, len), input(light, len), output(out_pdf, n)) };
        sampling::pdf_batch(&strategy, directions(view), directions(light), pdf);
        Ok(())
    })
}

/// Checks a sampler's kind and parameters (exponent in [0, 1e6], specular weight in [0, 1] for
/// `NBRDF_SAMPLING_PHONG`): `NBRDF_OK` or `NBRDF_ERROR_INVALID_ARGUMENT` with a message.
///
/// # Safety
/// `sampler` points to an `NbrdfSampler`.
#[no_mangle]
pub unsafe extern "C" fn nbrdf_sampler_validate(sampler: *const NbrdfSampler) -> i32 {
    // SAFETY: forwarded contract.
    guard("nbrdf_sampler_validate", || {
        unsafe { NbrdfSampler::strategy(sampler) }.map(drop)
    })
}

/// `nbrdf_network_sample` with an `NbrdfMixtureSampler` (any kind, two-lobe included).
///
/// # Safety
/// As `nbrdf_network_sample`, with `sampler` pointing to an `NbrdfMixtureSampler`.
#[no_mangle]
pub unsafe extern "C" fn nbrdf_network_sample_mixture(
    network: *const NbrdfNetwork,
    sampler: *const NbrdfMixtureSampler,
    view: *const f32,
    u: *const f32,
    n: usize,
    out_light: *mut f32,
    out_weight: *mut f32,
    out_pdf: *mut f32,
) -> i32 {
    // SAFETY: forwarded contract.
    unsafe {
        sample_impl(
            "nbrdf_network_sample_mixture",
            network,
            sampler,
            view,
            u,
            n,
            out_light,
            out_weight,
            out_pdf,
        )
    }
}

/// `nbrdf_merl_sample` with an `NbrdfMixtureSampler` (any kind, two-lobe included).
///
/// # Safety
/// As `nbrdf_merl_sample`, with `sampler` pointing to an `NbrdfMixtureSampler`.
#[no_mangle]
pub unsafe extern "C" fn nbrdf_merl_sample_mixture(
    merl: *const NbrdfMerl,
    sampler: *const NbrdfMixtureSampler,
    view: *const f32,
    u: *const f32,
    n: usize,
    out_light: *mut f32,
    out_weight: *mut f32,
    out_pdf: *mut f32,
) -> i32 {
    // SAFETY: forwarded contract.
    unsafe {
        sample_impl(
            "nbrdf_merl_sample_mixture",
            merl,
            sampler,
            view,
            u,
            n,
            out_light,
            out_weight,
            out_pdf,
        )
    }
}

/// `nbrdf_sampler_pdf` with an `NbrdfMixtureSampler` (any kind, two-lobe included).
///
/// # Safety
/// As `nbrdf_sampler_pdf`, with `sampler` pointing to an `NbrdfMixtureSampler`.
#[no_mangle]
pub unsafe extern "C" fn nbrdf_mixture_sampler_pdf(
    sampler: *const NbrdfMixtureSampler,
    view: *const f32,
    light: *const f32,
    n: usize,
    out_pdf: *mut f32,
) -> i32 {
    // SAFETY: forwarded contract.
    unsafe {
        pdf_impl(
            "nbrdf_mixture_sampler_pdf",
            sampler,
            view,
            light,
            n,
            out_pdf,
        )
    }
}

/// Checks an `NbrdfMixtureSampler`'s kind and parameters: `NBRDF_OK` or
/// `NBRDF_ERROR_INVALID_ARGUMENT` with a message.
///
/// # Safety
/// `sampler` points to an `NbrdfMixtureSampler`.
#[no_mangle]
pub unsafe extern "C" fn nbrdf_mixture_sampler_validate(
    sampler: *const NbrdfMixtureSampler,
) -> i32 {
    // SAFETY: forwarded contract.
    guard("nbrdf_mixture_sampler_validate", || {
        unsafe { NbrdfMixtureSampler::strategy(sampler) }.map(drop)
    })
}

/// Fills `*out` with the sampling strategy stored in the network file: `NBRDF_SAMPLING_PHONG`
/// (second lobe zero), `NBRDF_SAMPLING_TWO_LOBE`, `NBRDF_SAMPLING_ANISOTROPIC_PHONG`
/// (`exponent2` = `n_v`), or `NBRDF_SAMPLING_COSINE` with zero parameters when the file stores
/// none.
///
/// # Safety
/// `network` is a live handle; `out` points to a writable `NbrdfMixtureSampler`.
#[no_mangle]
pub unsafe extern "C" fn nbrdf_network_stored_sampler(
    network: *const NbrdfNetwork,
    out: *mut NbrdfMixtureSampler,
) -> i32 {
    guard("nbrdf_network_stored_sampler", || {
        // SAFETY: forwarded contract.
        let network = &unsafe { reference(network, "network")? }.network;
        check_pointer(out, "out")?;
        let mut sampler = NbrdfMixtureSampler {
            kind: NbrdfSamplingKind::NBRDF_SAMPLING_COSINE,
            exponent: 0.0,
            specular_weight: 0.0,
            exponent2: 0.0,
            specular_weight2: 0.0,
        };
        if let Some(stored) = &network.sampling {
            sampler.kind = NbrdfSamplingKind::NBRDF_SAMPLING_PHONG;
            sampler.exponent = stored.exponent;
            sampler.specular_weight = stored.specular_weight;
            if let Some(second) = stored.second_lobe {
                sampler.kind = NbrdfSamplingKind::NBRDF_SAMPLING_TWO_LOBE;
                sampler.exponent2 = second.exponent;
                sampler.specular_weight2 = second.specular_weight;
            }
            if let Some(exponent_v) = stored.exponent_v {
                sampler.kind = NbrdfSamplingKind::NBRDF_SAMPLING_ANISOTROPIC_PHONG;
                sampler.exponent2 = exponent_v;
            }
        }
        // SAFETY: non-null, aligned, writable by contract.
        unsafe { out.write(sampler) };
        Ok(())
    })
}

/// Value of `nbrdf_network_default_sampling` when the file names no default.
const NO_DEFAULT_SAMPLING: i32 = -1;

/// Writes to `*out` the sampling strategy the file names as the material's best
/// (`sampling.default`, chosen by `nbrdf fit-phong` for the lowest measured variance), as an
/// `NbrdfSamplingKind` value (`NBRDF_SAMPLING_TABULATED` included), or -1 when it names none.
///
/// # Safety
/// `network` is a live handle; `out` points to a writable `int32_t`.
#[no_mangle]
pub unsafe extern "C" fn nbrdf_network_default_sampling(
    network: *const NbrdfNetwork,
    out: *mut i32,
) -> i32 {
    guard("nbrdf_network_default_sampling", || {
        // SAFETY: forwarded contract.
        let network = &unsafe { reference(network, "network")? }.network;
        check_pointer(out, "out")?;
        let kind = match network.sampling.as_ref().and_then(|s| s.default) {
            Some(kind) => kind.code() as i32,
            None => NO_DEFAULT_SAMPLING,
        };
        // SAFETY: non-null, aligned, writable by contract.
        unsafe { out.write(kind) };
        Ok(())
    })
}

/// # Safety
/// See the exported `*_build_table` functions.
unsafe fn build_table_impl<H: BrdfHandle>(
    function: &str,
    handle: *const H,
    out: *mut *mut NbrdfTable,
) -> i32 {
    guard(function, || {
        if out.is_null() {
            return Err(Failure::null("out"));
        }
        // SAFETY: non-null and writable by contract; cleared first so that it never holds a
        // stale pointer after a failure.
        unsafe { out.write(std::ptr::null_mut()) };
        // SAFETY: forwarded contract.
        let handle = unsafe { reference(handle, H::ARGUMENT)? };
        let sampler = TabulatedSampler::from_brdf(handle.brdf(), &handle.table_config())?;
        let table = NbrdfTable {
            sampler: Arc::new(sampler),
        };
        // SAFETY: as above.
        unsafe { out.write(Box::into_raw(Box::new(table))) };
        Ok(())
    })
}

/// Tabulates the network for `sampling` = `tabulated` (about 330k evaluations, milliseconds),
/// with the defensive cosine weight of its file (`sampling.table_cosine_weight`, chosen by
/// `nbrdf fit-phong`; 0.1 without); free the result with `nbrdf_table_free`. `*out` is NULL after a failure.
///
/// # Safety
/// `network` is a live handle; `out` points to a writable pointer.
#[no_mangle]
pub unsafe extern "C" fn nbrdf_network_build_table(
    network: *const NbrdfNetwork,
    out: *mut *mut NbrdfTable,
) -> i32 {
    // SAFETY: forwarded contract.
    unsafe { build_table_impl("nbrdf_network_build_table", network, out) }
}

/// Tabulates a MERL table for `sampling` = `tabulated`, as `nbrdf_network_build_table`.
///
/// # Safety
/// `merl` is a live handle; `out` points to a writable pointer.
#[no_mangle]
pub unsafe extern "C" fn nbrdf_merl_build_table(
    merl: *const NbrdfMerl,
    out: *mut *mut NbrdfTable,
) -> i32 {
    // SAFETY: forwarded contract.
    unsafe { build_table_impl("nbrdf_merl_build_table", merl, out) }
}

/// Frees a table; NULL is a no-op.
///
/// # Safety
/// `table` is NULL or came from a `*_build_table` function and was not freed yet.
#[no_mangle]
pub unsafe extern "C" fn nbrdf_table_free(table: *mut NbrdfTable) {
    // SAFETY: forwarded contract.
    unsafe { free_impl(table) }
}

/// Fills `*out` with the table's shape and cosine weight.
///
/// # Safety
/// `table` is a live handle; `out` points to a writable `NbrdfTableInfo`.
#[no_mangle]
pub unsafe extern "C" fn nbrdf_table_info(
    table: *const NbrdfTable,
    out: *mut NbrdfTableInfo,
) -> i32 {
    guard("nbrdf_table_info", || {
        // SAFETY: forwarded contract.
        let table = unsafe { reference(table, "table")? };
        check_pointer(out, "out")?;
        let arrays = table.sampler.tables();
        let info = NbrdfTableInfo {
            rows: arrays.rows as u32,
            theta_bins: arrays.theta_bins as u32,
            phi_bins: arrays.phi_bins as u32,
            cosine_weight: arrays.cosine_weight as f32,
        };
        // SAFETY: non-null, aligned, writable by contract.
        unsafe { out.write(info) };
        Ok(())
    })
}

/// Copies the table's arrays (probabilities as float32) into caller buffers of the sizes
/// `NbrdfTableInfo` gives, for a second implementation of the sampler (the plugin's Dr.Jit
/// path).
///
/// # Safety
/// `table` is a live handle; the outputs point to writable buffers of the documented sizes.
#[no_mangle]
pub unsafe extern "C" fn nbrdf_table_arrays(
    table: *const NbrdfTable,
    out_mass: *mut f32,
    out_alias_probability: *mut f32,
    out_alias: *mut u32,
) -> i32 {
    guard("nbrdf_table_arrays", || {
        // SAFETY: forwarded contract.
        let table = unsafe { reference(table, "table")? };
        check_pointer(out_mass, "out_mass")?;
        check_pointer(out_alias_probability, "out_alias_probability")?;
        check_pointer(out_alias, "out_alias")?;
        let arrays = table.sampler.tables();
        for (src, dst) in [
            (&arrays.mass, out_mass),
            (&arrays.alias_probability, out_alias_probability),
        ] {
            // SAFETY: checked above; the size is the caller's contract.
            let dst = unsafe { output(dst, src.len()) };
            for (d, &v) in dst.iter_mut().zip(src) {
                *d = v as f32;
            }
        }
        // SAFETY: checked above; the size is the caller's contract and no other slice aliases it.
        let dst = unsafe { std::slice::from_raw_parts_mut(out_alias, arrays.alias.len()) };
        dst.copy_from_slice(&arrays.alias);
        Ok(())
    })
}

/// `nbrdf_network_sample` with the tabulated sampler `table`.
///
/// # Safety
/// As `nbrdf_network_sample`, with `table` a live `NbrdfTable`.
#[no_mangle]
pub unsafe extern "C" fn nbrdf_network_sample_table(
    network: *const NbrdfNetwork,
    table: *const NbrdfTable,
    view: *const f32,
    u: *const f32,
    n: usize,
    out_light: *mut f32,
    out_weight: *mut f32,
    out_pdf: *mut f32,
) -> i32 {
    // SAFETY: forwarded contract.
    unsafe {
        sample_impl(
            "nbrdf_network_sample_table",
            network,
            table,
            view,
            u,
            n,
            out_light,
            out_weight,
            out_pdf,
        )
    }
}

/// `nbrdf_merl_sample` with the tabulated sampler `table`.
///
/// # Safety
/// As `nbrdf_merl_sample`, with `table` a live `NbrdfTable`.
#[no_mangle]
pub unsafe extern "C" fn nbrdf_merl_sample_table(
    merl: *const NbrdfMerl,
    table: *const NbrdfTable,
    view: *const f32,
    u: *const f32,
    n: usize,
    out_light: *mut f32,
    out_weight: *mut f32,
    out_pdf: *mut f32,
) -> i32 {
    // SAFETY: forwarded contract.
    unsafe {
        sample_impl(
            "nbrdf_merl_sample_table",
            merl,
            table,
            view,
            u,
            n,
            out_light,
            out_weight,
            out_pdf,
        )
    }
}

/// `nbrdf_sampler_pdf` of the tabulated sampler `table`.
///
/// # Safety
/// As `nbrdf_sampler_pdf`, with `table` a live `NbrdfTable`.
#[no_mangle]
pub unsafe extern "C" fn nbrdf_table_pdf(
    table: *const NbrdfTable,
    view: *const f32,
    light: *const f32,
    n: usize,
    out_pdf: *mut f32,
) -> i32 {
    // SAFETY: forwarded contract.
    unsafe { pdf_impl("nbrdf_table_pdf", table, view, light, n, out_pdf) }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn last_error() -> String {
        // SAFETY: the library returns a valid NUL-terminated string.
        unsafe { CStr::from_ptr(nbrdf_last_error()) }
            .to_string_lossy()
            .into_owned()
    }

    #[test]
    fn guarded_failures_return_the_status_and_set_the_message() {
        let status = guard("some_function", || panic!("boom {}", 42));
        assert_eq!(status, NbrdfStatus::NBRDF_ERROR_PANIC as i32);
        assert!(
            last_error().starts_with("some_function: internal error (panic): boom 42"),
            "{}",
            last_error()
        );
        guard("f", || Err(Failure::invalid("bad")));
        assert_eq!(guard("g", || Ok(())), NbrdfStatus::NBRDF_OK as i32);
        assert_eq!(last_error(), "f: bad");
    }

    #[test]
    fn core_errors_map_to_status_codes() {
        let status = |error: NbrdfError| guard("f", || Err(error.into()));
        let io = NbrdfError::io("x.json", std::io::Error::from(std::io::ErrorKind::NotFound));
        assert_eq!(status(io), NbrdfStatus::NBRDF_ERROR_IO as i32);
        let binary = NbrdfError::io(
            "x.json",
            std::io::Error::from(std::io::ErrorKind::InvalidData),
        );
        assert_eq!(status(binary), NbrdfStatus::NBRDF_ERROR_FORMAT as i32);
        let format = NbrdfError::format("x.json", "bad");
        assert_eq!(status(format), NbrdfStatus::NBRDF_ERROR_FORMAT as i32);
        let invalid = NbrdfError::InvalidArgument("n".into());
        assert_eq!(
            status(invalid),
            NbrdfStatus::NBRDF_ERROR_INVALID_ARGUMENT as i32
        );
        assert_eq!(
            guard("f", || Err(Failure::null("x"))),
            NbrdfStatus::NBRDF_ERROR_NULL_POINTER as i32
        );
    }
}
