// Which samples reach the colour, feature and semantic heads (src/field/gpu/keep.rs
// `KeepPass`; the spec is reference::render::kept_samples): after the density MLP, a sample
// whose compositing weight w = T·α (from h0 and the interval alone, in the order the composite
// computes it) is below `threshold` is dropped; threshold 0 keeps every sample. The kept
// samples are packed in sample order (deterministic, so a step gives the same bits every run,
// and keeping all of them is the identity):
//   `count_kept`   one invocation per ray: how many of its samples are kept;
//   `scan_kept`    one workgroup: each ray's first packed row (exclusive prefix sum), the total
//                  into `row_count`, and the workgroup counts of every head kernel into
//                  `dispatch_args` (their dispatches are indirect, so they launch for the kept
//                  rows alone);
//   `compact_kept` one invocation per ray: `rows[k]` = sample of packed row k, `slot[n]` =
//                  packed row of sample n or NOT_KEPT;
//   `gather_rows`  one invocation per packed row: the head inputs the heads read in packed
//                  order, the density output row [h0 | g] and the view's SH coefficients.
//!include _dispatch.wgsl
//!include _step.wgsl
//!include _ray_layout.wgsl
//!include _density.wgsl

// Mirrors `field::gpu::keep::KeepUniforms` (32 bytes).
struct KeepUniforms {
    // FieldConfig::head_weight_threshold; 0 keeps every sample, even of rays that miss the box.
    threshold: f32,
    // Values per row of the density output [h0 | g] (1 + geometry).
    density_stride: u32,
    // Columns of the SH rows read, and the stride and offset of where they go in the packed
    // colour-input rows [SH | g].
    sh_width: u32,
    color_stride: u32,
    // Entries of `arg_specs`.
    arg_count: u32,
    // The device's max_compute_workgroups_per_dimension, to spread long 1D dispatches over y.
    max_groups_per_dimension: u32,
    // u32 words per ray of `targets`.
    target_stride: u32,
    pad0: u32,
}

const WORKGROUP_SIZE: u32 = 64u;
const SCAN_WORKGROUP: u32 = 256u;
const NOT_KEPT: u32 = 0xffffffffu;

@group(0) @binding(0) var<uniform> step_info: StepUniforms;
@group(0) @binding(1) var<uniform> keep: KeepUniforms;
@group(0) @binding(2) var<storage, read> density_out: array<f32>;
@group(0) @binding(3) var<storage, read> intervals: array<vec2<f32>>;
@group(0) @binding(4) var<storage, read> targets: array<u32>;
// Kept samples per ray, then (after the scan) each ray's first packed row.
@group(0) @binding(5) var<storage, read_write> ray_kept: array<u32>;
@group(0) @binding(6) var<storage, read_write> ray_first: array<u32>;
// One word: the packed row count every head kernel reads.
@group(0) @binding(7) var<storage, read_write> row_count: array<u32>;
// Three workgroup counts per head kernel shape.
@group(0) @binding(8) var<storage, read_write> dispatch_args: array<u32>;
// Per head kernel shape: (items per row, items per workgroup, z workgroups, unused).
@group(0) @binding(9) var<storage, read> arg_specs: array<vec4<u32>>;
@group(0) @binding(10) var<storage, read_write> rows: array<u32>;
@group(0) @binding(11) var<storage, read_write> slot: array<u32>;
// In the colour rows' format (COLOR_BF16: both bf16).
@group(0) @binding(12) var<storage, read> sh_rows: array<u32>;
@group(0) @binding(13) var<storage, read_write> density_packed: array<f32>;
// The colour MLP's input rows, f32 or bf16 (COLOR_BF16: as the MLP stores them, `InputRows`; the
// SH rows are then bf16 too, and their words are copied).
@group(0) @binding(14) var<storage, read_write> color_packed: array<u32>;
override COLOR_BF16: bool = false;
// Two words: the kept rows summed over every run of `scan_kept`, and the runs (wrapping), so
// `bench` can average the kept rows over the steps it timed without reading back each step.
@group(0) @binding(15) var<storage, read_write> kept_tally: array<u32>;

fn ray_hits_box(ray: u32) -> bool {
    return (targets[ray * keep.target_stride + TARGET_FLAGS] & RAY_HITS_BOX) != 0u;
}

fn is_kept(w: f32) -> bool {
    return w >= keep.threshold;
}

// Walks one ray's samples as the composite does and returns how many are kept; with `write`,
// also packs them from row `first_row` (`rows`, `slot`). `count_kept` and `compact_kept` both
// call it, so they make the same decisions.
fn keep_ray(ray: u32, first_row: u32, write: bool) -> u32 {
    let samples = step_info.samples_per_ray;
    let first = ray * samples;
    let keep_all = keep.threshold <= 0.0;
    let hits = ray_hits_box(ray);
    var next = first_row;
    var optical_depth = 0.0;
    for (var s = 0u; s < samples; s++) {
        let n = first + s;
        var kept = keep_all;
        if !keep_all && hits {
            kept = is_kept(transmittance_step(density_out[n * keep.density_stride], intervals[n].x, &optical_depth).x);
        }
        if write {
            if kept {
                rows[next] = n;
                slot[n] = next;
            } else {
                slot[n] = NOT_KEPT;
            }
        }
        if kept {
            next += 1u;
        }
    }
    return next - first_row;
}

@compute @workgroup_size(WORKGROUP_SIZE)
fn count_kept(
    @builtin(workgroup_id) workgroup_id: vec3<u32>,
    @builtin(num_workgroups) num_workgroups: vec3<u32>,
    @builtin(local_invocation_index) local_index: u32,
) {
    let ray = linear_item_index(workgroup_id, num_workgroups, local_index, WORKGROUP_SIZE);
    if ray >= step_info.batch_rays {
        return;
    }
    ray_kept[ray] = keep_ray(ray, 0u, false);
}

var<workgroup> partial: array<u32, SCAN_WORKGROUP>;

@compute @workgroup_size(SCAN_WORKGROUP)
fn scan_kept(@builtin(local_invocation_index) local_index: u32) {
    let batch = step_info.batch_rays;
    // Each invocation scans a contiguous run of rays, then the runs' totals are scanned.
    let per = (batch + SCAN_WORKGROUP - 1u) / SCAN_WORKGROUP;
    let begin = min(local_index * per, batch);
    let end = min(begin + per, batch);
    var sum = 0u;
    for (var r = begin; r < end; r++) {
        sum += ray_kept[r];
    }
    partial[local_index] = sum;
    workgroupBarrier();
    // Hillis-Steele inclusive scan of the run totals.
    for (var offset = 1u; offset < SCAN_WORKGROUP; offset *= 2u) {
        var add = 0u;
        if local_index >= offset {
            add = partial[local_index - offset];
        }
        workgroupBarrier();
        partial[local_index] += add;
        workgroupBarrier();
    }
    var running = partial[local_index] - sum;
    for (var r = begin; r < end; r++) {
        ray_first[r] = running;
        running += ray_kept[r];
    }
    if local_index != 0u {
        return;
    }
    let total = partial[SCAN_WORKGROUP - 1u];
    row_count[0] = total;
    kept_tally[0] += total;
    kept_tally[1] += 1u;
    for (var a = 0u; a < keep.arg_count; a++) {
        let spec = arg_specs[a];
        let groups = (total * spec.x + spec.y - 1u) / spec.y;
        // As gpu::pipeline::Dispatch1d: x up to the limit, then rows of it along y.
        let x = min(groups, keep.max_groups_per_dimension);
        var y = 1u;
        if x > 0u {
            y = (groups + x - 1u) / x;
        }
        dispatch_args[3u * a] = x;
        dispatch_args[3u * a + 1u] = y;
        dispatch_args[3u * a + 2u] = spec.z;
    }
}

@compute @workgroup_size(WORKGROUP_SIZE)
fn compact_kept(
    @builtin(workgroup_id) workgroup_id: vec3<u32>,
    @builtin(num_workgroups) num_workgroups: vec3<u32>,
    @builtin(local_invocation_index) local_index: u32,
) {
    let ray = linear_item_index(workgroup_id, num_workgroups, local_index, WORKGROUP_SIZE);
    if ray >= step_info.batch_rays {
        return;
    }
    keep_ray(ray, ray_first[ray], true);
}

@compute @workgroup_size(WORKGROUP_SIZE)
fn gather_rows(
    @builtin(workgroup_id) workgroup_id: vec3<u32>,
    @builtin(num_workgroups) num_workgroups: vec3<u32>,
    @builtin(local_invocation_index) local_index: u32,
) {
    let k = linear_item_index(workgroup_id, num_workgroups, local_index, WORKGROUP_SIZE);
    if k >= row_count[0] {
        return;
    }
    let n = rows[k];
    let width = keep.density_stride;
    for (var j = 0u; j < width; j++) {
        density_packed[k * width + j] = density_out[n * width + j];
    }
    let color_row = k * keep.color_stride;
    if COLOR_BF16 {
        // Whole words from the rows' starts (sh_width and the strides are even).
        let words = keep.sh_width >> 1u;
        for (var w = 0u; w < words; w++) {
            color_packed[(color_row >> 1u) + w] = sh_rows[n * words + w];
        }
    } else {
        for (var j = 0u; j < keep.sh_width; j++) {
            color_packed[color_row + j] = sh_rows[n * keep.sh_width + j];
        }
    }
}
