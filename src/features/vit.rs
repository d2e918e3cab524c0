//! The vision transformer of DINO (Caron et al. 2021) and DINOv2 (Oquab et al. 2023) on the CPU:
//! one implementation, since DINOv2's backbone is DINO's plus LayerScale (read from the weights).
//!
//! The architecture: a `p x p` stride-`p` patch embedding (a convolution 3 -> dim), a class
//! token, a position embedding for the square training grid that is bicubically resampled to the
//! patch grid (`interpolate_pos_encoding` with its `+ 0.1` offset, no antialiasing, in both
//! repositories), pre-norm transformer blocks (`x + ls1 * proj(attn(norm1(x)))`,
//! `x + ls2 * fc2(gelu(fc1(norm2(x))))`, LayerScale only in DINOv2, LayerNorm eps 1e-6, exact
//! GELU, softmax attention with scale `head_dim^-0.5`) and a final LayerNorm. The input is the
//! ImageNet normalisation of the RGB frame, `(pixel / 255 - mean) / std`.
//!
//! Names are those of the official checkpoints (`cls_token`, `pos_embed`,
//! `patch_embed.proj.weight`, `blocks.N.norm1.weight`, `blocks.N.attn.qkv.weight`, ...,
//! `blocks.N.ls1.gamma`, `norm.weight`); the dimensions and the depth are read from the tensors'
//! shapes and the number of heads is given (6 for ViT-S). Tested against the official PyTorch code
//! on random weights (`dino_vectors.rs`), never run on the real weights here.
use super::checkpoint::Checkpoint;
use super::ops;
use super::softmax::softmax_rows;
use super::{FeatureError, FeatureMap};
use crate::dense::{self, Activation, Dense};
use image::RgbImage;

const LN_EPS: f32 = 1e-6;
const IMAGENET_MEAN: [f32; 3] = [0.485, 0.456, 0.406];
const IMAGENET_STD: [f32; 3] = [0.229, 0.224, 0.225];
/// Query rows per attention block: a `BLOCK x tokens` score matrix (1.2 MB at 4800 tokens)
/// stays in cache between the scores, the softmax and the weighted sum.
const BLOCK: usize = 64;

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
    fn load(st: &Checkpoint, prefix: &str, dim: usize) -> Result<Self, FeatureError> {
        Ok(LayerNorm {
            weight: st.f32(&format!("{prefix}.weight"), &[dim])?,
            bias: st.f32(&format!("{prefix}.bias"), &[dim])?,
        })
    }

    fn forward(&self, x: &[f32], threads: usize) -> Vec<f32> {
        let d = self.weight.len();
        let mut out = vec![0.0; x.len()];
        dense::parallel_rows(&mut out, d, threads, 16, |row0, chunk| {
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

fn linear(st: &Checkpoint, prefix: &str, cin: usize, cout: usize) -> Result<Dense, FeatureError> {
    let (w, b) = linear_weights(st, prefix, cin, cout)?;
    Ok(Dense::new(cin, cout, &w, &b))
}

/// A linear layer's `[out, in]` weight and its bias.
fn linear_weights(
    st: &Checkpoint,
    prefix: &str,
    cin: usize,
    cout: usize,
) -> Result<(Vec<f32>, Vec<f32>), FeatureError> {
    let w = st.f32(&format!("{prefix}.weight"), &[cout, cin])?;
    let b = st.f32(&format!("{prefix}.bias"), &[cout])?;
    Ok((w, b))
}

/// A linear layer followed by DINOv2's LayerScale `gamma` (if the block has one), folded into
/// the layer: `gamma * (W x + b) = (diag(gamma) W) x + gamma * b`. This is exact up to rounding
/// and keeps the residual add fused into the matmul.
fn scaled_linear(
    st: &Checkpoint,
    prefix: &str,
    gamma: Option<&str>,
    cin: usize,
    cout: usize,
) -> Result<Dense, FeatureError> {
    let (mut w, mut b) = linear_weights(st, prefix, cin, cout)?;
    if let Some(gamma) = gamma {
        let g = st.f32(gamma, &[cout])?;
        for ((row, bias), g) in w.chunks_exact_mut(cin).zip(&mut b).zip(&g) {
            row.iter_mut().for_each(|v| *v *= g);
            *bias *= g;
        }
    }
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
    /// What the network is, for provenance: `dino-vits8`, `dinov2-vits14`, or `dino-vit` for
    /// one built from arbitrary weights.
    pub name: String,
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
    /// Whether the blocks have LayerScale (DINOv2), folded into `proj` and `fc2`.
    pub layer_scale: bool,
    norm: LayerNorm,
    threads: usize,
}

impl DinoVit {
    /// Any DINO or DINOv2 ViT with `heads` heads; width, patch size, depth, MLP width and
    /// LayerScale from the tensors. Refuses what this implementation would silently get wrong:
    /// register tokens (the `_reg` DINOv2 models), LayerScale on only some blocks.
    pub fn from_checkpoint(st: &Checkpoint, heads: usize) -> Result<Self, FeatureError> {
        let bad = |problem: String| FeatureError::invalid(st.file(), problem);
        let shape = |name: &str| {
            st.shape(name)
                .map(|s| s.to_vec())
                .ok_or_else(|| bad(format!("tensor `{name}` missing")))
        };
        if st.shape("register_tokens").is_some() {
            return Err(bad(
                "has `register_tokens`: a DINOv2 model with registers (`_reg`), whose tokens and position \
                 embedding resampling (antialiased, no offset) this extractor does not implement"
                    .into(),
            ));
        }
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
        let layer_scale = st.shape("blocks.0.ls1.gamma").is_some();
        let mut blocks = Vec::new();
        while st.shape(&format!("blocks.{}.norm1.weight", blocks.len())).is_some() {
            let p = format!("blocks.{}", blocks.len());
            // A malformed (0-d) shape leaves 0, which the shape check of `fc1` then reports.
            let mlp = shape(&format!("{p}.mlp.fc1.weight"))?.first().copied().unwrap_or(0);
            let (ls1, ls2) = (format!("{p}.ls1.gamma"), format!("{p}.ls2.gamma"));
            // Every block has both gammas or none does: a missing one is a broken file, not
            // a gamma of 1.
            if [&ls1, &ls2].iter().any(|g| st.shape(g).is_some() != layer_scale) {
                return Err(bad(format!(
                    "LayerScale (`ls1.gamma`, `ls2.gamma`) in some blocks but not in `{p}`"
                )));
            }
            let gamma = |name| layer_scale.then_some(name);
            blocks.push(VitBlock {
                norm1: LayerNorm::load(st, &format!("{p}.norm1"), dim)?,
                qkv: linear(st, &format!("{p}.attn.qkv"), dim, 3 * dim)?,
                proj: scaled_linear(st, &format!("{p}.attn.proj"), gamma(ls1.as_str()), dim, dim)?,
                norm2: LayerNorm::load(st, &format!("{p}.norm2"), dim)?,
                fc1: linear(st, &format!("{p}.mlp.fc1"), dim, mlp)?,
                fc2: scaled_linear(st, &format!("{p}.mlp.fc2"), gamma(ls2.as_str()), mlp, dim)?,
            });
        }
        if blocks.is_empty() {
            return Err(bad(
                "tensor `blocks.0.norm1.weight` missing (no transformer blocks)".into()
            ));
        }
        Ok(DinoVit {
            name: "dino-vit".into(),
            dim,
            heads,
            patch,
            patch_embed,
            cls,
            pos_cls: pos[..dim].to_vec(),
            pos_patches: pos[dim..].to_vec(),
            pos_side,
            blocks,
            layer_scale,
            norm: LayerNorm::load(st, "norm", dim)?,
            threads: dense::default_threads(),
        })
    }

    pub fn with_threads(mut self, threads: usize) -> Self {
        self.threads = threads.max(1);
        self
    }

    pub fn depth(&self) -> usize {
        self.blocks.len()
    }

    /// The hidden width of the blocks' MLP.
    pub fn mlp_width(&self) -> usize {
        self.blocks.first().map_or(0, |b| b.fc1.cout)
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
        let (d, hd) = (self.dim, self.dim / self.heads);
        let scale = (hd as f32).powf(-0.5);
        // Per head, the scores `q . k_j` are a dense layer whose weight rows are the keys, and the
        // output `p . v` one whose weight rows are the values' columns.
        let layers: Vec<(Dense, Dense)> = (0..self.heads)
            .map(|head| {
                let mut k = Vec::with_capacity(tokens * hd);
                let mut vt = vec![0.0; hd * tokens];
                for (i, r) in qkv.chunks_exact(3 * d).enumerate() {
                    k.extend_from_slice(&r[d + head * hd..][..hd]);
                    for (j, &v) in r[2 * d + head * hd..][..hd].iter().enumerate() {
                        vt[j * tokens + i] = v;
                    }
                }
                (
                    Dense::new(hd, tokens, &k, &vec![0.0; tokens]),
                    Dense::new(tokens, hd, &vt, &vec![0.0; hd]),
                )
            })
            .collect();
        let mut out = vec![0.0; tokens * d];
        // Each thread takes whole blocks of query rows, and for each block and head computes the
        // scores, their softmax and the weighted values while the `BLOCK x tokens` scores are
        // still in cache: one pass over them instead of three through memory.
        dense::parallel_rows(&mut out, d, self.threads, BLOCK, |row0, chunk| {
            let mut q = Vec::with_capacity(BLOCK * hd);
            let mut scores = vec![0.0; BLOCK * tokens];
            let mut o = vec![0.0; BLOCK * hd];
            for (b, oblock) in chunk.chunks_mut(BLOCK * d).enumerate() {
                let (first, rows) = (row0 + b * BLOCK, oblock.len() / d);
                for (head, (keys, values)) in layers.iter().enumerate() {
                    q.clear();
                    for r in qkv[first * 3 * d..(first + rows) * 3 * d].chunks_exact(3 * d) {
                        q.extend(r[head * hd..][..hd].iter().map(|v| v * scale));
                    }
                    let (scores, o) = (&mut scores[..rows * tokens], &mut o[..rows * hd]);
                    keys.forward_into(&q, Activation::None, None, 1, scores);
                    softmax_rows(scores, tokens);
                    values.forward_into(scores, Activation::None, None, 1, o);
                    for (orow, dst) in o.chunks_exact(hd).zip(oblock.chunks_exact_mut(d)) {
                        dst[head * hd..][..hd].copy_from_slice(orow);
                    }
                }
            }
        });
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

#[cfg(test)]
#[path = "vit_tests.rs"]
mod tests;
