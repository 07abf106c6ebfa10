//! The functions of `NbrdfMaterial`, a neural BRDF, a spatially varying neural material or a
//! MERL table behind one handle (what it holds: [`crate::handles`]): one entry point per
//! operation (load, free, info, eval, sample; a network's parameters and active units). Eval
//! and sample at texture coordinates, for every kind: [`crate::uv`].

use crate::args::{directions, exact_len, free_boxed, read_path, uvs, write};
use crate::handles::{NbrdfMaterial, NbrdfSampler, NbrdfSamplerParams};
use crate::status::guard;
use crate::vocabulary::NbrdfSamplingKind;
use nbrdf_core::brdf::{DirectionsMut, RgbMut};
use nbrdf_core::network::{ActiveUnits, Spectral};
use nbrdf_core::sampling;
use nbrdf_core::Nbrdf;
use nbrdf_ffi_common::{
    array_len, check_pointer, input, output, reference, Failure, FailureKind, FfiResult,
};
use std::ffi::c_char;

/// What an `NbrdfMaterial` holds (the `kind` of `NbrdfMaterialInfo`).
#[repr(C)]
#[allow(non_camel_case_types)]
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum NbrdfMaterialKind {
    /// A neural BRDF from an `*.nbrdf.json` file.
    NBRDF_MATERIAL_NETWORK = 0,
    /// A MERL-format table from a `.binary` file.
    NBRDF_MATERIAL_MERL = 1,
    /// A spatially varying neural material from an `*.nbrdf.json` file of format version 4 and
    /// its latent texture (`nbrdf_material_eval_uv`, `nbrdf_material_sample_uv`).
    NBRDF_MATERIAL_TEXTURED = 2,
}

/// Summary of a material (`nbrdf_material_info`).
#[repr(C)]
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct NbrdfMaterialInfo {
    /// An `NbrdfMaterialKind` value.
    pub kind: i32,
    /// 1 for an anisotropic network or textured material (file format version 2, or an
    /// `anisotropic` decoder: its input carries the half vector's azimuth `phi_h` in the local
    /// frame whose x axis is the tangent), else 0.
    pub anisotropic: u32,
    /// Width of a network's two hidden layers (21 for the paper's networks); 0 for a table and
    /// a textured material.
    pub hidden_width: u32,
    /// Number of a network's weights and biases (675 for width 21); 0 for a table and a
    /// textured material.
    pub parameter_count: u32,
    /// Inputs and outputs of a network's three dense layers (`y = x W + b`, `W` row-major
    /// inputs x outputs): `6 -> hidden -> hidden -> 3`, or `-> spectral_count` for a spectral
    /// network; zeros for a table and a textured material.
    pub layer_inputs: [u32; 3],
    pub layer_outputs: [u32; 3],
    /// The material's name (UTF-8, NUL-terminated, possibly empty; empty for a table), owned by
    /// the handle: valid until `nbrdf_material_free`.
    pub name: *const c_char,
    /// The sampling lobes the network file stores: `NBRDF_SAMPLING_PHONG`,
    /// `NBRDF_SAMPLING_TWO_LOBE` (second lobe in `exponent2`, `specular_weight2`) or
    /// `NBRDF_SAMPLING_ANISOTROPIC_PHONG` (`exponent_v`), or `NBRDF_SAMPLING_COSINE` with zero
    /// parameters when it stores none (and for a table and a textured material, whose lobes
    /// vary over its texture).
    pub stored_sampling: NbrdfSamplerParams,
    /// The strategy the file names as the material's best (`sampling.default`, chosen by
    /// `nbrdf fit-phong` for the lowest measured variance), an `NbrdfSamplingKind` value
    /// (`NBRDF_SAMPLING_TABULATED` included), or -1 when it names none (and for a table and a
    /// textured material).
    pub default_sampling: i32,
    /// The number of spectral coefficients a spectral network (file format version 3) or a
    /// spectral textured material (version 4 with a `spectral` object) outputs,
    /// `f_r(lambda) = sum_k c_k B_k(lambda)` with the clamped uniform cubic B-spline basis over
    /// `spectral_range_nm` (`nbrdf_material_eval_spectral`); 0 for RGB materials and tables.
    pub spectral_count: u32,
    /// The wavelength range of the spectral basis in nm; (0, 0) when not spectral.
    pub spectral_range_nm: [f32; 2],
    /// The channels `C` of a textured material's latent code (its decoder reads `6 + C`
    /// inputs); 0 for the other kinds.
    pub latent_channels: u32,
    /// A textured material's latent texture size in texels, (width, height); (0, 0) for the
    /// other kinds.
    pub texture_size: [u32; 2],
}

/// `default_sampling` of a material whose file names no default.
const NO_DEFAULT_SAMPLING: i32 = -1;

impl NbrdfMaterial {
    fn info(&self) -> NbrdfMaterialInfo {
        let to_u32 = |value: usize| u32::try_from(value).unwrap_or(u32::MAX);
        let mut info = NbrdfMaterialInfo {
            kind: NbrdfMaterialKind::NBRDF_MATERIAL_MERL as i32,
            anisotropic: 0,
            hidden_width: 0,
            parameter_count: 0,
            layer_inputs: [0; 3],
            layer_outputs: [0; 3],
            name: self.name().as_ptr(),
            stored_sampling: NbrdfSamplerParams::cosine(),
            default_sampling: NO_DEFAULT_SAMPLING,
            spectral_count: 0,
            spectral_range_nm: [0.0; 2],
            latent_channels: 0,
            texture_size: [0; 2],
        };
        if let Some(spectral) = self.spectral() {
            let basis = spectral.basis();
            info.spectral_count = to_u32(basis.count);
            info.spectral_range_nm = [basis.min_nm as f32, basis.max_nm as f32];
        }
        if let Some(textured) = self.textured() {
            info.kind = NbrdfMaterialKind::NBRDF_MATERIAL_TEXTURED as i32;
            info.anisotropic = u32::from(textured.decoder().anisotropic());
            info.latent_channels = to_u32(textured.decoder().latent_channels());
            let texture = textured.texture();
            info.texture_size = [to_u32(texture.width()), to_u32(texture.height())];
        }
        if let Some(loaded) = self.network() {
            let network = &loaded.network;
            info.kind = NbrdfMaterialKind::NBRDF_MATERIAL_NETWORK as i32;
            info.anisotropic = u32::from(network.anisotropic);
            info.hidden_width = to_u32(network.hidden_width());
            info.parameter_count = to_u32(network.parameter_count());
            info.layer_inputs = network.layers.each_ref().map(|l| to_u32(l.inputs));
            info.layer_outputs = network.layers.each_ref().map(|l| to_u32(l.outputs));
            info.stored_sampling = stored_sampling(network);
            info.default_sampling = network
                .sampling
                .as_ref()
                .and_then(|s| s.default)
                .map_or(NO_DEFAULT_SAMPLING, |kind| {
                    NbrdfSamplingKind::of(kind) as i32
                });
        }
        info
    }
}

/// The lobes a network file stores, as sampler parameters (see `NbrdfMaterialInfo`).
fn stored_sampling(network: &Nbrdf) -> NbrdfSamplerParams {
    let mut params = NbrdfSamplerParams::cosine();
    if let Some(stored) = &network.sampling {
        params.kind = NbrdfSamplingKind::NBRDF_SAMPLING_PHONG as i32;
        params.exponent = stored.exponent;
        params.specular_weight = stored.specular_weight;
        if let Some(second) = stored.second_lobe {
            params.kind = NbrdfSamplingKind::NBRDF_SAMPLING_TWO_LOBE as i32;
            params.exponent2 = second.exponent;
            params.specular_weight2 = second.specular_weight;
        }
        if let Some(exponent_v) = stored.exponent_v {
            params.kind = NbrdfSamplingKind::NBRDF_SAMPLING_ANISOTROPIC_PHONG as i32;
            params.exponent_v = exponent_v;
        }
    }
    params
}

/// Writes the flags of `active` (first hidden layer, then the second) as bytes.
fn write_flags(active: &ActiveUnits, out: &mut [u8]) {
    for (byte, &flag) in out
        .iter_mut()
        .zip(active.hidden1.iter().chain(&active.hidden2))
    {
        *byte = u8::from(flag);
    }
}

/// Loads a material and stores a new handle in `*out` (NULL on failure): a MERL-format table
/// (`.binary`, 34,992,012 bytes) when the file starts with a table's header (90, 90, 180 as
/// little-endian int32); a spatially varying material when the file is an `*.nbrdf.json` of
/// format version 4, with the latent texture it names (a missing or unreadable texture is an
/// error naming the file and the texture); else a neural BRDF (`*.nbrdf.json`), validated, and
/// proved once which of its hidden units can fire above the horizon (`nbrdf_material_network`;
/// the proof is made on the first call that needs it: evaluation, sampling or
/// `nbrdf_material_network`). Free it with `nbrdf_material_free`; `nbrdf_material_info` says
/// which kind it is.
///
/// # Safety
/// `path` is a NUL-terminated string; `out` points to writable storage for one pointer.
#[no_mangle]
pub unsafe extern "C" fn nbrdf_material_load(
    path: *const c_char,
    out: *mut *mut NbrdfMaterial,
) -> i32 {
    guard("nbrdf_material_load", || {
        // SAFETY: forwarded contract; cleared first so that `*out` never holds a stale pointer
        // after a failure.
        unsafe { write(out, "out", std::ptr::null_mut())? };
        // SAFETY: forwarded contract.
        let path = unsafe { read_path(path)? };
        let material = NbrdfMaterial::load(&path)?;
        // SAFETY: as above.
        unsafe { write(out, "out", Box::into_raw(Box::new(material))) }
    })
}

/// Frees a material; NULL is accepted and ignored.
///
/// # Safety
/// `material` is NULL or a handle from `nbrdf_material_load` that was not freed yet.
#[no_mangle]
pub unsafe extern "C" fn nbrdf_material_free(material: *mut NbrdfMaterial) {
    // SAFETY: forwarded contract.
    unsafe { free_boxed(material) }
}

/// Fills `*out` with the material's kind, shape, name and stored sampling (a textured
/// material's latent channels and texture size).
///
/// # Safety
/// `material` is a live handle; `out` points to a writable `NbrdfMaterialInfo`.
#[no_mangle]
pub unsafe extern "C" fn nbrdf_material_info(
    material: *const NbrdfMaterial,
    out: *mut NbrdfMaterialInfo,
) -> i32 {
    guard("nbrdf_material_info", || {
        // SAFETY: forwarded contract.
        let material = unsafe { reference(material, "material")? };
        // SAFETY: forwarded contract.
        unsafe { write(out, "out", material.info()) }
    })
}

/// Stores in `*out` a network's analytic base (the file's `base`) as JSON text: UTF-8,
/// NUL-terminated, a Mitsuba 3 BSDF dictionary, owned by the handle (valid until
/// `nbrdf_material_free`); NULL when the file has none, and for a table and a textured material.
/// Such a material's BRDF is the base plus the network, and eval and sample here give the
/// network alone: a renderer must add the base (the Mitsuba plugin does) or refuse the file.
///
/// # Safety
/// `material` is a live handle; `out` points to writable storage for one pointer.
#[no_mangle]
pub unsafe extern "C" fn nbrdf_material_base(
    material: *const NbrdfMaterial,
    out: *mut *const c_char,
) -> i32 {
    guard("nbrdf_material_base", || {
        // SAFETY: forwarded contract; cleared first so that `*out` is NULL after a failure.
        unsafe { write(out, "out", std::ptr::null())? };
        // SAFETY: forwarded contract.
        let material = unsafe { reference(material, "material")? };
        let base = material
            .base()
            .map_or(std::ptr::null(), |base| base.as_ptr());
        // SAFETY: as above.
        unsafe { write(out, "out", base) }
    })
}

/// Evaluates `f_r(view, light) * cos(theta_light)` (what Mitsuba's `BSDF.eval` returns) for `n`
/// direction pairs: `view` and `light` are planar `3 n` floats, `out_rgb` receives planar
/// `3 n` floats `[r.., g.., b..]`. Zero when either direction is at or below the horizon. A
/// network is evaluated without its hidden units that cannot fire (the same values); a table
/// by trilinear lookup. A spectral network gives the linear sRGB projection of its spectrum
/// under D65 (`nbrdf_material_spectral_srgb`). `NBRDF_ERROR_INVALID_ARGUMENT` for a textured
/// material, which varies over its surface (`nbrdf_material_eval_uv`).
///
/// # Safety
/// `material` is a live handle; the arrays hold `3 n` floats each and `out_rgb` overlaps neither
/// input.
#[no_mangle]
pub unsafe extern "C" fn nbrdf_material_eval(
    material: *const NbrdfMaterial,
    view: *const f32,
    light: *const f32,
    n: usize,
    out_rgb: *mut f32,
) -> i32 {
    guard("nbrdf_material_eval", || {
        // SAFETY: forwarded contract.
        let material = unsafe { reference(material, "material")? };
        let brdf = material.brdf()?;
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
        brdf.eval_cos_batch(directions(view), directions(light), rgb);
        Ok(())
    })
}

/// Importance-samples `n` light directions with `sampler` for the planar `view` directions from
/// the planar uniforms `u = [u0.., u1.., u2..]` (in [0, 1]; `u0` picks the lobe of a mixture).
/// Writes the planar light directions `out_light` (3 n), the weights
/// `f_r * cos(theta_light) / pdf` of the material as planar RGB `out_weight` (3 n) and the
/// solid-angle pdfs `out_pdf` (n), those `nbrdf_sampler_pdf` gives. Invalid samples (below the
/// horizon) have pdf 0 and weight 0. `NBRDF_ERROR_INVALID_ARGUMENT` for a textured material
/// (`nbrdf_material_sample_uv`).
///
/// # Safety
/// `material` and `sampler` are live handles; the arrays have the sizes above and the outputs
/// overlap neither each other nor the inputs.
#[no_mangle]
pub unsafe extern "C" fn nbrdf_material_sample(
    material: *const NbrdfMaterial,
    sampler: *const NbrdfSampler,
    view: *const f32,
    u: *const f32,
    n: usize,
    out_light: *mut f32,
    out_weight: *mut f32,
    out_pdf: *mut f32,
) -> i32 {
    guard("nbrdf_material_sample", || {
        // SAFETY: forwarded contract.
        let material = unsafe { reference(material, "material")? };
        let brdf = material.brdf()?;
        // SAFETY: forwarded contract.
        let sampler = unsafe { reference(sampler, "sampler")? };
        check_pointer(view, "view")?;
        check_pointer(u, "u")?;
        check_pointer(out_light, "out_light")?;
        check_pointer(out_weight, "out_weight")?;
        check_pointer(out_pdf, "out_pdf")?;
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
            sampler.strategy(),
            brdf,
            directions(view),
            directions(u),
            DirectionsMut::from_planar(light).expect("planar buffers have length 3 n"),
            RgbMut::from_planar(weight).expect("planar buffers have length 3 n"),
            pdf,
        );
        Ok(())
    })
}

/// Copies a network's parameters and the proof made at load time of which hidden units can
/// fire, for a second evaluator (the Mitsuba plugin's traced kernels) that needs neither to
/// read the file nor to prove again. `out_params` receives the `parameter_count` weights and
/// biases as the file stores them, `W1, b1, W2, b2, W3, b3` (the shapes of
/// `NbrdfMaterialInfo::layer_inputs` and `layer_outputs`); `out_active` receives
/// `2 hidden_width` bytes, the first hidden layer's units then the second's, 1 for a unit that
/// some pair of directions above the horizon may activate, 0 for one proved never to (it
/// outputs exactly 0 wherever the BRDF is evaluated, so an evaluator may leave it out).
/// `params_len` and `active_len` must be those sizes (`nbrdf_material_info`);
/// `NBRDF_ERROR_INVALID_ARGUMENT` for a table. `out_active` NULL with `active_len` 0 asks for
/// the parameters alone: the proof (milliseconds) is then not made.
///
/// # Safety
/// `material` is a live handle; `out_params` points to `params_len` writable floats and
/// `out_active` to `active_len` writable bytes (or is NULL with `active_len` 0).
#[no_mangle]
pub unsafe extern "C" fn nbrdf_material_network(
    material: *const NbrdfMaterial,
    out_params: *mut f32,
    params_len: usize,
    out_active: *mut u8,
    active_len: usize,
) -> i32 {
    guard("nbrdf_material_network", || {
        // SAFETY: forwarded contract.
        let material = unsafe { reference(material, "material")? };
        let loaded = material.loaded_network()?;
        check_pointer(out_params, "out_params")?;
        let parameters_only = out_active.is_null() && active_len == 0;
        if !parameters_only {
            check_pointer(out_active, "out_active")?;
        }
        let params = loaded.network.to_flat();
        exact_len(
            "out_params",
            params_len,
            params.len(),
            "NbrdfMaterialInfo::parameter_count",
        )?;
        let hidden = loaded.network.hidden_width();
        if !parameters_only {
            exact_len("out_active", active_len, 2 * hidden, "2 hidden_width")?;
        }
        // SAFETY: non-null and aligned (checked), `params_len` writable floats by contract.
        unsafe { output(out_params, params_len) }.copy_from_slice(&params);
        if !parameters_only {
            // SAFETY: non-null, `active_len` writable bytes by contract.
            let active = unsafe { std::slice::from_raw_parts_mut(out_active, active_len) };
            write_flags(&loaded.proved().active, active);
        }
        Ok(())
    })
}

/// Proves which hidden units of the material's network can fire once its parameters are
/// replaced by `params` (`count` finite floats, `W1, b1, W2, b2, W3, b3` in the shapes of the
/// loaded network: `parameter_count` of them): writes `active_len` = `2 hidden_width` bytes to
/// `out_active` as `nbrdf_material_network` does. For evaluators of updated weights (the
/// plugin's kernels after a parameter update); the material itself is not changed. Takes
/// milliseconds (a bounded interval-arithmetic proof over the hemisphere).
/// `NBRDF_ERROR_INVALID_ARGUMENT` for a table, wrong sizes and non-finite parameters.
///
/// # Safety
/// `material` is a live handle; `params` points to `count` readable floats and `out_active` to
/// `active_len` writable bytes.
#[no_mangle]
pub unsafe extern "C" fn nbrdf_material_active_units(
    material: *const NbrdfMaterial,
    params: *const f32,
    count: usize,
    out_active: *mut u8,
    active_len: usize,
) -> i32 {
    guard("nbrdf_material_active_units", || {
        // SAFETY: forwarded contract.
        let material = unsafe { reference(material, "material")? };
        let loaded = material.loaded_network()?;
        check_pointer(params, "params")?;
        check_pointer(out_active, "out_active")?;
        let hidden = loaded.network.hidden_width();
        exact_len(
            "params",
            count,
            loaded.network.parameter_count(),
            "NbrdfMaterialInfo::parameter_count",
        )?;
        exact_len("out_active", active_len, 2 * hidden, "2 hidden_width")?;
        // SAFETY: non-null and aligned (checked), `count` readable floats by contract; the
        // count is that of a loaded network, so it fits in isize.
        let params = unsafe { input(params, count) };
        let network = loaded.network.with_parameters(params)?;
        // SAFETY: non-null, `active_len` writable bytes by contract.
        let active = unsafe { std::slice::from_raw_parts_mut(out_active, active_len) };
        write_flags(&network.active_units(), active);
        Ok(())
    })
}

/// The spectral basis of a material, or an error for an RGB material or a table.
fn spectral_of(material: &NbrdfMaterial) -> FfiResult<&Spectral> {
    material.spectral().ok_or_else(|| {
        Failure::invalid(
            "the material is not spectral: an RGB network or spatially varying material, or a \
             table (spectral materials are networks of file format version 3 and version-4 \
             files with a \"spectral\" object)",
        )
    })
}

/// Evaluates a spectral material's `f_r(view, light, lambda) * cos(theta_light)` at `n` hits
/// (`view`, `light` planar `3 n` floats) and `m` wavelengths (nm) per hit: wavelength `j` of hit
/// `i` at `wavelengths[j n + i]`, its value written to `out[j n + i]`. `uv`: the hits' texture
/// coordinates, planar `2 n` floats `[u0.., v0..]` (Mitsuba's `si.uv`), which a spatially
/// varying material reads as `nbrdf_material_eval_uv` does (required: NULL is
/// `NBRDF_ERROR_NULL_POINTER`); a network ignores them and `uv` may be NULL. Zero when either
/// direction is at or below the horizon, where `nbrdf_material_eval_uv` is zero, and at
/// wavelengths outside `NbrdfMaterialInfo::spectral_range_nm` or not finite.
/// `NBRDF_ERROR_INVALID_ARGUMENT` for an RGB material (`spectral_count` 0) or a table.
///
/// # Safety
/// `material` is a live handle; `uv` is NULL (a network) or holds `2 n` floats, `view` and
/// `light` hold `3 n` floats, `wavelengths` and `out` `m n` floats, and `out` overlaps no input.
#[no_mangle]
pub unsafe extern "C" fn nbrdf_material_eval_spectral(
    material: *const NbrdfMaterial,
    uv: *const f32,
    view: *const f32,
    light: *const f32,
    wavelengths: *const f32,
    n: usize,
    m: usize,
    out: *mut f32,
) -> i32 {
    guard("nbrdf_material_eval_spectral", || {
        // SAFETY: forwarded contract.
        let material = unsafe { reference(material, "material")? };
        spectral_of(material)?;
        let textured = material.textured();
        if textured.is_some() && uv.is_null() {
            return Err(Failure {
                kind: FailureKind::NullPointer,
                message: "argument `uv` is a null pointer: a spatially varying material is \
                          evaluated at the hits' texture coordinates (planar 2 n floats)"
                    .into(),
            });
        }
        check_pointer(view, "view")?;
        check_pointer(light, "light")?;
        check_pointer(wavelengths, "wavelengths")?;
        check_pointer(out, "out")?;
        let len = array_len(n, 3)?;
        let uv_len = array_len(n, 2)?;
        let values = array_len(n, m)?;
        if values == 0 {
            return Ok(());
        }
        // SAFETY: checked above; sizes and aliasing are the caller's contract.
        let (view, light, wavelengths, out) = unsafe {
            (
                directions(input(view, len)),
                directions(input(light, len)),
                input(wavelengths, values),
                output(out, values),
            )
        };
        if let Some(textured) = textured {
            check_pointer(uv, "uv")?;
            // SAFETY: checked above; `2 n` floats by contract.
            let uv = uvs(unsafe { input(uv, uv_len) });
            textured.eval_spectral_cos_batch(uv, view, light, wavelengths, out)?;
        } else {
            let renderer = &material.loaded_network()?.proved().renderer;
            renderer.eval_spectral_cos_batch(view, light, wavelengths, out)?;
        }
        Ok(())
    })
}

/// Writes a spectral material's 3 x count matrix `M` (row-major, `len` = `3 spectral_count`
/// floats): the linear sRGB value under D65 of each basis function, so that the RGB value of
/// coefficients `c` is `M c` (what `nbrdf_material_eval` and `nbrdf_material_eval_uv` compute).
/// `NBRDF_ERROR_INVALID_ARGUMENT` for an RGB material, a table or a wrong `len`.
///
/// # Safety
/// `material` is a live handle; `out` points to `len` writable floats.
#[no_mangle]
pub unsafe extern "C" fn nbrdf_material_spectral_srgb(
    material: *const NbrdfMaterial,
    out: *mut f32,
    len: usize,
) -> i32 {
    guard("nbrdf_material_spectral_srgb", || {
        // SAFETY: forwarded contract.
        let material = unsafe { reference(material, "material")? };
        let spectral = spectral_of(material)?;
        check_pointer(out, "out")?;
        let matrix = spectral.srgb_matrix();
        exact_len(
            "out",
            len,
            matrix.len(),
            "3 NbrdfMaterialInfo::spectral_count",
        )?;
        // SAFETY: non-null and aligned (checked), `len` writable floats by contract.
        let out = unsafe { output(out, len) };
        for (o, &v) in out.iter_mut().zip(&matrix) {
            *o = v as f32;
        }
        Ok(())
    })
}
