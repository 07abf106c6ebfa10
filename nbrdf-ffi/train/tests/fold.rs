//! `nbrdf_train_directions`' fold argument: the reciprocal mean's pairs are the core's
//! `sample_directions_for(config, ReciprocalMean)`, none of them left out by the fold, so a
//! reciprocal distillation trains on the full sample count; an unknown fold is an error.

use glam::Vec3;
use nbrdf_core::source::RglFold;
use nbrdf_core::train::arrays::sample_directions_for;
use nbrdf_core::train::dataset::AngularSampling;
use nbrdf_core::train::TrainConfig;
use nbrdf_train::*;

mod common;
use common::{directions_for, last_error, planar_pairs, small_config, INVALID};

const AS_GIVEN: i32 = NbrdfTrainFold::NBRDF_TRAIN_FOLD_AS_GIVEN as i32;
const RECIPROCAL: i32 = NbrdfTrainFold::NBRDF_TRAIN_FOLD_RECIPROCAL_MEAN as i32;
/// Uniform sampling puts about 2 % of the pairs below the reciprocal mean's cosine cut.
const SAMPLES: usize = 3000;

/// The C config of the test, uniform sampling.
fn c_config() -> NbrdfTrainConfig {
    NbrdfTrainConfig {
        sampling: NbrdfTrainSampling::NBRDF_TRAIN_SAMPLING_UNIFORM as i32,
        samples: SAMPLES,
        ..small_config()
    }
}

/// The same settings written for the core directly, not through the library's conversion.
fn core_config() -> TrainConfig {
    TrainConfig {
        sampling: AngularSampling::Uniform,
        samples: SAMPLES,
        ..TrainConfig::default()
    }
}

fn left_out(pairs: &[(Vec3, Vec3)]) -> usize {
    pairs
        .iter()
        .filter(|(v, l)| !RglFold::ReciprocalMean.trains_on(f64::from(v.z), f64::from(l.z)))
        .count()
}

#[test]
fn reciprocal_pairs_are_the_cores_and_none_is_left_out() {
    let (view, light, n, n_validation) = directions_for(&c_config(), RECIPROCAL);
    let pairs = planar_pairs(&view, &light, n);
    let (expected, expected_validation) =
        sample_directions_for(&core_config(), RglFold::ReciprocalMean).unwrap();
    assert_eq!((n, n_validation), (SAMPLES + 300, 300));
    assert_eq!(
        (pairs.len(), n_validation),
        (expected.len(), expected_validation)
    );
    assert!(pairs == expected, "the C pairs differ from the core's");
    assert_eq!(left_out(&pairs), 0);
}

#[test]
fn as_given_pairs_are_the_cores_and_some_would_be_left_out() {
    // What the reciprocal distillation drew before the fold argument: the fix is only visible
    // if the as-given pairs hold pairs the reciprocal mean leaves out.
    let (view, light, n, _) = directions_for(&c_config(), AS_GIVEN);
    let pairs = planar_pairs(&view, &light, n);
    let (expected, _) = sample_directions_for(&core_config(), RglFold::AsMeasured).unwrap();
    assert!(pairs == expected, "the C pairs differ from the core's");
    let dropped = left_out(&pairs);
    assert!(
        (n / 200..n / 20).contains(&dropped),
        "{dropped} of {n} pairs below the cosine cut"
    );
}

#[test]
fn an_unknown_fold_is_an_error_with_a_message() {
    let config = c_config();
    let (view, _, n, _) = directions_for(&config, AS_GIVEN);
    let (mut out_view, mut out_light) = (vec![0.0f32; view.len()], vec![0.0f32; view.len()]);
    for fold in [2, -1] {
        // SAFETY: 3 n writable floats each.
        let status = unsafe {
            nbrdf_train_directions(
                &config,
                fold,
                n,
                out_view.as_mut_ptr(),
                out_light.as_mut_ptr(),
            )
        };
        assert_eq!(status, INVALID);
        let message = last_error();
        assert!(
            message.contains("nbrdf_train_directions") && message.contains(&format!("fold {fold}")),
            "{message}"
        );
    }
    assert!(out_view.iter().chain(&out_light).all(|&x| x == 0.0));
}
