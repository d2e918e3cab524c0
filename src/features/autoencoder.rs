//! The autoencoder (docs/features.md) that compresses an extractor's M-dimensional features to the
//! archive's 64-d codes: M → 128 → 64 (ReLU code) → 128 → M, ReLU hidden layers, trained with
//! ‖dec(enc(f)) − f‖² + λ·|enc(f)|₁ (λ = 0.01) by Adam on minibatches of cells.
//!
//! Inputs are standardized per channel first: extractors mix channels of very different scales
//! (colour means next to gradient energies, or a stage with large activations next to one with
//! small), and without it the reconstruction loss would only see the largest. Training splits
//! every minibatch across threads, each computing the gradient of its rows; the partial
//! gradients are summed in thread order, so a fit is deterministic for a given thread count.
use crate::adam::{Adam, AdamHyper};
use crate::dense::DenseLayer;
use crate::pause::{NoPause, Pause, run_to_end};
use crate::rng::SplitMix64;

#[derive(Clone, Debug, PartialEq)]
pub struct AutoencoderConfig {
    pub hidden: usize,
    pub code: usize,
    pub l1: f32,
    pub steps: u32,
    pub batch: usize,
    pub learning_rate: f32,
    pub seed: u64,
    pub threads: usize,
}

impl Default for AutoencoderConfig {
    fn default() -> Self {
        AutoencoderConfig {
            hidden: 128,
            code: 64,
            l1: 0.01,
            steps: 3000,
            batch: 256,
            learning_rate: 1e-3,
            seed: 0,
            threads: std::thread::available_parallelism().map_or(1, |n| n.get()),
        }
    }
}

/// One layer's weights (`w[o * inputs + i]`) and biases, run as the crate's CPU dense layer.
#[derive(Clone, Debug)]
struct Dense {
    inputs: usize,
    outputs: usize,
    w: Vec<f32>,
    b: Vec<f32>,
}

impl Dense {
    fn new(inputs: usize, outputs: usize, rng: &mut SplitMix64) -> Dense {
        // He-uniform: keeps activations of ReLU stacks at a steady scale. Drawn input-major
        // (the order of the first fits), stored output-major.
        let bound = (6.0 / inputs as f64).sqrt();
        let drawn: Vec<f32> = (0..inputs * outputs)
            .map(|_| rng.uniform(-bound, bound) as f32)
            .collect();
        let mut w = vec![0.0; inputs * outputs];
        for i in 0..inputs {
            for o in 0..outputs {
                w[o * inputs + i] = drawn[i * outputs + o];
            }
        }
        Dense {
            inputs,
            outputs,
            w,
            b: vec![0.0; outputs],
        }
    }

    fn layer(&self) -> DenseLayer<'_, f32> {
        DenseLayer::new(self.inputs, self.outputs, &self.w, Some(&self.b))
    }

    fn params(&self) -> usize {
        self.w.len() + self.b.len()
    }

    fn forward(&self, x: &[f32], rows: usize, y: &mut Vec<f32>) {
        y.clear();
        y.resize(rows * self.outputs, 0.0);
        self.layer().forward(x, y);
    }

    /// Adds dL/dW and dL/db to `grad` (laid out `[w..., b...]`) and writes dL/dx when asked.
    fn backward(&self, x: &[f32], dy: &[f32], grad: &mut [f32], dx: Option<&mut Vec<f32>>) {
        let (gw, gb) = grad.split_at_mut(self.w.len());
        let dx = dx.map(|dx| {
            dx.clear();
            dx.resize(x.len(), 0.0);
            &mut dx[..]
        });
        self.layer().backward(x, dy, gw, Some(gb), dx);
    }
}

fn relu_in_place(v: &mut [f32]) {
    v.iter_mut().for_each(|x| *x = x.max(0.0));
}

/// Zeroes the gradient where the ReLU's output was 0.
fn relu_backward(out: &[f32], d: &mut [f32]) {
    for (g, &o) in d.iter_mut().zip(out) {
        if o <= 0.0 {
            *g = 0.0;
        }
    }
}

#[derive(Clone, Debug)]
pub struct Autoencoder {
    mean: Vec<f32>,
    inv_std: Vec<f32>,
    /// enc1, enc2 (code), dec1, dec2.
    layers: [Dense; 4],
    l1: f32,
}

/// What training reached, for the progress line and the archive's provenance.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct FitReport {
    /// Mean squared reconstruction error per standardized value, over a held-out sample.
    pub reconstruction_mse: f64,
    /// The same for predicting every cell by the mean (i.e. 1.0 for standardized data): the
    /// fit is only worth something well below it.
    pub baseline_mse: f64,
    /// Fraction of code values that are exactly 0 on the held-out sample.
    pub code_sparsity: f64,
}

/// Activations of one minibatch (kept for the backward pass).
#[derive(Default)]
struct Pass {
    x: Vec<f32>,
    h1: Vec<f32>,
    code: Vec<f32>,
    h2: Vec<f32>,
    out: Vec<f32>,
}

impl Autoencoder {
    pub fn input_dim(&self) -> usize {
        self.mean.len()
    }

    pub fn code_dim(&self) -> usize {
        self.layers[1].outputs
    }

    /// Fits to `rows` (cells of `dim` values). `progress(step, steps, loss)` is called every
    /// 100 steps with the latest minibatch loss.
    pub fn fit(
        rows: &[f32],
        dim: usize,
        cfg: &AutoencoderConfig,
        progress: impl FnMut(u32, u32, f64),
    ) -> (Autoencoder, FitReport) {
        run_to_end(Autoencoder::fit_pausing(rows, dim, cfg, progress, &mut NoPause))
    }

    /// [`Autoencoder::fit`] that calls `pause` after every step, so the page, which fits on the
    /// thread that also draws, can give the thread back (`crate::pause`).
    pub async fn fit_pausing(
        rows: &[f32],
        dim: usize,
        cfg: &AutoencoderConfig,
        mut progress: impl FnMut(u32, u32, f64),
        pause: &mut impl Pause,
    ) -> (Autoencoder, FitReport) {
        assert!(
            dim > 0 && rows.len().is_multiple_of(dim) && rows.len() >= dim,
            "no rows to fit"
        );
        let n = rows.len() / dim;
        let (mean, inv_std) = standardization(rows, dim);
        let mut rng = SplitMix64::new(cfg.seed ^ 0xae5e_ed00);
        let mut ae = Autoencoder {
            mean,
            inv_std,
            layers: [
                Dense::new(dim, cfg.hidden, &mut rng),
                Dense::new(cfg.hidden, cfg.code, &mut rng),
                Dense::new(cfg.code, cfg.hidden, &mut rng),
                Dense::new(cfg.hidden, dim, &mut rng),
            ],
            l1: cfg.l1,
        };
        let sizes: Vec<usize> = ae.layers.iter().map(Dense::params).collect();
        let total: usize = sizes.iter().sum();
        // The usual defaults for a small network (the field's β₂ and ε are tuned for hash grids).
        let mut adam = Adam::new(
            AdamHyper {
                beta1: 0.9,
                beta2: 0.999,
                epsilon: 1e-8,
            },
            total,
        );
        let threads = cfg.threads.clamp(1, cfg.batch.max(1));
        let mut batch = vec![0.0f32; cfg.batch * dim];
        for step in 0..cfg.steps {
            for r in batch.chunks_exact_mut(dim) {
                let i = rng.below(n as u64) as usize;
                r.copy_from_slice(&rows[i * dim..(i + 1) * dim]);
            }
            ae.standardize(&mut batch);
            let per_thread = cfg.batch.div_ceil(threads);
            // One thread computes in place: wasm (the page) cannot start threads at all.
            let partials: Vec<(Vec<f32>, f64)> = if threads == 1 {
                vec![ae.gradient(&batch, total)]
            } else {
                std::thread::scope(|s| {
                    let ae = &ae;
                    let handles: Vec<_> = batch
                        .chunks(per_thread * dim)
                        .map(|part| s.spawn(move || ae.gradient(part, total)))
                        .collect();
                    handles
                        .into_iter()
                        .map(|h| h.join().expect("autoencoder thread panicked"))
                        .collect()
                })
            };
            let mut grad = vec![0.0f32; total];
            let mut loss = 0.0;
            for (g, l) in &partials {
                grad.iter_mut().zip(g).for_each(|(a, b)| *a += b);
                loss += l;
            }
            let scale = 1.0 / cfg.batch as f32;
            grad.iter_mut().for_each(|g| *g *= scale);
            // Linear decay to a tenth: big steps early, a settled fit at the end.
            let lr = cfg.learning_rate * (1.0 - 0.9 * step as f32 / cfg.steps.max(1) as f32);
            // Laid out `[w0, b0, w1, b1, ...]` like the gradient.
            let parts = ae.layers.iter_mut().flat_map(|l| [&mut l.w[..], &mut l.b[..]]);
            adam.update_parts(parts, &grad, lr);
            if (step + 1) % 100 == 0 || step + 1 == cfg.steps {
                progress(step + 1, cfg.steps, loss / cfg.batch as f64);
            }
            pause.pause().await;
        }
        let report = ae.evaluate(rows, dim, &mut rng);
        (ae, report)
    }

    fn standardize(&self, rows: &mut [f32]) {
        for r in rows.chunks_exact_mut(self.mean.len()) {
            for ((v, m), s) in r.iter_mut().zip(&self.mean).zip(&self.inv_std) {
                *v = (*v - m) * s;
            }
        }
    }

    fn forward(&self, x: &[f32], pass: &mut Pass) {
        let rows = x.len() / self.input_dim();
        pass.x.clear();
        pass.x.extend_from_slice(x);
        self.layers[0].forward(x, rows, &mut pass.h1);
        relu_in_place(&mut pass.h1);
        self.layers[1].forward(&pass.h1, rows, &mut pass.code);
        relu_in_place(&mut pass.code);
        self.layers[2].forward(&pass.code, rows, &mut pass.h2);
        relu_in_place(&mut pass.h2);
        self.layers[3].forward(&pass.h2, rows, &mut pass.out);
    }

    /// Summed (not averaged) loss and gradient of standardized rows `x`.
    fn gradient(&self, x: &[f32], total: usize) -> (Vec<f32>, f64) {
        let mut pass = Pass::default();
        self.forward(x, &mut pass);
        let mut loss = 0.0f64;
        let mut d_out: Vec<f32> = pass.out.iter().zip(x).map(|(o, t)| o - t).collect();
        loss += d_out.iter().map(|d| (d * d) as f64).sum::<f64>();
        d_out.iter_mut().for_each(|d| *d *= 2.0);
        loss += self.l1 as f64 * pass.code.iter().map(|c| c.abs() as f64).sum::<f64>();
        let mut grad = vec![0.0f32; total];
        let offsets: Vec<usize> = self
            .layers
            .iter()
            .scan(0, |o, l| {
                let start = *o;
                *o += l.params();
                Some(start)
            })
            .collect();
        let range = |k: usize| offsets[k]..offsets[k] + self.layers[k].params();
        let mut d_h2 = Vec::new();
        let r = range(3);
        self.layers[3].backward(&pass.h2, &d_out, &mut grad[r], Some(&mut d_h2));
        relu_backward(&pass.h2, &mut d_h2);
        let mut d_code = Vec::new();
        let r = range(2);
        self.layers[2].backward(&pass.code, &d_h2, &mut grad[r], Some(&mut d_code));
        for (d, &c) in d_code.iter_mut().zip(&pass.code) {
            if c > 0.0 {
                *d += self.l1;
            }
        }
        relu_backward(&pass.code, &mut d_code);
        let mut d_h1 = Vec::new();
        let r = range(1);
        self.layers[1].backward(&pass.h1, &d_code, &mut grad[r], Some(&mut d_h1));
        relu_backward(&pass.h1, &mut d_h1);
        let r = range(0);
        self.layers[0].backward(&pass.x, &d_h1, &mut grad[r], None);
        (grad, loss)
    }

    fn evaluate(&self, rows: &[f32], dim: usize, rng: &mut SplitMix64) -> FitReport {
        let n = rows.len() / dim;
        let sample = n.min(4096);
        let mut x = Vec::with_capacity(sample * dim);
        for _ in 0..sample {
            let i = rng.below(n as u64) as usize;
            x.extend_from_slice(&rows[i * dim..(i + 1) * dim]);
        }
        self.standardize(&mut x);
        let mut pass = Pass::default();
        self.forward(&x, &mut pass);
        let count = x.len() as f64;
        let mse = pass
            .out
            .iter()
            .zip(&x)
            .map(|(o, t)| ((o - t) * (o - t)) as f64)
            .sum::<f64>()
            / count;
        let baseline = x.iter().map(|t| (t * t) as f64).sum::<f64>() / count;
        let zeros = pass.code.iter().filter(|&&c| c == 0.0).count();
        FitReport {
            reconstruction_mse: mse,
            baseline_mse: baseline,
            code_sparsity: zeros as f64 / pass.code.len().max(1) as f64,
        }
    }

    /// The codes of `rows` (cells of `input_dim` values), `code_dim` values per cell.
    pub fn encode(&self, rows: &[f32]) -> Vec<f32> {
        let mut pass = Pass::default();
        let mut out = Vec::with_capacity(rows.len() / self.input_dim() * self.code_dim());
        // Chunks bound the activations' memory on big scenes.
        for chunk in rows.chunks(4096 * self.input_dim()) {
            let mut x = chunk.to_vec();
            self.standardize(&mut x);
            let n = x.len() / self.input_dim();
            self.layers[0].forward(&x, n, &mut pass.h1);
            relu_in_place(&mut pass.h1);
            self.layers[1].forward(&pass.h1, n, &mut pass.code);
            relu_in_place(&mut pass.code);
            out.extend_from_slice(&pass.code);
        }
        out
    }
}

/// Per-channel mean and 1/std (1 for constant channels, which then stay 0).
fn standardization(rows: &[f32], dim: usize) -> (Vec<f32>, Vec<f32>) {
    let n = (rows.len() / dim) as f64;
    let mut sum = vec![0.0f64; dim];
    let mut sq = vec![0.0f64; dim];
    for r in rows.chunks_exact(dim) {
        for (k, &v) in r.iter().enumerate() {
            sum[k] += v as f64;
            sq[k] += (v as f64) * (v as f64);
        }
    }
    let mean: Vec<f32> = sum.iter().map(|s| (s / n) as f32).collect();
    let inv_std = sum
        .iter()
        .zip(&sq)
        .map(|(s, q)| {
            let m = s / n;
            let var = (q / n - m * m).max(0.0);
            if var > 1e-12 { (1.0 / var.sqrt()) as f32 } else { 1.0 }
        })
        .collect();
    (mean, inv_std)
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Features on a 3-d manifold embedded in 12 dims: an autoencoder with a 64-d code must
    /// reconstruct them far better than the mean does.
    fn manifold_rows(n: usize) -> Vec<f32> {
        let mut rng = SplitMix64::new(7);
        let mut rows = Vec::with_capacity(n * 12);
        for _ in 0..n {
            let (a, b, c) = (rng.next_f32(), rng.next_f32(), rng.next_f32());
            for k in 0..12 {
                let k = k as f32;
                rows.push((a * (k + 1.0)).sin() + b * (0.3 * k).cos() * 4.0 + c * c * k);
            }
        }
        rows
    }

    #[test]
    fn fitting_reconstructs_structured_features_and_codes_are_non_negative() {
        let rows = manifold_rows(2000);
        let cfg = AutoencoderConfig {
            hidden: 32,
            code: 16,
            steps: 600,
            batch: 64,
            learning_rate: 3e-3,
            threads: 2,
            ..AutoencoderConfig::default()
        };
        let (ae, report) = Autoencoder::fit(&rows, 12, &cfg, |_, _, _| {});
        assert!(report.reconstruction_mse < 0.1 * report.baseline_mse, "{report:?}");
        let codes = ae.encode(&rows[..120]);
        assert_eq!(codes.len(), 10 * 16);
        assert!(codes.iter().all(|&c| c >= 0.0 && c.is_finite()));
    }

    #[test]
    fn the_gradient_matches_finite_differences() {
        let rows = manifold_rows(5);
        let cfg = AutoencoderConfig {
            hidden: 6,
            code: 4,
            steps: 0,
            batch: 5,
            threads: 1,
            ..Default::default()
        };
        let (mut ae, _) = Autoencoder::fit(&rows, 12, &cfg, |_, _, _| {});
        // Biases away from 0 so few ReLUs sit at their kink.
        for l in ae.layers.iter_mut() {
            l.b.iter_mut().enumerate().for_each(|(i, b)| *b = 0.1 + 0.01 * i as f32);
        }
        let mut x = rows.clone();
        ae.standardize(&mut x);
        let total: usize = ae.layers.iter().map(Dense::params).sum();
        let (grad, _) = ae.gradient(&x, total);
        let mut checked = 0;
        for (k, layer_index) in [(0usize, 0usize), (3, 1), (7, 2), (11, 3)] {
            let offset: usize = ae.layers[..layer_index].iter().map(Dense::params).sum();
            let h = 1e-2f32;
            let mut plus = ae.clone();
            plus.layers[layer_index].w[k] += h;
            let mut minus = ae.clone();
            minus.layers[layer_index].w[k] -= h;
            let numeric = (plus.gradient(&x, total).1 - minus.gradient(&x, total).1) / (2.0 * h as f64);
            let analytic = grad[offset + k] as f64;
            assert!(
                (numeric - analytic).abs() < 2e-2 * (1.0 + analytic.abs()),
                "layer {layer_index} w[{k}]: {numeric} vs {analytic}"
            );
            checked += 1;
        }
        assert_eq!(checked, 4);
    }

    #[test]
    fn fitting_is_deterministic_for_a_seed() {
        let rows = manifold_rows(300);
        let cfg = AutoencoderConfig {
            hidden: 8,
            code: 4,
            steps: 50,
            batch: 32,
            threads: 2,
            ..Default::default()
        };
        let a = Autoencoder::fit(&rows, 12, &cfg, |_, _, _| {}).0.encode(&rows);
        let b = Autoencoder::fit(&rows, 12, &cfg, |_, _, _| {}).0.encode(&rows);
        assert_eq!(a, b);
    }
}
