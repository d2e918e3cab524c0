// The density activation and one sample's step of the transmittance walk, shared by the
// composite and the keep stage so both make the same decision from the same bits
// (reference::activations::density, reference::render).

// reference::activations::DENSITY_LOG_CLAMP
const DENSITY_LOG_CLAMP: f32 = 15.0;

fn density(h0: f32) -> f32 {
    return exp(clamp(h0, -DENSITY_LOG_CLAMP, DENSITY_LOG_CLAMP));
}

// The interval sample_points.wgsl gives a ray's opaque last sample
// (reference::render::OPAQUE_INTERVAL): it takes the transmittance left, whatever its density.
const OPAQUE_INTERVAL: f32 = -1.0;

// Advances `optical_depth` over one sample of pre-activation density `h0` and length
// `interval`; returns (compositing weight T·α, transmittance after the sample).
fn transmittance_step(h0: f32, interval: f32, optical_depth: ptr<function, f32>) -> vec2<f32> {
    let sigma = density(h0);
    let t_before = exp(-*optical_depth);
    if interval < 0.0 {
        return vec2<f32>(t_before, 0.0);
    }
    *optical_depth += sigma * interval;
    let t_after = exp(-*optical_depth);
    return vec2<f32>(t_before - t_after, t_after);
}
