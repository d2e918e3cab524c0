//! The field's optimizer: the crate's Adam (`crate::adam`, whose update rule the GPU's
//! `adam.wgsl` must match exactly) with β₁, β₂ and ε from the field's [`AdamConfig`].
pub use crate::adam::{Adam, AdamHyper};
use crate::field::config::AdamConfig;

impl From<AdamConfig> for AdamHyper {
    fn from(c: AdamConfig) -> AdamHyper {
        AdamHyper {
            beta1: c.beta1,
            beta2: c.beta2,
            epsilon: c.epsilon,
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::field::AdamConfig;

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
