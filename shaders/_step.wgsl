// The per-step uniform block the trainer writes with queue.write_buffer before each submit.
// Mirrors `field::gpu::rays::StepUniforms` field by field (32 bytes); bind it as
// `var<uniform> step_info: StepUniforms;` (a stage picks its own binding).
struct StepUniforms {
    // Adam step t (1-based) and the RNG's counter: (seed, step, ray) names every random number.
    step: u32,
    seed: u32,
    batch_rays: u32,
    samples_per_ray: u32,
    lr: f32,
    // Adam bias corrections 1/(1 - beta1^t) and 1/(1 - beta2^t).
    adam_c1: f32,
    adam_c2: f32,
    // The last `labelled_rays` rays of the batch are drawn from labelled pixels (when any exist).
    labelled_rays: u32,
}
