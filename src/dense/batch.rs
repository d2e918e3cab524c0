//! The batched `f32` engine of the dense layer: `act(x Wᵀ + b + residual)` for many rows at
//! once, through `matrixmultiply`'s blocked product (its own run-time-selected AVX/FMA kernels),
//! with the work split over output rows with `std::thread::scope`.
use super::DenseLayer;

/// What follows a layer's bias (and residual).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Activation {
    None,
    /// `clamp(x, 0, 6)`.
    Relu6,
    /// The exact GELU, `x * (1 + erf(x / sqrt 2)) / 2`.
    Gelu,
}

impl Activation {
    #[inline(always)]
    pub(crate) fn apply(self, v: f32) -> f32 {
        match self {
            Activation::None => v,
            Activation::Relu6 => v.clamp(0.0, 6.0),
            Activation::Gelu => gelu(v),
        }
    }
}

/// The exact (erf) GELU.
pub fn gelu(x: f32) -> f32 {
    let x = x as f64;
    (0.5 * x * (1.0 + erf(x * std::f64::consts::FRAC_1_SQRT_2))) as f32
}

/// `erf` to about 1.5e-7 absolute (Abramowitz & Stegun 7.1.26), enough for `f32` activations.
pub fn erf(x: f64) -> f64 {
    const P: f64 = 0.327_591_1;
    const A: [f64; 5] = [
        0.254_829_592,
        -0.284_496_736,
        1.421_413_741,
        -1.453_152_027,
        1.061_405_429,
    ];
    let t = 1.0 / (1.0 + P * x.abs());
    let poly = t * (A[0] + t * (A[1] + t * (A[2] + t * (A[3] + t * A[4]))));
    let y = 1.0 - poly * (-x * x).exp();
    if x < 0.0 { -y } else { y }
}

/// The number of threads to use by default: all the cores this process may use.
pub fn default_threads() -> usize {
    std::thread::available_parallelism().map(|n| n.get()).unwrap_or(1)
}

/// Runs `f(first_row, rows)` on contiguous chunks of `out` (rows of `row_len` values, chunks a
/// multiple of `grain` rows) on up to `threads` threads.
pub fn parallel_rows<F>(out: &mut [f32], row_len: usize, threads: usize, grain: usize, f: F)
where
    F: Fn(usize, &mut [f32]) + Sync,
{
    let rows = out.len() / row_len.max(1);
    let threads = threads.max(1).min(rows.div_ceil(grain.max(1)).max(1));
    if threads <= 1 {
        f(0, out);
        return;
    }
    let per = rows.div_ceil(threads).div_ceil(grain) * grain;
    std::thread::scope(|s| {
        let mut chunks = out.chunks_mut(per * row_len).enumerate();
        let first = chunks.next();
        for (i, chunk) in chunks {
            let f = &f;
            s.spawn(move || f(i * per, chunk));
        }
        if let Some((_, chunk)) = first {
            f(0, chunk);
        }
    });
}

/// Rows handed to one thread at a time are a multiple of this.
const ROW_GRAIN: usize = 4;

/// A fully connected layer `y = x Wᵀ + b` on rows of `cin` values, owning its weights
/// (`weight[o * cin + i]`, PyTorch's `[out, in]` layout) and biases.
#[derive(Clone, Debug)]
pub struct Dense {
    pub cin: usize,
    pub cout: usize,
    weight: Vec<f32>,
    bias: Vec<f32>,
}

impl Dense {
    /// From `weight[o * cin + i]` (PyTorch's `[out, in]` layout) and `bias[o]`.
    pub fn new(cin: usize, cout: usize, weight: &[f32], bias: &[f32]) -> Self {
        assert_eq!(weight.len(), cin * cout, "weight size");
        assert_eq!(bias.len(), cout, "bias size");
        Dense {
            cin,
            cout,
            weight: weight.to_vec(),
            bias: bias.to_vec(),
        }
    }

    /// The layer as a [`DenseLayer`] over its weights.
    pub fn layer(&self) -> DenseLayer<'_, f32> {
        DenseLayer::new(self.cin, self.cout, &self.weight, Some(&self.bias))
    }

    /// `act(x W^T + b + residual)` for `x` of `rows x cin` values; `rows x cout` values out.
    pub fn forward(&self, x: &[f32], act: Activation, residual: Option<&[f32]>, threads: usize) -> Vec<f32> {
        let mut out = vec![0.0; x.len() / self.cin * self.cout];
        self.forward_into(x, act, residual, threads, &mut out);
        out
    }

    /// [`Dense::forward`] into `out` (`rows x cout` values, overwritten): lets a caller that
    /// runs many small layers reuse one buffer instead of allocating each time.
    pub fn forward_into(&self, x: &[f32], act: Activation, residual: Option<&[f32]>, threads: usize, out: &mut [f32]) {
        assert_eq!(x.len() % self.cin, 0, "input not a whole number of rows");
        let rows = x.len() / self.cin;
        if let Some(r) = residual {
            assert_eq!(r.len(), rows * self.cout, "residual size");
        }
        assert_eq!(out.len(), rows * self.cout, "output size");
        let (cin, cout) = (self.cin, self.cout);
        parallel_rows(out, cout, threads, ROW_GRAIN, |row0, chunk| {
            let n = chunk.len() / cout.max(1);
            // C starts as the bias (plus the residual), and the product is added to it.
            for (r, o) in chunk.chunks_exact_mut(cout).enumerate() {
                o.copy_from_slice(&self.bias);
                if let Some(res) = residual {
                    for (o, &s) in o.iter_mut().zip(&res[(row0 + r) * cout..][..cout]) {
                        *o += s;
                    }
                }
            }
            if n > 0 && cin > 0 && cout > 0 {
                let x = &x[row0 * cin..][..n * cin];
                // SAFETY: A is the n x cin rows of `x` (row stride cin), B = Wᵀ is cin x cout read
                // from `weight` (row stride 1, column stride cin), C the n x cout `chunk` (row stride
                // cout): every index the product touches lies inside the three slices, whose
                // lengths were checked above, and C aliases neither input.
                unsafe {
                    matrixmultiply::sgemm(
                        n,
                        cin,
                        cout,
                        1.0,
                        x.as_ptr(),
                        cin as isize,
                        1,
                        self.weight.as_ptr(),
                        1,
                        cin as isize,
                        1.0,
                        chunk.as_mut_ptr(),
                        cout as isize,
                        1,
                    );
                }
            }
            if act != Activation::None {
                for v in chunk.iter_mut() {
                    *v = act.apply(*v);
                }
            }
        });
    }

    /// Multiply-adds per input row.
    pub fn macs_per_row(&self) -> usize {
        self.cin * self.cout
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::dense::test_support::{assert_close, noise};

    #[test]
    fn the_matmul_matches_naive_loops_for_ragged_sizes_threads_and_residuals() {
        for &(rows, cin, cout) in &[(1, 1, 1), (7, 3, 17), (70, 27, 32), (131, 40, 24), (9, 5, 33)] {
            let x = noise(rows * cin, 1);
            let w = noise(cin * cout, 2);
            let b = noise(cout, 3);
            let res = noise(rows * cout, 4);
            let layer = Dense::new(cin, cout, &w, &b);
            for act in [Activation::None, Activation::Relu6] {
                let mut want = vec![0f64; rows * cout];
                for r in 0..rows {
                    for o in 0..cout {
                        let mut v = b[o] as f64 + 4.0 * res[r * cout + o] as f64;
                        for i in 0..cin {
                            v += x[r * cin + i] as f64 * w[o * cin + i] as f64 * 3.0;
                        }
                        want[r * cout + o] = if act == Activation::Relu6 { v.clamp(0.0, 6.0) } else { v };
                    }
                }
                // Scale so that ReLU6 clamps above as well as below.
                let x3: Vec<f32> = x.iter().map(|v| v * 3.0).collect();
                let res4: Vec<f32> = res.iter().map(|v| v * 4.0).collect();
                for threads in [1, 3] {
                    let got = layer.forward(&x3, act, Some(&res4), threads);
                    assert_close(&got, &want, 1e-5);
                }
                let got = layer.forward(&x3, act, None, 2);
                for r in 0..rows {
                    for o in 0..cout {
                        let mut v = b[o] as f64;
                        for i in 0..cin {
                            v += x3[r * cin + i] as f64 * w[o * cin + i] as f64;
                        }
                        let v = if act == Activation::Relu6 { v.clamp(0.0, 6.0) } else { v };
                        assert!((got[r * cout + o] as f64 - v).abs() < 1e-5 * (1.0 + v.abs()));
                    }
                }
            }
        }
    }

    #[test]
    fn the_batched_forward_is_the_dense_layer_forward() {
        let (rows, cin, cout) = (37, 19, 21);
        let (x, w, b) = (noise(rows * cin, 11), noise(cin * cout, 12), noise(cout, 13));
        let mut want = vec![0.0f32; rows * cout];
        DenseLayer::new(cin, cout, &w, Some(&b)).forward(&x, &mut want);
        let want: Vec<f64> = want.iter().map(|&v| v as f64).collect();
        assert_close(
            &Dense::new(cin, cout, &w, &b).forward(&x, Activation::None, None, 2),
            &want,
            1e-5,
        );
    }
}
