//! The workgroup-tiled dense kernels (`shaders/dense_*.wgsl` over `_dense_tile.wgsl`): the
//! tile shape picked per layer shape, and how the weight gradient is cut into chunks of rows.
use super::spec::DenseLayerSpec;
use crate::gpu::pipeline::Dispatch1d;
use crate::gpu::{GpuContext, GpuError};

/// Outputs per invocation along the rows and columns of a tile (`RM`, `RN` in the shader).
const PER_INVOCATION: u32 = 4;
/// Capacities in f32 of the two staging arrays (`A_TILE_CAP`, `B_TILE_CAP` in the shader).
const A_TILE_CAP: u32 = 2048;
const B_TILE_CAP: u32 = 1024;
/// Workgroup size of `reduce_chunks`.
pub(super) const REDUCE_WORKGROUP: u32 = 256;
/// `reduce_chunks` uses no tile constants; its pipeline is built with the shader's defaults.
pub(super) const REDUCE_SHAPE: TileShape = TileShape { tx: 16, ty: 16, kc: 16 };
/// Enough workgroups for the weight gradient to keep a GPU (or lavapipe's threads) busy; more
/// only lengthens the second reduction.
const WEIGHT_GRADIENT_TARGET_WORKGROUPS: u64 = 1024;
/// Fewest rows a weight-gradient chunk sums, so small batches do not make many tiny partials.
const MIN_CHUNK_ROWS: u32 = 256;

/// Invocation grid and chunk depth of one kernel instance: the workgroup is `tx × ty`
/// invocations and computes a `4·ty × 4·tx` tile of its product, staging `kc` deep chunks.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub struct TileShape {
    pub tx: u32,
    pub ty: u32,
    pub kc: u32,
}

impl TileShape {
    /// The shape for a product with `columns` output columns and `rows` output rows (`None`:
    /// as many as wanted, i.e. the N rows of a batch).
    pub fn for_product(columns: u32, rows: Option<u32>) -> TileShape {
        let tx = columns.div_ceil(PER_INVOCATION).next_power_of_two().min(16);
        let tall = (256 / tx).min(64);
        let ty = match rows {
            None => tall,
            Some(rows) => rows.div_ceil(PER_INVOCATION).next_power_of_two().min(tall),
        };
        let kc = (A_TILE_CAP / (ty * PER_INVOCATION))
            .min(B_TILE_CAP / (tx * PER_INVOCATION))
            .min(32);
        // Both caps and tile sides are powers of two, so kc is one too (cheap % and / in WGSL).
        TileShape { tx, ty, kc }
    }

    /// Rows and columns of the product one workgroup computes.
    pub fn tile_rows(&self) -> u32 {
        self.ty * PER_INVOCATION
    }

    pub fn tile_columns(&self) -> u32 {
        self.tx * PER_INVOCATION
    }

    pub(super) fn workgroup_storage_bytes(&self) -> u64 {
        4 * u64::from(self.tile_rows() * self.kc + self.tile_columns() * self.kc)
    }
}

pub(super) fn row_tile_dispatch(
    ctx: &GpuContext,
    rows: u32,
    shape: TileShape,
    column_tiles: u32,
) -> Result<[u32; 3], GpuError> {
    let tiles = Dispatch1d::for_device(ctx, u64::from(rows.div_ceil(shape.tile_rows())), 1)?;
    Ok([tiles.x, tiles.y, column_tiles])
}

/// Rows per weight-gradient chunk and the chunk count: enough workgroups to fill the device,
/// chunks a multiple of the staging depth, partials within one binding and the z-dimension limit.
pub(super) fn weight_chunks(ctx: &GpuContext, spec: &DenseLayerSpec, shape: TileShape) -> Result<(u32, u32), GpuError> {
    let tiles = u64::from(spec.in_dim.div_ceil(shape.tile_columns()) * spec.out_dim.div_ceil(shape.tile_rows()));
    let matrix_bytes = 4 * u64::from(spec.in_dim) * u64::from(spec.out_dim);
    let by_binding = (ctx
        .limits
        .max_storage_buffer_binding_size
        .min(ctx.limits.max_buffer_size)
        / matrix_bytes)
        .max(1);
    let max_chunks = by_binding
        .min(u64::from(ctx.limits.max_compute_workgroups_per_dimension))
        .min(u64::from(spec.rows.div_ceil(MIN_CHUNK_ROWS)))
        .max(1);
    let wanted = WEIGHT_GRADIENT_TARGET_WORKGROUPS.div_ceil(tiles).clamp(1, max_chunks);
    let chunk_rows = (u64::from(spec.rows).div_ceil(wanted) as u32).next_multiple_of(shape.kc);
    let chunks = spec.rows.div_ceil(chunk_rows);
    if u64::from(chunks) > max_chunks {
        return Err(GpuError::LimitExceeded {
            what: format!("{} weight-gradient partial sums", spec.label),
            limit: "max_storage_buffer_binding_size",
            needed: u64::from(chunks) * matrix_bytes,
            allowed: max_chunks * matrix_bytes,
        });
    }
    Ok((chunk_rows, chunks))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn tile_shapes_fit_the_staging_arrays_and_webgpu_limits() {
        for columns in 1..=300 {
            for rows in [None, Some(1), Some(3), Some(16), Some(128), Some(1000)] {
                let s = TileShape::for_product(columns, rows);
                assert!(s.tx * s.ty <= 256 && s.tx >= 1 && s.ty >= 1, "{s:?}");
                assert!(s.kc.is_power_of_two() && s.kc >= 2, "{s:?}");
                assert!(
                    s.tile_rows() * s.kc <= A_TILE_CAP && s.tile_columns() * s.kc <= B_TILE_CAP,
                    "{s:?}"
                );
                assert!(s.workgroup_storage_bytes() <= 16 * 1024);
            }
        }
        assert_eq!(TileShape::for_product(128, None), TileShape { tx: 16, ty: 16, kc: 16 });
        assert_eq!(TileShape::for_product(3, None), TileShape { tx: 1, ty: 64, kc: 8 });
    }
}
