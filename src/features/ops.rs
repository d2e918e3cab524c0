//! CPU kernels for convolutional feature extractors, on channels-last (HWC) `f32` tensors:
//! depthwise convolutions, im2col and TensorFlow "SAME" padding. The dense layer (1x1 and
//! im2col convolutions, fully connected layers) is the crate's one CPU dense layer,
//! `crate::dense::Dense`, with its activations and thread helpers. Written so
//! that LLVM autovectorizes the inner loops; on x86-64 the same code is also compiled with
//! AVX2+FMA and picked at run time. Work is split over output rows with `std::thread::scope`.
use crate::dense::{Activation, parallel_rows};

/// TensorFlow "SAME" padding of a length-`n` axis for kernel `k` and stride `s`:
/// `(output length, padding before)`. The total padding is `max((ceil(n/s) - 1) * s + k - n, 0)`,
/// the smaller half before, the larger half after.
pub fn same_padding(n: usize, k: usize, s: usize) -> (usize, usize) {
    let out = n.div_ceil(s);
    let total = ((out.max(1) - 1) * s + k).saturating_sub(n);
    (out, total / 2)
}

#[inline(always)]
fn madd<const FMA: bool>(a: f32, b: f32, c: f32) -> f32 {
    if FMA { a.mul_add(b, c) } else { a * b + c }
}

#[cfg(target_arch = "x86_64")]
pub(super) fn has_avx2_fma() -> bool {
    std::is_x86_feature_detected!("avx2") && std::is_x86_feature_detected!("fma")
}

/// A depthwise `k x k` convolution with stride `stride` and SAME padding on `c` channels.
#[derive(Clone, Debug)]
pub struct Depthwise {
    pub c: usize,
    pub k: usize,
    pub stride: usize,
    /// `weight[(ky * k + kx) * c + ch]`.
    weight: Vec<f32>,
    bias: Vec<f32>,
}

impl Depthwise {
    /// From `weight[ch * k * k + ky * k + kx]` (PyTorch's `[c, 1, k, k]` layout) and `bias[ch]`.
    pub fn new(c: usize, k: usize, stride: usize, weight: &[f32], bias: &[f32]) -> Self {
        assert_eq!(weight.len(), c * k * k, "weight size");
        assert_eq!(bias.len(), c, "bias size");
        let mut w = vec![0.0; c * k * k];
        for ch in 0..c {
            for t in 0..k * k {
                w[t * c + ch] = weight[ch * k * k + t];
            }
        }
        Depthwise {
            c,
            k,
            stride,
            weight: w,
            bias: bias.to_vec(),
        }
    }

    /// The output grid for an `h x w` input.
    pub fn output_size(&self, h: usize, w: usize) -> (usize, usize) {
        (
            same_padding(h, self.k, self.stride).0,
            same_padding(w, self.k, self.stride).0,
        )
    }

    /// `act(conv(x) + b)` of the `h x w x c` input `x`; `oh x ow x c` values out.
    pub fn forward(&self, x: &[f32], h: usize, w: usize, act: Activation, threads: usize) -> Vec<f32> {
        assert_eq!(x.len(), h * w * self.c, "input size");
        let (oh, ow) = self.output_size(h, w);
        let mut out = vec![0.0; oh * ow * self.c];
        parallel_rows(&mut out, ow * self.c, threads, 1, |oy0, chunk| {
            let job = DepthwiseJob {
                layer: self,
                x,
                h,
                w,
                act,
                oy0,
            };
            #[cfg(target_arch = "x86_64")]
            if has_avx2_fma() {
                // SAFETY: the CPU supports AVX2 and FMA (checked just above).
                unsafe { depthwise_rows_avx2(&job, chunk) };
                return;
            }
            depthwise_rows::<false>(&job, chunk);
        });
        out
    }
}

struct DepthwiseJob<'a> {
    layer: &'a Depthwise,
    x: &'a [f32],
    h: usize,
    w: usize,
    act: Activation,
    oy0: usize,
}

#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx2,fma")]
fn depthwise_rows_avx2(job: &DepthwiseJob, out: &mut [f32]) {
    depthwise_rows::<true>(job, out)
}

#[inline(always)]
fn depthwise_rows<const FMA: bool>(job: &DepthwiseJob, out: &mut [f32]) {
    let d = job.layer;
    let (c, k, s) = (d.c, d.k, d.stride);
    let (h, w) = (job.h, job.w);
    let (_, pad_y) = same_padding(h, k, s);
    let (ow, pad_x) = same_padding(w, k, s);
    for (row, out_row) in out.chunks_exact_mut(ow * c).enumerate() {
        let oy = job.oy0 + row;
        for (ox, o) in out_row.chunks_exact_mut(c).enumerate() {
            o.copy_from_slice(&d.bias);
            for ky in 0..k {
                let Some(iy) = (oy * s + ky).checked_sub(pad_y).filter(|&iy| iy < h) else {
                    continue;
                };
                for kx in 0..k {
                    let Some(ix) = (ox * s + kx).checked_sub(pad_x).filter(|&ix| ix < w) else {
                        continue;
                    };
                    let input = &job.x[(iy * w + ix) * c..][..c];
                    let wt = &d.weight[(ky * k + kx) * c..][..c];
                    for ((o, &a), &b) in o.iter_mut().zip(input).zip(wt) {
                        *o = madd::<FMA>(a, b, *o);
                    }
                }
            }
            for v in o.iter_mut() {
                *v = job.act.apply(*v);
            }
        }
    }
}

/// The patches of a `k x k`, stride `s`, SAME-padded convolution of the `h x w x c` input:
/// `(rows, oh, ow)`, one row of `k * k * c` values per output pixel in `(ky, kx, ch)` order,
/// zeros where the window leaves the image.
pub fn im2col(x: &[f32], h: usize, w: usize, c: usize, k: usize, s: usize) -> (Vec<f32>, usize, usize) {
    assert_eq!(x.len(), h * w * c, "input size");
    let (oh, pad_y) = same_padding(h, k, s);
    let (ow, pad_x) = same_padding(w, k, s);
    let mut out = vec![0.0; oh * ow * k * k * c];
    for (p, patch) in out.chunks_exact_mut(k * k * c).enumerate() {
        let (oy, ox) = (p / ow, p % ow);
        for ky in 0..k {
            let Some(iy) = (oy * s + ky).checked_sub(pad_y).filter(|&iy| iy < h) else {
                continue;
            };
            for kx in 0..k {
                let Some(ix) = (ox * s + kx).checked_sub(pad_x).filter(|&ix| ix < w) else {
                    continue;
                };
                patch[(ky * k + kx) * c..][..c].copy_from_slice(&x[(iy * w + ix) * c..][..c]);
            }
        }
    }
    (out, oh, ow)
}

/// Reorders a PyTorch convolution weight `[out, in, k, k]` to `[out, k, k, in]`, the row order of
/// [`im2col`], so that the convolution is `Dense::new(k * k * in, out, ..)` on its patches.
pub fn conv_weight_to_im2col(weight: &[f32], cout: usize, cin: usize, k: usize) -> Vec<f32> {
    assert_eq!(weight.len(), cout * cin * k * k, "weight size");
    let mut out = vec![0.0; weight.len()];
    for o in 0..cout {
        for i in 0..cin {
            for t in 0..k * k {
                out[(o * k * k + t) * cin + i] = weight[((o * cin + i) * k * k) + t];
            }
        }
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::dense::Dense;
    use crate::dense::test_support::{assert_close, noise};

    #[test]
    fn same_padding_matches_tensorflow() {
        // (n, k, s) -> (out, before); TF puts the odd pixel of padding after.
        assert_eq!(same_padding(224, 3, 2), (112, 0));
        assert_eq!(same_padding(225, 3, 2), (113, 1));
        assert_eq!(same_padding(112, 3, 1), (112, 1));
        assert_eq!(same_padding(56, 5, 2), (28, 1));
        assert_eq!(same_padding(57, 5, 2), (29, 2));
        assert_eq!(same_padding(7, 5, 1), (7, 2));
        assert_eq!(same_padding(1, 1, 1), (1, 0));
        assert_eq!(same_padding(5, 1, 2), (3, 0));
    }

    /// A naive depthwise convolution with explicit zero padding, channels first.
    fn naive_depthwise(x: &[f32], shape: (usize, usize, usize, usize, usize), wt: &[f32], b: &[f32]) -> Vec<f64> {
        let (h, w, c, k, s) = shape;
        let (oh, py) = same_padding(h, k, s);
        let (ow, px) = same_padding(w, k, s);
        let mut out = vec![0f64; oh * ow * c];
        for ch in 0..c {
            for oy in 0..oh {
                for ox in 0..ow {
                    let mut v = b[ch] as f64;
                    for ky in 0..k {
                        for kx in 0..k {
                            let iy = (oy * s + ky) as isize - py as isize;
                            let ix = (ox * s + kx) as isize - px as isize;
                            if iy >= 0 && ix >= 0 && (iy as usize) < h && (ix as usize) < w {
                                let xv = x[(iy as usize * w + ix as usize) * c + ch] as f64;
                                v += xv * wt[ch * k * k + ky * k + kx] as f64;
                            }
                        }
                    }
                    out[(oy * ow + ox) * c + ch] = v;
                }
            }
        }
        out
    }

    #[test]
    fn depthwise_convolution_matches_naive_loops() {
        for &(h, w, c, k, s) in &[
            (9, 7, 5, 3, 1),
            (9, 7, 5, 3, 2),
            (10, 12, 19, 5, 2),
            (6, 5, 8, 5, 1),
            (4, 4, 3, 5, 2),
        ] {
            let x = noise(h * w * c, 5);
            let wt = noise(c * k * k, 6);
            let b = noise(c, 7);
            let layer = Depthwise::new(c, k, s, &wt, &b);
            let want = naive_depthwise(&x, (h, w, c, k, s), &wt, &b);
            for threads in [1, 2, 4] {
                assert_close(&layer.forward(&x, h, w, Activation::None, threads), &want, 1e-5);
            }
            let relu: Vec<f64> = want.iter().map(|v| v.clamp(0.0, 6.0)).collect();
            assert_close(&layer.forward(&x, h, w, Activation::Relu6, 2), &relu, 1e-5);
        }
    }

    #[test]
    fn im2col_and_dense_make_a_same_padded_strided_convolution() {
        let (h, w, cin, cout, k, s) = (11, 8, 3, 6, 3, 2);
        let x = noise(h * w * cin, 8);
        let wt = noise(cout * cin * k * k, 9);
        let b = noise(cout, 10);
        let (patches, oh, ow) = im2col(&x, h, w, cin, k, s);
        let layer = Dense::new(k * k * cin, cout, &conv_weight_to_im2col(&wt, cout, cin, k), &b);
        let got = layer.forward(&patches, Activation::None, None, 2);
        let (_, py) = same_padding(h, k, s);
        let (_, px) = same_padding(w, k, s);
        let mut want = vec![0f64; oh * ow * cout];
        for oy in 0..oh {
            for ox in 0..ow {
                for o in 0..cout {
                    let mut v = b[o] as f64;
                    for i in 0..cin {
                        for ky in 0..k {
                            for kx in 0..k {
                                let iy = (oy * s + ky) as isize - py as isize;
                                let ix = (ox * s + kx) as isize - px as isize;
                                if iy >= 0 && ix >= 0 && (iy as usize) < h && (ix as usize) < w {
                                    v += x[(iy as usize * w + ix as usize) * cin + i] as f64
                                        * wt[((o * cin + i) * k + ky) * k + kx] as f64;
                                }
                            }
                        }
                    }
                    want[(oy * ow + ox) * cout + o] = v;
                }
            }
        }
        assert_close(&got, &want, 1e-5);
    }

    fn cpu_seconds() -> f64 {
        let stat = std::fs::read_to_string("/proc/self/stat").unwrap_or_default();
        let fields: Vec<&str> = stat.rsplit_once(')').map_or("", |r| r.1).split_whitespace().collect();
        let ticks = |i: usize| fields.get(i).and_then(|v| v.parse::<f64>().ok()).unwrap_or(f64::NAN);
        (ticks(11) + ticks(12)) / 100.0
    }

    /// Timing, not a test: `cargo test --release --lib ops::tests::bench -- --ignored --nocapture`.
    #[test]
    #[ignore]
    fn bench_kernels() {
        let time = |name: &str, macs: usize, f: &dyn Fn()| {
            f();
            let (t0, c0) = (std::time::Instant::now(), cpu_seconds());
            let runs = 10;
            for _ in 0..runs {
                f();
            }
            let wall = t0.elapsed().as_secs_f64() / runs as f64;
            let cpu = (cpu_seconds() - c0) / runs as f64;
            println!(
                "{name}: {:.2} ms wall, {:.2} ms CPU, {:.1} GFLOP/s per CPU-second",
                wall * 1e3,
                cpu * 1e3,
                2.0 * macs as f64 / cpu / 1e9
            );
        };
        for &(rows, cin, cout) in &[
            (19200, 24, 144),
            (19200, 144, 24),
            (4800, 40, 240),
            (4800, 240, 40),
            (1200, 480, 80),
        ] {
            let x = noise(rows * cin, 1);
            let layer = Dense::new(cin, cout, &noise(cin * cout, 2), &noise(cout, 3));
            time(&format!("dense {rows}x{cin} -> {cout}"), rows * cin * cout, &|| {
                std::hint::black_box(layer.forward(&x, Activation::Relu6, None, 1));
            });
        }
        for &(h, w, c, k, s) in &[(120, 160, 144, 5, 2), (60, 80, 240, 3, 1), (240, 320, 96, 3, 2)] {
            let x = noise(h * w * c, 4);
            let layer = Depthwise::new(c, k, s, &noise(c * k * k, 5), &noise(c, 6));
            let (oh, ow) = layer.output_size(h, w);
            time(
                &format!("depthwise {h}x{w}x{c} k{k} s{s}"),
                oh * ow * c * k * k,
                &|| {
                    std::hint::black_box(layer.forward(&x, h, w, Activation::Relu6, 1));
                },
            );
        }
    }
}
