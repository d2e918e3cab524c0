// Picks the batch's rays on the GPU and writes each ray's geometry and targets
// (src/field/gpu/rays.rs `RayBatchPass`; CPU twin `rays::pick_pixel`).
// Rays [0, B - labelled_rays) are uniform over all pixels of all frames; the last
// `labelled_rays` draw a class uniformly among the classes that have labelled pixels, then a
// pixel of that class (all uniform while nothing is labelled). One invocation per ray.
//!include _dispatch.wgsl
//!include _step.wgsl
//!include _ray_random.wgsl
//!include _ray_layout.wgsl

// Mirrors `field::gpu::scene_buffers::SceneUniforms` (80 bytes).
struct SceneUniforms {
    width: u32,
    height: u32,
    frame_count: u32,
    pixels_per_frame: u32,
    total_pixels: u32,
    feature_height: u32,
    feature_width: u32,
    // The config's D (the target row's length); codes exist when has_features != 0.
    feature_dim: u32,
    fx: f32,
    fy: f32,
    cx: f32,
    cy: f32,
    bounds_min: vec3<f32>,
    depth_scale: f32,
    bounds_max: vec3<f32>,
    has_features: u32,
}

const WORKGROUP_SIZE: u32 = 64u;

@group(0) @binding(0) var<uniform> step_info: StepUniforms;
@group(0) @binding(1) var<uniform> scene: SceneUniforms;
// One packed RGBA8 word per pixel (r in the low byte), frames back to back.
@group(0) @binding(2) var<storage, read> rgb: array<u32>;
// Two u16 depth values per word (even pixel in the low half), in depth_scale units; 0 = none.
@group(0) @binding(3) var<storage, read> depth: array<u32>;
// Camera-to-world 3x4 per frame: rows [r0 r1 r2 t] as three vec4s.
@group(0) @binding(4) var<storage, read> poses: array<vec4<f32>>;
// Feature codes as f16 pairs, [frame][row][column][dim] (scene-archive.md).
@group(0) @binding(5) var<storage, read> features: array<u32>;
// [K, (class, start, count) x K, pixel indices...] (scene_buffers::LabelIndex::to_words).
@group(0) @binding(6) var<storage, read> labels: array<u32>;
@group(0) @binding(7) var<storage, read_write> rays: array<RayGeometry>;
@group(0) @binding(8) var<storage, read_write> targets: array<u32>;

fn feature_value(index: u32) -> f32 {
    let pair = unpack2x16float(features[index >> 1u]);
    return select(pair.x, pair.y, (index & 1u) == 1u);
}

@compute @workgroup_size(WORKGROUP_SIZE)
fn ray_batch(
    @builtin(workgroup_id) workgroup_id: vec3<u32>,
    @builtin(num_workgroups) num_workgroups: vec3<u32>,
    @builtin(local_invocation_index) local_index: u32,
) {
    let ray = linear_item_index(workgroup_id, num_workgroups, local_index, WORKGROUP_SIZE);
    let batch = step_info.batch_rays;
    if ray >= batch {
        return;
    }

    // Which pixel (the CPU twin `rays::pick_pixel` must stay in step with this block).
    let base = ray_stream_base(step_info.seed, step_info.step, ray);
    var pixel = random_below(ray_random(base, STREAM_PIXEL), scene.total_pixels);
    var label = NO_LABEL;
    let present_classes = labels[0];
    let first_labelled = batch - min(step_info.labelled_rays, batch);
    if ray >= first_labelled && present_classes > 0u {
        let k = random_below(ray_random(base, STREAM_CLASS), present_classes);
        let class_id = labels[1u + 3u * k];
        let start = labels[2u + 3u * k];
        let count = labels[3u + 3u * k];
        pixel = labels[start + random_below(ray_random(base, STREAM_ENTRY), count)];
        label = class_id;
    }
    write_ray(ray, pixel, label);
}

// Writes ray `ray`'s geometry and targets for the centre of global pixel `pixel`.
fn write_ray(ray: u32, pixel: u32, label: u32) {
    let frame = pixel / scene.pixels_per_frame;
    let in_frame = pixel - frame * scene.pixels_per_frame;
    let x = in_frame % scene.width;
    let y = in_frame / scene.width;

    // The ray through the pixel centre (reference::sampling::ray_through_pixel).
    let camera_dir = vec3<f32>((f32(x) - scene.cx) / scene.fx, (f32(y) - scene.cy) / scene.fy, 1.0);
    let length_z1 = length(camera_dir);
    let unit_camera_dir = camera_dir / length_z1;
    let r0 = poses[3u * frame];
    let r1 = poses[3u * frame + 1u];
    let r2 = poses[3u * frame + 2u];
    let origin = vec3<f32>(r0.w, r1.w, r2.w);
    let dir = vec3<f32>(dot(r0.xyz, unit_camera_dir), dot(r1.xyz, unit_camera_dir), dot(r2.xyz, unit_camera_dir));

    // Slab clipping (reference::sampling::clip_to_bounds), nothing behind the camera.
    var near = 0.0;
    // f32::MAX spelled so that every WGSL compiler accepts it (Chrome rejects 3.4028235e38).
    var far = 3.4028234e38;
    var inside = true;
    for (var a = 0u; a < 3u; a++) {
        let o = origin[a];
        let d = dir[a];
        let lo = scene.bounds_min[a];
        let hi = scene.bounds_max[a];
        if abs(d) < 1e-12 {
            if o < lo || o > hi {
                inside = false;
            }
            continue;
        }
        let t0 = (lo - o) / d;
        let t1 = (hi - o) / d;
        near = max(near, min(t0, t1));
        far = min(far, max(t0, t1));
    }
    let hits = inside && far > near;
    if !hits {
        near = 0.0;
        far = 0.0;
    }

    let depth_word = depth[pixel >> 1u];
    let depth_units = (depth_word >> (16u * (pixel & 1u))) & 0xffffu;
    let depth_m = f32(depth_units) * scene.depth_scale;

    var flags = select(0u, RAY_HITS_BOX, hits);
    if scene.has_features != 0u {
        flags |= RAY_HAS_CODE;
    }
    rays[ray] = RayGeometry(origin, 1.0 / length_z1, dir, near, far, depth_m, pixel, flags);

    let colour = unpack4x8unorm(rgb[pixel]);
    let row = ray * (TARGET_HEADER_WORDS + scene.feature_dim);
    targets[row + TARGET_RGB] = bitcast<u32>(colour.r);
    targets[row + TARGET_RGB + 1u] = bitcast<u32>(colour.g);
    targets[row + TARGET_RGB + 2u] = bitcast<u32>(colour.b);
    targets[row + TARGET_DEPTH] = bitcast<u32>(depth_m);
    targets[row + TARGET_LABEL] = label;
    targets[row + TARGET_FLAGS] = flags;
    targets[row + TARGET_PIXEL] = pixel;
    targets[row + 7u] = 0u;

    // The code of the feature cell holding the pixel (cells tile the image evenly).
    let cell_row = y * scene.feature_height / scene.height;
    let cell_col = x * scene.feature_width / scene.width;
    let code_start = ((frame * scene.feature_height + cell_row) * scene.feature_width + cell_col) * scene.feature_dim;
    for (var d = 0u; d < scene.feature_dim; d++) {
        var value = 0.0;
        if scene.has_features != 0u {
            value = feature_value(code_start + d);
        }
        targets[row + TARGET_HEADER_WORDS + d] = bitcast<u32>(value);
    }
}

// Mirrors `field::gpu::rays::TileUniforms`: the rays of a rendered tile are the consecutive
// global pixels [first_pixel, first_pixel + count); rays past `count` miss everything.
struct TileUniforms {
    first_pixel: u32,
    count: u32,
    _pad0: u32,
    _pad1: u32,
}

@group(0) @binding(9) var<uniform> tile: TileUniforms;

// Rays of a frame, in pixel order, for rendering (no randomness, no labels).
@compute @workgroup_size(WORKGROUP_SIZE)
fn frame_tile(
    @builtin(workgroup_id) workgroup_id: vec3<u32>,
    @builtin(num_workgroups) num_workgroups: vec3<u32>,
    @builtin(local_invocation_index) local_index: u32,
) {
    let ray = linear_item_index(workgroup_id, num_workgroups, local_index, WORKGROUP_SIZE);
    if ray >= step_info.batch_rays {
        return;
    }
    if ray >= tile.count {
        rays[ray] = RayGeometry(vec3<f32>(0.0), 1.0, vec3<f32>(0.0, 0.0, 1.0), 0.0, 0.0, 0.0, 0u, 0u);
        let row = ray * (TARGET_HEADER_WORDS + scene.feature_dim);
        for (var w = 0u; w < TARGET_HEADER_WORDS + scene.feature_dim; w++) {
            targets[row + w] = 0u;
        }
        targets[row + TARGET_LABEL] = NO_LABEL;
        return;
    }
    write_ray(ray, tile.first_pixel + ray, NO_LABEL);
}
