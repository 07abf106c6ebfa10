//! Training samples: angular sampling of light/view pairs, their network inputs and the
//! log-space targets (docs/design.md section 5).
//!
//! * Adaptive: `theta_h, theta_d ~ U[0, pi/2]`, `phi_d ~ U[0, 2 pi)`, `phi_h = 0`, uniform in
//!   the angles, which puts many samples near the specular peak (`theta_h` small). For an
//!   anisotropic network `phi_h ~ U[-pi, pi)` as well (the fourth uniform), so all four angles
//!   are covered.
//! * Uniform: light and view each uniform over the hemisphere (all four angles already vary).
//!
//! Sample inputs are [`crate::coords::network_input_for`] of the network's kind.
//!
//! A candidate is dropped when the light or the view is at or below the horizon (the BRDF is 0
//! there and `cos_light` would be 0) or when the target function reports invalid data; candidates
//! are drawn until `count` samples are kept. Candidate `k` always uses the same uniforms
//! (counter-based [`SplitMix64`]), and blocks of candidates are merged in order, so the data set
//! depends on the seed only, not on the thread count.

use crate::coords::{from_rusinkiewicz, to_rusinkiewicz, RusinkiewiczAngles};
use crate::error::{NbrdfError, Result};
use crate::network::{INPUTS, OUTPUTS};
use crate::rng::{SplitMix64, Stream};
use glam::{DVec3, Vec3};
use rayon::prelude::*;
use std::f64::consts::{FRAC_PI_2, PI};
use std::fmt;
use std::str::FromStr;

/// How light/view pairs are drawn.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Default)]
pub enum AngularSampling {
    #[default]
    Adaptive,
    Uniform,
}

impl AngularSampling {
    pub fn as_str(self) -> &'static str {
        match self {
            AngularSampling::Adaptive => "adaptive",
            AngularSampling::Uniform => "uniform",
        }
    }
}

impl fmt::Display for AngularSampling {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(self.as_str())
    }
}

impl FromStr for AngularSampling {
    type Err = NbrdfError;

    fn from_str(s: &str) -> Result<Self> {
        match s {
            "adaptive" => Ok(AngularSampling::Adaptive),
            "uniform" => Ok(AngularSampling::Uniform),
            other => Err(NbrdfError::InvalidArgument(format!(
                "unknown sampling '{other}' (expected 'adaptive' or 'uniform')"
            ))),
        }
    }
}

/// The reflectance to learn: `f_r` in linear RGB at a set of angles, or `None` where the data is
/// invalid (such points never become samples).
pub type TargetFn<'a> = dyn Fn(&RusinkiewiczAngles) -> Option<[f64; 3]> + Sync + 'a;

/// One training sample, 40 bytes, so that a shuffled gather touches one or two cache lines.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
#[repr(C)]
pub struct Sample {
    /// Network input [`crate::coords::network_input_for`] of the `f32` directions.
    pub x: [f32; INPUTS],
    /// `ln(1 + f_r cos_light)` per channel.
    pub log_target: [f32; OUTPUTS],
    /// `cos(theta_light)`, in `(0, 1]`.
    pub cos_light: f32,
}

/// A set of samples and what was dropped while drawing it.
#[derive(Clone, Debug, Default)]
pub struct DataSet {
    pub samples: Vec<Sample>,
    /// Candidates drawn, kept or not.
    pub candidates: u64,
    pub below_horizon: u64,
    pub invalid: u64,
}

/// `out = [samples[i] for i in order]`, in parallel pieces of `piece` samples (the result does
/// not depend on the threads or the piece). A tight loop of independent loads keeps many cache
/// misses in flight at once.
pub fn gather<T: Copy + Default + Send + Sync>(
    samples: &[T],
    order: &[u32],
    out: &mut Vec<T>,
    piece: usize,
) {
    out.resize(order.len(), T::default());
    out.par_chunks_mut(piece)
        .zip(order.par_chunks(piece))
        .for_each(|(out, order)| {
            for (o, &i) in out.iter_mut().zip(order) {
                *o = samples[i as usize];
            }
        });
}

/// Why a candidate was not kept.
#[derive(Clone, Copy, PartialEq, Eq)]
enum Outcome {
    Kept,
    BelowHorizon,
    Invalid,
}

const BLOCK: u64 = 8192;
const BLOCKS_PER_ROUND: u64 = 16;
/// Give up when fewer than one candidate in this many is kept: the target is almost all invalid.
const MAX_CANDIDATES_PER_SAMPLE: u64 = 64;

/// Draws `count` samples of `target` from stream `stream` of `seed`.
pub fn draw(
    target: &TargetFn<'_>,
    sampling: AngularSampling,
    anisotropic: bool,
    count: usize,
    seed: u64,
    stream: Stream,
) -> Result<DataSet> {
    let mut set = DataSet {
        samples: Vec::with_capacity(count),
        ..DataSet::default()
    };
    let limit = MAX_CANDIDATES_PER_SAMPLE * count as u64 + 16 * BLOCK;
    let mut next_block = 0u64;
    while set.samples.len() < count {
        if set.candidates >= limit {
            return Err(NbrdfError::InvalidArgument(format!(
                "only {} of {} candidate directions have valid data (wanted {count} samples): \
                 is the table mostly unmeasured?",
                set.samples.len(),
                set.candidates
            )));
        }
        let blocks: Vec<(Vec<Sample>, Vec<Outcome>)> = (next_block..next_block + BLOCKS_PER_ROUND)
            .into_par_iter()
            .map(|b| draw_block(target, sampling, anisotropic, seed, stream, b))
            .collect();
        next_block += BLOCKS_PER_ROUND;
        for (samples, outcomes) in blocks {
            let mut kept = samples.into_iter();
            for outcome in outcomes {
                if set.samples.len() == count {
                    break;
                }
                set.candidates += 1;
                match outcome {
                    Outcome::Kept => set.samples.extend(kept.next()),
                    Outcome::BelowHorizon => set.below_horizon += 1,
                    Outcome::Invalid => set.invalid += 1,
                }
            }
        }
    }
    Ok(set)
}

fn draw_block(
    target: &TargetFn<'_>,
    sampling: AngularSampling,
    anisotropic: bool,
    seed: u64,
    stream: Stream,
    block: u64,
) -> (Vec<Sample>, Vec<Outcome>) {
    let mut samples = Vec::with_capacity(BLOCK as usize);
    let mut outcomes = Vec::with_capacity(BLOCK as usize);
    for k in block * BLOCK..(block + 1) * BLOCK {
        let u = candidate_uniforms(seed, stream, k);
        let outcome = match candidate(target, sampling, anisotropic, u) {
            Ok(sample) => {
                samples.push(sample);
                Outcome::Kept
            }
            Err(reason) => reason,
        };
        outcomes.push(outcome);
    }
    (samples, outcomes)
}

/// The view/light pair and angles of four uniforms; `anisotropic` draws `phi_h` too (adaptive
/// sampling; uniform sampling covers it anyway).
pub fn directions(
    sampling: AngularSampling,
    anisotropic: bool,
    u: [f64; 4],
) -> (DVec3, DVec3, RusinkiewiczAngles) {
    match sampling {
        AngularSampling::Adaptive => {
            let angles = RusinkiewiczAngles {
                theta_h: u[0] * FRAC_PI_2,
                phi_h: if anisotropic {
                    (2.0 * u[3] - 1.0) * PI
                } else {
                    0.0
                },
                theta_d: u[1] * FRAC_PI_2,
                phi_d: u[2] * 2.0 * PI,
            };
            let (view, light) = from_rusinkiewicz(&angles);
            (view, light, angles)
        }
        AngularSampling::Uniform => {
            let light = uniform_hemisphere(u[0], u[1]);
            let view = uniform_hemisphere(u[2], u[3]);
            (view, light, to_rusinkiewicz(view, light))
        }
    }
}

/// Uniform on the upper hemisphere: `cos theta` is uniform (Archimedes). Not
/// [`crate::sampling::uniform_hemisphere`]: that one rounds `sin theta` differently, and a seed's
/// training samples must not change.
fn uniform_hemisphere(u_cos: f64, u_phi: f64) -> DVec3 {
    let cos = u_cos;
    let sin = (1.0 - cos * cos).max(0.0).sqrt();
    let (s, c) = (2.0 * PI * u_phi).sin_cos();
    DVec3::new(sin * c, sin * s, cos)
}

/// The `f32` view and light of candidate uniforms `u` with their angles, or `None` when either
/// is at or below the horizon: the f32 directions are what a renderer hands the network, so
/// they decide the horizon.
fn candidate_directions(
    sampling: AngularSampling,
    anisotropic: bool,
    u: [f64; 4],
) -> Option<(Vec3, Vec3, RusinkiewiczAngles)> {
    let (view, light, angles) = directions(sampling, anisotropic, u);
    let (v, l) = (view.as_vec3(), light.as_vec3());
    (l.z > 0.0 && v.z > 0.0).then_some((v, l, angles))
}

/// The uniforms of candidate `k` of stream `stream` of `seed`.
fn candidate_uniforms(seed: u64, stream: Stream, k: u64) -> [f64; 4] {
    let mut rng = SplitMix64::new(seed, stream, 4 * k);
    [
        rng.next_f64(),
        rng.next_f64(),
        rng.next_f64(),
        rng.next_f64(),
    ]
}

fn candidate(
    target: &TargetFn<'_>,
    sampling: AngularSampling,
    anisotropic: bool,
    u: [f64; 4],
) -> std::result::Result<Sample, Outcome> {
    let (v, l, angles) =
        candidate_directions(sampling, anisotropic, u).ok_or(Outcome::BelowHorizon)?;
    let f = target(&angles).ok_or(Outcome::Invalid)?;
    if !f.iter().all(|c| c.is_finite() && *c >= 0.0) {
        return Err(Outcome::Invalid);
    }
    let cos_light = l.z;
    Ok(sample(anisotropic, v, l, f.map(|c| c * cos_light as f64)))
}

/// The sample of a view/light pair above the horizon and its `f_r cos_light` (finite, >= 0),
/// with the network input of an isotropic or anisotropic network.
pub fn sample(anisotropic: bool, view: Vec3, light: Vec3, f_cos_light: [f64; 3]) -> Sample {
    Sample {
        x: crate::coords::network_input_for(anisotropic, view, light),
        log_target: f_cos_light.map(|c| c.ln_1p() as f32),
        cos_light: light.z,
    }
}

/// The `(view, light)` pairs that [`draw`] would make samples of, for a target valid
/// everywhere: the first `count` candidates of stream `stream` of `seed` above the horizon, in
/// order (`anisotropic` draws `phi_h` too, as [`draw`] does). A caller that evaluates its own
/// reflectance at them (the distiller, [`crate::train::arrays`]) trains on the trainer's own
/// sampling.
pub fn draw_directions(
    sampling: AngularSampling,
    anisotropic: bool,
    count: usize,
    seed: u64,
    stream: Stream,
) -> Vec<(Vec3, Vec3)> {
    draw_directions_where(sampling, anisotropic, count, seed, stream, |_, _| true)
}

/// [`draw_directions`] for a target valid only where `keep(view, light)`: the pairs [`draw`]
/// keeps for a target that is `None` exactly where `keep` is false (e.g. the RGL reciprocal
/// mean at grazing angles), so that dropped pairs are replaced by the next candidates.
/// `keep` must hold for a good share of the hemisphere (the caller's to ensure).
pub fn draw_directions_where(
    sampling: AngularSampling,
    anisotropic: bool,
    count: usize,
    seed: u64,
    stream: Stream,
    keep: impl Fn(Vec3, Vec3) -> bool,
) -> Vec<(Vec3, Vec3)> {
    let mut pairs = Vec::with_capacity(count);
    let mut k = 0u64;
    while pairs.len() < count {
        let u = candidate_uniforms(seed, stream, k);
        if let Some((v, l, _)) = candidate_directions(sampling, anisotropic, u) {
            if keep(v, l) {
                pairs.push((v, l));
            }
        }
        k += 1;
    }
    pairs
}

#[cfg(test)]
mod tests {
    use super::*;

    fn constant(a: &RusinkiewiczAngles) -> Option<[f64; 3]> {
        // Invalid for grazing difference angles, like unmeasured MERL cells.
        (a.theta_d < 1.2).then_some([0.1, 0.2, 0.3])
    }

    #[test]
    fn keeps_only_valid_samples_above_the_horizon() {
        for sampling in [AngularSampling::Adaptive, AngularSampling::Uniform] {
            let set = draw(&constant, sampling, false, 5000, 3, Stream::TrainSamples).unwrap();
            assert_eq!(set.samples.len(), 5000);
            assert_eq!(set.candidates, 5000 + set.below_horizon + set.invalid);
            assert!(set.invalid > 0, "{sampling}");
            // Uniform hemisphere directions are above the horizon by construction.
            assert_eq!(
                set.below_horizon > 0,
                sampling == AngularSampling::Adaptive,
                "{sampling}"
            );
            for s in &set.samples {
                assert!(s.cos_light > 0.0 && s.cos_light <= 1.0);
                let expect = (0.1 * s.cos_light as f64).ln_1p() as f32;
                assert!((s.log_target[0] - expect).abs() < 1e-7);
                // theta_d = acos(d.z) must be below the invalid region.
                assert!(s.x[5] >= (1.2f32).cos() - 1e-4);
            }
        }
    }

    /// Anisotropic draws cover phi_h uniformly (the input's `x[1] = sin th sin ph` takes both
    /// signs, `atan2(x1, x0)` spreads over all four quadrants); isotropic ones keep `x[1] = 0`.
    #[test]
    fn anisotropic_draws_cover_phi_h() {
        for sampling in [AngularSampling::Adaptive, AngularSampling::Uniform] {
            let iso = draw(&constant, sampling, false, 2000, 5, Stream::TrainSamples).unwrap();
            assert!(iso.samples.iter().all(|s| s.x[1] == 0.0 && s.x[0] >= 0.0));
            let aniso = draw(&constant, sampling, true, 4000, 5, Stream::TrainSamples).unwrap();
            let mut quadrants = [0usize; 4];
            for s in &aniso.samples {
                let phi = s.x[1].atan2(s.x[0]);
                let q = ((phi + std::f32::consts::PI) / std::f32::consts::FRAC_PI_2) as usize;
                quadrants[q.min(3)] += 1;
            }
            assert!(
                quadrants.iter().all(|&q| q > 800 && q < 1200),
                "{sampling}: {quadrants:?}"
            );
        }
    }

    #[test]
    fn fails_clearly_when_nothing_is_valid() {
        let err = draw(
            &|_: &RusinkiewiczAngles| None,
            AngularSampling::Adaptive,
            false,
            10,
            0,
            Stream::TrainSamples,
        )
        .unwrap_err();
        assert!(err.to_string().contains("valid data"), "{err}");
    }

    #[test]
    fn adaptive_sampling_is_uniform_in_theta_h() {
        let set = draw(
            &constant,
            AngularSampling::Adaptive,
            false,
            4000,
            9,
            Stream::TrainSamples,
        )
        .unwrap();
        // Before the horizon cut theta_h is uniform; near the pole few samples are cut, so about
        // 2/9 of the kept samples have theta_h < 20 degrees, far more than uniform sampling gives.
        let near = set
            .samples
            .iter()
            .filter(|s| s.x[2] > 20f32.to_radians().cos())
            .count();
        assert!(near as f64 > 0.15 * 4000.0, "{near}");
    }
}
