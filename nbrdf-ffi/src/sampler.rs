//! The functions of `NbrdfSampler`, any importance-sampling strategy (the data-driven table
//! included) behind one handle (what it holds: [`crate::handles`]): created from a parameter
//! struct and a material; its pdf, shape and table arrays.

use crate::args::{directions, exact_len, free_boxed, write};
use crate::handles::{NbrdfMaterial, NbrdfSampler, NbrdfSamplerParams};
use crate::status::guard;
use crate::vocabulary::NbrdfSamplingKind;
use nbrdf_core::sampling::{self, SamplingStrategy};
use nbrdf_ffi_common::{array_len, check_pointer, input, output, reference, Failure};

/// Shape of a sampler (`nbrdf_sampler_info`). For `NBRDF_SAMPLING_TABULATED`, the per-band
/// half-vector table: `nbrdf_sampler_table` gives `mass` (each bin's probability, row-major
/// `[row][theta bin][phi bin]`; the `phi_bins` span `|phi_h - phi_v|` over `[0, pi]`, each bin
/// standing for itself and its mirror image across the plane of incidence, so a bin's mass is
/// spread over both), `alias_probability` and `alias` (per row, Walker's alias table over the
/// row's bins: a bin `k` drawn uniformly is kept with probability `alias_probability[k]`, else
/// replaced by the bin `alias[k]`, an index within the row), each `rows * theta_bins * phi_bins`
/// values. Every other kind has no table: zeros.
#[repr(C)]
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct NbrdfSamplerInfo {
    /// An `NbrdfSamplingKind` value.
    pub kind: i32,
    pub rows: u32,
    pub theta_bins: u32,
    pub phi_bins: u32,
    /// Weight of the defensive cosine component of the tabulated mixture.
    pub cosine_weight: f32,
}

/// Creates a sampler from `params` and stores a new handle in `*out` (NULL on failure): checks
/// the kind and its parameters (`NBRDF_ERROR_INVALID_ARGUMENT` with a message), and for
/// `NBRDF_SAMPLING_TABULATED` tabulates `material` (about 330k evaluations, milliseconds) with
/// the defensive cosine weight its file stores (`sampling.table_cosine_weight`, chosen by
/// `nbrdf fit-phong`; 0.1 without). `material` may be NULL for every other kind; it is not
/// referenced after the call. Free the sampler with `nbrdf_sampler_free`.
///
/// # Safety
/// `material` is NULL or a live handle; `params` points to an `NbrdfSamplerParams`; `out` to
/// writable storage for one pointer.
#[no_mangle]
pub unsafe extern "C" fn nbrdf_sampler_create(
    material: *const NbrdfMaterial,
    params: *const NbrdfSamplerParams,
    out: *mut *mut NbrdfSampler,
) -> i32 {
    guard("nbrdf_sampler_create", || {
        // SAFETY: forwarded contract; cleared first so that `*out` never holds a stale pointer
        // after a failure.
        unsafe { write(out, "out", std::ptr::null_mut())? };
        // SAFETY: forwarded contract.
        let params = unsafe { reference(params, "params")? };
        let material = if material.is_null() {
            None
        } else {
            // SAFETY: forwarded contract.
            Some(unsafe { reference(material, "material")? })
        };
        let sampler = NbrdfSampler::new(params, material)?;
        // SAFETY: as above.
        unsafe { write(out, "out", Box::into_raw(Box::new(sampler))) }
    })
}

/// Frees a sampler; NULL is accepted and ignored.
///
/// # Safety
/// `sampler` is NULL or a handle from `nbrdf_sampler_create` that was not freed yet.
#[no_mangle]
pub unsafe extern "C" fn nbrdf_sampler_free(sampler: *mut NbrdfSampler) {
    // SAFETY: forwarded contract.
    unsafe { free_boxed(sampler) }
}

/// Fills `*out` with the sampler's kind and, for a tabulated one, its table's shape and cosine
/// weight.
///
/// # Safety
/// `sampler` is a live handle; `out` points to a writable `NbrdfSamplerInfo`.
#[no_mangle]
pub unsafe extern "C" fn nbrdf_sampler_info(
    sampler: *const NbrdfSampler,
    out: *mut NbrdfSamplerInfo,
) -> i32 {
    guard("nbrdf_sampler_info", || {
        // SAFETY: forwarded contract.
        let sampler = unsafe { reference(sampler, "sampler")? };
        let mut info = NbrdfSamplerInfo {
            kind: NbrdfSamplingKind::of(sampler.strategy().kind()) as i32,
            ..NbrdfSamplerInfo::default()
        };
        if let SamplingStrategy::Tabulated(table) = sampler.strategy() {
            let arrays = table.tables();
            let to_u32 = |value: usize| u32::try_from(value).unwrap_or(u32::MAX);
            info.rows = to_u32(arrays.rows);
            info.theta_bins = to_u32(arrays.theta_bins);
            info.phi_bins = to_u32(arrays.phi_bins);
            info.cosine_weight = arrays.cosine_weight as f32;
        }
        // SAFETY: forwarded contract.
        unsafe { write(out, "out", info) }
    })
}

/// Copies a tabulated sampler's arrays (probabilities as float32) into caller buffers of `len`
/// values each, `rows * theta_bins * phi_bins` (`NbrdfSamplerInfo`), for a second
/// implementation of the sampler (the plugin's Dr.Jit path). `NBRDF_ERROR_INVALID_ARGUMENT` for
/// a sampler of another kind.
///
/// # Safety
/// `sampler` is a live handle; the outputs point to `len` writable values each.
#[no_mangle]
pub unsafe extern "C" fn nbrdf_sampler_table(
    sampler: *const NbrdfSampler,
    out_mass: *mut f32,
    out_alias_probability: *mut f32,
    out_alias: *mut u32,
    len: usize,
) -> i32 {
    guard("nbrdf_sampler_table", || {
        // SAFETY: forwarded contract.
        let sampler = unsafe { reference(sampler, "sampler")? };
        let SamplingStrategy::Tabulated(table) = sampler.strategy() else {
            return Err(Failure::invalid(format!(
                "the sampler is {}, which has no table (NBRDF_SAMPLING_TABULATED has)",
                sampler.strategy().kind()
            )));
        };
        check_pointer(out_mass, "out_mass")?;
        check_pointer(out_alias_probability, "out_alias_probability")?;
        check_pointer(out_alias, "out_alias")?;
        let arrays = table.tables();
        exact_len(
            "len",
            len,
            arrays.mass.len(),
            "rows * theta_bins * phi_bins",
        )?;
        for (src, dst) in [
            (&arrays.mass, out_mass),
            (&arrays.alias_probability, out_alias_probability),
        ] {
            // SAFETY: checked above; `len` writable floats by contract.
            let dst = unsafe { output(dst, len) };
            for (d, &v) in dst.iter_mut().zip(src) {
                *d = v as f32;
            }
        }
        // SAFETY: checked above; `len` writable values that no other slice aliases.
        unsafe { std::slice::from_raw_parts_mut(out_alias, len) }.copy_from_slice(&arrays.alias);
        Ok(())
    })
}

/// Solid-angle pdf with which `sampler` draws each planar `light` direction given the planar
/// `view` direction (`3 n` floats each); writes `n` floats to `out_pdf` (0 at or below the
/// horizon).
///
/// # Safety
/// `sampler` is a live handle; the arrays have the sizes above and `out_pdf` overlaps neither
/// input.
#[no_mangle]
pub unsafe extern "C" fn nbrdf_sampler_pdf(
    sampler: *const NbrdfSampler,
    view: *const f32,
    light: *const f32,
    n: usize,
    out_pdf: *mut f32,
) -> i32 {
    guard("nbrdf_sampler_pdf", || {
        // SAFETY: forwarded contract.
        let sampler = unsafe { reference(sampler, "sampler")? };
        check_pointer(view, "view")?;
        check_pointer(light, "light")?;
        check_pointer(out_pdf, "out_pdf")?;
        let len = array_len(n, 3)?;
        if n == 0 {
            return Ok(());
        }
        // SAFETY: checked above; sizes and aliasing are the caller's contract.
        let (view, light, pdf) =
            unsafe { (input(view, len), input(light, len), output(out_pdf, n)) };
        sampling::pdf_batch(sampler.strategy(), directions(view), directions(light), pdf);
        Ok(())
    })
}
