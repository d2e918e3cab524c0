//! DINO ViT-S/8 (Caron et al. 2021) on the CPU: dense features at stride 8 from the last block.
//!
//! **This has never been run on the real DINO weights** (none are available here). It is tested
//! only with small random weights against an independent naive `f64` implementation in the tests
//! below, written from the DINO repository's `vision_transformer.py` (timm-style blocks). See
//! `docs/features.md`.
//!
//! The architecture: an 8x8 stride-8 patch embedding (a convolution 3 -> dim), a class token, a
//! position embedding for the 224x224 training grid that is bicubically resampled to the patch
//! grid (DINO's `interpolate_pos_encoding`, with its `+ 0.1`), pre-norm transformer blocks
//! (`x + proj(attn(norm1(x)))`, `x + fc2(gelu(fc1(norm2(x))))`, LayerNorm eps 1e-6, exact GELU,
//! softmax attention with scale `head_dim^-0.5`) and a final LayerNorm. The input is the ImageNet
//! normalisation of the RGB frame, `(pixel / 255 - mean) / std`.
//!
//! Names are those of the official DINO checkpoints (`cls_token`, `pos_embed`,
//! `patch_embed.proj.weight`, `blocks.N.norm1.weight`, `blocks.N.attn.qkv.weight`, ...,
//! `norm.weight`), converted to safetensors; the dimensions are read from the tensors' shapes and
//! the number of heads is given (6 for ViT-S).
use super::ops::{self, Activation, Dense};
use super::safetensors::SafeTensors;
use super::{Extractor, FeatureError, FeatureMap};
use image::RgbImage;
use std::ffi::OsString;
use std::path::{Path, PathBuf};

/// The environment variable that names the weights file when no flag does.
pub const WEIGHTS_ENV: &str = "SCRIBBLEFIELD_DINO";
/// Where the weights are looked for last, relative to the working directory.
pub const DEFAULT_WEIGHTS: &str = "../shared/models/dino-vits8/dino-vits8.safetensors";
/// ViT-S/8: heads, width, depth, MLP width, patch size.
pub const VITS8_HEADS: usize = 6;
pub const VITS8_DIM: usize = 384;
pub const VITS8_DEPTH: usize = 12;
pub const VITS8_MLP: usize = 1536;
pub const VITS8_PATCH: usize = 8;

const LN_EPS: f32 = 1e-6;
const IMAGENET_MEAN: [f32; 3] = [0.485, 0.456, 0.406];
const IMAGENET_STD: [f32; 3] = [0.229, 0.224, 0.225];
/// Query rows per attention chunk (bounds the score matrix to `CHUNK x tokens`).
const CHUNK: usize = 1024;

/// Where to get the weights, for [`FeatureError::Missing`].
pub fn weights_hint() -> String {
    format!(
        "convert the official DINO ViT-S/8 checkpoint dino_deitsmall8_pretrain.pth (from the DINO \
         repository's README) tensor-for-tensor to safetensors (docs/features.md, section \"DINO \
         ViT-S/8\"), and name the file with the flag or {WEIGHTS_ENV}; note that this extractor has \
         never been run on the real weights"
    )
}

/// The weights file: `flag`, else `$SCRIBBLEFIELD_DINO` (if set and not empty), else
/// [`DEFAULT_WEIGHTS`]; an error if that file is absent.
pub fn resolve_weights(flag: Option<&Path>) -> Result<PathBuf, FeatureError> {
    resolve_weights_from(flag, std::env::var_os(WEIGHTS_ENV))
}

/// [`resolve_weights`] with the environment variable's value given.
pub fn resolve_weights_from(flag: Option<&Path>, env: Option<OsString>) -> Result<PathBuf, FeatureError> {
    super::weights::resolve_weights_file(
        flag,
        env,
        WEIGHTS_ENV,
        DEFAULT_WEIGHTS,
        "DINO ViT-S/8 weights",
        weights_hint,
    )
}

/// The network input for an RGB frame: ImageNet-normalised, channels last, padded by repeating
/// the last row and column up to a multiple of `patch` pixels.
pub fn input_from_rgb(rgb: &RgbImage, patch: usize) -> FeatureMap {
    let (w, h) = (rgb.width() as usize, rgb.height() as usize);
    let (pw, ph) = (w.div_ceil(patch) * patch, h.div_ceil(patch) * patch);
    let mut data = Vec::with_capacity(pw * ph * 3);
    for y in 0..ph {
        for x in 0..pw {
            let p = rgb.get_pixel(x.min(w - 1) as u32, y.min(h - 1) as u32).0;
            for c in 0..3 {
                data.push((p[c] as f32 / 255.0 - IMAGENET_MEAN[c]) / IMAGENET_STD[c]);
            }
        }
    }
    FeatureMap {
        height: ph as u32,
        width: pw as u32,
        dim: 3,
        data,
    }
}

#[derive(Clone, Debug)]
struct LayerNorm {
    weight: Vec<f32>,
    bias: Vec<f32>,
}

impl LayerNorm {
    fn load(st: &SafeTensors, prefix: &str, dim: usize) -> Result<Self, FeatureError> {
        Ok(LayerNorm {
            weight: st.f32(&format!("{prefix}.weight"), &[dim])?,
            bias: st.f32(&format!("{prefix}.bias"), &[dim])?,
        })
    }

    fn forward(&self, x: &[f32], threads: usize) -> Vec<f32> {
        let d = self.weight.len();
        let mut out = vec![0.0; x.len()];
        ops::parallel_rows(&mut out, d, threads, 16, |row0, chunk| {
            for (r, o) in chunk.chunks_exact_mut(d).enumerate() {
                let row = &x[(row0 + r) * d..][..d];
                let mean = row.iter().map(|&v| v as f64).sum::<f64>() / d as f64;
                let var = row.iter().map(|&v| (v as f64 - mean).powi(2)).sum::<f64>() / d as f64;
                let inv = 1.0 / (var + LN_EPS as f64).sqrt();
                for (((o, &v), &g), &b) in o.iter_mut().zip(row).zip(&self.weight).zip(&self.bias) {
                    *o = ((v as f64 - mean) * inv) as f32 * g + b;
                }
            }
        });
        out
    }
}

fn linear(st: &SafeTensors, prefix: &str, cin: usize, cout: usize) -> Result<Dense, FeatureError> {
    let w = st.f32(&format!("{prefix}.weight"), &[cout, cin])?;
    let b = st.f32(&format!("{prefix}.bias"), &[cout])?;
    Ok(Dense::new(cin, cout, &w, &b))
}

#[derive(Clone, Debug)]
struct VitBlock {
    norm1: LayerNorm,
    qkv: Dense,
    proj: Dense,
    norm2: LayerNorm,
    fc1: Dense,
    fc2: Dense,
}

/// What the dense map holds for each patch.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum DinoOutput {
    /// The patch tokens after the last block and the final LayerNorm.
    Tokens,
    /// The last block's attention keys (all heads side by side), often better for matching.
    Keys,
}

/// A DINO vision transformer with its weights.
#[derive(Clone, Debug)]
pub struct DinoVit {
    pub dim: usize,
    pub heads: usize,
    pub patch: usize,
    patch_embed: Dense,
    cls: Vec<f32>,
    /// The class token's position embedding and the patches' (`side x side x dim`).
    pos_cls: Vec<f32>,
    pos_patches: Vec<f32>,
    pos_side: usize,
    blocks: Vec<VitBlock>,
    norm: LayerNorm,
    threads: usize,
}

impl DinoVit {
    /// Loads DINO ViT-S/8 from `path`, checking that the file is one (width 384, patch 8,
    /// 12 blocks, MLP 1536).
    pub fn load_vits8(path: &Path) -> Result<Self, FeatureError> {
        let st = SafeTensors::open(&resolve_weights_from(Some(path), None)?)?;
        let vit = Self::from_safetensors(&st, VITS8_HEADS)?;
        let mlp = vit.blocks.first().map_or(0, |b| b.fc1.cout);
        if (vit.dim, vit.patch, vit.blocks.len(), mlp) != (VITS8_DIM, VITS8_PATCH, VITS8_DEPTH, VITS8_MLP) {
            return Err(FeatureError::invalid(
                st.file(),
                format!(
                    "not ViT-S/8: width {}, patch {}, {} blocks, MLP {} (expected {VITS8_DIM}, {VITS8_PATCH}, \
                     {VITS8_DEPTH}, {VITS8_MLP})",
                    vit.dim,
                    vit.patch,
                    vit.blocks.len(),
                    mlp
                ),
            ));
        }
        Ok(vit)
    }

    /// Any DINO ViT with `heads` heads; width, patch size, depth and MLP width from the shapes.
    pub fn from_safetensors(st: &SafeTensors, heads: usize) -> Result<Self, FeatureError> {
        let bad = |problem: String| FeatureError::invalid(st.file(), problem);
        let shape = |name: &str| {
            st.info(name)
                .map(|i| i.shape.clone())
                .ok_or_else(|| bad(format!("tensor `{name}` missing")))
        };
        let pe = shape("patch_embed.proj.weight")?;
        let [dim, 3, patch, p2] = pe[..] else {
            return Err(bad(format!(
                "tensor `patch_embed.proj.weight` has shape {pe:?}, expected [dim, 3, p, p]"
            )));
        };
        if p2 != patch || patch == 0 || heads == 0 || !dim.is_multiple_of(heads) {
            return Err(bad(format!("patch embedding {pe:?} with {heads} heads")));
        }
        let w = st.f32("patch_embed.proj.weight", &pe)?;
        let b = st.f32("patch_embed.proj.bias", &[dim])?;
        let patch_embed = Dense::new(
            3 * patch * patch,
            dim,
            &ops::conv_weight_to_im2col(&w, dim, 3, patch),
            &b,
        );
        let cls = st.f32("cls_token", &[1, 1, dim])?;
        let pos_shape = shape("pos_embed")?;
        let tokens = match pos_shape[..] {
            [1, t, d] if d == dim && t >= 2 => t,
            _ => {
                return Err(bad(format!(
                    "tensor `pos_embed` has shape {pos_shape:?}, expected [1, 1 + n, {dim}]"
                )));
            }
        };
        let pos_side = ((tokens - 1) as f64).sqrt().round() as usize;
        if pos_side * pos_side != tokens - 1 {
            return Err(bad(format!(
                "tensor `pos_embed`: {} patch positions is not a square grid",
                tokens - 1
            )));
        }
        let pos = st.f32("pos_embed", &pos_shape)?;
        let mut blocks = Vec::new();
        while st.info(&format!("blocks.{}.norm1.weight", blocks.len())).is_some() {
            let p = format!("blocks.{}", blocks.len());
            let mlp = shape(&format!("{p}.mlp.fc1.weight"))?[0];
            blocks.push(VitBlock {
                norm1: LayerNorm::load(st, &format!("{p}.norm1"), dim)?,
                qkv: linear(st, &format!("{p}.attn.qkv"), dim, 3 * dim)?,
                proj: linear(st, &format!("{p}.attn.proj"), dim, dim)?,
                norm2: LayerNorm::load(st, &format!("{p}.norm2"), dim)?,
                fc1: linear(st, &format!("{p}.mlp.fc1"), dim, mlp)?,
                fc2: linear(st, &format!("{p}.mlp.fc2"), mlp, dim)?,
            });
        }
        if blocks.is_empty() {
            return Err(bad(
                "tensor `blocks.0.norm1.weight` missing (no transformer blocks)".into()
            ));
        }
        Ok(DinoVit {
            dim,
            heads,
            patch,
            patch_embed,
            cls,
            pos_cls: pos[..dim].to_vec(),
            pos_patches: pos[dim..].to_vec(),
            pos_side,
            blocks,
            norm: LayerNorm::load(st, "norm", dim)?,
            threads: ops::default_threads(),
        })
    }

    pub fn with_threads(mut self, threads: usize) -> Self {
        self.threads = threads.max(1);
        self
    }

    pub fn depth(&self) -> usize {
        self.blocks.len()
    }

    /// The patch position embeddings for a `gh x gw` grid (`gh * gw * dim` values): as trained
    /// for the square training grid, else bicubically resampled like DINO's
    /// `interpolate_pos_encoding` (PyTorch `interpolate(mode="bicubic", align_corners=False)`
    /// with scale factors `(g + 0.1) / side`).
    pub fn position_embedding(&self, gh: usize, gw: usize) -> Vec<f32> {
        let (n, d) = (self.pos_side, self.dim);
        if (gh, gw) == (n, n) {
            return self.pos_patches.clone();
        }
        let taps = |g: usize| -> Vec<[(usize, f64); 4]> {
            let ratio = n as f64 / (g as f64 + 0.1);
            (0..g)
                .map(|o| {
                    let src = ratio * (o as f64 + 0.5) - 0.5;
                    let i0 = src.floor();
                    let w = cubic_weights(src - i0);
                    std::array::from_fn(|j| ((i0 as isize - 1 + j as isize).clamp(0, n as isize - 1) as usize, w[j]))
                })
                .collect()
        };
        let (ty, tx) = (taps(gh), taps(gw));
        let mut out = vec![0.0; gh * gw * d];
        let mut acc = vec![0f64; d];
        for (oy, wy) in ty.iter().enumerate() {
            for (ox, wx) in tx.iter().enumerate() {
                acc.iter_mut().for_each(|a| *a = 0.0);
                for &(iy, a) in wy {
                    for &(ix, b) in wx {
                        let p = &self.pos_patches[(iy * n + ix) * d..][..d];
                        acc.iter_mut().zip(p).for_each(|(s, &v)| *s += a * b * v as f64);
                    }
                }
                for (o, &a) in out[(oy * gw + ox) * d..][..d].iter_mut().zip(&acc) {
                    *o = a as f32;
                }
            }
        }
        out
    }

    /// The dense map (`H/patch x W/patch x dim`) of a normalised input whose sides are multiples
    /// of the patch size ([`input_from_rgb`]).
    pub fn forward(&self, input: &FeatureMap, output: DinoOutput) -> FeatureMap {
        let (h, w, p, d) = (input.height as usize, input.width as usize, self.patch, self.dim);
        assert!(
            input.dim == 3 && h.is_multiple_of(p) && w.is_multiple_of(p),
            "input not padded to patches"
        );
        let (patches, gh, gw) = ops::im2col(&input.data, h, w, 3, p, p);
        let embedded = self.patch_embed.forward(&patches, Activation::None, None, self.threads);
        let pos = self.position_embedding(gh, gw);
        let tokens = 1 + gh * gw;
        let mut x = Vec::with_capacity(tokens * d);
        x.extend(self.cls.iter().zip(&self.pos_cls).map(|(a, b)| a + b));
        x.extend(embedded.iter().zip(&pos).map(|(a, b)| a + b));
        let last = self.blocks.len() - 1;
        for (i, block) in self.blocks.iter().enumerate() {
            if i == last && output == DinoOutput::Keys {
                let qkv = block.qkv.forward(
                    &block.norm1.forward(&x, self.threads),
                    Activation::None,
                    None,
                    self.threads,
                );
                let mut keys = Vec::with_capacity(gh * gw * d);
                for row in qkv.chunks_exact(3 * d).skip(1) {
                    keys.extend_from_slice(&row[d..2 * d]);
                }
                return map(gh, gw, d, keys);
            }
            x = self.block(block, x, tokens);
        }
        let x = self.norm.forward(&x, self.threads);
        map(gh, gw, d, x[d..].to_vec())
    }

    fn block(&self, b: &VitBlock, x: Vec<f32>, tokens: usize) -> Vec<f32> {
        let (d, t) = (self.dim, self.threads);
        let qkv = b.qkv.forward(&b.norm1.forward(&x, t), Activation::None, None, t);
        let attended = self.attention(&qkv, tokens);
        let x = b.proj.forward(&attended, Activation::None, Some(&x), t);
        let hidden = b.fc1.forward(&b.norm2.forward(&x, t), Activation::Gelu, None, t);
        let x = b.fc2.forward(&hidden, Activation::None, Some(&x), t);
        debug_assert_eq!(x.len(), tokens * d);
        x
    }

    /// Multi-head softmax attention of `qkv` (`tokens x 3 dim`: q, k, v, each heads side by side).
    fn attention(&self, qkv: &[f32], tokens: usize) -> Vec<f32> {
        let (d, hd, t) = (self.dim, self.dim / self.heads, self.threads);
        let scale = (hd as f32).powf(-0.5);
        let zeros_t = vec![0.0; tokens];
        let zeros_hd = vec![0.0; hd];
        let mut out = vec![0.0; tokens * d];
        for head in 0..self.heads {
            let column = |part: usize, row: &[f32]| row[part * d + head * hd..][..hd].to_vec();
            let q: Vec<f32> = qkv
                .chunks_exact(3 * d)
                .flat_map(|r| column(0, r))
                .map(|v| v * scale)
                .collect();
            let k: Vec<f32> = qkv.chunks_exact(3 * d).flat_map(|r| column(1, r)).collect();
            let mut vt = vec![0.0; hd * tokens];
            for (i, r) in qkv.chunks_exact(3 * d).enumerate() {
                for (j, &v) in r[2 * d + head * hd..][..hd].iter().enumerate() {
                    vt[j * tokens + i] = v;
                }
            }
            // Scores are `q . k_j` for every key j: a dense layer whose weight rows are the keys.
            let keys = Dense::new(hd, tokens, &k, &zeros_t);
            let values = Dense::new(tokens, hd, &vt, &zeros_hd);
            for (c, qc) in q.chunks(CHUNK * hd).enumerate() {
                let mut scores = keys.forward(qc, Activation::None, None, t);
                ops::parallel_rows(&mut scores, tokens, t, 8, |_, rows| {
                    for row in rows.chunks_exact_mut(tokens) {
                        let max = row.iter().cloned().fold(f32::NEG_INFINITY, f32::max);
                        let mut sum = 0.0;
                        for v in row.iter_mut() {
                            *v = (*v - max).exp();
                            sum += *v;
                        }
                        let inv = 1.0 / sum;
                        row.iter_mut().for_each(|v| *v *= inv);
                    }
                });
                let o = values.forward(&scores, Activation::None, None, t);
                for (r, orow) in o.chunks_exact(hd).enumerate() {
                    let token = c * CHUNK + r;
                    out[token * d + head * hd..][..hd].copy_from_slice(orow);
                }
            }
        }
        out
    }
}

fn map(height: usize, width: usize, dim: usize, data: Vec<f32>) -> FeatureMap {
    FeatureMap {
        height: height as u32,
        width: width as u32,
        dim: dim as u32,
        data,
    }
}

/// PyTorch's bicubic weights (A = -0.75) for the 4 taps around a sample at fraction `t`.
fn cubic_weights(t: f64) -> [f64; 4] {
    const A: f64 = -0.75;
    let near = |x: f64| ((A + 2.0) * x - (A + 3.0)) * x * x + 1.0;
    let far = |x: f64| ((A * x - 5.0 * A) * x + 8.0 * A) * x - 4.0 * A;
    [far(t + 1.0), near(t), near(1.0 - t), far(2.0 - t)]
}

/// Dense DINO features of a frame at stride `patch` (8): `ceil(H/8) x ceil(W/8)` cells (the
/// frame is padded by repeating its last row and column).
pub struct DinoExtractor {
    pub vit: DinoVit,
    pub output: DinoOutput,
}

impl Extractor for DinoExtractor {
    fn describe(&self) -> String {
        let what = match self.output {
            DinoOutput::Tokens => "tokens",
            DinoOutput::Keys => "keys",
        };
        format!(
            "dino-vit dim {} patch {} {what} stride {}",
            self.vit.dim, self.vit.patch, self.vit.patch
        )
    }

    /// Errors with frame 0 for frames smaller than a patch (the caller knows the index).
    fn extract(&self, rgb: &RgbImage) -> Result<FeatureMap, FeatureError> {
        let (w, h) = rgb.dimensions();
        if (w.min(h) as usize) < self.vit.patch {
            return Err(FeatureError::Frame {
                frame: 0,
                problem: format!("{w}x{h} pixels, smaller than one {0}x{0} patch", self.vit.patch),
            });
        }
        Ok(self.vit.forward(&input_from_rgb(rgb, self.vit.patch), self.output))
    }
}

#[cfg(test)]
mod tests {
    use super::super::safetensors;
    use super::*;

    fn noise(n: usize, seed: u64, scale: f32) -> Vec<f32> {
        let mut s = seed.wrapping_mul(0x9E37_79B9_7F4A_7C15) ^ 0xD1B5_4A32_D192_ED03;
        (0..n)
            .map(|_| {
                s ^= s << 13;
                s ^= s >> 7;
                s ^= s << 17;
                ((s >> 40) as f32 / (1u64 << 24) as f32 * 2.0 - 1.0) * scale
            })
            .collect()
    }

    /// A small random DINO ViT (the official names), as named tensors.
    struct Weights {
        dim: usize,
        heads: usize,
        mlp: usize,
        patch: usize,
        side: usize,
        tensors: Vec<(String, Vec<usize>, Vec<f32>)>,
    }

    impl Weights {
        fn random(dim: usize, heads: usize, depth: usize, mlp: usize, patch: usize, side: usize) -> Self {
            let mut tensors = Vec::new();
            let mut seed = 1;
            let mut add = |name: String, shape: Vec<usize>, scale: f32, offset: f32| {
                seed += 1;
                let n = shape.iter().product();
                let v = noise(n, seed, scale).into_iter().map(|v| v + offset).collect();
                tensors.push((name, shape, v));
            };
            let inv = |n: usize| 1.0 / (n as f32).sqrt();
            add("cls_token".into(), vec![1, 1, dim], 0.5, 0.0);
            add("pos_embed".into(), vec![1, 1 + side * side, dim], 0.5, 0.0);
            add(
                "patch_embed.proj.weight".into(),
                vec![dim, 3, patch, patch],
                inv(3 * patch * patch),
                0.0,
            );
            add("patch_embed.proj.bias".into(), vec![dim], 0.1, 0.0);
            for b in 0..depth {
                let p = format!("blocks.{b}");
                add(format!("{p}.norm1.weight"), vec![dim], 0.2, 1.0);
                add(format!("{p}.norm1.bias"), vec![dim], 0.1, 0.0);
                // Large q/k weights so that the softmax is far from uniform.
                add(format!("{p}.attn.qkv.weight"), vec![3 * dim, dim], 3.0 * inv(dim), 0.0);
                add(format!("{p}.attn.qkv.bias"), vec![3 * dim], 0.1, 0.0);
                add(format!("{p}.attn.proj.weight"), vec![dim, dim], inv(dim), 0.0);
                add(format!("{p}.attn.proj.bias"), vec![dim], 0.1, 0.0);
                add(format!("{p}.norm2.weight"), vec![dim], 0.2, 1.0);
                add(format!("{p}.norm2.bias"), vec![dim], 0.1, 0.0);
                add(format!("{p}.mlp.fc1.weight"), vec![mlp, dim], 2.0 * inv(dim), 0.0);
                add(format!("{p}.mlp.fc1.bias"), vec![mlp], 0.1, 0.0);
                add(format!("{p}.mlp.fc2.weight"), vec![dim, mlp], inv(mlp), 0.0);
                add(format!("{p}.mlp.fc2.bias"), vec![dim], 0.1, 0.0);
            }
            add("norm.weight".into(), vec![dim], 0.2, 1.0);
            add("norm.bias".into(), vec![dim], 0.1, 0.0);
            Weights {
                dim,
                heads,
                mlp,
                patch,
                side,
                tensors,
            }
        }

        fn get(&self, name: &str) -> Vec<f64> {
            let t = self.tensors.iter().find(|t| t.0 == name).unwrap();
            t.2.iter().map(|&v| v as f64).collect()
        }

        fn safetensors(&self) -> SafeTensors {
            let list: Vec<(&str, &[usize], &[f32])> = self
                .tensors
                .iter()
                .map(|(n, s, v)| (n.as_str(), &s[..], &v[..]))
                .collect();
            SafeTensors::from_bytes("random-vit.safetensors", safetensors::to_bytes(&list)).unwrap()
        }
    }

    /// erf by its Taylor series (plenty accurate in f64 for |x| < 4.5; ±1 beyond).
    fn erf_series(x: f64) -> f64 {
        if x.abs() > 4.5 {
            return x.signum();
        }
        let (mut term, mut sum) = (x, x);
        for n in 1..200 {
            term *= -x * x / n as f64;
            sum += term / (2 * n + 1) as f64;
        }
        sum * 2.0 / std::f64::consts::PI.sqrt()
    }

    /// Keys' cubic convolution kernel with a = -0.75, by distance.
    fn keys_kernel(d: f64) -> f64 {
        let (a, d) = (-0.75, d.abs());
        if d <= 1.0 {
            (a + 2.0) * d.powi(3) - (a + 3.0) * d * d + 1.0
        } else if d < 2.0 {
            a * d.powi(3) - 5.0 * a * d * d + 8.0 * a * d - 4.0 * a
        } else {
            0.0
        }
    }

    fn layer_norm(x: &[f64], g: &[f64], b: &[f64]) -> Vec<f64> {
        let n = x.len() as f64;
        let mean = x.iter().sum::<f64>() / n;
        let var = x.iter().map(|v| (v - mean).powi(2)).sum::<f64>() / n;
        x.iter()
            .zip(g)
            .zip(b)
            .map(|((v, g), b)| (v - mean) / (var + 1e-6).sqrt() * g + b)
            .collect()
    }

    /// `W x + b` for PyTorch's `[out, in]` weight.
    fn affine(x: &[f64], w: &[f64], b: &[f64]) -> Vec<f64> {
        b.iter()
            .enumerate()
            .map(|(o, bo)| {
                bo + x
                    .iter()
                    .zip(&w[o * x.len()..][..x.len()])
                    .map(|(a, b)| a * b)
                    .sum::<f64>()
            })
            .collect()
    }

    /// The whole network, naively in f64 on the channels-first input `img[c][y][x]`, following
    /// DINO's `vision_transformer.py`: tokens (or last-block keys) of the patches.
    fn reference(wt: &Weights, img: &[Vec<Vec<f64>>], keys_out: bool) -> (usize, usize, Vec<Vec<f64>>) {
        let (d, p, n) = (wt.dim, wt.patch, wt.side);
        let (h, w) = (img[0].len(), img[0][0].len());
        let (gh, gw) = (h / p, w / p);
        let pw = wt.get("patch_embed.proj.weight");
        let pb = wt.get("patch_embed.proj.bias");
        let pos = wt.get("pos_embed");
        // Patch positions, resampled unless the grid is the square training grid.
        let pos_at = |gy: usize, gx: usize| -> Vec<f64> {
            if (gh, gw) == (n, n) {
                return pos[(1 + gy * n + gx) * d..][..d].to_vec();
            }
            let sy = (gy as f64 + 0.5) * n as f64 / (gh as f64 + 0.1) - 0.5;
            let sx = (gx as f64 + 0.5) * n as f64 / (gw as f64 + 0.1) - 0.5;
            let mut v = vec![0.0; d];
            for j in (sy.floor() as i64 - 1)..=(sy.floor() as i64 + 2) {
                for i in (sx.floor() as i64 - 1)..=(sx.floor() as i64 + 2) {
                    let wgt = keys_kernel(sy - j as f64) * keys_kernel(sx - i as f64);
                    let (jj, ii) = (j.clamp(0, n as i64 - 1) as usize, i.clamp(0, n as i64 - 1) as usize);
                    for c in 0..d {
                        v[c] += wgt * pos[(1 + jj * n + ii) * d + c];
                    }
                }
            }
            v
        };
        let mut x: Vec<Vec<f64>> = vec![wt.get("cls_token").iter().zip(&pos[..d]).map(|(a, b)| a + b).collect()];
        for gy in 0..gh {
            for gx in 0..gw {
                let pe = pos_at(gy, gx);
                x.push(
                    (0..d)
                        .map(|o| {
                            let mut v = pb[o] + pe[o];
                            for c in 0..3 {
                                for ky in 0..p {
                                    for kx in 0..p {
                                        v += pw[((o * 3 + c) * p + ky) * p + kx] * img[c][gy * p + ky][gx * p + kx];
                                    }
                                }
                            }
                            v
                        })
                        .collect(),
                );
            }
        }
        let depth = (0..)
            .take_while(|b| wt.tensors.iter().any(|t| t.0 == format!("blocks.{b}.norm1.weight")))
            .count();
        let hd = d / wt.heads;
        for b in 0..depth {
            let g = |s: &str| wt.get(&format!("blocks.{b}.{s}"));
            let normed: Vec<Vec<f64>> = x
                .iter()
                .map(|t| layer_norm(t, &g("norm1.weight"), &g("norm1.bias")))
                .collect();
            let qkv: Vec<Vec<f64>> = normed
                .iter()
                .map(|t| affine(t, &g("attn.qkv.weight"), &g("attn.qkv.bias")))
                .collect();
            if b == depth - 1 && keys_out {
                return (gh, gw, qkv[1..].iter().map(|r| r[d..2 * d].to_vec()).collect());
            }
            let mut attended = vec![vec![0.0; d]; x.len()];
            for head in 0..wt.heads {
                for (i, out) in attended.iter_mut().enumerate() {
                    let q = &qkv[i][head * hd..][..hd];
                    let logits: Vec<f64> = qkv
                        .iter()
                        .map(|r| {
                            q.iter().zip(&r[d + head * hd..][..hd]).map(|(a, b)| a * b).sum::<f64>()
                                / (hd as f64).sqrt()
                        })
                        .collect();
                    let m = logits.iter().cloned().fold(f64::MIN, f64::max);
                    let e: Vec<f64> = logits.iter().map(|l| (l - m).exp()).collect();
                    let s: f64 = e.iter().sum();
                    for (j, r) in qkv.iter().enumerate() {
                        for c in 0..hd {
                            out[head * hd + c] += e[j] / s * r[2 * d + head * hd + c];
                        }
                    }
                }
            }
            for (t, a) in x.iter_mut().zip(&attended) {
                let y = affine(a, &g("attn.proj.weight"), &g("attn.proj.bias"));
                t.iter_mut().zip(y).for_each(|(t, y)| *t += y);
                let hidden: Vec<f64> = affine(
                    &layer_norm(t, &g("norm2.weight"), &g("norm2.bias")),
                    &g("mlp.fc1.weight"),
                    &g("mlp.fc1.bias"),
                )
                .into_iter()
                .map(|v| 0.5 * v * (1.0 + erf_series(v / 2f64.sqrt())))
                .collect();
                assert_eq!(hidden.len(), wt.mlp);
                let y = affine(&hidden, &g("mlp.fc2.weight"), &g("mlp.fc2.bias"));
                t.iter_mut().zip(y).for_each(|(t, y)| *t += y);
            }
        }
        let (nw, nb) = (wt.get("norm.weight"), wt.get("norm.bias"));
        (gh, gw, x[1..].iter().map(|t| layer_norm(t, &nw, &nb)).collect())
    }

    #[test]
    fn gelu_is_the_exact_erf_gelu() {
        for i in -80..=80 {
            let x = i as f64 / 10.0;
            assert!((ops::erf(x) - erf_series(x)).abs() < 3e-7, "erf({x})");
            let want = 0.5 * x * (1.0 + erf_series(x / 2f64.sqrt()));
            assert!(
                (ops::gelu(x as f32) as f64 - want).abs() < 1e-6 * (1.0 + want.abs()),
                "gelu({x})"
            );
        }
    }

    #[test]
    fn a_small_random_vit_matches_a_naive_f64_reference() {
        let wt = Weights::random(32, 4, 2, 64, 8, 4);
        let st = wt.safetensors();
        let vit = DinoVit::from_safetensors(&st, wt.heads).unwrap().with_threads(2);
        assert_eq!((vit.dim, vit.patch, vit.depth()), (32, 8, 2));
        // 32x32: the training grid (embedding as is); 24x40 and 48x16: resampled embeddings.
        for (h, w) in [(32, 32), (24, 40), (48, 16)] {
            let img: Vec<Vec<Vec<f64>>> = (0..3)
                .map(|c| {
                    (0..h)
                        .map(|y| {
                            (0..w)
                                .map(|x| (0.3 * x as f64 + 0.17 * y as f64 + c as f64).sin() * 1.5)
                                .collect()
                        })
                        .collect()
                })
                .collect();
            let mut data = Vec::new();
            for y in 0..h {
                for x in 0..w {
                    for ch in &img {
                        data.push(ch[y][x] as f32);
                    }
                }
            }
            let input = map(h, w, 3, data);
            for (output, keys) in [(DinoOutput::Tokens, false), (DinoOutput::Keys, true)] {
                let got = vit.forward(&input, output);
                let (gh, gw, want) = reference(&wt, &img, keys);
                assert_eq!(
                    (got.height as usize, got.width as usize, got.dim as usize),
                    (gh, gw, 32)
                );
                let mut worst = 0f64;
                for (cell, want) in got.data.chunks_exact(32).zip(&want) {
                    for (&g, &w) in cell.iter().zip(want) {
                        worst = worst.max((g as f64 - w).abs() / (1.0 + w.abs()));
                    }
                }
                eprintln!("{h}x{w} {output:?}: worst error {worst:.2e}");
                assert!(worst < 1e-4, "{h}x{w} {output:?}: error {worst:.2e}");
            }
        }
    }

    #[test]
    fn the_position_embedding_resampling_keeps_a_constant_and_the_training_grid() {
        let mut wt = Weights::random(8, 2, 1, 16, 8, 5);
        let pos = wt.tensors.iter_mut().find(|t| t.0 == "pos_embed").unwrap();
        pos.2.iter_mut().enumerate().for_each(|(i, v)| *v = (i % 8) as f32);
        let vit = DinoVit::from_safetensors(&wt.safetensors(), 2).unwrap();
        for (gh, gw) in [(3, 7), (10, 10), (5, 5), (1, 2)] {
            let p = vit.position_embedding(gh, gw);
            assert_eq!(p.len(), gh * gw * 8);
            for (i, v) in p.iter().enumerate() {
                assert!((v - (i % 8) as f32).abs() < 1e-5, "{gh}x{gw}: {v}");
            }
        }
    }

    #[test]
    fn the_extractor_pads_to_whole_patches_and_refuses_tiny_frames() {
        let wt = Weights::random(16, 2, 1, 32, 8, 4);
        let vit = DinoVit::from_safetensors(&wt.safetensors(), 2).unwrap();
        let ex = DinoExtractor {
            vit,
            output: DinoOutput::Tokens,
        };
        assert_eq!(ex.describe(), "dino-vit dim 16 patch 8 tokens stride 8");
        let rgb = RgbImage::from_fn(37, 20, |x, y| image::Rgb([(x * 6) as u8, (y * 9) as u8, 40]));
        let m = ex.extract(&rgb).unwrap();
        assert_eq!((m.height, m.width, m.dim), (3, 5, 16));
        let input = input_from_rgb(&rgb, 8);
        assert_eq!((input.height, input.width), (24, 40));
        // The padding repeats the last column: pixel (39, 23) is pixel (36, 19).
        assert_eq!(input.cell(39, 23), input.cell(36, 19));
        let err = ex.extract(&RgbImage::new(7, 30)).unwrap_err().to_string();
        assert!(err.contains("7x30"), "{err}");
    }

    #[test]
    fn missing_or_wrong_weights_are_explained() {
        let absent = Path::new("/nonexistent/dino-vits8.safetensors");
        let err = DinoVit::load_vits8(absent).unwrap_err();
        let FeatureError::Missing { hint, .. } = &err else {
            panic!("{err}")
        };
        assert!(
            hint.contains("dino_deitsmall8_pretrain.pth") && hint.contains("never been run"),
            "{hint}"
        );
        let err = resolve_weights_from(None, Some(absent.into())).unwrap_err().to_string();
        assert!(err.contains(WEIGHTS_ENV), "{err}");
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("small.safetensors");
        let wt = Weights::random(24, 6, 1, 32, 8, 4);
        let list: Vec<(&str, &[usize], &[f32])> = wt
            .tensors
            .iter()
            .map(|(n, s, v)| (n.as_str(), &s[..], &v[..]))
            .collect();
        std::fs::write(&path, safetensors::to_bytes(&list)).unwrap();
        let err = DinoVit::load_vits8(&path).unwrap_err().to_string();
        assert!(
            err.contains("not ViT-S/8") && err.contains("small.safetensors"),
            "{err}"
        );
        let no_qkv: Vec<_> = list
            .iter()
            .filter(|t| t.0 != "blocks.0.attn.qkv.bias")
            .cloned()
            .collect();
        let st = SafeTensors::from_bytes("x.safetensors", safetensors::to_bytes(&no_qkv)).unwrap();
        let err = DinoVit::from_safetensors(&st, 6).unwrap_err().to_string();
        assert!(err.contains("`blocks.0.attn.qkv.bias` missing"), "{err}");
    }
}
