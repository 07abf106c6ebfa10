//! Adam (Kingma and Ba 2015), updating parameters in place.
//!
//! The update follows Keras/TensorFlow 2, which trained the authors' reference networks:
//! `lr_t = lr sqrt(1 - b2^t) / (1 - b1^t)`, `p -= lr_t m / (sqrt(v) + eps)` with the epsilon
//! added to the uncorrected `sqrt(v)` ("epsilon hat" of the paper's section 2) and Keras's
//! default `eps = 1e-7`.

#[derive(Clone, Copy, Debug, PartialEq)]
pub struct AdamConfig {
    pub learning_rate: f32,
    pub beta1: f32,
    pub beta2: f32,
    pub epsilon: f32,
}

impl Default for AdamConfig {
    fn default() -> Self {
        AdamConfig {
            learning_rate: 5e-4,
            beta1: 0.9,
            beta2: 0.999,
            epsilon: 1e-7,
        }
    }
}

/// Moment estimates of one parameter vector.
#[derive(Clone, Debug)]
pub struct Adam {
    pub config: AdamConfig,
    m: Vec<f32>,
    v: Vec<f32>,
    steps: u32,
}

impl Adam {
    pub fn new(config: AdamConfig, len: usize) -> Self {
        Adam {
            config,
            m: vec![0.0; len],
            v: vec![0.0; len],
            steps: 0,
        }
    }

    /// One update of `params` with gradient `grad` at learning rate `lr`.
    pub fn step(&mut self, params: &mut [f32], grad: &[f32], lr: f32) {
        self.steps += 1;
        let AdamConfig {
            beta1,
            beta2,
            epsilon,
            ..
        } = self.config;
        let t = self.steps as f64;
        let lr_t = (lr as f64 * (1.0 - (beta2 as f64).powf(t)).sqrt()
            / (1.0 - (beta1 as f64).powf(t))) as f32;
        for (((p, &g), m), v) in params
            .iter_mut()
            .zip(grad)
            .zip(&mut self.m)
            .zip(&mut self.v)
        {
            *m = beta1 * *m + (1.0 - beta1) * g;
            *v = beta2 * *v + (1.0 - beta2) * g * g;
            *p -= lr_t * *m / (v.sqrt() + epsilon);
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn first_step_moves_each_parameter_by_about_lr() {
        let mut adam = Adam::new(AdamConfig::default(), 3);
        let mut p = [1.0f32, 1.0, 1.0];
        adam.step(&mut p, &[0.3, -2.0, 0.0], 5e-4);
        assert!((p[0] - (1.0 - 5e-4)).abs() < 1e-6);
        assert!((p[1] - (1.0 + 5e-4)).abs() < 1e-6);
        assert_eq!(
            p[2], 1.0,
            "zero gradients must leave (padding) parameters untouched"
        );
    }

    #[test]
    fn minimises_a_quadratic() {
        let mut adam = Adam::new(AdamConfig::default(), 2);
        let mut p = [3.0f32, -2.0];
        for _ in 0..3000 {
            let g = [2.0 * (p[0] - 1.0), 2.0 * (p[1] + 0.5)];
            adam.step(&mut p, &g, 1e-2);
        }
        assert!(
            (p[0] - 1.0).abs() < 1e-2 && (p[1] + 0.5).abs() < 1e-2,
            "{p:?}"
        );
    }
}
