//! The learning rate within a run: constant, or a short linear warm-up followed by a half cosine
//! down to a small fraction of the rate at the last epoch (docs/design.md section 5).
//!
//! The rate is recomputed before every mini-batch from the fraction of the run done, so it
//! depends on nothing but the settings (not on the thread count either).

use std::f64::consts::PI;

/// How the Adam learning rate moves over a run of `max_epochs` epochs (drops on plateaus,
/// [`super::TrainConfig::lr_decays`], multiply on top of it).
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum LrSchedule {
    /// The configured rate throughout (the paper's recipe and the 0.2 defaults).
    Constant,
    /// From 0 up to the configured rate linearly over the first `warmup_epochs`, then a half
    /// cosine down to `final_fraction` times the rate at `max_epochs`.
    Cosine {
        warmup_epochs: f64,
        final_fraction: f64,
    },
}

impl LrSchedule {
    /// The schedule of the defaults: one epoch of warm-up (Adam's first steps, with its second
    /// moment still tiny, otherwise overshoot at twice the old rate), down to 1 % at the end.
    pub const COSINE: LrSchedule = LrSchedule::Cosine {
        warmup_epochs: 1.0,
        final_fraction: 0.01,
    };

    /// The factor of the configured rate after `done` epochs (fractional: batches count) of a
    /// run of `max_epochs`. Exactly 1 for [`LrSchedule::Constant`].
    pub fn factor(self, done: f64, max_epochs: usize) -> f32 {
        match self {
            LrSchedule::Constant => 1.0,
            LrSchedule::Cosine {
                warmup_epochs,
                final_fraction,
            } => {
                let total = max_epochs as f64;
                if done < warmup_epochs {
                    // The first batch must move: count it as done.
                    return ((done + 1e-3).max(0.0) / warmup_epochs).min(1.0) as f32;
                }
                let decay = (total - warmup_epochs).max(1e-9);
                let t = ((done - warmup_epochs) / decay).clamp(0.0, 1.0);
                (final_fraction + (1.0 - final_fraction) * 0.5 * (1.0 + (PI * t).cos())) as f32
            }
        }
    }

    /// Whether the settings can run: a warm-up of at least 0 epochs, a final fraction in
    /// `(0, 1]`.
    pub fn is_valid(self) -> bool {
        match self {
            LrSchedule::Constant => true,
            LrSchedule::Cosine {
                warmup_epochs,
                final_fraction,
            } => {
                warmup_epochs.is_finite()
                    && warmup_epochs >= 0.0
                    && final_fraction > 0.0
                    && final_fraction <= 1.0
            }
        }
    }

    /// The name written in a network's provenance.
    pub fn describe(self) -> String {
        match self {
            LrSchedule::Constant => "constant".into(),
            LrSchedule::Cosine {
                warmup_epochs,
                final_fraction,
            } => format!("cosine (warm-up {warmup_epochs} epochs, down to {final_fraction})"),
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The closed form, at the points where it is known exactly.
    #[test]
    fn cosine_warms_up_then_falls_to_the_final_fraction() {
        let s = LrSchedule::Cosine {
            warmup_epochs: 2.0,
            final_fraction: 0.1,
        };
        let f = |done: f64| f64::from(s.factor(done, 102));
        assert!(
            f(0.0) > 0.0 && f(0.0) < 1e-3,
            "the first batch moves, barely"
        );
        assert!((f(1.0) - 0.5).abs() < 1e-3);
        assert!((f(2.0) - 1.0).abs() < 1e-6);
        // Halfway through the decay the cosine is 0: the mean of 1 and the final fraction.
        assert!((f(52.0) - 0.55).abs() < 1e-6);
        assert!((f(102.0) - 0.1).abs() < 1e-6);
        assert!(
            (f(500.0) - 0.1).abs() < 1e-6,
            "past the end it stays at the floor"
        );
        let mut last = f(2.0);
        for k in 3..=102 {
            assert!(f(k as f64) <= last, "monotone after the warm-up");
            last = f(k as f64);
        }
    }

    #[test]
    fn constant_is_exactly_one_and_bad_settings_are_refused() {
        assert_eq!(LrSchedule::Constant.factor(17.3, 20), 1.0);
        assert!(LrSchedule::COSINE.is_valid() && LrSchedule::Constant.is_valid());
        for (warmup_epochs, final_fraction) in
            [(-1.0, 0.1), (1.0, 0.0), (1.0, 1.5), (f64::NAN, 0.1)]
        {
            let s = LrSchedule::Cosine {
                warmup_epochs,
                final_fraction,
            };
            assert!(!s.is_valid(), "{s:?}");
        }
    }
}
