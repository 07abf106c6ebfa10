//! Sampling lobes for every texel without a lobe fit per texel: the baked codes are clustered
//! into at most `K` representatives (k-means, deterministic), a Blinn-Phong lobe (or two) is fitted
//! to the decoder at each representative code with the homogeneous lobe fitter, and each texel
//! takes its nearest representative's lobe. Sampling reads the stored lobe channels, so the pdf
//! stays the exact density of what is sampled; only the variance depends on how well a lobe
//! suits its texels.

use crate::coords::{from_rusinkiewicz, network_input_for};
use crate::error::Result;
use crate::fastmath::Unfused;
use crate::fit::lobes::{fit_lobe, fit_two_lobes, LobeFitConfig};
use crate::textured::Decoder;
use rayon::prelude::*;

/// The most representatives of a bake.
pub const MAX_REPRESENTATIVES: usize = 256;
/// At most this many codes (evenly strided over the texels) are clustered; every texel is then
/// assigned to its nearest representative.
pub const MAX_CLUSTERED_CODES: usize = 1 << 16;
/// Lloyd iterations at most (they stop earlier once no assignment changes).
const MAX_ITERATIONS: usize = 30;

/// Representative codes of `codes` (`channels` values each): at most `k`, fewer when there are
/// fewer distinct codes. Farthest-point initialisation from the code nearest the mean, then
/// Lloyd iterations; no randomness, so the result depends on the codes only.
pub(crate) fn representatives(
    codes: &[f32],
    channels: usize,
    k: usize,
    progress: &mut dyn FnMut(usize, usize),
) -> Vec<Vec<f32>> {
    let texels = codes.len() / channels;
    let stride = texels.div_ceil(MAX_CLUSTERED_CODES).max(1);
    let points: Vec<&[f32]> = (0..texels)
        .step_by(stride)
        .map(|t| &codes[t * channels..(t + 1) * channels])
        .collect();
    let mean = mean_of(points.iter().copied(), channels);
    let first = nearest(&points, &mean).0;
    let mut centres = vec![points[first].to_vec()];
    let mut distance: Vec<f64> = points.par_iter().map(|p| squared(p, &centres[0])).collect();
    while centres.len() < k {
        let (far, &d) = distance
            .iter()
            .enumerate()
            .fold((0, &0.0), |a, b| if b.1 > a.1 { b } else { a });
        if d <= 0.0 {
            break;
        }
        let centre = points[far].to_vec();
        distance
            .par_iter_mut()
            .zip(&points)
            .for_each(|(d, p)| *d = d.min(squared(p, &centre)));
        centres.push(centre);
    }
    let mut assignment = vec![usize::MAX; points.len()];
    for iteration in 0..MAX_ITERATIONS {
        progress(iteration + 1, MAX_ITERATIONS);
        let next = assign(&points, &centres);
        if next == assignment {
            break;
        }
        assignment = next;
        update_centres(&points, &assignment, &mut centres);
    }
    centres
}

/// Each centre moved to the mean of its points (float64, in point order); a centre without
/// points stays where it was.
fn update_centres(points: &[&[f32]], assignment: &[usize], centres: &mut [Vec<f32>]) {
    let channels = centres[0].len();
    let mut sums = vec![0.0f64; centres.len() * channels];
    let mut counts = vec![0usize; centres.len()];
    for (p, &a) in points.iter().zip(assignment) {
        counts[a] += 1;
        for (s, &v) in sums[a * channels..].iter_mut().zip(p.iter()) {
            *s += f64::from(v);
        }
    }
    for ((centre, sum), &count) in centres.iter_mut().zip(sums.chunks(channels)).zip(&counts) {
        if count > 0 {
            for (c, s) in centre.iter_mut().zip(sum) {
                *c = (s / count as f64) as f32;
            }
        }
    }
}

/// Mean of equally long rows, accumulated in float64 in order.
fn mean_of<'a>(rows: impl Iterator<Item = &'a [f32]>, channels: usize) -> Vec<f32> {
    let mut sum = vec![0.0f64; channels];
    let mut n = 0usize;
    for row in rows {
        for (s, &v) in sum.iter_mut().zip(row) {
            *s += f64::from(v);
        }
        n += 1;
    }
    sum.iter().map(|s| (s / n.max(1) as f64) as f32).collect()
}

fn squared(a: &[f32], b: &[f32]) -> f64 {
    a.iter()
        .zip(b)
        .map(|(&x, &y)| (f64::from(x) - f64::from(y)).powi(2))
        .sum()
}

/// The nearest centre of `code` and its squared distance (ties: the first).
pub(crate) fn nearest(centres: &[&[f32]], code: &[f32]) -> (usize, f64) {
    centres
        .iter()
        .enumerate()
        .map(|(i, c)| (i, squared(code, c)))
        .fold((0, f64::INFINITY), |a, b| if b.1 < a.1 { b } else { a })
}

/// The nearest centre of every point, on all cores.
pub(crate) fn assign(points: &[&[f32]], centres: &[Vec<f32>]) -> Vec<usize> {
    let centres: Vec<&[f32]> = centres.iter().map(Vec::as_slice).collect();
    points.par_iter().map(|p| nearest(&centres, p).0).collect()
}

/// The lobe parameters of a representative, in texture order (`[n, w]` or `[n1, w1, n2, w2]`,
/// exponents not yet encoded).
pub(crate) fn fit_lobes(
    decoder: &Decoder,
    code: &[f32],
    lobes: usize,
    config: &LobeFitConfig,
) -> Result<Vec<f64>> {
    let target = |angles: &crate::coords::RusinkiewiczAngles| {
        let (view, light) = from_rusinkiewicz(angles);
        let features = network_input_for(decoder.anisotropic(), view.as_vec3(), light.as_vec3());
        Some(decoder.forward::<Unfused>(&features, code).map(f64::from))
    };
    Ok(match lobes {
        1 => {
            let fit = fit_lobe(&target, config)?;
            vec![fit.exponent, fit.specular_weight]
        }
        _ => {
            let fit = fit_two_lobes(&target, config)?;
            vec![
                fit.exponents[0],
                fit.weights[0],
                fit.exponents[1],
                fit.weights[1],
            ]
        }
    })
}
