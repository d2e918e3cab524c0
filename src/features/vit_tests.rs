use super::super::checkpoint::Checkpoint;
use super::super::dino::{DinoExtractor, DinoModel};
use super::super::{Extractor, FeatureError};
use super::*;
use crate::safetensors::{self, SafeTensors};
use std::path::Path;

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
        Self::random_with(dim, heads, depth, mlp, patch, side, false)
    }

    /// With `layer_scale`, DINOv2's `blocks.N.ls1.gamma` and `ls2.gamma` (far from 1, so that
    /// a misapplied gamma shows).
    fn random_with(
        dim: usize,
        heads: usize,
        depth: usize,
        mlp: usize,
        patch: usize,
        side: usize,
        layer_scale: bool,
    ) -> Self {
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
            if layer_scale {
                add(format!("{p}.ls1.gamma"), vec![dim], 0.3, 0.5);
                add(format!("{p}.ls2.gamma"), vec![dim], 0.3, 0.5);
            }
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

    fn list(&self) -> Vec<(&str, &[usize], &[f32])> {
        self.tensors
            .iter()
            .map(|(n, s, v)| (n.as_str(), &s[..], &v[..]))
            .collect()
    }

    fn safetensors(&self) -> Checkpoint {
        let bytes = safetensors::to_bytes(&self.list());
        Checkpoint::SafeTensors(SafeTensors::from_bytes("random-vit.safetensors", bytes).unwrap())
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
                        q.iter().zip(&r[d + head * hd..][..hd]).map(|(a, b)| a * b).sum::<f64>() / (hd as f64).sqrt()
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
        // DINOv2's LayerScale multiplies each branch's output channels; DINO has none (gamma 1).
        let gamma = |name: &str| match wt.tensors.iter().any(|t| t.0 == format!("blocks.{b}.{name}")) {
            true => g(name),
            false => vec![1.0; d],
        };
        let (ls1, ls2) = (gamma("ls1.gamma"), gamma("ls2.gamma"));
        for (t, a) in x.iter_mut().zip(&attended) {
            let y = affine(a, &g("attn.proj.weight"), &g("attn.proj.bias"));
            t.iter_mut().zip(y).zip(&ls1).for_each(|((t, y), l)| *t += l * y);
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
            t.iter_mut().zip(y).zip(&ls2).for_each(|((t, y), l)| *t += l * y);
        }
    }
    let (nw, nb) = (wt.get("norm.weight"), wt.get("norm.bias"));
    (gh, gw, x[1..].iter().map(|t| layer_norm(t, &nw, &nb)).collect())
}

#[test]
fn gelu_is_the_exact_erf_gelu() {
    for i in -80..=80 {
        let x = i as f64 / 10.0;
        assert!((crate::dense::erf(x) - erf_series(x)).abs() < 3e-7, "erf({x})");
        let want = 0.5 * x * (1.0 + erf_series(x / 2f64.sqrt()));
        assert!(
            (crate::dense::gelu(x as f32) as f64 - want).abs() < 1e-6 * (1.0 + want.abs()),
            "gelu({x})"
        );
    }
}

#[test]
fn a_small_random_vit_matches_a_naive_f64_reference() {
    matches_the_naive_reference(false);
}

#[test]
fn a_small_random_vit_with_layer_scale_matches_a_naive_f64_reference() {
    matches_the_naive_reference(true);
}

fn matches_the_naive_reference(layer_scale: bool) {
    let wt = Weights::random_with(32, 4, 2, 64, 8, 4, layer_scale);
    let vit = DinoVit::from_checkpoint(&wt.safetensors(), wt.heads)
        .unwrap()
        .with_threads(2);
    assert_eq!(
        (vit.dim, vit.patch, vit.depth(), vit.layer_scale),
        (32, 8, 2, layer_scale)
    );
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
    let vit = DinoVit::from_checkpoint(&wt.safetensors(), 2).unwrap();
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
    let vit = DinoVit::from_checkpoint(&wt.safetensors(), 2).unwrap();
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
    for model in [DinoModel::DinoVits8, DinoModel::Dinov2Vits14] {
        let err = model.load(absent).unwrap_err();
        let FeatureError::Missing { hint, .. } = &err else {
            panic!("{err}")
        };
        let official = model.checkpoint_url().rsplit('/').next().unwrap();
        assert!(hint.contains(official) && hint.contains("never been run"), "{hint}");
        let err = model
            .resolve_weights_from(None, Some(absent.into()))
            .unwrap_err()
            .to_string();
        assert!(err.contains(model.weights_env()), "{err}");
    }
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("small.safetensors");
    let wt = Weights::random(24, 6, 1, 32, 8, 4);
    std::fs::write(&path, safetensors::to_bytes(&wt.list())).unwrap();
    let err = DinoModel::DinoVits8.load(&path).unwrap_err().to_string();
    assert!(
        err.contains("not DINO ViT-S/8") && err.contains("small.safetensors"),
        "{err}"
    );
    let err = DinoModel::Dinov2Vits14.load(&path).unwrap_err().to_string();
    assert!(
        err.contains("not DINOv2 ViT-S/14") && err.contains("without LayerScale"),
        "{err}"
    );
    let list = wt.list();
    let without = |skip: &str| -> Checkpoint {
        let kept: Vec<_> = list.iter().filter(|t| t.0 != skip).cloned().collect();
        Checkpoint::SafeTensors(SafeTensors::from_bytes("x.safetensors", safetensors::to_bytes(&kept)).unwrap())
    };
    let err = DinoVit::from_checkpoint(&without("blocks.0.attn.qkv.bias"), 6)
        .unwrap_err()
        .to_string();
    assert!(err.contains("`blocks.0.attn.qkv.bias` missing"), "{err}");
    // A DINOv2 file with registers, or with LayerScale in only some blocks, is refused.
    let wt = Weights::random_with(24, 6, 2, 32, 8, 4, true);
    let mut list = wt.list();
    let reg = vec![0.0; 4 * 24];
    list.push(("register_tokens", &[1, 4, 24], &reg));
    let st = SafeTensors::from_bytes("reg.safetensors", safetensors::to_bytes(&list)).unwrap();
    let err = DinoVit::from_checkpoint(&Checkpoint::SafeTensors(st), 6)
        .unwrap_err()
        .to_string();
    assert!(err.contains("register_tokens"), "{err}");
    let kept: Vec<_> = wt.list().into_iter().filter(|t| t.0 != "blocks.1.ls2.gamma").collect();
    let st = SafeTensors::from_bytes("ls.safetensors", safetensors::to_bytes(&kept)).unwrap();
    let err = DinoVit::from_checkpoint(&Checkpoint::SafeTensors(st), 6)
        .unwrap_err()
        .to_string();
    assert!(err.contains("LayerScale") && err.contains("`blocks.1`"), "{err}");
}

/// Time per 640x480 frame of both extractors with full-size random weights (ViT-S, 12 blocks):
/// `cargo test --release --lib bench_dino_640x480 -- --ignored --nocapture`.
#[test]
#[ignore]
fn bench_dino_640x480() {
    let rgb = RgbImage::from_fn(640, 480, |x, y| {
        image::Rgb([(x * 7 % 256) as u8, (y * 3 % 256) as u8, ((x + y) % 256) as u8])
    });
    let threads = crate::dense::default_threads();
    for (model, side) in [(DinoModel::DinoVits8, 28), (DinoModel::Dinov2Vits14, 37)] {
        let layer_scale = model == DinoModel::Dinov2Vits14;
        let wt = Weights::random_with(384, 6, 12, 1536, model.patch(), side, layer_scale);
        let vit = model.from_checkpoint(&wt.safetensors()).unwrap();
        let ex = DinoExtractor {
            vit,
            output: DinoOutput::Keys,
        };
        let started = std::time::Instant::now();
        let m = ex.extract(&rgb).unwrap();
        eprintln!(
            "{}: 640x480 -> {}x{}x{} keys in {:.2} s ({threads} threads)",
            model.name(),
            m.height,
            m.width,
            m.dim,
            started.elapsed().as_secs_f64()
        );
    }
}
