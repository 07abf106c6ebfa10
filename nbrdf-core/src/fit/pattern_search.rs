//! Pattern search with halving steps: the refinement after the grids of the lobe fits
//! ([`crate::fit::lobes`]'s two lobes, [`crate::fit::anisotropic`]), generic over the lobe
//! parameters.

use rayon::prelude::*;

/// A point of the search: its score (lower is better), the parameters scored, and the
/// coordinates the next moves start from.
#[derive(Clone, Copy, Debug, PartialEq)]
pub(crate) struct SearchPoint<P, const D: usize> {
    pub score: f64,
    pub params: P,
    pub x: [f64; D],
}

/// A pattern search over `D` coordinates.
pub(crate) struct PatternSearch<const D: usize> {
    /// Moves as multiples of the steps, tried in this order (a tie goes to the first).
    pub moves: Vec<[f64; D]>,
    /// Steps of the coordinates at the first level; halved after each level.
    pub steps: [f64; D],
    pub levels: usize,
    /// Accepted moves per level at most (`usize::MAX`: until no move improves).
    pub max_passes: usize,
}

impl<const D: usize> PatternSearch<D> {
    /// `-1` and `+1` along each coordinate in turn.
    pub fn axis_moves() -> Vec<[f64; D]> {
        (0..D)
            .flat_map(|k| {
                [-1.0, 1.0].map(|sign| {
                    let mut m = [0.0; D];
                    m[k] = sign;
                    m
                })
            })
            .collect()
    }

    /// From `start`, moves to the lowest-scoring neighbour `x + move * steps` as long as it
    /// scores lower than the current point, then halves the steps. `candidate` turns moved
    /// coordinates into parameters and the coordinates to continue from (`None` outside the
    /// domain); scores that are not finite are never accepted.
    pub fn minimise<P: Send>(
        &self,
        start: SearchPoint<P, D>,
        candidate: impl Fn([f64; D]) -> Option<(P, [f64; D])>,
        score: impl Fn(&P) -> f64 + Sync,
    ) -> SearchPoint<P, D> {
        let mut current = start;
        let mut steps = self.steps;
        for _ in 0..self.levels {
            for _ in 0..self.max_passes {
                let moved: Vec<(P, [f64; D])> = self
                    .moves
                    .iter()
                    .filter_map(|m| {
                        let mut y = current.x;
                        for k in 0..D {
                            y[k] += m[k] * steps[k];
                        }
                        candidate(y)
                    })
                    .collect();
                let found = moved
                    .into_par_iter()
                    .map(|(params, x)| SearchPoint {
                        score: score(&params),
                        params,
                        x,
                    })
                    .filter(|p| p.score.is_finite())
                    .reduce_with(|a, b| if b.score < a.score { b } else { a });
                match found {
                    Some(p) if p.score < current.score => current = p,
                    _ => break,
                }
            }
            steps = steps.map(|s| s * 0.5);
        }
        current
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A convex quadratic with its minimum off the grid of the first steps; the search ends
    /// within the last step of it.
    #[test]
    fn finds_the_minimum_of_a_quadratic_within_the_last_step() {
        let search = PatternSearch::<2> {
            moves: PatternSearch::<2>::axis_moves(),
            steps: [0.5, 0.5],
            levels: 10,
            max_passes: usize::MAX,
        };
        let f = |p: &[f64; 2]| (p[0] - 0.3).powi(2) + 2.0 * (p[1] + 1.7).powi(2);
        let end = search.minimise(
            SearchPoint {
                score: f(&[0.0, 0.0]),
                params: [0.0, 0.0],
                x: [0.0, 0.0],
            },
            |y| Some((y, y)),
            f,
        );
        let last_step = 0.5 * 0.5f64.powi(9);
        assert!((end.x[0] - 0.3).abs() <= last_step, "{end:?}");
        assert!((end.x[1] + 1.7).abs() <= last_step, "{end:?}");
    }

    /// Moves outside the domain are not scored, non-finite scores are not accepted, and a
    /// limit on passes stops a level early.
    #[test]
    fn respects_the_domain_and_the_pass_limit() {
        let search = PatternSearch::<1> {
            moves: PatternSearch::<1>::axis_moves(),
            steps: [1.0],
            levels: 1,
            max_passes: 3,
        };
        let start = SearchPoint {
            score: 0.0,
            params: 0.0,
            x: [0.0],
        };
        // Lower to the right forever: three passes reach 3.
        let end = search.minimise(start, |y| Some((y[0], y)), |&p| -p);
        assert_eq!(end.x, [3.0]);
        // The domain stops it at 1; beyond, the score is NaN (never accepted).
        let end = search.minimise(start, |y| (y[0] <= 1.0).then_some((y[0], y)), |&p| -p);
        assert_eq!(end.x, [1.0]);
        let end = search.minimise(
            start,
            |y| Some((y[0], y)),
            |&p| if p > 0.0 { f64::NAN } else { -p },
        );
        assert_eq!(end.x, [0.0]);
    }
}
