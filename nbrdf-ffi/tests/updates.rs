//! Property test of the C ABI's sampler updates: a caller that keeps the last sampler
//! `nbrdf_sampler_create` accepted, through random sequences of valid and invalid parameters,
//! always evaluates pdfs with that sampler; rejected parameters fail with
//! `NBRDF_ERROR_INVALID_ARGUMENT`, give no handle, and do not disturb later calls.
//! The reference is `SamplingStrategy::validated` of nbrdf-core and its pdf.

use nbrdf_core::SamplingStrategy;
use nbrdf_ffi::*;
use proptest::prelude::*;

const OK: i32 = NbrdfStatus::NBRDF_OK as i32;
const INVALID: i32 = NbrdfStatus::NBRDF_ERROR_INVALID_ARGUMENT as i32;

fn any_sampler() -> impl Strategy<Value = NbrdfSamplerParams> {
    let exponent = || {
        prop_oneof![
            Just(f32::NAN),
            Just(f32::INFINITY),
            Just(-1.0f32),
            Just(1e6f32),
            Just(2e6f32),
            Just(3.4e38f32),
            0.0f32..1e4,
        ]
    };
    let weight = || prop_oneof![Just(f32::NAN), Just(-0.1f32), Just(1.5f32), 0.0f32..=1.0];
    // Every strategy but the tabulated one (parameter-free, and tabulating costs milliseconds),
    // and codes that name none.
    let kind = prop_oneof![
        Just(NbrdfSamplingKind::NBRDF_SAMPLING_UNIFORM as i32),
        Just(NbrdfSamplingKind::NBRDF_SAMPLING_COSINE as i32),
        Just(NbrdfSamplingKind::NBRDF_SAMPLING_PHONG as i32),
        Just(NbrdfSamplingKind::NBRDF_SAMPLING_PHONG as i32),
        Just(NbrdfSamplingKind::NBRDF_SAMPLING_TWO_LOBE as i32),
        Just(NbrdfSamplingKind::NBRDF_SAMPLING_ANISOTROPIC_PHONG as i32),
        Just(6),
        Just(-1),
    ];
    (kind, exponent(), weight(), exponent(), weight(), exponent()).prop_map(
        |(kind, exponent, specular_weight, exponent2, specular_weight2, exponent_v)| {
            NbrdfSamplerParams {
                kind,
                exponent,
                specular_weight,
                exponent2,
                specular_weight2,
                exponent_v,
            }
        },
    )
}

/// Whether nbrdf-core accepts the strategy `s` describes.
fn core_accepts(s: &NbrdfSamplerParams) -> bool {
    let f = f64::from;
    let strategy = match NbrdfSamplingKind::from_code(s.kind) {
        Some(NbrdfSamplingKind::NBRDF_SAMPLING_UNIFORM) => SamplingStrategy::Uniform,
        Some(NbrdfSamplingKind::NBRDF_SAMPLING_COSINE) => SamplingStrategy::Cosine,
        Some(NbrdfSamplingKind::NBRDF_SAMPLING_PHONG) => SamplingStrategy::Phong {
            exponent: f(s.exponent),
            specular_weight: f(s.specular_weight),
        },
        Some(NbrdfSamplingKind::NBRDF_SAMPLING_TWO_LOBE) => SamplingStrategy::TwoLobe {
            exponent1: f(s.exponent),
            weight1: f(s.specular_weight),
            exponent2: f(s.exponent2),
            weight2: f(s.specular_weight2),
        },
        Some(NbrdfSamplingKind::NBRDF_SAMPLING_ANISOTROPIC_PHONG) => {
            SamplingStrategy::anisotropic(f(s.exponent), f(s.exponent_v), f(s.specular_weight))
        }
        Some(NbrdfSamplingKind::NBRDF_SAMPLING_TABULATED) | None => return false,
    };
    strategy.validated().is_ok()
}

/// A sampler handle, freed on drop.
struct Sampler(*mut NbrdfSampler);

impl Drop for Sampler {
    fn drop(&mut self) {
        // SAFETY: null or a handle from nbrdf_sampler_create.
        unsafe { nbrdf_sampler_free(self.0) }
    }
}

/// `nbrdf_sampler_create` without a material: the status and the handle.
fn create(params: &NbrdfSamplerParams) -> (i32, Sampler) {
    let mut out = std::ptr::null_mut();
    // SAFETY: valid pointers.
    let status = unsafe { nbrdf_sampler_create(std::ptr::null(), params, &mut out) };
    (status, Sampler(out))
}

/// Pdfs of a fixed set of direction pairs under `sampler`, with the status.
fn pdfs(sampler: &Sampler) -> (i32, Vec<f32>) {
    let n = 4;
    let view = [
        0.0, 0.3, -0.2, 0.5, 0.0, 0.1, 0.2, 0.0, 1.0, 0.95, 0.97, 0.86,
    ];
    let light = [
        0.0, -0.3, 0.2, 0.1, 0.0, -0.1, -0.2, 0.3, 1.0, 0.95, 0.97, 0.95,
    ];
    let mut out = vec![-7.0f32; n];
    // SAFETY: the arrays hold 3 n and n floats and do not overlap.
    let status = unsafe {
        nbrdf_sampler_pdf(
            sampler.0,
            view.as_ptr(),
            light.as_ptr(),
            n,
            out.as_mut_ptr(),
        )
    };
    (status, out)
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(128))]

    #[test]
    fn rejected_updates_leave_the_last_valid_sampler(
        updates in prop::collection::vec(any_sampler(), 1..24)
    ) {
        let mut state = create(&NbrdfSamplerParams::cosine()).1;
        let mut expected = pdfs(&state).1;
        for update in updates {
            let (status, sampler) = create(&update);
            prop_assert_eq!(status == OK, core_accepts(&update), "{:?}", update);
            if status == OK {
                state = sampler;
                let (s, values) = pdfs(&state);
                prop_assert_eq!(s, OK);
                prop_assert!(values.iter().all(|p| p.is_finite() && *p >= 0.0), "{:?}", values);
                expected = values;
            } else {
                prop_assert_eq!(status, INVALID);
                prop_assert!(sampler.0.is_null(), "a refused sampler has a handle");
            }
            // The kept sampler still gives what it gave when it was accepted.
            prop_assert_eq!(pdfs(&state), (OK, expected.clone()));
        }
    }
}
