// Shared by the dense kernels that form dZ from dY (src/field/gpu/dense/): each declares its own
// `y_value(row, j)`, since Y is an f32 binding in the tiled kernels and f32 or bf16 rows in the
// packed-weight ones.

// dL/dZ of one element: dY, masked by the ReLU's derivative (0 at 0, as the reference) read
// from the stored activation Y, value j of the row starting at `y_row`. Uses the stage's own
// `y_value`; Y is only read for ReLU layers.
fn output_gradient(dy_value: f32, y_row: u32, j: u32) -> f32 {
    if dims.relu != 0u && !(y_value(y_row, j) > 0.0) {
        return 0.0;
    }
    return dy_value;
}
