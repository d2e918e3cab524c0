//! The WGSL stages of `shaders/`, validated by naga and include-expanded at build time by
//! `build.rs` (conventions in `shaders/README.md`). One constant per stage file (`matmul.wgsl` →
//! `MATMUL`) and `ALL` listing (file name, source) pairs.
include!(concat!(env!("OUT_DIR"), "/shaders.rs"));
