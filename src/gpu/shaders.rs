//! The WGSL stages of `shaders/`, validated by naga and include-expanded at build time by
//! `build.rs` (conventions in `shaders/README.md`). One constant per stage file (`matmul.wgsl` →
//! `MATMUL`) and `ALL` listing (file name, source) pairs; per stage, the resource bindings each
//! entry point uses (`MATMUL_BINDINGS`, and `ALL_BINDINGS` by file name), which passes bind by
//! name (`gpu::dispatch::bind_named`).
include!(concat!(env!("OUT_DIR"), "/shaders.rs"));

/// One resource binding an entry point uses: the WGSL variable's name and its place.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct ShaderBinding {
    pub entry_point: &'static str,
    pub name: &'static str,
    pub group: u32,
    pub binding: u32,
}

/// The binding table of the stage whose (expanded) source is `source`, found by the source's
/// hash and length (`build.rs` computes the same).
pub fn bindings_of(source: &str) -> Option<&'static [ShaderBinding]> {
    let hash = source_hash(source);
    ALL_BINDINGS
        .iter()
        .find(|(_, h, len, _)| *h == hash && *len == source.len())
        .map(|(_, _, _, table)| *table)
}

/// 64-bit FNV-1a of a stage's source.
fn source_hash(text: &str) -> u64 {
    text.bytes().fold(0xcbf2_9ce4_8422_2325, |h, b| {
        (h ^ u64::from(b)).wrapping_mul(0x0100_0000_01b3)
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn every_stage_has_a_binding_table_by_entry_point() {
        assert_eq!(ALL.len(), ALL_BINDINGS.len());
        for ((file, source), (table_file, ..)) in ALL.iter().zip(ALL_BINDINGS) {
            assert_eq!(file, table_file);
            // By value: `ALL_BINDINGS` is a constant, and each use of one may be its own copy.
            assert_eq!(
                bindings_of(source),
                ALL_BINDINGS.iter().find(|t| t.0 == *file).map(|t| t.3),
                "{file}"
            );
        }
        let composite = bindings_of(COMPOSITE).unwrap();
        assert!(composite.contains(&ShaderBinding {
            entry_point: "composite",
            name: "ray_outputs",
            group: 0,
            binding: 9
        }));
        // `frame_tile` reads no labels; `ray_batch` reads no tile.
        let rays = bindings_of(RAY_BATCH).unwrap();
        let uses = |entry: &str, name: &str| rays.iter().any(|b| b.entry_point == entry && b.name == name);
        assert!(uses("ray_batch", "labels") && !uses("frame_tile", "labels"));
        assert!(uses("frame_tile", "tile") && !uses("ray_batch", "tile"));
        assert_eq!(bindings_of("not a shader"), None);
    }
}
