//! The batched `f32` engine of the dense layer: `act(x Wᵀ + b + residual)` for many rows at
//! once, through a packed, register-blocked matrix product (LLVM autovectorizes the inner loops;
//! on x86-64 the same code is also compiled with AVX2+FMA and picked at run time), with the work
//! split over output rows with `std::thread::scope`.

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

#[inline(always)]
fn madd<const FMA: bool>(a: f32, b: f32, c: f32) -> f32 {
    if FMA { a.mul_add(b, c) } else { a * b + c }
}

#[cfg(target_arch = "x86_64")]
fn has_avx2_fma() -> bool {
    std::is_x86_feature_detected!("avx2") && std::is_x86_feature_detected!("fma")
}

/// Output columns per packed weight panel and rows per micro-kernel call.
const NR: usize = 16;
const MR: usize = 4;
/// Rows per cache block: a panel (`cin * NR` values) is reused over this many rows.
const MC: usize = 64;

/// A fully connected layer `y = x W^T + b` on rows of `cin` values, with `W` packed in panels of
/// `NR` output columns (`panels[p][k][j] = W[p * NR + j][k]`, zero past `cout`).
#[derive(Clone, Debug)]
pub struct Dense {
    pub cin: usize,
    pub cout: usize,
    panels: Vec<f32>,
    bias: Vec<f32>,
}

impl Dense {
    /// From `weight[o * cin + i]` (PyTorch's `[out, in]` layout) and `bias[o]`.
    pub fn new(cin: usize, cout: usize, weight: &[f32], bias: &[f32]) -> Self {
        assert_eq!(weight.len(), cin * cout, "weight size");
        assert_eq!(bias.len(), cout, "bias size");
        let np = cout.div_ceil(NR);
        let mut panels = vec![0.0; np * cin * NR];
        for o in 0..cout {
            for i in 0..cin {
                panels[(o / NR) * cin * NR + i * NR + o % NR] = weight[o * cin + i];
            }
        }
        let mut padded = vec![0.0; np * NR];
        padded[..cout].copy_from_slice(bias);
        Dense {
            cin,
            cout,
            panels,
            bias: padded,
        }
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
        parallel_rows(out, self.cout, threads, MR, |row0, chunk| {
            let job = DenseJob {
                layer: self,
                x,
                residual,
                act,
                row0,
            };
            #[cfg(target_arch = "x86_64")]
            if has_avx2_fma() {
                // SAFETY: the CPU supports AVX2 and FMA (checked just above).
                unsafe { dense_rows_avx2(&job, chunk) };
                return;
            }
            dense_rows::<false>(&job, chunk);
        });
    }

    /// Multiply-adds per input row.
    pub fn macs_per_row(&self) -> usize {
        self.cin * self.cout
    }
}

struct DenseJob<'a> {
    layer: &'a Dense,
    x: &'a [f32],
    residual: Option<&'a [f32]>,
    act: Activation,
    /// The first row (of `x`) of the output chunk.
    row0: usize,
}

#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx2,fma")]
fn dense_rows_avx2(job: &DenseJob, out: &mut [f32]) {
    dense_rows::<true>(job, out)
}

/// `bias + sum_k x_r[k] * panel[k]` for 4 rows: 4 x `NR` accumulators that stay in registers.
#[inline(always)]
fn micro_kernel<const FMA: bool>(panel: &[f32], x: [&[f32]; MR], bias: &[f32; NR]) -> [[f32; NR]; MR] {
    let mut acc = [*bias; MR];
    for ((((w, &a0), &a1), &a2), &a3) in panel.chunks_exact(NR).zip(x[0]).zip(x[1]).zip(x[2]).zip(x[3]) {
        let w: &[f32; NR] = w.try_into().unwrap();
        for j in 0..NR {
            acc[0][j] = madd::<FMA>(a0, w[j], acc[0][j]);
            acc[1][j] = madd::<FMA>(a1, w[j], acc[1][j]);
            acc[2][j] = madd::<FMA>(a2, w[j], acc[2][j]);
            acc[3][j] = madd::<FMA>(a3, w[j], acc[3][j]);
        }
    }
    acc
}

#[inline(always)]
fn dense_rows<const FMA: bool>(job: &DenseJob, out: &mut [f32]) {
    let d = job.layer;
    let (cin, cout) = (d.cin, d.cout);
    let n = out.len() / cout;
    // Rows past the end of a chunk (at most 3) read zeros.
    let zeros = vec![0.0; cin];
    let xrow = |r: usize| {
        if r < n {
            &job.x[(job.row0 + r) * cin..][..cin]
        } else {
            &zeros[..]
        }
    };
    for mc in (0..n).step_by(MC) {
        let mend = (mc + MC).min(n);
        for (p, panel) in d.panels.chunks_exact(cin * NR).enumerate() {
            let c0 = p * NR;
            let cw = NR.min(cout - c0);
            let bias: &[f32; NR] = d.bias[c0..c0 + NR].try_into().unwrap();
            for r in (mc..mend).step_by(MR) {
                let acc = micro_kernel::<FMA>(panel, [xrow(r), xrow(r + 1), xrow(r + 2), xrow(r + 3)], bias);
                for (i, acc) in acc.iter().enumerate() {
                    let row = r + i;
                    if row >= mend {
                        break;
                    }
                    let o = &mut out[row * cout + c0..][..cw];
                    match job.residual {
                        Some(res) => {
                            let res = &res[(job.row0 + row) * cout + c0..][..cw];
                            for ((o, &a), &s) in o.iter_mut().zip(acc).zip(res) {
                                *o = job.act.apply(a + s);
                            }
                        }
                        None => {
                            for (o, &a) in o.iter_mut().zip(acc) {
                                *o = job.act.apply(a);
                            }
                        }
                    }
                }
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::dense::DenseLayer;

    /// A deterministic pseudo-random sequence in [-1, 1).
    fn noise(n: usize, seed: u64) -> Vec<f32> {
        let mut s = seed.wrapping_mul(6364136223846793005).wrapping_add(1442695040888963407);
        (0..n)
            .map(|_| {
                s = s.wrapping_mul(6364136223846793005).wrapping_add(1442695040888963407);
                ((s >> 40) as f32 / (1u64 << 24) as f32) * 2.0 - 1.0
            })
            .collect()
    }

    fn assert_close(a: &[f32], b: &[f64], tol: f64) {
        assert_eq!(a.len(), b.len());
        for (i, (&a, &b)) in a.iter().zip(b).enumerate() {
            assert!((a as f64 - b).abs() <= tol * (1.0 + b.abs()), "element {i}: {a} vs {b}");
        }
    }

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
