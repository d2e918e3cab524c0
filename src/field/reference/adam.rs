//! Adam with bias correction, element by element over the flat parameter buffer.
//!
//! At step t = 1, 2, … with gradient g (the GPU must compute exactly this, in f32):
//! ```text
//! m ← β₁ m + (1 − β₁) g
//! v ← β₂ v + (1 − β₂) g²
//! p ← p − lr · (m · c₁) / (√(v · c₂) + ε),   c₁ = 1/(1 − β₁^t), c₂ = 1/(1 − β₂^t)
//! ```
//! c₁ and c₂ are computed once per step in f64 and rounded to f32 (a kernel gets them as
//! uniforms). Every parameter is updated every step, also hash entries no ray touched
//! (their momentum keeps moving them, as in instant-ngp's plain Adam).
use crate::field::config::AdamConfig;

#[derive(Clone, Debug)]
pub struct Adam {
    pub config: AdamConfig,
    /// First and second moments, one per parameter.
    pub m: Vec<f32>,
    pub v: Vec<f32>,
    /// Steps taken so far (t of the last update).
    pub step: u32,
}

impl Adam {
    pub fn new(config: AdamConfig, parameter_count: usize) -> Adam {
        Adam {
            config,
            m: vec![0.0; parameter_count],
            v: vec![0.0; parameter_count],
            step: 0,
        }
    }

    /// (c₁, c₂) of step `t` (t ≥ 1).
    pub fn bias_corrections(&self, t: u32) -> (f32, f32) {
        let c1 = 1.0 / (1.0 - (self.config.beta1 as f64).powi(t as i32));
        let c2 = 1.0 / (1.0 - (self.config.beta2 as f64).powi(t as i32));
        (c1 as f32, c2 as f32)
    }

    /// One update of `params` (same length as the moments) with gradient `grad`.
    pub fn update(&mut self, params: &mut [f32], grad: &[f32], lr: f32) {
        self.step += 1;
        let (c1, c2) = self.bias_corrections(self.step);
        let AdamConfig {
            beta1, beta2, epsilon, ..
        } = self.config;
        for (((p, g), m), v) in params.iter_mut().zip(grad).zip(&mut self.m).zip(&mut self.v) {
            *m = beta1 * *m + (1.0 - beta1) * g;
            *v = beta2 * *v + (1.0 - beta2) * g * g;
            *p -= lr * (*m * c1) / ((*v * c2).sqrt() + epsilon);
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn first_step_moves_by_lr_against_the_gradient_sign() {
        // With bias correction, m̂ = g and v̂ = g² at t = 1: the step is lr·sign(g).
        let mut adam = Adam::new(AdamConfig::default(), 3);
        let mut p = [1.0f32, 1.0, 1.0];
        adam.update(&mut p, &[0.5, -2e-3, 0.0], 0.1);
        assert!(
            (p[0] - 0.9).abs() < 1e-6 && (p[1] - 1.1).abs() < 1e-6 && p[2] == 1.0,
            "{p:?}"
        );
    }

    #[test]
    fn minimizes_a_quadratic() {
        let mut adam = Adam::new(AdamConfig::default(), 2);
        let mut p = [3.0f32, -2.0];
        for _ in 0..500 {
            let g = [2.0 * p[0], 20.0 * p[1]];
            adam.update(&mut p, &g, 0.05);
        }
        assert!(p[0].abs() < 0.05 && p[1].abs() < 0.05, "{p:?}");
    }
}
