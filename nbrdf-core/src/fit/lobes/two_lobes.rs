//! The two-lobe search: `w1 phong(n1) + w2 phong(n2) + (1 - w1 - w2) cosine` on the one-lobe
//! search's quadrature, a coarse grid then a pattern search.

use super::one_lobe::ViewQuadrature;
use super::{LobeFit, LobeFitConfig, LobeQuadrature};
use crate::error::Result;
use crate::fit::pattern_search::{PatternSearch, SearchPoint};
use crate::sampling::{SamplingStrategy, MAX_EXPONENT};
use crate::train::dataset::TargetFn;
use rayon::prelude::*;
use std::f64::consts::FRAC_1_PI;

/// The two-lobe sampling mixture `w1 phong(n1) + w2 phong(n2) + (1 - w1 - w2) cosine` chosen
/// for the lowest mean relative variance on the same quadrature as the one-lobe search.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct TwoLobeFit {
    /// `[n1, n2]` with `n1 >= n2` (the sharp lobe first).
    pub exponents: [f64; 2],
    pub weights: [f64; 2],
    /// Mean `R - 1` with the two lobes; never above `one_lobe.relative_variance`.
    pub relative_variance: f64,
    /// The one-lobe search the two-lobe one starts from (its candidate with `w2 = 0`).
    pub one_lobe: LobeFit,
}

impl TwoLobeFit {
    /// The sampling strategy of this fit.
    pub fn strategy(&self) -> SamplingStrategy {
        SamplingStrategy::TwoLobe {
            exponent1: self.exponents[0],
            weight1: self.weights[0],
            exponent2: self.exponents[1],
            weight2: self.weights[1],
        }
    }
}

/// Exponents of the coarse two-lobe grid: 0 and `10^(k/4)` up to 1e5 (every other exponent of
/// the one-lobe grid).
fn two_lobe_grid_exponents() -> Vec<f64> {
    std::iter::once(0.0)
        .chain((0..=20).map(|k| 10f64.powf(k as f64 / 4.0)))
        .collect()
}

/// Weights of the coarse two-lobe grid (pairs with `w1 + w2 <= 1` are used).
const TWO_LOBE_GRID_WEIGHTS: [f64; 12] =
    [0.05, 0.1, 0.2, 0.3, 0.4, 0.5, 0.6, 0.7, 0.8, 0.9, 0.95, 1.0];

/// Halvings of the pattern search's steps after the grid.
const TWO_LOBE_REFINE_LEVELS: usize = 7;

/// Relative second moment `R` of a mixture of Blinn-Phong lobes `(n, w)` and cosine (weight
/// `1 - sum w`, at least 0) for a view: [`super::one_lobe::second_moment`] with more lobes.
/// Lobes of weight 0 are skipped, so a second lobe of weight 0 scores exactly as the one-lobe
/// mixture.
pub(super) fn mixture_second_moment(q: &ViewQuadrature, lobes: &[(f64, f64)]) -> f64 {
    let cosine_weight = (1.0 - lobes.iter().map(|l| l.1).sum::<f64>()).max(0.0);
    let t = &q.terms;
    t.relative_second_moment(|i| {
        let mut pdf = cosine_weight * t.cosine_pdf[i];
        for &(n, w) in lobes {
            if w > 0.0 {
                pdf += w * t.lobe_density(i, n, (n + 1.0) * 0.5 * FRAC_1_PI);
            }
        }
        pdf
    })
}

/// The light densities of one Blinn-Phong lobe at every quadrature point of a view.
fn lobe_densities(q: &ViewQuadrature, n: f64) -> Vec<f64> {
    let norm = (n + 1.0) * 0.5 * FRAC_1_PI;
    (0..q.terms.g2_dw.len())
        .map(|i| q.terms.lobe_density(i, n, norm))
        .collect()
}

/// A candidate of the two-lobe search: `(R - 1, [n1, n2], [w1, w2])`.
type TwoLobeCandidate = (f64, [f64; 2], [f64; 2]);

fn better(a: TwoLobeCandidate, b: TwoLobeCandidate) -> TwoLobeCandidate {
    if b.0 < a.0 {
        b
    } else {
        a
    }
}

impl LobeQuadrature {
    /// Mean relative variance `R - 1` over the views of the two-lobe mixture.
    pub fn two_lobe_relative_variance(&self, exponents: [f64; 2], weights: [f64; 2]) -> f64 {
        let lobes = [(exponents[0], weights[0]), (exponents[1], weights[1])];
        self.views
            .iter()
            .map(|q| mixture_second_moment(q, &lobes))
            .sum::<f64>()
            / self.views.len() as f64
            - 1.0
    }

    /// The best weights of the coarse grid for each exponent pair: the lobe densities are
    /// computed once per pair, the weights only rescale them.
    fn two_lobe_grid(&self) -> Option<TwoLobeCandidate> {
        let exponents = two_lobe_grid_exponents();
        let pairs: Vec<[f64; 2]> = exponents
            .iter()
            .enumerate()
            .flat_map(|(i, &n1)| exponents[..i].iter().map(move |&n2| [n1, n2]))
            .collect();
        let weight_pairs: Vec<[f64; 2]> = TWO_LOBE_GRID_WEIGHTS
            .iter()
            .flat_map(|&w1| TWO_LOBE_GRID_WEIGHTS.iter().map(move |&w2| [w1, w2]))
            .filter(|w| w[0] + w[1] <= 1.0 + 1e-12)
            .collect();
        pairs
            .par_iter()
            .map(|&pair| {
                let mut sums = vec![0.0; weight_pairs.len()];
                for q in &self.views {
                    let t = &q.terms;
                    if t.integral_sq <= 0.0 {
                        // R = 1 whatever the weights: skip the densities.
                        sums.iter_mut().for_each(|s| *s += 1.0);
                        continue;
                    }
                    let (d1, d2) = (lobe_densities(q, pair[0]), lobe_densities(q, pair[1]));
                    for (sum, w) in sums.iter_mut().zip(&weight_pairs) {
                        let cosine_weight = (1.0 - w[0] - w[1]).max(0.0);
                        *sum += t.relative_second_moment(|i| {
                            w[0] * d1[i] + w[1] * d2[i] + cosine_weight * t.cosine_pdf[i]
                        });
                    }
                }
                let views = self.views.len() as f64;
                sums.iter()
                    .zip(&weight_pairs)
                    .map(|(s, &w)| (s / views - 1.0, pair, w))
                    .filter(|c| c.0.is_finite())
                    .reduce(better)
            })
            .flatten()
            .reduce_with(better)
    }

    /// The two-lobe mixture of lowest mean relative variance: the one-lobe search of `config`
    /// (its lobe with `w2 = 0` is a candidate, so the result is never worse), a coarse grid over
    /// both exponents and weights, then a pattern search in `(log10(1 + n1), log10(1 + n2), w1,
    /// w2)` with halving steps from the better of the two.
    pub fn fit_two_lobes(&self, config: &LobeFitConfig) -> Result<TwoLobeFit> {
        let one_lobe = self.fit(config)?;
        let mut best: TwoLobeCandidate = (
            self.two_lobe_relative_variance(
                [one_lobe.exponent, 0.0],
                [one_lobe.specular_weight, 0.0],
            ),
            [one_lobe.exponent, 0.0],
            [one_lobe.specular_weight, 0.0],
        );
        if let Some(grid) = self.two_lobe_grid() {
            best = better(best, grid);
        }
        if best.0.is_finite() {
            best = self.refine_two_lobes(best);
        }
        let (mut relative_variance, mut exponents, mut weights) = best;
        if relative_variance.is_nan() || relative_variance > one_lobe.relative_variance {
            (relative_variance, exponents, weights) = (
                one_lobe.relative_variance,
                [one_lobe.exponent, 0.0],
                [one_lobe.specular_weight, 0.0],
            );
        }
        if exponents[1] > exponents[0] {
            exponents.swap(0, 1);
            weights.swap(0, 1);
        }
        Ok(TwoLobeFit {
            exponents,
            weights,
            relative_variance,
            one_lobe,
        })
    }

    /// Coordinate pattern search from `start` in `(log10(1 + n1), log10(1 + n2), w1, w2)`;
    /// moves stay in the valid domain.
    fn refine_two_lobes(&self, start: TwoLobeCandidate) -> TwoLobeCandidate {
        let to_t = |n: f64| (1.0 + n).log10();
        let to_n = |t: f64| (10f64.powf(t) - 1.0).clamp(0.0, MAX_EXPONENT);
        let t_max = to_t(MAX_EXPONENT);
        let search = PatternSearch {
            moves: PatternSearch::<4>::axis_moves(),
            steps: [0.125, 0.125, 0.025, 0.025],
            levels: TWO_LOBE_REFINE_LEVELS,
            // At most a few passes per level: each accepted move restarts the pass.
            max_passes: 8,
        };
        let start = SearchPoint {
            score: start.0,
            params: (start.1, start.2),
            x: [to_t(start.1[0]), to_t(start.1[1]), start.2[0], start.2[1]],
        };
        let in_domain = |y: &[f64; 4]| {
            (0.0..=t_max).contains(&y[0])
                && (0.0..=t_max).contains(&y[1])
                && y[2] >= 0.0
                && y[3] >= 0.0
                && y[2] + y[3] <= 1.0
        };
        let end = search.minimise(
            start,
            |y| in_domain(&y).then(|| (([to_n(y[0]), to_n(y[1])], [y[2], y[3]]), y)),
            |&(n, w)| self.two_lobe_relative_variance(n, w),
        );
        (end.score, end.params.0, end.params.1)
    }
}

/// Chooses the two-lobe mixture for `target` (a table or a network, `f_r` by Rusinkiewicz
/// angles).
pub fn fit_two_lobes(target: &TargetFn<'_>, config: &LobeFitConfig) -> Result<TwoLobeFit> {
    LobeQuadrature::new(target, config)?.fit_two_lobes(config)
}
