// Volume rendering, the four losses and their backward, one invocation per ray looping over its
// S samples (src/field/gpu/composite.rs `CompositePass`). The spec is reference::activations,
// reference::render (composite, composite_backward) and reference::loss::ray_loss, with the
// same operation order where it matters: transmittance from the summed optical depth, the
// backward suffix sum accumulated back to front.
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
// Two entry points: `composite` (training: all of the above) and `composite_render` (display:
// the rendered block only, no loss and no backward; the forward is the same function, so the
// rendered values are the same).
//!include _dispatch.wgsl
//!include _step.wgsl
//!include _ray_layout.wgsl
//!include _density.wgsl

// Mirrors `field::gpu::composite::CompositeUniforms` (64 bytes). Head outputs are read at
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
}

const WORKGROUP_SIZE: u32 = 64u;
const LOSS_WORDS: u32 = 4u;

@group(0) @binding(0) var<uniform> step_info: StepUniforms;
@group(0) @binding(1) var<uniform> params: CompositeUniforms;
@group(0) @binding(2) var<storage, read> h0_source: array<f32>;
@group(0) @binding(3) var<storage, read> color_source: array<f32>;
@group(0) @binding(4) var<storage, read> logits_source: array<f32>;
@group(0) @binding(5) var<storage, read> feature_source: array<f32>;
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
    return feature_source[h * params.feature_stride + params.feature_offset + d];
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
    flags: u32,
}

fn ray_rows(ray: u32, batch: u32) -> RayRows {
    let k = 4u + params.classes + params.feature_dim;
    let rendered_at = batch * LOSS_WORDS + ray * k;
    let target_row = ray * params.target_stride;
    return RayRows(
        ray * step_info.samples_per_ray,
        k,
        rendered_at,
        rendered_at + batch * k,
        target_row,
        targets[target_row + TARGET_FLAGS],
    );
}

// Forward (reference::render::composite) of a ray that hits the box: writes its rendered
// channels and returns (rgb, depth). The weights and transmittances are parked in the first two
// words of each sample's gradient row (the training backward overwrites them), so the logits
// and features can be summed channel by channel in a register: C and D need no fixed-size
// local array, and each sum runs over the samples in the reference's order.
fn forward(rows: RayRows) -> vec4<f32> {
    let samples = step_info.samples_per_ray;
    let k = rows.k;
    let first = rows.first;
    let semantic_at = 4u;
    let feature_at = 4u + params.classes;
    var rgb = vec3<f32>(0.0);
    var depth = 0.0;
    var optical_depth = 0.0;
    for (var s = 0u; s < samples; s++) {
        let n = first + s;
        let interval = intervals[n];
        let step = transmittance_step(h0_source[n * params.h0_stride + params.h0_offset], interval.x, &optical_depth);
        let w = step.x;
        let t_after = step.y;
        rgb += w * vec3<f32>(colour_of(n, 0u), colour_of(n, 1u), colour_of(n, 2u));
        depth += w * interval.y;
        grad_heads[n * k] = w;
        grad_heads[n * k + 1u] = t_after;
    }
    for (var c = 0u; c < params.classes; c++) {
        var sum = 0.0;
        for (var s = 0u; s < samples; s++) {
            sum += grad_heads[(first + s) * k] * logit_of(first + s, c);
        }
        ray_outputs[rows.rendered_at + semantic_at + c] = sum;
    }
    for (var d = 0u; d < params.feature_dim; d++) {
        var sum = 0.0;
        for (var s = 0u; s < samples; s++) {
            sum += grad_heads[(first + s) * k] * feature_of(first + s, d);
        }
        ray_outputs[rows.rendered_at + feature_at + d] = sum;
    }
    ray_outputs[rows.rendered_at] = rgb.x;
    ray_outputs[rows.rendered_at + 1u] = rgb.y;
    ray_outputs[rows.rendered_at + 2u] = rgb.z;
    ray_outputs[rows.rendered_at + 3u] = depth;
    return vec4<f32>(rgb, depth);
}

@compute @workgroup_size(WORKGROUP_SIZE)
fn composite_render(
    @builtin(workgroup_id) workgroup_id: vec3<u32>,
    @builtin(num_workgroups) num_workgroups: vec3<u32>,
    @builtin(local_invocation_index) local_index: u32,
) {
    let ray = linear_item_index(workgroup_id, num_workgroups, local_index, WORKGROUP_SIZE);
    let batch = step_info.batch_rays;
    if ray >= batch {
        return;
    }
    let rows = ray_rows(ray, batch);
    if (rows.flags & RAY_HITS_BOX) == 0u {
        for (var c = 0u; c < rows.k; c++) {
            ray_outputs[rows.rendered_at + c] = 0.0;
        }
        return;
    }
    forward(rows);
}

@compute @workgroup_size(WORKGROUP_SIZE)
fn composite(
    @builtin(workgroup_id) workgroup_id: vec3<u32>,
    @builtin(num_workgroups) num_workgroups: vec3<u32>,
    @builtin(local_invocation_index) local_index: u32,
) {
    let ray = linear_item_index(workgroup_id, num_workgroups, local_index, WORKGROUP_SIZE);
    let batch = step_info.batch_rays;
    if ray >= batch {
        return;
    }
    let samples = step_info.samples_per_ray;
    let classes = params.classes;
    let feature_dim = params.feature_dim;
    let semantic_at = 4u;
    let feature_at = 4u + classes;
    let rows = ray_rows(ray, batch);
    let k = rows.k;
    let out_row = ray * LOSS_WORDS;
    let rendered_at = rows.rendered_at;
    let grad_at = rows.grad_at;
    let first = rows.first;
    let target_row = rows.target_row;
    let flags = rows.flags;

    for (var c = 0u; c < LOSS_WORDS; c++) {
        ray_outputs[out_row + c] = 0.0;
    }
    for (var c = 0u; c < k; c++) {
        ray_outputs[rendered_at + c] = 0.0;
        ray_outputs[grad_at + c] = 0.0;
    }
    if (flags & RAY_HITS_BOX) == 0u {
        for (var s = 0u; s < samples; s++) {
            let h = slot[first + s];
            for (var c = 0u; c < k; c++) {
                grad_heads[(first + s) * k + c] = 0.0;
                if h != NOT_KEPT {
                    head_grads[h * k + c] = 0.0;
                }
            }
        }
        return;
    }

    let rendered = forward(rows);
    let rgb = rendered.xyz;
    let depth = rendered.w;

    // Losses and dL/drendered (reference::loss::ray_loss), scaled by 1/B.
    let inv_batch = 1.0 / f32(batch);
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

    var grad_depth = 0.0;
    let target_depth = target_f32(target_row, TARGET_DEPTH);
    if target_depth > 0.0 {
        let depth_weight = params.weight_depth * inv_batch;
        let diff = depth - target_depth;
        ray_outputs[out_row + 1u] = abs(diff) * depth_weight;
        grad_depth = sign_or_zero(diff) * depth_weight;
    }
    ray_outputs[grad_at + 3u] = grad_depth;

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

    // Backward, back to front (reference::render::composite_backward, then the activations'
    // backward): u_i = g . h_i, dsigma_i = delta_i (T_{i+1} u_i - sum_{j>i} w_j u_j).
    var suffix = 0.0;
    for (var back = 0u; back < samples; back++) {
        let s = samples - 1u - back;
        let n = first + s;
        let interval = intervals[n];
        let w = grad_heads[n * k];
        let t_after = grad_heads[n * k + 1u];
        let colour = vec3<f32>(colour_of(n, 0u), colour_of(n, 1u), colour_of(n, 2u));
        var u = grad_rgb.x * colour.x + grad_rgb.y * colour.y + grad_rgb.z * colour.z + grad_depth * interval.y;
        for (var c = 0u; c < classes; c++) {
            u += ray_outputs[grad_at + semantic_at + c] * logit_of(n, c);
        }
        for (var d = 0u; d < feature_dim; d++) {
            u += ray_outputs[grad_at + feature_at + d] * feature_of(n, d);
        }
        let grad_sigma = interval.x * (t_after * u - suffix);
        suffix += w * u;

        grad_heads[n * k] = grad_sigma * density(h0_source[n * params.h0_stride + params.h0_offset]);
        let h = slot[n];
        if h == NOT_KEPT {
            continue;
        }
        let row = h * k;
        let grad_colour = w * grad_rgb;
        head_grads[row] = 0.0;
        head_grads[row + 1u] = grad_colour.x * colour.x * (1.0 - colour.x);
        head_grads[row + 2u] = grad_colour.y * colour.y * (1.0 - colour.y);
        head_grads[row + 3u] = grad_colour.z * colour.z * (1.0 - colour.z);
        for (var c = 0u; c < classes; c++) {
            head_grads[row + semantic_at + c] = w * ray_outputs[grad_at + semantic_at + c];
        }
        for (var d = 0u; d < feature_dim; d++) {
            head_grads[row + feature_at + d] = w * ray_outputs[grad_at + feature_at + d];
        }
    }
}
