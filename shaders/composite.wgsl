// Volume rendering, the four losses and their backward, one invocation per ray looping over its
// S samples, for CPU devices (src/field/gpu/composite.rs `CompositeKernel`; GPUs run
// composite_lanes.wgsl, one workgroup per ray). The spec is reference::activations,
// reference::render (composite, composite_backward) and reference::loss::ray_loss, with the
// same operation order where it matters: transmittance from the summed optical depth, the
// backward suffix sum accumulated back to front. Layout, bindings and entry points:
// _composite.wgsl.
//!include _dispatch.wgsl
//!include _step.wgsl
//!include _ray_layout.wgsl
//!include _density.wgsl
//!include _bf16.wgsl
//!include _composite.wgsl

const WORKGROUP_SIZE: u32 = 64u;

// Forward (reference::render::composite) of a ray that hits the box: writes its rendered
// channels. The weights and transmittances are parked in the first two words of each sample's
// gradient row (the training backward overwrites them), so the logits and features can be
// summed channel by channel in a register: C and D need no fixed-size local array, and each sum
// runs over the samples in the reference's order.
fn forward(rows: RayRows) {
    let samples = step_info.samples_per_ray;
    let k = rows.k;
    let first = rows.first;
    var rgb = vec3<f32>(0.0);
    var depth = 0.0;
    var optical_depth = 0.0;
    for (var s = 0u; s < samples; s++) {
        let n = first + s;
        let interval = intervals[n];
        let step = transmittance_step(h0_source[n * params.h0_stride + params.h0_offset], interval.x, &optical_depth);
        let w = step.x;
        rgb += w * vec3<f32>(colour_of(n, 0u), colour_of(n, 1u), colour_of(n, 2u));
        depth += w * interval.y;
        grad_heads[n * k] = w;
        grad_heads[n * k + 1u] = step.y;
    }
    for (var ch = 4u; ch < k; ch++) {
        var sum = 0.0;
        for (var s = 0u; s < samples; s++) {
            sum += grad_heads[(first + s) * k] * channel_value(first + s, ch);
        }
        ray_outputs[rows.rendered_at + ch] = sum;
    }
    ray_outputs[rows.rendered_at] = rgb.x;
    ray_outputs[rows.rendered_at + 1u] = rgb.y;
    ray_outputs[rows.rendered_at + 2u] = rgb.z;
    ray_outputs[rows.rendered_at + 3u] = depth;
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
    if (targets[rows.target_row + TARGET_FLAGS] & RAY_HITS_BOX) == 0u {
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
    let rows = ray_rows(ray, batch);
    let k = rows.k;
    let first = rows.first;
    let grad_at = rows.grad_at;
    let flags = targets[rows.target_row + TARGET_FLAGS];

    clear_losses_and_gradient(ray, rows, 0u, 1u);
    if (flags & RAY_HITS_BOX) == 0u {
        clear_missed_ray(rows, 0u, 1u);
        return;
    }

    forward(rows);
    losses(rows, ray, flags);
    let grad_rgb = vec3<f32>(ray_outputs[grad_at], ray_outputs[grad_at + 1u], ray_outputs[grad_at + 2u]);

    // Backward, back to front (reference::render::composite_backward, then the activations'
    // backward): u_i = g . h_i, dsigma_i = delta_i (T_{i+1} u_i - sum_{j>i} w_j u_j).
    var suffix = 0.0;
    for (var back = 0u; back < samples; back++) {
        let s = samples - 1u - back;
        let n = first + s;
        let w = grad_heads[n * k];
        let t_after = grad_heads[n * k + 1u];
        let u = upstream(rows, n);
        let grad_sigma = intervals[n].x * (t_after * u - suffix);
        suffix += w * u;

        grad_heads[n * k] = grad_sigma * density(h0_source[n * params.h0_stride + params.h0_offset]);
        let h = slot[n];
        if h == NOT_KEPT {
            continue;
        }
        let row = h * k;
        let colour = vec3<f32>(colour_of(n, 0u), colour_of(n, 1u), colour_of(n, 2u));
        let grad_colour = w * grad_rgb;
        head_grads[row] = 0.0;
        head_grads[row + 1u] = grad_colour.x * colour.x * (1.0 - colour.x);
        head_grads[row + 2u] = grad_colour.y * colour.y * (1.0 - colour.y);
        head_grads[row + 3u] = grad_colour.z * colour.z * (1.0 - colour.z);
        for (var ch = 4u; ch < k; ch++) {
            head_grads[row + ch] = w * ray_outputs[grad_at + ch];
        }
    }
}
