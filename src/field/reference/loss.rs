//! The four loss terms of one ray and their gradients w.r.t. the rendered channels.
//!
//! Per ray (weights from `LossWeights`, defaults in brackets):
//! - colour [1.0]: ‖ĉ − c‖², summed over the 3 channels;
//! - depth [0.1]: |d̂ − d|, only where the depth image has a value;
//! - semantic [1.0]: −log softmax(ŝ)[label], only on labelled rays;
//! - feature [0.5]: mean over the D dims of |f̂ − code|, only when feature supervision is on
//!   and the ray has a code (the mean keeps the weight's meaning independent of D);
//! - opacity [1.0] ([`opacity_loss`]): (T − [label = far class])², T the transmittance a ray
//!   leaves for its opaque last sample, only on labelled rays that end in one and only when the
//!   labels name a far class. It is counted with the semantic term (both come from the labels),
//!   so the GPU keeps four loss words.
//!
//! Batch averaging: every term is summed over the rays where it applies and divided by the
//! batch size B (all rays), not by the number of rays that have it. Each ray's gradient is
//! then its own business (scaled by 1/B), so a GPU thread per ray needs no batch-wide count
//! before the backward pass. With half the batch labelled, the semantic term is half of a
//! per-labelled-ray mean; the weights above are applied on top of this convention.
//! The derivative of |x| is taken as sign(x), 0 at 0.
use super::real::Real;
use super::render::Channels;
use crate::field::config::LossWeights;

/// What a ray is supervised with.
#[derive(Clone, Debug, PartialEq)]
pub struct RayTarget {
    /// Pixel colour in [0,1].
    pub rgb: [f32; 3],
    /// Measured z-depth in metres (the depth image's value, converted); None where missing.
    pub depth: Option<f32>,
    /// Class id of an annotated pixel; None if unlabelled.
    pub label: Option<u32>,
    /// The archive's feature code at this pixel (D values); None without features.
    pub code: Option<Vec<f32>>,
}

/// Weighted loss terms (already multiplied by their weights and divided by the batch size).
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct LossTerms {
    pub rgb: f64,
    pub depth: f64,
    pub semantic: f64,
    pub feature: f64,
}

impl LossTerms {
    pub fn total(&self) -> f64 {
        self.rgb + self.depth + self.semantic + self.feature
    }

    pub fn add(&mut self, other: &LossTerms) {
        self.rgb += other.rgb;
        self.depth += other.depth;
        self.semantic += other.semantic;
        self.feature += other.feature;
    }
}

/// Unweighted squared error over colour channels and its gradient 2(ĉ − c).
pub fn rgb_squared_error<R: Real>(pred: &[R], target: [f32; 3]) -> (R, [R; 3]) {
    let diff: [R; 3] = std::array::from_fn(|c| pred[c] - R::of_f32(target[c]));
    (diff.iter().map(|d| *d * *d).sum(), diff.map(|d| d + d))
}

/// |x| and its derivative sign(x) (0 at 0).
pub fn abs_error<R: Real>(pred: R, target: f32) -> (R, R) {
    let d = pred - R::of_f32(target);
    let sign = if d > R::ZERO {
        R::ONE
    } else if d < R::ZERO {
        -R::ONE
    } else {
        R::ZERO
    };
    (d.abs(), sign)
}

/// −log softmax(logits)[label] (with the max subtracted for stability) and its gradient
/// softmax(logits) − onehot(label). `label` must be < logits.len().
pub fn cross_entropy<R: Real>(logits: &[R], label: usize) -> (R, Vec<R>) {
    let max = logits.iter().fold(logits[0], |m, v| m.max(*v));
    let exps: Vec<R> = logits.iter().map(|l| (*l - max).exp()).collect();
    let sum: R = exps.iter().copied().sum();
    let loss = sum.ln() - (logits[label] - max);
    let mut grad: Vec<R> = exps.iter().map(|e| *e / sum).collect();
    grad[label] -= R::ONE;
    (loss, grad)
}

/// Mean over dims of |f̂ − code| and its gradient sign(f̂ − code)/D.
pub fn feature_l1<R: Real>(pred: &[R], code: &[f32]) -> (R, Vec<R>) {
    let inv_d = R::ONE / R::of(pred.len() as f64);
    let mut loss = R::ZERO;
    let grad = pred
        .iter()
        .zip(code)
        .map(|(p, c)| {
            let (l, g) = abs_error(*p, *c);
            loss += l;
            g * inv_d
        })
        .collect();
    (loss * inv_d, grad)
}

/// The opacity term of one ray and ∂loss/∂T, scaled by `1 / batch_size`, or `None` where it
/// does not apply. `left` is the transmittance the ray leaves for its opaque last sample (that
/// sample's weight; `None` when the ray has none), `far_class` the class of what lies beyond
/// the scene box (`PropagationCache::far_class`). A ray labelled with that class should pass
/// through the box (T = 1), one labelled with another class should stop in it (T = 0): the
/// strokes and their spread say which pixels see the room, and a room seen through the box from
/// one view cannot have density there in another.
pub fn opacity_loss<R: Real>(
    weights: &LossWeights,
    left: Option<R>,
    label: Option<u32>,
    far_class: Option<u32>,
    classes: usize,
    batch_size: usize,
) -> Option<(f64, R)> {
    let left = left?;
    let label = label.filter(|l| (*l as usize) < classes)?;
    let far_class = far_class?;
    let target = if label == far_class { R::ONE } else { R::ZERO };
    let w = weights.opacity as f64 / batch_size as f64;
    let diff = left - target;
    Some(((diff * diff).to_f64() * w, (diff + diff) * R::of(w)))
}

/// Counts the opacity term (from [`opacity_loss`]; `None` where it does not apply) in the
/// semantic one, as the trainer does, and returns its ∂loss/∂T (0 where it does not apply).
pub fn add_opacity<R: Real>(terms: &mut LossTerms, opacity: Option<(f64, R)>) -> R {
    match opacity {
        Some((term, grad)) => {
            terms.semantic += term;
            grad
        }
        None => R::ZERO,
    }
}

/// Loss of one rendered ray (`channels.count()` values) and ∂loss/∂rendered, both already
/// scaled by `1 / batch_size`. A label outside `[0, classes)` is treated as unlabelled
/// (labels are user data; they are validated upstream, and the reference must not panic).
pub fn ray_loss<R: Real>(
    weights: &LossWeights,
    feature_supervision: bool,
    channels: &Channels,
    rendered: &[R],
    target: &RayTarget,
    batch_size: usize,
) -> (LossTerms, Vec<R>) {
    let scale = 1.0 / batch_size as f64;
    let mut terms = LossTerms::default();
    let mut grad = vec![R::ZERO; channels.count()];

    let (l, g) = rgb_squared_error(&rendered[Channels::RGB..Channels::RGB + 3], target.rgb);
    let w = weights.rgb as f64 * scale;
    terms.rgb = l.to_f64() * w;
    for (gc, g) in grad[Channels::RGB..Channels::RGB + 3].iter_mut().zip(g) {
        *gc = g * R::of(w);
    }

    if let Some(depth) = target.depth {
        let (l, g) = abs_error(rendered[Channels::DEPTH], depth);
        let w = weights.depth as f64 * scale;
        terms.depth = l.to_f64() * w;
        grad[Channels::DEPTH] = g * R::of(w);
    }

    if let Some(label) = target.label.map(|l| l as usize).filter(|l| *l < channels.classes) {
        let logits = &rendered[Channels::SEMANTIC..Channels::SEMANTIC + channels.classes];
        let (l, g) = cross_entropy(logits, label);
        let w = weights.semantic as f64 * scale;
        terms.semantic = l.to_f64() * w;
        for (gc, g) in grad[Channels::SEMANTIC..].iter_mut().zip(g) {
            *gc = g * R::of(w);
        }
    }

    if let Some(code) = target
        .code
        .as_deref()
        .filter(|c| feature_supervision && c.len() == channels.feature_dim)
    {
        let start = channels.feature();
        let (l, g) = feature_l1(&rendered[start..start + channels.feature_dim], code);
        let w = weights.feature as f64 * scale;
        terms.feature = l.to_f64() * w;
        for (gc, g) in grad[start..].iter_mut().zip(g) {
            *gc = g * R::of(w);
        }
    }
    (terms, grad)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::field::reference::gradcheck::{assert_close, central_differences, random_vec};
    use crate::rng::SplitMix64;

    #[test]
    fn cross_entropy_of_uniform_logits_is_log_classes() {
        let (l, g) = cross_entropy(&[0.3f64, 0.3, 0.3, 0.3], 2);
        assert!((l - 4f64.ln()).abs() < 1e-12);
        assert!((g[2] + 0.75).abs() < 1e-12 && (g[0] - 0.25).abs() < 1e-12);
        // Huge logits stay finite thanks to the max subtraction.
        let (l, _) = cross_entropy(&[1000.0f32, -1000.0], 1);
        assert!(l.is_finite() && (l - 2000.0).abs() < 1e-3);
    }

    #[test]
    fn missing_supervision_contributes_nothing() {
        let ch = Channels {
            classes: 3,
            feature_dim: 2,
        };
        let rendered = vec![0.5f64; ch.count()];
        let target = RayTarget {
            rgb: [0.5; 3],
            depth: None,
            label: Some(7),
            code: Some(vec![1.0, 1.0]),
        };
        let (terms, grad) = ray_loss(&LossWeights::default(), false, &ch, &rendered, &target, 4);
        assert_eq!(terms.total(), 0.0);
        assert!(grad.iter().all(|g| *g == 0.0));
    }

    #[test]
    fn ray_loss_gradient_matches_finite_differences() {
        let ch = Channels {
            classes: 3,
            feature_dim: 5,
        };
        let mut rng = SplitMix64::new(31);
        let rendered = random_vec(&mut rng, ch.count(), 1.0);
        let target = RayTarget {
            rgb: [0.1, 0.7, 0.4],
            depth: Some(0.35),
            label: Some(1),
            // Codes well away from the rendered values, so no |x| kink is within h.
            code: Some(rendered[ch.feature()..].iter().map(|v| (*v + 0.3) as f32).collect()),
        };
        let weights = LossWeights::default();
        let loss = |r: &[f64]| ray_loss(&weights, true, &ch, r, &target, 8).0.total();
        let (terms, analytic) = ray_loss(&weights, true, &ch, &rendered, &target, 8);
        assert!(terms.rgb > 0.0 && terms.depth > 0.0 && terms.semantic > 0.0 && terms.feature > 0.0);
        let numeric = central_differences(loss, &rendered, 1e-6);
        assert_close("ray loss", &analytic, &numeric, 1e-7);
    }

    #[test]
    fn opacity_pulls_the_far_class_through_the_box_and_the_rest_into_it() {
        let w = LossWeights::default();
        let term = |left: f64, label| opacity_loss(&w, Some(left), Some(label), Some(0), 2, 4).unwrap();
        // Labelled with the far class: T is pulled up to 1.
        let (loss, grad) = term(0.25, 0);
        assert!((loss - 0.5625 / 4.0).abs() < 1e-12 && grad < 0.0);
        // Any other class: T is pulled down to 0.
        let (loss, grad) = term(0.25, 1);
        assert!((loss - 0.0625 / 4.0).abs() < 1e-12 && grad > 0.0);
        let numeric = central_differences(|t: &[f64]| term(t[0], 1).0, &[0.25], 1e-6);
        assert_close("opacity", &[grad], &numeric, 1e-9);
        // No opaque sample, no label (or one out of range), or no far class: no term.
        assert!(opacity_loss::<f64>(&w, None, Some(0), Some(0), 2, 4).is_none());
        assert!(opacity_loss(&w, Some(0.5f64), None, Some(0), 2, 4).is_none());
        assert!(opacity_loss(&w, Some(0.5f64), Some(5), Some(0), 2, 4).is_none());
        assert!(opacity_loss(&w, Some(0.5f64), Some(0), None, 2, 4).is_none());
    }
}
