//! The one CPU dense (fully connected) layer of the crate: `y = x Wᵀ + b` on rows of `inputs`
//! values, `W` row-major `[outputs][inputs]` (PyTorch's `[out, in]` and the field's parameter
//! layout, `field::params::MlpLayout`), the bias optional.
//!
//! - [`DenseLayer`] is the layer over borrowed weights, generic over the scalar, with its
//!   forward and backward pass: the field's CPU reference (`f32` against the GPU, `f64` for
//!   finite differences) and the feature autoencoder's training use it.
//! - [`Dense`] (native only) owns `f32` weights and runs the same forward pass on large batches
//!   through a blocked matrix product on several threads, with an activation and a residual
//!   folded in: the feature extractors' 1x1 and im2col convolutions and linear layers. Its tests
//!   compare it with [`DenseLayer::forward`].
//!
//! Activations other than the extractors' fused ones (ReLU of hidden layers) are the caller's.
use std::ops::{Add, AddAssign, Mul};

#[cfg(not(target_arch = "wasm32"))]
mod batch;
#[cfg(not(target_arch = "wasm32"))]
pub use batch::{Activation, Dense, default_threads, erf, gelu, parallel_rows};

/// What the tests of the batched layer and of the extractors' operations share.
#[cfg(all(test, not(target_arch = "wasm32")))]
pub(crate) mod test_support {
    /// A deterministic pseudo-random sequence in [-1, 1).
    pub fn noise(n: usize, seed: u64) -> Vec<f32> {
        let mut s = seed.wrapping_mul(6364136223846793005).wrapping_add(1442695040888963407);
        (0..n)
            .map(|_| {
                s = s.wrapping_mul(6364136223846793005).wrapping_add(1442695040888963407);
                ((s >> 40) as f32 / (1u64 << 24) as f32) * 2.0 - 1.0
            })
            .collect()
    }

    /// `a` equals `b` to within `tol`, relative to 1 + |b|.
    pub fn assert_close(a: &[f32], b: &[f64], tol: f64) {
        assert_eq!(a.len(), b.len());
        for (i, (&a, &b)) in a.iter().zip(b).enumerate() {
            assert!((a as f64 - b).abs() <= tol * (1.0 + b.abs()), "element {i}: {a} vs {b}");
        }
    }
}

/// What a layer computes in: `f32` and `f64` (and anything with the same arithmetic).
/// `Default` is zero.
pub trait Scalar: Copy + Default + PartialEq + Add<Output = Self> + Mul<Output = Self> + AddAssign {}

impl<T: Copy + Default + PartialEq + Add<Output = T> + Mul<Output = T> + AddAssign> Scalar for T {}

/// One dense layer over borrowed weights.
#[derive(Clone, Copy, Debug)]
pub struct DenseLayer<'a, T> {
    pub inputs: usize,
    pub outputs: usize,
    /// `weight[o * inputs + i]`.
    pub weight: &'a [T],
    /// `bias[o]`; `None` for a bias-free layer.
    pub bias: Option<&'a [T]>,
}

impl<'a, T: Scalar> DenseLayer<'a, T> {
    pub fn new(inputs: usize, outputs: usize, weight: &'a [T], bias: Option<&'a [T]>) -> Self {
        assert_eq!(weight.len(), inputs * outputs, "dense layer: weight size");
        if let Some(b) = bias {
            assert_eq!(b.len(), outputs, "dense layer: bias size");
        }
        DenseLayer {
            inputs,
            outputs,
            weight,
            bias,
        }
    }

    /// Weights plus biases.
    pub fn parameter_count(&self) -> usize {
        self.weight.len() + self.bias.map_or(0, <[T]>::len)
    }

    /// `y = x Wᵀ + b` for `x` of whole rows of `inputs` values; `y` gets as many rows of
    /// `outputs` values (overwritten).
    pub fn forward(&self, x: &[T], y: &mut [T]) {
        assert_eq!(
            x.len() % self.inputs.max(1),
            0,
            "dense layer: input not a whole number of rows"
        );
        let rows = x.len() / self.inputs.max(1);
        assert_eq!(y.len(), rows * self.outputs, "dense layer: output size");
        for (xr, yr) in x.chunks_exact(self.inputs).zip(y.chunks_exact_mut(self.outputs)) {
            for (o, (v, wr)) in yr.iter_mut().zip(self.weight.chunks_exact(self.inputs)).enumerate() {
                let b = self.bias.map_or(T::default(), |b| b[o]);
                *v = b + dot(wr, xr);
            }
        }
    }

    /// The backward pass of [`DenseLayer::forward`] for the rows `x` and the gradient `dy` of
    /// their outputs: adds ∂L/∂W into `weight_grad` (the layout of `weight`) and ∂L/∂b into
    /// `bias_grad`, and writes ∂L/∂x into `dx` (overwritten) when asked.
    pub fn backward(
        &self,
        x: &[T],
        dy: &[T],
        weight_grad: &mut [T],
        bias_grad: Option<&mut [T]>,
        dx: Option<&mut [T]>,
    ) {
        let rows = x.len() / self.inputs.max(1);
        assert_eq!(dy.len(), rows * self.outputs, "dense layer: output gradient size");
        assert_eq!(
            weight_grad.len(),
            self.weight.len(),
            "dense layer: weight gradient size"
        );
        for (xr, dyr) in x.chunks_exact(self.inputs).zip(dy.chunks_exact(self.outputs)) {
            for (&g, gr) in dyr.iter().zip(weight_grad.chunks_exact_mut(self.inputs)) {
                if g != T::default() {
                    for (w, &xi) in gr.iter_mut().zip(xr) {
                        *w += g * xi;
                    }
                }
            }
        }
        if let Some(gb) = bias_grad {
            assert_eq!(gb.len(), self.outputs, "dense layer: bias gradient size");
            for dyr in dy.chunks_exact(self.outputs) {
                for (b, &g) in gb.iter_mut().zip(dyr) {
                    *b += g;
                }
            }
        }
        if let Some(dx) = dx {
            assert_eq!(dx.len(), x.len(), "dense layer: input gradient size");
            self.input_gradient(dy, dx);
        }
    }

    /// dx = dy · W over the rows of `dy` (overwritten).
    pub fn input_gradient(&self, dy: &[T], dx: &mut [T]) {
        for (dxr, dyr) in dx.chunks_exact_mut(self.inputs).zip(dy.chunks_exact(self.outputs)) {
            dxr.fill(T::default());
            for (&g, wr) in dyr.iter().zip(self.weight.chunks_exact(self.inputs)) {
                if g != T::default() {
                    for (d, &w) in dxr.iter_mut().zip(wr) {
                        *d += g * w;
                    }
                }
            }
        }
    }
}

/// A dot product in eight independent lanes, so that the compiler can vectorize it.
pub fn dot<T: Scalar>(a: &[T], b: &[T]) -> T {
    let mut acc = [T::default(); 8];
    let (ca, cb) = (a.chunks_exact(8), b.chunks_exact(8));
    let mut tail = T::default();
    for (&x, &y) in ca.remainder().iter().zip(cb.remainder()) {
        tail += x * y;
    }
    for (x, y) in ca.zip(cb) {
        for k in 0..8 {
            acc[k] += x[k] * y[k];
        }
    }
    let mut sum = T::default();
    for a in acc {
        sum += a;
    }
    sum + tail
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn forward_computes_rows_with_and_without_bias() {
        // 2 rows of 2 inputs -> 3 outputs.
        let w = [1.0f64, 2.0, 3.0, 0.0, -1.0, 0.5];
        let b = [0.5, -1.0, 2.0];
        let x = [1.0, -1.0, 2.0, 4.0];
        let mut y = [0.0; 6];
        DenseLayer::new(2, 3, &w, Some(&b)).forward(&x, &mut y);
        assert_eq!(y, [-0.5, 2.0, 0.5, 10.5, 5.0, 2.0]);
        DenseLayer::new(2, 3, &w, None).forward(&x, &mut y);
        assert_eq!(y, [-1.0, 3.0, -1.5, 10.0, 6.0, 0.0]);
    }

    #[test]
    fn backward_matches_finite_differences() {
        let (inputs, outputs, rows) = (11, 5, 3);
        // A fixed pseudo-random sequence in [-1, 1) (this module sits below `rng`).
        let mut state = 3u64;
        let mut v = |n: usize| {
            (0..n)
                .map(|_| {
                    state = state
                        .wrapping_mul(6364136223846793005)
                        .wrapping_add(1442695040888963407);
                    (state >> 11) as f64 / (1u64 << 53) as f64 * 2.0 - 1.0
                })
                .collect::<Vec<f64>>()
        };
        let (w, b, x, probe) = (v(inputs * outputs), v(outputs), v(rows * inputs), v(rows * outputs));
        let loss = |w: &[f64], b: &[f64], x: &[f64]| {
            let mut y = vec![0.0; rows * outputs];
            DenseLayer::new(inputs, outputs, w, Some(b)).forward(x, &mut y);
            y.iter().zip(&probe).map(|(a, p)| a * p).sum::<f64>()
        };
        let (mut gw, mut gb, mut gx) = (vec![0.0; w.len()], vec![0.0; b.len()], vec![0.0; x.len()]);
        DenseLayer::new(inputs, outputs, &w, Some(&b)).backward(&x, &probe, &mut gw, Some(&mut gb), Some(&mut gx));
        let numeric = |f: &dyn Fn(&[f64]) -> f64, at: &[f64]| -> Vec<f64> {
            (0..at.len())
                .map(|k| {
                    let (mut p, mut m) = (at.to_vec(), at.to_vec());
                    p[k] += 1e-6;
                    m[k] -= 1e-6;
                    (f(&p) - f(&m)) / 2e-6
                })
                .collect()
        };
        let close = |a: &[f64], b: &[f64]| a.iter().zip(b).all(|(a, b)| (a - b).abs() < 1e-7);
        assert!(close(&gw, &numeric(&|w| loss(w, &b, &x), &w)), "weights");
        assert!(close(&gb, &numeric(&|b| loss(&w, b, &x), &b)), "biases");
        assert!(close(&gx, &numeric(&|x| loss(&w, &b, x), &x)), "inputs");
    }
}
