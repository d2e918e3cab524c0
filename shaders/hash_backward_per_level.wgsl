// Backward of the hash grid (field::gpu::encoding::HashGridBackwardPass) without atomics, for
// CPU devices that have no float atomics (SwiftShader, natively and in a browser): one
// invocation per level walks every sample in order and adds into that level's part of the
// table, which no other invocation touches, so plain loads and stores are safe. SwiftShader
// ran hash_backward.wgsl (a compare-exchange loop per add, a workgroup barrier) about ten times
// slower (docs/results/bench.md, "The hash backward without atomics on CPU devices"); a
// handful of levels is enough work to fill a CPU's cores.
//
// Consecutive samples in the same cell (a ray's samples on coarse levels) are summed in
// registers and added once, as hash_backward.wgsl does within a workgroup. Every entry gets its
// adds in sample order, so the result does not depend on scheduling.
//
// One dispatch covers the samples [range.first, range.end): lavapipe ends every loop of an
// invocation once all its loops together have run 65,535 iterations (gallivm's loop limiter),
// so the pass splits the samples into dispatches that stay under that, counting the feature
// loops (`PER_LEVEL_LOOP_BUDGET` in src/field/gpu/encoding.rs). The corners are unrolled for
// the same reason.
//
// The gradient buffer must be zeroed before this pass, as for the atomic variants.

//!include _hash_grid.wgsl

@group(0) @binding(0) var<uniform> grid: HashGridUniforms;
@group(0) @binding(1) var<storage, read> positions: array<vec4<f32>>;
@group(0) @binding(2) var<storage, read> encoding_grad: array<f32>;
@group(0) @binding(3) var<storage, read_write> gradient: array<f32>;

// Mirrors `SampleRange` in src/field/gpu/encoding.rs.
struct SampleRange {
    first: u32,
    end: u32,
    _pad0: u32,
    _pad1: u32,
}

@group(0) @binding(4) var<uniform> range: SampleRange;

// The current run's sums, two vec4s per feature: [2f] for corners 0-3, [2f + 1] for corners
// 4-7 (`corner_weight`'s numbering: bit 2 of the corner is z).
var<private> sums: array<vec4<f32>, 16>;

// Index of feature 0 of the corner's entry in the gradient buffer.
fn corner_index(cell: vec3<u32>, corner: u32, geometry: vec4<u32>) -> u32 {
    let entry = corner_entry(cell, corner, geometry.y, grid.table_size);
    return table_index(grid.table_offset, grid.features, geometry.z, entry);
}

// Adds the run's sums to the 8 corners of `cell` and clears them.
fn flush_run(cell: vec3<u32>, geometry: vec4<u32>) {
    var first: array<u32, 8>;
    first[0] = corner_index(cell, 0u, geometry);
    first[1] = corner_index(cell, 1u, geometry);
    first[2] = corner_index(cell, 2u, geometry);
    first[3] = corner_index(cell, 3u, geometry);
    first[4] = corner_index(cell, 4u, geometry);
    first[5] = corner_index(cell, 5u, geometry);
    first[6] = corner_index(cell, 6u, geometry);
    first[7] = corner_index(cell, 7u, geometry);
    for (var f = 0u; f < grid.features; f++) {
        let low = sums[2u * f];
        let high = sums[2u * f + 1u];
        gradient[first[0] + f] += low.x;
        gradient[first[1] + f] += low.y;
        gradient[first[2] + f] += low.z;
        gradient[first[3] + f] += low.w;
        gradient[first[4] + f] += high.x;
        gradient[first[5] + f] += high.y;
        gradient[first[6] + f] += high.z;
        gradient[first[7] + f] += high.w;
        sums[2u * f] = vec4(0.0);
        sums[2u * f + 1u] = vec4(0.0);
    }
}

// Invocations (levels) per workgroup: a CPU device runs a workgroup's invocations as the lanes
// of one SIMD group (4 on SwiftShader), so lanes given levels do their work side by side.
const LEVELS_PER_GROUP: u32 = 4u;

@compute @workgroup_size(LEVELS_PER_GROUP)
fn hash_backward(
    @builtin(workgroup_id) workgroup_id: vec3<u32>,
    @builtin(local_invocation_index) local_index: u32,
) {
    let level = workgroup_id.x * LEVELS_PER_GROUP + local_index;
    if level >= grid.levels {
        return;
    }
    let geometry = grid.level_geometry[level];
    var run_cell = vec3<u32>(0u);
    var in_run = false;
    for (var sample = range.first; sample < range.end; sample++) {
        let located = locate_cell(positions[sample].xyz, geometry.x);
        if in_run && any(located.cell != run_cell) {
            flush_run(run_cell, geometry);
        }
        run_cell = located.cell;
        in_run = true;
        let weights = corner_weights(located.frac);
        let row = sample * grid.row_stride + level * grid.features;
        for (var f = 0u; f < grid.features; f++) {
            let g = encoding_grad[row + f];
            sums[2u * f] += weights[0] * g;
            sums[2u * f + 1u] += weights[1] * g;
        }
    }
    if in_run {
        flush_run(run_cell, geometry);
    }
}
