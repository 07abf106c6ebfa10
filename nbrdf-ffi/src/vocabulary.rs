//! The sampling strategies' codes and names as C sees them: `NbrdfSamplingKind` carries the
//! codes of nbrdf-core's `SamplingKind` (checked at compile time), `nbrdf_sampling_kind_name`
//! its canonical names, so that callers (the Python plugin) take both from here.

use crate::args::write;
use crate::status::guard;
use nbrdf_core::sampling::SamplingKind;
use nbrdf_ffi_common::Failure;
use std::ffi::{c_char, CString};
use std::sync::OnceLock;

/// Importance-sampling strategy of an `NbrdfSampler` (the `kind` of `NbrdfSamplerParams`); the
/// codes of nbrdf-core's `SamplingKind`, whose canonical names `nbrdf_sampling_kind_name`
/// gives.
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
    NBRDF_SAMPLING_TWO_LOBE = 3,
    /// The material's data-driven half-vector table mixed with cosine, tabulated from the
    /// material when the sampler is created.
    NBRDF_SAMPLING_TABULATED = 4,
    /// Anisotropic Blinn-Phong lobe (Ashikhmin-Shirley: `exponent` = `n_u` along the tangent x,
    /// `exponent_v` = `n_v` across it, weight `specular_weight`) mixed with a cosine lobe; for
    /// anisotropic networks, whose directions are in the shading frame.
    NBRDF_SAMPLING_ANISOTROPIC_PHONG = 5,
}

impl NbrdfSamplingKind {
    /// The core's strategy of this code.
    pub const fn core(self) -> SamplingKind {
        match self {
            NbrdfSamplingKind::NBRDF_SAMPLING_UNIFORM => SamplingKind::Uniform,
            NbrdfSamplingKind::NBRDF_SAMPLING_COSINE => SamplingKind::Cosine,
            NbrdfSamplingKind::NBRDF_SAMPLING_PHONG => SamplingKind::Phong,
            NbrdfSamplingKind::NBRDF_SAMPLING_TWO_LOBE => SamplingKind::TwoLobe,
            NbrdfSamplingKind::NBRDF_SAMPLING_TABULATED => SamplingKind::Tabulated,
            NbrdfSamplingKind::NBRDF_SAMPLING_ANISOTROPIC_PHONG => SamplingKind::AnisotropicPhong,
        }
    }

    /// The C code of a core strategy (exhaustive: a strategy added to the core needs a code).
    pub const fn of(kind: SamplingKind) -> Self {
        match kind {
            SamplingKind::Uniform => NbrdfSamplingKind::NBRDF_SAMPLING_UNIFORM,
            SamplingKind::Cosine => NbrdfSamplingKind::NBRDF_SAMPLING_COSINE,
            SamplingKind::Phong => NbrdfSamplingKind::NBRDF_SAMPLING_PHONG,
            SamplingKind::TwoLobe => NbrdfSamplingKind::NBRDF_SAMPLING_TWO_LOBE,
            SamplingKind::Tabulated => NbrdfSamplingKind::NBRDF_SAMPLING_TABULATED,
            SamplingKind::AnisotropicPhong => NbrdfSamplingKind::NBRDF_SAMPLING_ANISOTROPIC_PHONG,
        }
    }

    /// The strategy of a code written by C (any integer), or `None`.
    pub fn from_code(code: i32) -> Option<Self> {
        let kind = SamplingKind::try_from(u32::try_from(code).ok()?).ok()?;
        Some(Self::of(kind))
    }
}

// The header's codes are the core's, both ways.
const _: () = {
    let mut i = 0;
    while i < SamplingKind::ALL.len() {
        let kind = SamplingKind::ALL[i];
        assert!(NbrdfSamplingKind::of(kind) as u32 == kind.code());
        assert!(NbrdfSamplingKind::of(kind).core() as u32 == kind.code());
        i += 1;
    }
};

/// The canonical names, NUL-terminated, in the order of `SamplingKind::ALL`.
fn names() -> &'static [CString] {
    static NAMES: OnceLock<Vec<CString>> = OnceLock::new();
    NAMES.get_or_init(|| {
        SamplingKind::ALL
            .iter()
            .map(|kind| CString::new(kind.name()).unwrap_or_default())
            .collect()
    })
}

/// The message of an unknown code, listing the known ones.
pub(crate) fn unknown_kind(code: i32) -> Failure {
    let known: Vec<String> = SamplingKind::ALL
        .iter()
        .map(|&kind| format!("{} = {kind}", kind.code()))
        .collect();
    Failure::invalid(format!(
        "unknown sampling kind {code} (expected {})",
        known.join(", ")
    ))
}

/// Stores in `*out_name` the canonical name of the sampling strategy `kind` (an
/// `NbrdfSamplingKind` value): "uniform", "cosine", "phong", "two_lobe", "tabulated",
/// "anisotropic_phong" (the names of network files' `sampling.default` and of the Mitsuba
/// plugin's `sampling` parameter). A static string. `NBRDF_ERROR_INVALID_ARGUMENT` for a code
/// that names no strategy (`*out_name` is then NULL), so callers can list every strategy by
/// asking until it fails.
///
/// # Safety
/// `out_name` points to writable storage for one pointer.
#[no_mangle]
pub unsafe extern "C" fn nbrdf_sampling_kind_name(kind: i32, out_name: *mut *const c_char) -> i32 {
    guard("nbrdf_sampling_kind_name", || {
        // SAFETY: forwarded contract.
        unsafe { write(out_name, "out_name", std::ptr::null())? };
        let code = NbrdfSamplingKind::from_code(kind).ok_or_else(|| unknown_kind(kind))?;
        let index = SamplingKind::ALL
            .iter()
            .position(|&k| k == code.core())
            .ok_or_else(|| unknown_kind(kind))?;
        // SAFETY: as above.
        unsafe { write(out_name, "out_name", names()[index].as_ptr()) }
    })
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::ffi::CStr;

    #[test]
    fn every_code_names_its_core_strategy_and_round_trips() {
        for code in 0..SamplingKind::ALL.len() as i32 {
            let mut name = std::ptr::null();
            // SAFETY: a valid out pointer.
            assert_eq!(unsafe { nbrdf_sampling_kind_name(code, &mut name) }, 0);
            // SAFETY: a static NUL-terminated string.
            let name = unsafe { CStr::from_ptr(name) }.to_str().unwrap();
            let kind: SamplingKind = name.parse().unwrap();
            assert_eq!(NbrdfSamplingKind::of(kind) as i32, code);
            assert_eq!(NbrdfSamplingKind::from_code(code).unwrap().core(), kind);
        }
        let mut name = c"stale".as_ptr();
        // SAFETY: a valid out pointer.
        assert_eq!(unsafe { nbrdf_sampling_kind_name(6, &mut name) }, 2);
        assert!(name.is_null());
        assert_eq!(NbrdfSamplingKind::from_code(-1), None);
    }
}
