//! Adam with bias correction, element by element over a flat parameter buffer: the CPU
//! optimizer of the whole crate (the field's CPU reference, which the GPU's `adam.wgsl` must
//! match, and the feature autoencoder).
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

/// β₁, β₂ and ε. The field's are in its config (`field::AdamConfig` converts); other users name
/// their own.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct AdamHyper {
    pub beta1: f32,
    pub beta2: f32,
    pub epsilon: f32,
}

#[derive(Clone, Debug)]
pub struct Adam {
    pub hyper: AdamHyper,
    /// First and second moments, one per parameter.
    pub m: Vec<f32>,
    pub v: Vec<f32>,
    /// Steps taken so far (t of the last update).
    pub step: u32,
}

impl Adam {
    pub fn new(hyper: impl Into<AdamHyper>, parameter_count: usize) -> Adam {
        Adam {
            hyper: hyper.into(),
            m: vec![0.0; parameter_count],
            v: vec![0.0; parameter_count],
            step: 0,
        }
    }

    /// (c₁, c₂) of step `t` (t ≥ 1).
    pub fn bias_corrections(&self, t: u32) -> (f32, f32) {
        let c1 = 1.0 / (1.0 - (self.hyper.beta1 as f64).powi(t as i32));
        let c2 = 1.0 / (1.0 - (self.hyper.beta2 as f64).powi(t as i32));
        (c1 as f32, c2 as f32)
    }

    /// One update of `params` (same length as the moments) with gradient `grad`.
    pub fn update(&mut self, params: &mut [f32], grad: &[f32], lr: f32) {
        self.update_parts([params], grad, lr);
    }

    /// One update of parameters kept in several slices (a network's layers), which together
    /// are laid out as `grad` is.
    pub fn update_parts<'a>(&mut self, parts: impl IntoIterator<Item = &'a mut [f32]>, grad: &[f32], lr: f32) {
        self.step += 1;
        let (c1, c2) = self.bias_corrections(self.step);
        let AdamHyper { beta1, beta2, epsilon } = self.hyper;
        let params = parts.into_iter().flat_map(|part| part.iter_mut());
        for (((p, g), m), v) in params.zip(grad).zip(&mut self.m).zip(&mut self.v) {
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
    fn parts_update_as_one_flat_buffer_does() {
        let hyper = AdamHyper {
            beta1: 0.9,
            beta2: 0.999,
            epsilon: 1e-8,
        };
        let (mut flat, mut split) = (Adam::new(hyper, 5), Adam::new(hyper, 5));
        let mut p = [1.0f32, -2.0, 0.5, 3.0, -1.0];
        let (mut a, mut b) = ([1.0f32, -2.0], [0.5f32, 3.0, -1.0]);
        for step in 0..20 {
            let g: Vec<f32> = (0..5).map(|i| ((i + step) as f32 * 0.7).sin()).collect();
            flat.update(&mut p, &g, 0.01);
            split.update_parts([&mut a[..], &mut b[..]], &g, 0.01);
        }
        assert_eq!(p[..2], a);
        assert_eq!(p[2..], b);
    }
}
