// What both composite kernels share (composite.wgsl, one invocation per ray, for CPU devices;
// composite_lanes.wgsl, one workgroup per ray, for GPUs): the layout, the bindings, reading a
// sample's channels, the losses and the backward's dot product, in the reference's order
// (reference::render, reference::loss::ray_loss).
//
// `ray_outputs` holds three blocks of B rows each, k = 4 + C + D channels in
// reference::render::Channels order [rgb, depth, logits, feature]:
//   [losses: B x (loss rgb, loss depth, loss semantic, loss feature)]
//   [rendered: B x k] [dL/drendered: B x k]
// so that reading the losses back is one contiguous range, and so is reading a render.
// Per sample n = ray * S + s a row of `grad_heads` (stride k) whose first word is dL/dh0, and
// per kept sample a row of `head_grads` (stride k, at the sample's packed row `slot[n]`):
//   [unused, dL/d(colour pre-sigmoid) (3), dL/dlogits (C), dL/dfeature (D)].
// The heads ran on the kept samples alone (keep.wgsl): their outputs are read at the packed
// row, and a sample that was not kept renders 0 for colour, logits and feature (its density
// still counts, and its depth).
// The rest of a `grad_heads` row is scratch (the second word holds the transmittance).
// Losses are weighted and divided by the whole batch B. Rays that miss the scene box render
// nothing and contribute no loss and no gradient (the reference never builds them).
//
// The feature head's rows are f32 or bf16 (FEATURE_BF16: as the feature MLP stores its output,
// `dense::mlp_row_format`).
//
// Each kernel has two entry points: `composite` (training: all of the above) and `composite_render` (display:
// the rendered block only, no loss and no backward; the forward is the same function, so the
// rendered values are the same).

// Mirrors `field::gpu::composite::CompositeUniforms` (80 bytes). Head outputs are read at
// row * stride + offset from buffers other passes own.
struct CompositeUniforms {
    classes: u32,
    feature_dim: u32,
    // The config's feature_supervision (rays still need RAY_HAS_CODE).
    supervise_features: u32,
    target_stride: u32,
    h0_stride: u32,
    h0_offset: u32,
    color_stride: u32,
    color_offset: u32,
    logits_stride: u32,
    logits_offset: u32,
    feature_stride: u32,
    feature_offset: u32,
    weight_rgb: f32,
    weight_depth: f32,
    weight_semantic: f32,
    weight_feature: f32,
    weight_opacity: f32,
    // The class of what lies beyond the scene box, or NO_FAR_CLASS: no opacity term.
    far_class: u32,
    _pad0: u32,
    _pad1: u32,
}

const LOSS_WORDS: u32 = 4u;
const NO_FAR_CLASS: u32 = 0xffffffffu;

@group(0) @binding(0) var<uniform> step_info: StepUniforms;
@group(0) @binding(1) var<uniform> params: CompositeUniforms;
@group(0) @binding(2) var<storage, read> h0_source: array<f32>;
@group(0) @binding(3) var<storage, read> color_source: array<f32>;
@group(0) @binding(4) var<storage, read> logits_source: array<f32>;
@group(0) @binding(5) var<storage, read> feature_source: array<u32>;

override FEATURE_BF16: bool = false;
@group(0) @binding(6) var<storage, read> intervals: array<vec2<f32>>;
@group(0) @binding(7) var<storage, read> targets: array<u32>;
@group(0) @binding(8) var<storage, read_write> grad_heads: array<f32>;
@group(0) @binding(9) var<storage, read_write> ray_outputs: array<f32>;
// Per sample: its packed row in the head outputs and `head_grads`, or NOT_KEPT.
@group(0) @binding(10) var<storage, read> slot: array<u32>;
@group(0) @binding(11) var<storage, read_write> head_grads: array<f32>;

const NOT_KEPT: u32 = 0xffffffffu;

fn sigmoid(h: f32) -> f32 {
    return 1.0 / (1.0 + exp(-h));
}

fn sign_or_zero(x: f32) -> f32 {
    return select(select(0.0, -1.0, x < 0.0), 1.0, x > 0.0);
}

fn colour_of(n: u32, c: u32) -> f32 {
    let h = slot[n];
    if h == NOT_KEPT {
        return 0.0;
    }
    return sigmoid(color_source[h * params.color_stride + params.color_offset + c]);
}

fn logit_of(n: u32, c: u32) -> f32 {
    let h = slot[n];
    if h == NOT_KEPT {
        return 0.0;
    }
    return logits_source[h * params.logits_stride + params.logits_offset + c];
}

fn feature_of(n: u32, d: u32) -> f32 {
    let h = slot[n];
    if h == NOT_KEPT {
        return 0.0;
    }
    let row = h * params.feature_stride + params.feature_offset;
    return row_value(feature_source[row_word(row, d, FEATURE_BF16)], d, FEATURE_BF16);
}

fn target_f32(row: u32, word: u32) -> f32 {
    return bitcast<f32>(targets[row + word]);
}

// Where one ray's values live.
struct RayRows {
    // The ray's first sample.
    first: u32,
    // Channels k.
    k: u32,
    // Its rendered channels and dL/drendered in `ray_outputs`.
    rendered_at: u32,
    grad_at: u32,
    target_row: u32,
}

fn ray_rows(ray: u32, batch: u32) -> RayRows {
    let k = 4u + params.classes + params.feature_dim;
    let rendered_at = batch * LOSS_WORDS + ray * k;
    return RayRows(
        ray * step_info.samples_per_ray,
        k,
        rendered_at,
        rendered_at + batch * k,
        ray * params.target_stride,
    );
}

// The clearing both kernels do, split over invocations: this one takes items first,
// first + step, ... (one invocation per ray: 0, 1; a workgroup per ray: its lane, its size).

// Zeroes the ray's losses and dL/drendered, before the losses add what applies to it.
fn clear_losses_and_gradient(ray: u32, rows: RayRows, first: u32, step: u32) {
    for (var c = first; c < LOSS_WORDS; c += step) {
        ray_outputs[ray * LOSS_WORDS + c] = 0.0;
    }
    for (var ch = first; ch < rows.k; ch += step) {
        ray_outputs[rows.grad_at + ch] = 0.0;
    }
}

// A ray that misses the scene box renders nothing and passes no gradient to its samples.
fn clear_missed_ray(rows: RayRows, first: u32, step: u32) {
    let k = rows.k;
    for (var ch = first; ch < k; ch += step) {
        ray_outputs[rows.rendered_at + ch] = 0.0;
    }
    for (var s = 0u; s < step_info.samples_per_ray; s++) {
        let n = rows.first + s;
        let h = slot[n];
        for (var ch = first; ch < k; ch += step) {
            grad_heads[n * k + ch] = 0.0;
            if h != NOT_KEPT {
                head_grads[h * k + ch] = 0.0;
            }
        }
    }
}

// Channel `ch` of sample n in reference::render::Channels order: colour (after the sigmoid),
// z-depth, logits, feature.
fn channel_value(n: u32, ch: u32) -> f32 {
    if ch < 3u {
        return colour_of(n, ch);
    }
    if ch == 3u {
        return intervals[n].y;
    }
    if ch < 4u + params.classes {
        return logit_of(n, ch - 4u);
    }
    return feature_of(n, ch - 4u - params.classes);
}

// The opacity term's target for the ray (reference::loss::opacity_loss): 1 when it is labelled
// with the far class, 0 when labelled with another, -1 where the term does not apply (no far
// class, no label, or a last sample that is not opaque).
fn opacity_target(rows: RayRows) -> f32 {
    let label = targets[rows.target_row + TARGET_LABEL];
    let last = rows.first + step_info.samples_per_ray - 1u;
    if params.far_class == NO_FAR_CLASS || label >= params.classes || intervals[last].x >= 0.0 {
        return -1.0;
    }
    return select(0.0, 1.0, label == params.far_class);
}

// The losses and dL/drendered (reference::loss::ray_loss), scaled by 1/B, from the rendered
// channels; the rest of the gradient row must be zero already. The opacity term is added to the
// semantic word; it reads the opaque sample's weight, parked in its gradient row by the forward.
fn losses(rows: RayRows, ray: u32, flags: u32) {
    let classes = params.classes;
    let feature_dim = params.feature_dim;
    let semantic_at = 4u;
    let feature_at = 4u + classes;
    let out_row = ray * LOSS_WORDS;
    let rendered_at = rows.rendered_at;
    let grad_at = rows.grad_at;
    let target_row = rows.target_row;
    let batch = step_info.batch_rays;
    let inv_batch = 1.0 / f32(batch);
    let rgb = vec3<f32>(ray_outputs[rendered_at], ray_outputs[rendered_at + 1u], ray_outputs[rendered_at + 2u]);
    let depth = ray_outputs[rendered_at + 3u];
    let target_rgb = vec3<f32>(
        target_f32(target_row, TARGET_RGB),
        target_f32(target_row, TARGET_RGB + 1u),
        target_f32(target_row, TARGET_RGB + 2u),
    );
    let rgb_weight = params.weight_rgb * inv_batch;
    let rgb_diff = rgb - target_rgb;
    ray_outputs[out_row] = dot(rgb_diff, rgb_diff) * rgb_weight;
    let grad_rgb = (rgb_diff + rgb_diff) * rgb_weight;
    ray_outputs[grad_at] = grad_rgb.x;
    ray_outputs[grad_at + 1u] = grad_rgb.y;
    ray_outputs[grad_at + 2u] = grad_rgb.z;

    let target_depth = target_f32(target_row, TARGET_DEPTH);
    if target_depth > 0.0 {
        let depth_weight = params.weight_depth * inv_batch;
        let diff = depth - target_depth;
        ray_outputs[out_row + 1u] = abs(diff) * depth_weight;
        ray_outputs[grad_at + 3u] = sign_or_zero(diff) * depth_weight;
    }

    let label = targets[target_row + TARGET_LABEL];
    if label < classes {
        let semantic_weight = params.weight_semantic * inv_batch;
        var max_logit = ray_outputs[rendered_at + semantic_at];
        for (var c = 1u; c < classes; c++) {
            max_logit = max(max_logit, ray_outputs[rendered_at + semantic_at + c]);
        }
        var sum = 0.0;
        for (var c = 0u; c < classes; c++) {
            sum += exp(ray_outputs[rendered_at + semantic_at + c] - max_logit);
        }
        let loss = log(sum) - (ray_outputs[rendered_at + semantic_at + label] - max_logit);
        ray_outputs[out_row + 2u] = loss * semantic_weight;
        for (var c = 0u; c < classes; c++) {
            var g = exp(ray_outputs[rendered_at + semantic_at + c] - max_logit) / sum;
            if c == label {
                g -= 1.0;
            }
            ray_outputs[grad_at + semantic_at + c] = g * semantic_weight;
        }
    }

    if params.supervise_features != 0u && (flags & RAY_HAS_CODE) != 0u {
        let inv_dim = 1.0 / f32(feature_dim);
        let feature_weight = params.weight_feature * inv_batch;
        var loss = 0.0;
        for (var d = 0u; d < feature_dim; d++) {
            let diff = ray_outputs[rendered_at + feature_at + d] - target_f32(target_row, TARGET_HEADER_WORDS + d);
            loss += abs(diff);
            ray_outputs[grad_at + feature_at + d] = sign_or_zero(diff) * inv_dim * feature_weight;
        }
        ray_outputs[out_row + 3u] = loss * inv_dim * feature_weight;
    }

    let opacity = opacity_target(rows);
    if opacity >= 0.0 {
        let left = grad_heads[(rows.first + step_info.samples_per_ray - 1u) * rows.k];
        let diff = left - opacity;
        ray_outputs[out_row + 2u] += diff * diff * (params.weight_opacity * inv_batch);
    }
}

// dL/dT of the opacity term, T = `left` being the weight of the ray's opaque last sample; 0
// where the term does not apply.
fn opacity_gradient(rows: RayRows, left: f32) -> f32 {
    let opacity = opacity_target(rows);
    if opacity < 0.0 {
        return 0.0;
    }
    let diff = left - opacity;
    return (diff + diff) * (params.weight_opacity * (1.0 / f32(step_info.batch_rays)));
}

// u = dL/drendered . (the sample's channels), in the reference's order, plus the opacity term's
// dL/dT at an opaque last sample (reference::render::composite_backward's grad_left). Reads the
// sample's weight from its gradient row, so it runs before the backward overwrites that row.
fn upstream(rows: RayRows, n: u32) -> f32 {
    let grad_at = rows.grad_at;
    let interval = intervals[n];
    var u = ray_outputs[grad_at] * colour_of(n, 0u) + ray_outputs[grad_at + 1u] * colour_of(n, 1u)
        + ray_outputs[grad_at + 2u] * colour_of(n, 2u) + ray_outputs[grad_at + 3u] * interval.y;
    for (var c = 0u; c < params.classes; c++) {
        u += ray_outputs[grad_at + 4u + c] * logit_of(n, c);
    }
    for (var d = 0u; d < params.feature_dim; d++) {
        u += ray_outputs[grad_at + 4u + params.classes + d] * feature_of(n, d);
    }
    if interval.x < 0.0 {
        u += opacity_gradient(rows, grad_heads[n * rows.k]);
    }
    return u;
}

