//! Bias-free fully connected networks: ReLU after every hidden layer, linear output (the
//! caller applies the output activation).
//!
//! `dims` = [in, hidden…, out]; `weights` holds the layers back to back, layer k a row-major
//! `[dims[k+1]][dims[k]]` matrix (the layout of `field::params::MlpLayout`). Each layer is the
//! crate's one CPU dense layer, `crate::dense::DenseLayer`, without bias.
use super::real::Real;
use crate::dense::DenseLayer;
use crate::field::bf16;

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
    forward_stored(dims, weights, input, &StoredRows::default())
}

/// [`forward`] with the input, every hidden layer's output (after the ReLU) and the output seen
/// as `rows` says (`input`, `hidden`, `output`): as the GPU stores them, so every layer, the
/// backward and what reads the output see what the GPU's do.
pub fn forward_stored<R: Real>(dims: &[usize], weights: &[R], input: &[R], rows: &StoredRows) -> MlpTrace<R> {
    debug_assert_eq!(weights.len(), weight_count(dims));
    debug_assert_eq!(input.len(), dims[0]);
    let layers = dims.len() - 1;
    let hidden = rows.hidden;
    let mut activations = Vec::with_capacity(dims.len());
    activations.push(input.iter().map(|&v| rows.input.apply(v)).collect::<Vec<R>>());
    let mut offset = 0;
    for k in 0..layers {
        let (n_in, n_out) = (dims[k], dims[k + 1]);
        let layer = DenseLayer::new(n_in, n_out, &weights[offset..offset + n_in * n_out], None);
        let mut y = vec![R::ZERO; n_out];
        layer.forward(&activations[k], &mut y);
        if k + 1 < layers {
            y.iter_mut().for_each(|v| *v = hidden.apply(v.max(R::ZERO)));
        } else {
            y.iter_mut().for_each(|v| *v = rows.output.apply(*v));
        }
        activations.push(y);
        offset += n_in * n_out;
    }
    MlpTrace { activations }
}

/// How the reference sees a value the GPU stores: as computed, or rounded to bf16 (through f32)
/// as the GPU's bf16 rows hold it (`crate::field::bf16`).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub enum Rounding {
    #[default]
    Exact,
    Bf16,
}

impl Rounding {
    pub fn apply<R: Real>(self, value: R) -> R {
        match self {
            Rounding::Exact => value,
            Rounding::Bf16 => R::of_f32(bf16::round(value.to_f64() as f32)),
        }
    }
}

/// How the GPU stores an MLP's rows, for the reference to round the same way.
#[derive(Clone, Debug, Default, PartialEq, Eq)]
pub struct StoredRows {
    /// How layer k's weight gradient sees its dZ (∂L/∂ the layer's output before the ReLU):
    /// rounded where the GPU's uniform-window weight gradient stores it as bf16 (layers past
    /// the end: exact). The input gradient always takes dZ as computed.
    pub dz: Vec<Rounding>,
    /// How the hidden layers' outputs are stored ([`forward_stored`]).
    pub hidden: Rounding,
    /// How the input gradients between hidden layers (dX of every layer but the first) are
    /// stored ([`backward_stored`]).
    pub hidden_gradients: Rounding,
    /// How the MLP's input rows are stored ([`forward_stored`]): bf16 where the MLP owns them
    /// (`dense::MlpPass::input`) and stores its hidden rows so.
    pub input: Rounding,
    /// How the first layer's input gradient (the MLP's ∂L/∂input) is stored
    /// ([`backward_stored`]).
    pub input_gradient: Rounding,
    /// How the MLP's output rows are stored ([`forward_stored`]).
    pub output: Rounding,
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
    backward_stored(dims, weights, trace, grad_out, weight_grad, &StoredRows::default())
}

/// [`backward`] with the rows seen as `rows` says: each layer's weight gradient reads dZ as
/// `rows.dz[k]`, each hidden layer's input gradient is seen as `rows.hidden_gradients` by the
/// layer below, and the MLP's input gradient is returned as `rows.input_gradient` (the trace's
/// activations are the forward's, [`forward_stored`]).
pub fn backward_stored<R: Real>(
    dims: &[usize],
    weights: &[R],
    trace: &MlpTrace<R>,
    grad_out: &[R],
    weight_grad: &mut [R],
    rows: &StoredRows,
) -> Vec<R> {
    let dz = &rows.dz;
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
        match dz.get(k).copied().unwrap_or_default() {
            Rounding::Exact => layer.backward(x, &grad, wg, None, Some(&mut grad_in)),
            Rounding::Bf16 => {
                let rounded: Vec<R> = grad.iter().map(|&g| Rounding::Bf16.apply(g)).collect();
                layer.backward(x, &rounded, wg, None, None);
                layer.input_gradient(&grad, &mut grad_in);
            }
        }
        if k > 0 {
            // x is the ReLU output of the previous layer.
            for (gi, xi) in grad_in.iter_mut().zip(x) {
                *gi = if *xi <= R::ZERO {
                    R::ZERO
                } else {
                    rows.hidden_gradients.apply(*gi)
                };
            }
        }
        grad = grad_in;
    }
    grad.iter().map(|&g| rows.input_gradient.apply(g)).collect()
}

/// dZ of every layer (∂L/∂ its output before the ReLU; the last layer's is `grad_out`), first
/// layer first: what each layer's weight gradient sums against its input.
pub fn layer_output_gradients<R: Real>(
    dims: &[usize],
    weights: &[R],
    trace: &MlpTrace<R>,
    grad_out: &[R],
) -> Vec<Vec<R>> {
    let layers = dims.len() - 1;
    let mut dz = vec![grad_out.to_vec()];
    let mut end = weight_count(dims);
    for k in (1..layers).rev() {
        let (n_in, n_out) = (dims[k], dims[k + 1]);
        let layer = DenseLayer::new(n_in, n_out, &weights[end - n_in * n_out..end], None);
        end -= n_in * n_out;
        let mut grad_in = vec![R::ZERO; n_in];
        layer.input_gradient(&dz[dz.len() - 1], &mut grad_in);
        for (gi, xi) in grad_in.iter_mut().zip(&trace.activations[k]) {
            if *xi <= R::ZERO {
                *gi = R::ZERO;
            }
        }
        dz.push(grad_in);
    }
    dz.reverse();
    dz
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

    #[test]
    fn layer_output_gradients_give_the_weight_gradient_and_bf16_rounds_only_it() {
        let dims = [5, 7, 6, 3];
        let mut rng = SplitMix64::new(12);
        let weights = random_vec(&mut rng, weight_count(&dims), 0.8);
        let input = random_vec(&mut rng, dims[0], 1.0);
        let probe = random_vec(&mut rng, 3, 1.0);
        let trace = forward(&dims, &weights, &input);
        let mut exact = vec![0.0; weights.len()];
        let input_grad = backward(&dims, &weights, &trace, &probe, &mut exact);
        let dz = layer_output_gradients(&dims, &weights, &trace, &probe);
        assert_eq!(dz.iter().map(Vec::len).collect::<Vec<_>>(), [7, 6, 3]);
        let mut from_dz = Vec::new();
        for (k, g) in dz.iter().enumerate() {
            for &go in g {
                from_dz.extend(trace.activations[k].iter().map(|x| go * x));
            }
        }
        assert_close("dW from dZ", &from_dz, &exact, 1e-12);

        // Layer 1 rounded: its dW takes bf16(dZ); the other layers and dX stay exact.
        let mut rounded = vec![0.0; weights.len()];
        let rows = [Rounding::Exact, Rounding::Bf16];
        let rows = StoredRows {
            dz: rows.to_vec(),
            ..StoredRows::default()
        };
        let input_grad_rounded = backward_stored(&dims, &weights, &trace, &probe, &mut rounded, &rows);
        assert_eq!(input_grad_rounded, input_grad);
        let layer1 = 35..35 + 42;
        let mut expected = exact.clone();
        for (o, &go) in dz[1].iter().enumerate() {
            let g = f64::from(bf16::round(go as f32));
            for (i, x) in trace.activations[1].iter().enumerate() {
                expected[layer1.start + o * 7 + i] = g * x;
            }
        }
        assert_eq!(rounded[..35], exact[..35]);
        assert_eq!(rounded[77..], exact[77..]);
        assert_close(
            "dW of the rounded layer",
            &rounded[layer1.clone()],
            &expected[layer1.clone()],
            1e-12,
        );
        assert!(rounded[layer1.clone()] != exact[layer1], "rounding changed nothing");
    }
}
