//! Volume rendering along one ray and its O(n) backward pass.
//!
//! Samples i = 0…n−1 (front to back) have density σ_i, interval length δ_i (metres) and a
//! value vector h_i of `k` channels. With optical depth τ_i = Σ_{j<i} σ_j δ_j,
//! transmittance T_i = e^(−τ_i), α_i = 1 − e^(−σ_i δ_i) and weight w_i = T_i α_i, the
//! rendered value is R = Σ_i w_i h_i.
//!
//! A ray's last sample may be opaque (`FieldConfig::last_sample`, marked by an interval
//! of [`OPAQUE_INTERVAL`]): it takes all the transmittance left, w = T_last, whatever its
//! density, so what lies beyond the scene box (a photo capture's room) is painted on the
//! samples at the box's far side instead of on density inside the box (docs/results/quality-log.md, "The
//! room beyond the box"). Otherwise nothing is composited behind the last sample and an empty
//! ray renders 0.
//!
//! All channels are rendered by the same weights, so the model concatenates them per sample
//! in the order of [`Channels`]: colour (3), z-depth (1), semantic logits (C), feature (D).
use super::real::Real;

/// Offsets of the rendered channels in a sample's value vector and the rendered output.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Channels {
    pub classes: usize,
    pub feature_dim: usize,
}

impl Channels {
    pub const RGB: usize = 0;
    pub const DEPTH: usize = 3;
    pub const SEMANTIC: usize = 4;

    pub fn feature(&self) -> usize {
        Self::SEMANTIC + self.classes
    }

    pub fn count(&self) -> usize {
        Self::SEMANTIC + self.classes + self.feature_dim
    }
}

/// The interval that marks a ray's opaque last sample (any negative value would do: an
/// interval is never negative otherwise). Its length does not matter: the sample's weight is
/// the transmittance left whatever its density, and its density gets no gradient.
pub const OPAQUE_INTERVAL: f32 = -1.0;

/// One sample's step along the ray: (weight T·α, transmittance after it), advancing the summed
/// optical depth. Shared by `composite` and `kept_samples` (and `shaders/_density.wgsl`).
fn transmittance_step<R: Real>(sigma: R, delta: R, optical_depth: &mut R) -> (R, R) {
    let t_before = (-*optical_depth).exp();
    if delta < R::ZERO {
        return (t_before, R::ZERO);
    }
    *optical_depth += sigma * delta;
    let t_after = (-*optical_depth).exp();
    (t_before - t_after, t_after)
}

/// Forward results kept for the backward pass.
#[derive(Clone, Debug)]
pub struct Composite<R> {
    /// w_i, n values.
    pub weights: Vec<R>,
    /// T_{i+1} = T_i (1 − α_i): transmittance behind each sample, n values.
    pub transmittance_after: Vec<R>,
    /// R, k values.
    pub output: Vec<R>,
}

/// Renders one ray. `sigmas`, `deltas`: n values; `values`: n × k, row-major (sample-major).
pub fn composite<R: Real>(sigmas: &[R], deltas: &[R], values: &[R], k: usize) -> Composite<R> {
    let n = sigmas.len();
    debug_assert_eq!(deltas.len(), n);
    debug_assert_eq!(values.len(), n * k);
    let mut weights = Vec::with_capacity(n);
    let mut transmittance_after = Vec::with_capacity(n);
    let mut output = vec![R::ZERO; k];
    // Transmittance from the summed optical depth rather than a running product: same value,
    // but no drift from multiplying many factors near 1.
    let mut optical_depth = R::ZERO;
    for i in 0..n {
        let (w, t_after) = transmittance_step(sigmas[i], deltas[i], &mut optical_depth);
        for (o, h) in output.iter_mut().zip(&values[i * k..(i + 1) * k]) {
            *o += w * *h;
        }
        weights.push(w);
        transmittance_after.push(t_after);
    }
    Composite {
        weights,
        transmittance_after,
        output,
    }
}

/// Which samples of a ray reach the colour, feature and semantic heads
/// (`FieldConfig::head_weight_threshold`): those whose compositing weight w_i, computed from
/// the density pre-activations `h0` alone, is at least `threshold`; 0 keeps every sample.
/// Always in f32 and in the order of `composite` (and of `shaders/keep.wgsl`), whatever the
/// reference's scalar type, so that the reference and the GPU make the same choice.
pub fn kept_samples(h0: &[f32], deltas: &[f32], threshold: f32) -> Vec<bool> {
    debug_assert_eq!(h0.len(), deltas.len());
    if threshold <= 0.0 {
        return vec![true; h0.len()];
    }
    let mut optical_depth = 0.0f32;
    h0.iter()
        .zip(deltas)
        .map(|(&h, &delta)| {
            transmittance_step(super::activations::density(h), delta, &mut optical_depth).0 >= threshold
        })
        .collect()
}

/// The transmittance a ray leaves for its opaque last sample (that sample's weight), or `None`
/// when its last sample is not opaque.
pub fn left_for_opaque_sample<R: Real>(forward: &Composite<R>, deltas: &[R]) -> Option<R> {
    match (deltas.last(), forward.weights.last()) {
        (Some(d), Some(w)) if *d < R::ZERO => Some(*w),
        _ => None,
    }
}

/// Vector-Jacobian product of `composite`. Given `grad_output` = ∂L/∂R (k values) and
/// `grad_left` = ∂L/∂w of an opaque last sample (the transmittance it takes,
/// [`left_for_opaque_sample`]; ignored when the last sample is not opaque) returns
/// (∂L/∂σ, n values; ∂L/∂h, n × k values):
/// - ∂L/∂h_i = w_i · g
/// - ∂L/∂σ_i = δ_i (T_{i+1} u_i − Σ_{j>i} w_j u_j), with u_i = g · h_i (plus `grad_left` for
///   the opaque sample, as if it rendered one more channel of value 1 that no other sample has),
///
/// because ∂w_i/∂σ_i = δ_i T_{i+1} and ∂w_j/∂σ_i = −δ_i w_j for j > i (an opaque last sample
/// gets 0: its T_{i+1} and its suffix are both 0). The suffix sum is
/// accumulated back to front, so the pass is O(n·k). (instant-ngp gets the suffix as
/// `total − prefix` in a forward scan instead; the same value up to rounding.)
pub fn composite_backward<R: Real>(
    forward: &Composite<R>,
    deltas: &[R],
    values: &[R],
    k: usize,
    grad_output: &[R],
    grad_left: R,
) -> (Vec<R>, Vec<R>) {
    let n = deltas.len();
    let mut grad_sigma = vec![R::ZERO; n];
    let mut grad_values = vec![R::ZERO; n * k];
    let mut suffix = R::ZERO;
    for i in (0..n).rev() {
        let h = &values[i * k..(i + 1) * k];
        let mut u: R = grad_output.iter().zip(h).map(|(g, v)| *g * *v).sum();
        if deltas[i] < R::ZERO {
            u += grad_left;
        }
        grad_sigma[i] = deltas[i] * (forward.transmittance_after[i] * u - suffix);
        suffix += forward.weights[i] * u;
        for (gv, g) in grad_values[i * k..(i + 1) * k].iter_mut().zip(grad_output) {
            *gv = forward.weights[i] * *g;
        }
    }
    (grad_sigma, grad_values)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::field::reference::gradcheck::{assert_close, central_differences, random_vec};
    use crate::rng::SplitMix64;

    #[test]
    fn opaque_first_sample_takes_all_weight() {
        let c = composite(&[1e6f64, 3.0], &[0.1, 0.1], &[0.2, 0.9], 1);
        assert!((c.weights[0] - 1.0).abs() < 1e-12 && c.weights[1].abs() < 1e-12);
        assert!((c.output[0] - 0.2).abs() < 1e-12);
        // Weights of a constant-density ray sum to 1 − e^(−σ·length).
        let c = composite(&[2.0f64; 4], &[0.25; 4], &[1.0; 4], 1);
        assert!((c.output[0] - (1.0 - (-2.0f64).exp())).abs() < 1e-12);
    }

    #[test]
    fn samples_behind_an_opaque_one_are_not_kept() {
        let h0 = [-30.0, 12.0, 1.0, 1.0];
        let deltas = [0.1; 4];
        // exp(-15) * 0.1 is below 1e-4: the empty first sample is dropped, the surface kept,
        // nothing behind it survives.
        assert_eq!(kept_samples(&h0, &deltas, 1e-4), [false, true, false, false]);
        assert_eq!(kept_samples(&h0, &deltas, 0.0), [true; 4]);
    }

    #[test]
    fn an_opaque_last_sample_takes_what_the_ray_has_left() {
        let opaque = f64::from(OPAQUE_INTERVAL);
        // A nearly empty ray: the last sample takes the rest, whatever its own density.
        for last_sigma in [1e-7, 1.0, 1e6] {
            let c = composite(&[0.5f64, 1e-7, last_sigma], &[0.2, 0.2, opaque], &[1.0, 0.0, 3.0], 1);
            let first = 1.0 - (-0.1f64).exp();
            assert!((c.weights.iter().sum::<f64>() - 1.0).abs() < 1e-12);
            assert!((c.weights[2] - (1.0 - first) * (-2e-8f64).exp()).abs() < 1e-12);
            assert_eq!(c.transmittance_after[2], 0.0);
        }
        // Behind an opaque surface it gets nothing, as any other sample.
        let c = composite(&[1e6f64, 1.0], &[0.1, opaque], &[0.2, 0.9], 1);
        assert!(c.weights[1].abs() < 1e-12);
        // The keep rule sees the same weights: an empty ray keeps its last sample.
        let empty = [-30.0, -30.0, -30.0];
        assert_eq!(kept_samples(&empty, &[0.1, 0.1, 0.1], 1e-4), [false; 3]);
        assert_eq!(
            kept_samples(&empty, &[0.1, 0.1, OPAQUE_INTERVAL], 1e-4),
            [false, false, true]
        );
    }

    #[test]
    fn backward_matches_finite_differences() {
        for opaque_last in [false, true] {
            backward_matches_finite_differences_with(opaque_last);
        }
    }

    fn backward_matches_finite_differences_with(opaque_last: bool) {
        let (n, k) = (9, 4);
        let mut rng = SplitMix64::new(21);
        let sigmas: Vec<f64> = (0..n).map(|_| rng.uniform(0.0, 6.0)).collect();
        let mut deltas: Vec<f64> = (0..n).map(|_| rng.uniform(0.01, 0.3)).collect();
        if opaque_last {
            deltas[n - 1] = f64::from(OPAQUE_INTERVAL);
        }
        let values = random_vec(&mut rng, n * k, 1.0);
        let probe = random_vec(&mut rng, k, 1.0);
        // A loss on the transmittance left for an opaque last sample too.
        let probe_left = 0.7;
        let loss = |s: &[f64], v: &[f64]| {
            let c = composite(s, &deltas, v, k);
            let left = left_for_opaque_sample(&c, &deltas).map_or(0.0, |t| t * probe_left);
            c.output.iter().zip(&probe).map(|(a, b)| a * b).sum::<f64>() + left
        };
        let fwd = composite(&sigmas, &deltas, &values, k);
        assert_eq!(left_for_opaque_sample(&fwd, &deltas).is_some(), opaque_last);
        let (grad_sigma, grad_values) = composite_backward(&fwd, &deltas, &values, k, &probe, probe_left);
        let numeric_sigma = central_differences(|s| loss(s, &values), &sigmas, 1e-6);
        let numeric_values = central_differences(|v| loss(&sigmas, v), &values, 1e-6);
        assert_close("render sigma", &grad_sigma, &numeric_sigma, 1e-7);
        assert_close("render values", &grad_values, &numeric_values, 1e-7);
    }
}
