//! Bias-free fully connected networks: ReLU after every hidden layer, linear output (the
//! caller applies the output activation).
//!
//! `dims` = [in, hidden…, out]; `weights` holds the layers back to back, layer k a row-major
//! `[dims[k+1]][dims[k]]` matrix (the layout of `field::params::MlpLayout`). Each layer is the
//! crate's one CPU dense layer, `crate::dense::DenseLayer`, without bias.
use super::real::Real;
use crate::dense::DenseLayer;

/// Number of weights of an MLP with these layer sizes.
pub fn weight_count(dims: &[usize]) -> usize {
    dims.windows(2).map(|io| io[0] * io[1]).sum()
}

/// What the backward pass needs: the input of every layer and the final output.
/// `activations[0]` is the input, `activations[k]` (0 < k < layers) the ReLU output of hidden
/// layer k − 1, and the last entry the linear output (`dims[last]` values).
#[derive(Clone, Debug)]
pub struct MlpTrace<R> {
    pub activations: Vec<Vec<R>>,
}

impl<R: Real> MlpTrace<R> {
    pub fn output(&self) -> &[R] {
        &self.activations[self.activations.len() - 1]
    }
}

/// Forward pass of one input vector (`dims[0]` values).
pub fn forward<R: Real>(dims: &[usize], weights: &[R], input: &[R]) -> MlpTrace<R> {
    debug_assert_eq!(weights.len(), weight_count(dims));
    debug_assert_eq!(input.len(), dims[0]);
    let layers = dims.len() - 1;
    let mut activations = Vec::with_capacity(dims.len());
    activations.push(input.to_vec());
    let mut offset = 0;
    for k in 0..layers {
        let (n_in, n_out) = (dims[k], dims[k + 1]);
        let layer = DenseLayer::new(n_in, n_out, &weights[offset..offset + n_in * n_out], None);
        let mut y = vec![R::ZERO; n_out];
        layer.forward(&activations[k], &mut y);
        if k + 1 < layers {
            y.iter_mut().for_each(|v| *v = v.max(R::ZERO));
        }
        activations.push(y);
        offset += n_in * n_out;
    }
    MlpTrace { activations }
}

/// Vector-Jacobian product: given `grad_out` = ∂L/∂output (`dims[last]` values), adds
/// ∂L/∂weights into `weight_grad` (same layout as `weights`) and returns ∂L/∂input
/// (`dims[0]` values). The ReLU derivative is taken as 0 at 0 (the activation stored is the
/// ReLU output, so the test is `activation > 0`).
pub fn backward<R: Real>(
    dims: &[usize],
    weights: &[R],
    trace: &MlpTrace<R>,
    grad_out: &[R],
    weight_grad: &mut [R],
) -> Vec<R> {
    let layers = dims.len() - 1;
    let mut offsets = Vec::with_capacity(layers);
    let mut offset = 0;
    for k in 0..layers {
        offsets.push(offset);
        offset += dims[k] * dims[k + 1];
    }
    let mut grad = grad_out.to_vec();
    for k in (0..layers).rev() {
        let (n_in, n_out) = (dims[k], dims[k + 1]);
        let layer = DenseLayer::new(n_in, n_out, &weights[offsets[k]..offsets[k] + n_in * n_out], None);
        let wg = &mut weight_grad[offsets[k]..offsets[k] + n_in * n_out];
        let x = &trace.activations[k];
        let mut grad_in = vec![R::ZERO; n_in];
        layer.backward(x, &grad, wg, None, Some(&mut grad_in));
        if k > 0 {
            // x is the ReLU output of the previous layer.
            for (gi, xi) in grad_in.iter_mut().zip(x) {
                if *xi <= R::ZERO {
                    *gi = R::ZERO;
                }
            }
        }
        grad = grad_in;
    }
    grad
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::field::reference::gradcheck::{assert_close, central_differences, random_vec};
    use crate::rng::SplitMix64;

    #[test]
    fn computes_relu_layers() {
        // 2 → 2 → 1: hidden = relu([1·1 + 2·(−1), 3·1 + 0·(−1)]) = [0, 3]; out = 2·0 + 0.5·3.
        let dims = [2, 2, 1];
        let w = [1.0f64, 2.0, 3.0, 0.0, 2.0, 0.5];
        let t = forward(&dims, &w, &[1.0, -1.0]);
        assert_eq!(t.activations[1], vec![0.0, 3.0]);
        assert_eq!(t.output(), &[1.5]);
    }

    #[test]
    fn backward_matches_finite_differences() {
        let dims = [5, 7, 6, 3];
        let mut rng = SplitMix64::new(11);
        let weights = random_vec(&mut rng, weight_count(&dims), 0.8);
        let input = random_vec(&mut rng, dims[0], 1.0);
        let probe = random_vec(&mut rng, 3, 1.0);
        let loss = |w: &[f64], x: &[f64]| {
            forward(&dims, w, x)
                .output()
                .iter()
                .zip(&probe)
                .map(|(a, b)| a * b)
                .sum()
        };
        let trace = forward(&dims, &weights, &input);
        let mut weight_grad = vec![0.0; weights.len()];
        let input_grad = backward(&dims, &weights, &trace, &probe, &mut weight_grad);
        let numeric_w = central_differences(|w| loss(w, &input), &weights, 1e-6);
        let numeric_x = central_differences(|x| loss(&weights, x), &input, 1e-6);
        assert_close("mlp weights", &weight_grad, &numeric_w, 1e-7);
        assert_close("mlp input", &input_grad, &numeric_x, 1e-7);
    }
}
