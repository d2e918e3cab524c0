// Volume rendering, the four losses and their backward, one workgroup of LANES invocations per
// ray, for GPUs (src/field/gpu/composite.rs `CompositeKernel`, whose docs say why; CPU devices
// run composite.wgsl, one invocation per ray). The spec is reference::activations,
// reference::render (composite, composite_backward) and reference::loss::ray_loss. The lanes
// split what is independent (the channels of the rendered sums, the samples of the backward's
// dot products, the channels of a sample's head gradients); the two walks along the ray (the
// transmittance, the backward's suffix sum) and the losses run on lane 0 over values the lanes
// staged in workgroup memory, so every sum adds in the same order as composite.wgsl's.
// Layout and bindings: _composite.wgsl.
//!include _dispatch.wgsl
//!include _step.wgsl
//!include _ray_layout.wgsl
//!include _density.wgsl
//!include _bf16.wgsl
//!include _composite.wgsl

// Invocations per ray: samples are staged LANES at a time, channels split LANES ways.
const LANES: u32 = 64u;

// One chunk of LANES samples, staged for lane 0's walks along the ray.
var<workgroup> chunk_h0: array<f32, LANES>;
var<workgroup> chunk_delta: array<f32, LANES>;
var<workgroup> chunk_w: array<f32, LANES>;
var<workgroup> chunk_t: array<f32, LANES>;
var<workgroup> chunk_u: array<f32, LANES>;
var<workgroup> chunk_grad_sigma: array<f32, LANES>;
// The ray's flags, read by lane 0 and made workgroup-uniform (barriers follow branches on it).
var<workgroup> ray_flags: u32;

fn flags_of_ray(rows: RayRows, lane: u32) -> u32 {
    if lane == 0u {
        ray_flags = targets[rows.target_row + TARGET_FLAGS];
    }
    return workgroupUniformLoad(&ray_flags);
}

// Forward (reference::render::composite) of a ray that hits the box: writes its rendered
// channels. The weights and transmittances are parked in the first two words of each sample's
// gradient row (the training backward overwrites them): lane 0 walks each staged chunk, then
// every lane sums its channels over all samples in order.
fn forward(rows: RayRows, lane: u32) {
    let samples = step_info.samples_per_ray;
    let k = rows.k;
    var optical_depth = 0.0;
    for (var base = 0u; base < samples; base += LANES) {
        let s = base + lane;
        let n = rows.first + s;
        if s < samples {
            chunk_h0[lane] = h0_source[n * params.h0_stride + params.h0_offset];
            chunk_delta[lane] = intervals[n].x;
        }
        workgroupBarrier();
        if lane == 0u {
            let count = min(LANES, samples - base);
            for (var i = 0u; i < count; i++) {
                let step = transmittance_step(chunk_h0[i], chunk_delta[i], &optical_depth);
                chunk_w[i] = step.x;
                chunk_t[i] = step.y;
            }
        }
        workgroupBarrier();
        if s < samples {
            grad_heads[n * k] = chunk_w[lane];
            grad_heads[n * k + 1u] = chunk_t[lane];
        }
    }
    storageBarrier();
    for (var ch = lane; ch < k; ch += LANES) {
        var sum = 0.0;
        for (var s = 0u; s < samples; s++) {
            let n = rows.first + s;
            sum += grad_heads[n * k] * channel_value(n, ch);
        }
        ray_outputs[rows.rendered_at + ch] = sum;
    }
    storageBarrier();
}

// One workgroup per ray, spread over a 2D grid of workgroups.
fn ray_of_workgroup(workgroup_id: vec3<u32>, num_workgroups: vec3<u32>) -> u32 {
    return linear_item_index(workgroup_id, num_workgroups, 0u, 1u);
}

@compute @workgroup_size(LANES)
fn composite_render(
    @builtin(workgroup_id) workgroup_id: vec3<u32>,
    @builtin(num_workgroups) num_workgroups: vec3<u32>,
    @builtin(local_invocation_index) lane: u32,
) {
    let ray = ray_of_workgroup(workgroup_id, num_workgroups);
    let batch = step_info.batch_rays;
    if ray >= batch {
        return;
    }
    let rows = ray_rows(ray, batch);
    if (flags_of_ray(rows, lane) & RAY_HITS_BOX) == 0u {
        for (var ch = lane; ch < rows.k; ch += LANES) {
            ray_outputs[rows.rendered_at + ch] = 0.0;
        }
        return;
    }
    forward(rows, lane);
}

// Backward, back to front, chunk by chunk (reference::render::composite_backward, then the
// activations' backward): u_i = g . h_i, dsigma_i = delta_i (T_{i+1} u_i - sum_{j>i} w_j u_j).
// Lanes form the chunk's u, lane 0 walks the suffix sum, then each kept sample's head gradient
// row is written by all lanes at once.
fn backward(rows: RayRows, lane: u32) {
    let samples = step_info.samples_per_ray;
    let k = rows.k;
    var suffix = 0.0;
    for (var chunk = (samples + LANES - 1u) / LANES; chunk > 0u; chunk--) {
        let base = (chunk - 1u) * LANES;
        let count = min(LANES, samples - base);
        let s = base + lane;
        let n = rows.first + s;
        if s < samples {
            chunk_u[lane] = upstream(rows, n);
            chunk_w[lane] = grad_heads[n * k];
            chunk_t[lane] = grad_heads[n * k + 1u];
            chunk_delta[lane] = intervals[n].x;
        }
        workgroupBarrier();
        if lane == 0u {
            for (var i = count; i > 0u; i--) {
                let j = i - 1u;
                chunk_grad_sigma[j] = chunk_delta[j] * (chunk_t[j] * chunk_u[j] - suffix);
                suffix += chunk_w[j] * chunk_u[j];
            }
        }
        workgroupBarrier();
        if s < samples {
            grad_heads[n * k] = chunk_grad_sigma[lane] * density(h0_source[n * params.h0_stride + params.h0_offset]);
        }
        for (var i = 0u; i < count; i++) {
            let m = rows.first + base + i;
            let h = slot[m];
            if h == NOT_KEPT {
                continue;
            }
            let w = chunk_w[i];
            for (var ch = lane; ch < k; ch += LANES) {
                var g = 0.0;
                if ch >= 4u {
                    g = w * ray_outputs[rows.grad_at + ch];
                } else if ch > 0u {
                    let colour = colour_of(m, ch - 1u);
                    g = w * ray_outputs[rows.grad_at + ch - 1u] * colour * (1.0 - colour);
                }
                head_grads[h * k + ch] = g;
            }
        }
        workgroupBarrier();
    }
}

@compute @workgroup_size(LANES)
fn composite(
    @builtin(workgroup_id) workgroup_id: vec3<u32>,
    @builtin(num_workgroups) num_workgroups: vec3<u32>,
    @builtin(local_invocation_index) lane: u32,
) {
    let ray = ray_of_workgroup(workgroup_id, num_workgroups);
    let batch = step_info.batch_rays;
    if ray >= batch {
        return;
    }
    let rows = ray_rows(ray, batch);
    let flags = flags_of_ray(rows, lane);

    clear_losses_and_gradient(ray, rows, lane, LANES);
    if (flags & RAY_HITS_BOX) == 0u {
        clear_missed_ray(rows, lane, LANES);
        return;
    }

    forward(rows, lane);
    if lane == 0u {
        losses(rows, ray, flags);
    }
    storageBarrier();
    backward(rows, lane);
}
