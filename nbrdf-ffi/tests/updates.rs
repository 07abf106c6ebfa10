//! Property test of the C ABI's sampler updates (issue 16): a caller that keeps the last sampler
//! `nbrdf_sampler_validate` accepted, through random sequences of valid and invalid updates,
//! always samples and evaluates pdfs with that sampler; a rejected sampler fails every call
//! with `NBRDF_ERROR_INVALID_ARGUMENT`, writes nothing, and does not disturb later calls.
//! The reference is `SamplingStrategy::validated` of nbrdf-core and its pdf.

use nbrdf_core::SamplingStrategy;
use nbrdf_ffi::*;
use proptest::prelude::*;

const OK: i32 = NbrdfStatus::NBRDF_OK as i32;
const INVALID: i32 = NbrdfStatus::NBRDF_ERROR_INVALID_ARGUMENT as i32;

fn any_sampler() -> impl Strategy<Value = NbrdfSampler> {
    let exponent = prop_oneof![
        Just(f32::NAN),
        Just(f32::INFINITY),
        Just(-1.0f32),
        Just(1e6f32),
        Just(2e6f32),
        Just(3.4e38f32),
        0.0f32..1e4,
    ];
    let weight = prop_oneof![Just(f32::NAN), Just(-0.1f32), Just(1.5f32), 0.0f32..=1.0];
    let kind = prop_oneof![
        Just(NbrdfSamplingKind::NBRDF_SAMPLING_UNIFORM),
        Just(NbrdfSamplingKind::NBRDF_SAMPLING_COSINE),
        Just(NbrdfSamplingKind::NBRDF_SAMPLING_PHONG),
        Just(NbrdfSamplingKind::NBRDF_SAMPLING_PHONG),
        Just(NbrdfSamplingKind::NBRDF_SAMPLING_TWO_LOBE),
        Just(NbrdfSamplingKind::NBRDF_SAMPLING_ANISOTROPIC_PHONG),
        Just(NbrdfSamplingKind::NBRDF_SAMPLING_TABULATED),
    ];
    (kind, exponent, weight).prop_map(|(kind, exponent, specular_weight)| NbrdfSampler {
        kind,
        exponent,
        specular_weight,
    })
}

fn core_accepts(s: &NbrdfSampler) -> bool {
    let strategy = match s.kind {
        NbrdfSamplingKind::NBRDF_SAMPLING_UNIFORM => SamplingStrategy::Uniform,
        NbrdfSamplingKind::NBRDF_SAMPLING_COSINE => SamplingStrategy::Cosine,
        NbrdfSamplingKind::NBRDF_SAMPLING_PHONG => SamplingStrategy::Phong {
            exponent: f64::from(s.exponent),
            specular_weight: f64::from(s.specular_weight),
        },
        // The one-lobe struct has no second lobe: two-lobe samplers go through
        // NbrdfMixtureSampler, and this struct refuses the kind.
        NbrdfSamplingKind::NBRDF_SAMPLING_TWO_LOBE
        | NbrdfSamplingKind::NBRDF_SAMPLING_ANISOTROPIC_PHONG => return false,
        // Tabulated sampling needs an NbrdfTable (the *_table functions).
        NbrdfSamplingKind::NBRDF_SAMPLING_TABULATED => return false,
    };
    strategy.validated().is_ok()
}

/// Pdfs of a fixed set of direction pairs under `sampler`, with the status.
fn pdfs(sampler: &NbrdfSampler) -> (i32, Vec<f32>) {
    let n = 4;
    let view = [
        0.0, 0.3, -0.2, 0.5, 0.0, 0.1, 0.2, 0.0, 1.0, 0.95, 0.97, 0.86,
    ];
    let light = [
        0.0, -0.3, 0.2, 0.1, 0.0, -0.1, -0.2, 0.3, 1.0, 0.95, 0.97, 0.95,
    ];
    let mut out = vec![-7.0f32; n];
    // SAFETY: the arrays hold 3 n and n floats and do not overlap.
    let status =
        unsafe { nbrdf_sampler_pdf(sampler, view.as_ptr(), light.as_ptr(), n, out.as_mut_ptr()) };
    (status, out)
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(128))]

    #[test]
    fn rejected_updates_leave_the_last_valid_sampler(
        updates in prop::collection::vec(any_sampler(), 1..24)
    ) {
        let mut state = NbrdfSampler {
            kind: NbrdfSamplingKind::NBRDF_SAMPLING_COSINE,
            exponent: 0.0,
            specular_weight: 0.0,
        };
        let mut expected = pdfs(&state).1;
        for update in updates {
            // SAFETY: a valid pointer to a sampler.
            let status = unsafe { nbrdf_sampler_validate(&update) };
            prop_assert_eq!(status == OK, core_accepts(&update), "{:?}", update);
            if status == OK {
                state = update;
                let (s, values) = pdfs(&state);
                prop_assert_eq!(s, OK);
                prop_assert!(values.iter().all(|p| p.is_finite() && *p >= 0.0), "{:?}", values);
                expected = values;
            } else {
                prop_assert_eq!(status, INVALID);
                let (s, values) = pdfs(&update);
                prop_assert_eq!(s, INVALID);
                prop_assert!(values.iter().all(|p| *p == -7.0), "written on failure: {:?}", values);
            }
            // The kept sampler still gives what it gave when it was accepted.
            prop_assert_eq!(pdfs(&state), (OK, expected.clone()));
        }
    }
}
