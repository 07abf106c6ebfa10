//! The functions of `NbrdfMaterial` at texture coordinates: eval (with the pdf) and sample of any
//! material at `n` hits, each with its UV. A spatially varying material reads its latent texture
//! there; a homogeneous one (network or table) is the same at every hit and ignores the UVs.

use crate::args::{directions, uvs};
use crate::handles::{AtHits, NbrdfMaterial};
use crate::status::guard;
use nbrdf_core::brdf::{DirectionsMut, RgbMut};
use nbrdf_core::sampling;
use nbrdf_ffi_common::{array_len, check_pointer, input, output, reference};

/// Evaluates `f_r(view, light) * cos(theta_light)` (what Mitsuba's `BSDF.eval` returns) at `n`
/// hits: `uv` holds planar `2 n` floats `[u0.., v0..]` (Mitsuba's `si.uv`), `view` and `light`
/// planar `3 n` floats; `out_rgb` receives planar `3 n` floats `[r.., g.., b..]` and, unless
/// NULL, `out_pdf` the `n` solid-angle pdfs with which `nbrdf_material_sample_uv` draws each
/// `light` (Mitsuba's `BSDF.eval_pdf`). A textured material reads its texture at each UV, mapped
/// and wrapped as its file says (UVs far outside [0, 1] wrap); a UV that is not finite gives 0
/// and the cosine lobe's pdf, texels holding a non-finite value give 0 (and the cosine lobe
/// where the value is a lobe's). A network or a table ignores the UVs: the values of
/// `nbrdf_material_eval` and the pdfs of its stored lobes (`NbrdfMaterialInfo::stored_sampling`,
/// cosine without). Zero when either direction is at or below the horizon.
///
/// # Safety
/// `material` is a live handle; `uv` holds `2 n` floats, the other arrays the sizes above, and
/// the outputs overlap neither each other nor the inputs.
#[no_mangle]
pub unsafe extern "C" fn nbrdf_material_eval_uv(
    material: *const NbrdfMaterial,
    uv: *const f32,
    view: *const f32,
    light: *const f32,
    n: usize,
    out_rgb: *mut f32,
    out_pdf: *mut f32,
) -> i32 {
    guard("nbrdf_material_eval_uv", || {
        // SAFETY: forwarded contract.
        let material = unsafe { reference(material, "material")? };
        check_pointer(uv, "uv")?;
        check_pointer(view, "view")?;
        check_pointer(light, "light")?;
        check_pointer(out_rgb, "out_rgb")?;
        if !out_pdf.is_null() {
            check_pointer(out_pdf, "out_pdf")?;
        }
        let len = array_len(n, 3)?;
        let uv_len = array_len(n, 2)?;
        if n == 0 {
            return Ok(());
        }
        // SAFETY: checked above; sizes and aliasing are the caller's contract.
        let (uv, view, light, rgb) = unsafe {
            (
                input(uv, uv_len),
                input(view, len),
                input(light, len),
                output(out_rgb, len),
            )
        };
        // SAFETY: as above; NULL asks for no pdfs.
        let pdf = (!out_pdf.is_null()).then(|| unsafe { output(out_pdf, n) });
        let rgb = RgbMut::from_planar(rgb).expect("planar buffers have length 3 n");
        let (view, light) = (directions(view), directions(light));
        match material.at_hits() {
            AtHits::Textured(textured) => {
                textured.eval_cos_batch(uvs(uv), view, light, rgb);
                if let Some(pdf) = pdf {
                    textured.pdf_batch(uvs(uv), view, light, pdf);
                }
            }
            AtHits::Everywhere { brdf, sampling } => {
                brdf.eval_cos_batch(view, light, rgb);
                if let Some(pdf) = pdf {
                    sampling::pdf_batch(&sampling, view, light, pdf);
                }
            }
        }
        Ok(())
    })
}

/// Importance-samples `n` light directions at `n` hits (`uv` planar `2 n` floats
/// `[u0.., v0..]`) for the planar `view` directions from the planar uniforms
/// `u = [u0.., u1.., u2..]` (in [0, 1]; `u0` picks the lobe of a mixture), with the material's
/// own sampling: a textured material's lobes at each UV (cosine where the texture stores none,
/// at non-finite UVs and where a lobe's value is not finite), a network's stored lobes (`NbrdfMaterialInfo::stored_sampling`,
/// cosine without; the UVs ignored), cosine for a table. Writes the planar light directions
/// `out_light` (3 n), the weights `f_r * cos(theta_light) / pdf` as planar RGB `out_weight`
/// (3 n) and the solid-angle pdfs `out_pdf` (n), those `nbrdf_material_eval_uv` gives. Invalid
/// samples (below the horizon) have pdf 0 and weight 0.
///
/// # Safety
/// `material` is a live handle; the arrays have the sizes above and the outputs overlap neither
/// each other nor the inputs.
#[no_mangle]
pub unsafe extern "C" fn nbrdf_material_sample_uv(
    material: *const NbrdfMaterial,
    uv: *const f32,
    view: *const f32,
    u: *const f32,
    n: usize,
    out_light: *mut f32,
    out_weight: *mut f32,
    out_pdf: *mut f32,
) -> i32 {
    guard("nbrdf_material_sample_uv", || {
        // SAFETY: forwarded contract.
        let material = unsafe { reference(material, "material")? };
        check_pointer(uv, "uv")?;
        check_pointer(view, "view")?;
        check_pointer(u, "u")?;
        check_pointer(out_light, "out_light")?;
        check_pointer(out_weight, "out_weight")?;
        check_pointer(out_pdf, "out_pdf")?;
        let len = array_len(n, 3)?;
        let uv_len = array_len(n, 2)?;
        if n == 0 {
            return Ok(());
        }
        // SAFETY: checked above; sizes and aliasing are the caller's contract.
        let (uv, view, u, light, weight, pdf) = unsafe {
            (
                input(uv, uv_len),
                input(view, len),
                input(u, len),
                output(out_light, len),
                output(out_weight, len),
                output(out_pdf, n),
            )
        };
        let light = DirectionsMut::from_planar(light).expect("planar buffers have length 3 n");
        let weight = RgbMut::from_planar(weight).expect("planar buffers have length 3 n");
        let (view, u) = (directions(view), directions(u));
        match material.at_hits() {
            AtHits::Textured(textured) => {
                textured.sample_batch(uvs(uv), view, u, light, weight, pdf);
            }
            AtHits::Everywhere { brdf, sampling } => {
                sampling::sample_batch(&sampling, brdf, view, u, light, weight, pdf);
            }
        }
        Ok(())
    })
}
