// The multiresolution hash grid shared by hash_encode.wgsl and hash_backward.wgsl: the uniform
// block of both passes and the cell geometry of `field::reference::hash_grid`, operation for
// operation (clamp, cell = min(floor(p·res), res − 1), frac = p·res − cell, weights multiplied
// x then y then z, dense index or spatial hash), so the GPU picks the same table entries and
// bit-identical trilinear weights as the f32 reference.

const MAX_HASH_LEVELS: u32 = 32u;

// Mirrors `field::gpu::encoding::HashGridUniforms` field by field.
struct HashGridUniforms {
    // Samples N: rows of the position, encoding and encoding-gradient buffers.
    sample_count: u32,
    // Hash-grid levels (0 for the frequency-only encoding).
    levels: u32,
    // Features per level (F).
    features: u32,
    // Entries of a hashed level (a power of two); a dense level holds its vertices only.
    table_size: u32,
    // Index of the table's first value in the flat params / gradient buffer.
    table_offset: u32,
    // Values per encoding row (the encoding dimension).
    row_stride: u32,
    // Column of the first frequency value (= levels · F).
    frequency_column: u32,
    // Octaves of the frequency encoding (0: none).
    frequencies: u32,
    // Backward only: workgroups covering the N samples of one level.
    groups_per_level: u32,
    _pad0: u32,
    _pad1: u32,
    _pad2: u32,
    // Per level: x = cells per axis, y = vertices per axis when indexed densely, 0 when hashed,
    // z = the level's first entry in the table (levels hold min((res+1)³, table_size) entries,
    // one after the other), w = 0.
    level_geometry: array<vec4<u32>, MAX_HASH_LEVELS>,
}

struct GridCell {
    cell: vec3<u32>,
    frac: vec3<f32>,
}

// The cell holding `p` on a level of `resolution` cells per axis. The min keeps p = 1 in the
// last cell and keeps every index inside the level's table even for garbage positions.
fn locate_cell(p: vec3<f32>, resolution: u32) -> GridCell {
    let x = clamp(p, vec3(0.0), vec3(1.0)) * f32(resolution);
    let cell = min(vec3<u32>(floor(x)), vec3(resolution - 1u));
    return GridCell(cell, x - vec3<f32>(cell));
}

// Corner c takes the upper vertex on axis d when bit d of c is set.
fn corner_weight(frac: vec3<f32>, corner: u32) -> f32 {
    let upper = vec3<bool>((corner & 1u) != 0u, (corner & 2u) != 0u, (corner & 4u) != 0u);
    let t = select(vec3(1.0) - frac, frac, upper);
    return t.x * t.y * t.z;
}

// `corner_weight` of all 8 corners at once, corners 0-3 and 4-7 as two vec4s, with the same
// products in the same order (x · y, then · z), so each weight is bit-identical to it.
fn corner_weights(frac: vec3<f32>) -> array<vec4<f32>, 2> {
    let x = vec4(1.0 - frac.x, frac.x, 1.0 - frac.x, frac.x);
    let y = vec4(1.0 - frac.y, 1.0 - frac.y, frac.y, frac.y);
    let xy = x * y;
    return array(xy * (1.0 - frac.z), xy * frac.z);
}

// Entry of the corner's vertex within its level's table.
fn corner_entry(cell: vec3<u32>, corner: u32, dense_side: u32, table_size: u32) -> u32 {
    let v = cell + vec3<u32>(corner & 1u, (corner >> 1u) & 1u, (corner >> 2u) & 1u);
    if dense_side != 0u {
        return v.x + v.y * dense_side + v.z * dense_side * dense_side;
    }
    // u32 multiplication wraps, as the reference's wrapping_mul.
    return (v.x ^ (v.y * 2654435761u) ^ (v.z * 805459861u)) & (table_size - 1u);
}

// Index of feature 0 of a level's table entry in the flat params / gradient buffer
// (`level_first_entry`: level_geometry's z).
fn table_index(table_offset: u32, features: u32, level_first_entry: u32, entry: u32) -> u32 {
    return table_offset + (level_first_entry + entry) * features;
}
