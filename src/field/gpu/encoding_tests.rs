use super::*;
use crate::field::config::Encoding;

#[test]
fn uniform_blocks_match_the_wgsl_layout() {
    // 12 scalars then 32 vec4<u32> (stride 16 in the uniform address space).
    assert_eq!(size_of::<HashGridUniforms>(), 12 * 4 + MAX_HASH_LEVELS * 16);
    assert_eq!(size_of::<crate::field::gpu::sh_encode::ShUniforms>(), 32);
}

#[test]
fn uniforms_follow_the_reference_grid() {
    let cfg = FieldConfig::default();
    let u = HashGridUniforms::new(&cfg, 1000, 7).unwrap();
    assert_eq!(
        (u.levels, u.features, u.table_size, u.table_offset),
        (16, 2, 1 << 19, 7)
    );
    assert_eq!((u.row_stride, u.frequency_column, u.frequencies), (44, 32, 2));
    assert_eq!(u.groups_per_level, 1000usize.div_ceil(WORKGROUP_SIZE as usize) as u32);
    // 16, 32, 64 cells are dense (65³ ≤ 2^19); 128 is hashed.
    assert_eq!(
        &u.level_geometry[..4],
        &[
            [16, 17, 0, 0],
            [32, 33, 4913, 0],
            [64, 65, 4913 + 35_937, 0],
            [128, 0, 315_475, 0]
        ]
    );
    assert_eq!(u.level_geometry[15][0], 16 << 15);
    assert_eq!(u.level_geometry[15][2], 315_475 + 12 * (1 << 19));
    assert_eq!(u.level_geometry[16], [0; 4]);

    let freq = FieldConfig {
        encoding: Encoding::freq_only_baseline(),
        ..FieldConfig::default()
    };
    let u = HashGridUniforms::new(&freq, 10, 0).unwrap();
    assert_eq!(
        (u.levels, u.row_stride, u.frequency_column, u.frequencies),
        (0, 60, 0, 10)
    );
}

#[test]
fn invalid_configs_are_refused() {
    let cfg = FieldConfig {
        hash_levels: 0,
        ..FieldConfig::default()
    };
    assert!(HashGridUniforms::new(&cfg, 10, 0).is_err());
    assert!(HashGridUniforms::new(&FieldConfig::default(), 10, usize::MAX).is_err());
}
