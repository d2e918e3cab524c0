//! Checks that every Rust `#[repr(C)]` struct written into a GPU buffer has the layout of the
//! WGSL struct it mirrors: the same size and every named field at the same offset, with the same
//! size and scalar kind. naga's [`Layouter`](naga::proc::Layouter) gives the WGSL side; a small
//! parser of the Rust struct's text gives the Rust side (the structs hold only `u32`, `i32`,
//! `f32` and arrays of them, which is all a uniform mirror needs).
//!
//! Like `shader_check`, this file is compiled twice: by `build.rs` (a mismatch fails the build)
//! and by the library on native targets (so tests can prove a mismatch is caught). It depends on
//! nothing but `naga`, `std` and `shader_check`.
use std::fmt;

use super::naga;
use super::shader_check::ExpandedShader;

/// One Rust struct and the WGSL struct it mirrors.
#[derive(Debug, Clone, Copy)]
pub struct Mirror {
    /// The Rust file (relative to the crate root) that defines the struct.
    pub rust_file: &'static str,
    pub rust_struct: &'static str,
    /// A stage file in `shaders/` whose expanded source declares the WGSL struct.
    pub wgsl_stage: &'static str,
    pub wgsl_struct: &'static str,
}

const fn mirror(
    rust_file: &'static str,
    rust_struct: &'static str,
    wgsl_stage: &'static str,
    wgsl_struct: &'static str,
) -> Mirror {
    Mirror {
        rust_file,
        rust_struct,
        wgsl_stage,
        wgsl_struct,
    }
}

/// Every Rust struct that is uploaded as a WGSL struct. A test (`every_repr_c_struct_is_listed`)
/// fails when a `#[repr(C)]` struct in `src/` is missing here.
pub const MIRRORS: &[Mirror] = &[
    mirror("src/gpu/matmul.rs", "DimsUniform", "matmul.wgsl", "Dims"),
    mirror("src/field/gpu/adam.rs", "AdamConstants", "adam.wgsl", "AdamConstants"),
    mirror(
        "src/field/gpu/composite.rs",
        "CompositeUniforms",
        "composite.wgsl",
        "CompositeUniforms",
    ),
    mirror(
        "src/field/gpu/dense/chain.rs",
        "ChainDims",
        "dense_backward_chain_uniform.wgsl",
        "ChainDims",
    ),
    mirror(
        "src/field/gpu/dense/spec.rs",
        "DenseDims",
        "dense_forward.wgsl",
        "DenseDims",
    ),
    mirror(
        "src/field/gpu/dense/uniform.rs",
        "ChunkInfo",
        "dense_backward_weight_uniform.wgsl",
        "ChunkInfo",
    ),
    mirror(
        "src/field/gpu/dense/uniform.rs",
        "PackJob",
        "dense_pack_weights.wgsl",
        "PackJob",
    ),
    mirror(
        "src/field/gpu/encoding.rs",
        "HashGridUniforms",
        "hash_encode.wgsl",
        "HashGridUniforms",
    ),
    mirror(
        "src/field/gpu/encoding.rs",
        "SampleRange",
        "hash_backward_per_level.wgsl",
        "SampleRange",
    ),
    mirror(
        "src/field/gpu/sh_encode.rs",
        "ShUniforms",
        "sh_encode.wgsl",
        "ShUniforms",
    ),
    mirror("src/field/gpu/head_glue.rs", "GlueDims", "head_glue.wgsl", "GlueDims"),
    mirror("src/field/gpu/keep.rs", "KeepUniforms", "keep.wgsl", "KeepUniforms"),
    mirror(
        "src/field/gpu/rays.rs",
        "StepUniforms",
        "ray_batch.wgsl",
        "StepUniforms",
    ),
    mirror("src/field/gpu/rays.rs", "RayGeometry", "ray_batch.wgsl", "RayGeometry"),
    mirror(
        "src/field/gpu/rays.rs",
        "TileUniforms",
        "ray_batch.wgsl",
        "TileUniforms",
    ),
    mirror(
        "src/field/gpu/rays.rs",
        "SamplePlanUniforms",
        "sample_points.wgsl",
        "SamplePlanUniforms",
    ),
    mirror("src/refine/gpu.rs", "RefineUniforms", "refine.wgsl", "RefineUniforms"),
    mirror(
        "src/field/gpu/scene_buffers.rs",
        "SceneUniforms",
        "ray_batch.wgsl",
        "SceneUniforms",
    ),
];

/// The scalar a field is made of (a vector or array counts as its element's scalar).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Scalar {
    U32,
    I32,
    F32,
}

#[derive(Debug, Clone, PartialEq, Eq)]
pub struct FieldLayout {
    pub name: String,
    pub offset: u32,
    pub size: u32,
    pub scalar: Scalar,
}

/// A struct's size and fields, on one side of the mirror.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct StructLayout {
    /// Where it comes from, for messages: "`DenseDims` in src/field/gpu/dense/spec.rs".
    pub origin: String,
    pub name: String,
    pub size: u32,
    pub fields: Vec<FieldLayout>,
}

/// One way the two sides disagree, or why a side could not be read.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct LayoutProblem(pub String);

impl fmt::Display for LayoutProblem {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(&self.0)
    }
}

/// Padding fields carry no data, so their names need not match (`_pad: [u32; 3]` on one side,
/// `pad0, pad1, pad2` on the other); the size check still covers the bytes they take.
pub fn is_padding(name: &str) -> bool {
    name.starts_with('_') || name.starts_with("pad")
}

fn round_up(value: u32, to: u32) -> u32 {
    value.div_ceil(to) * to
}

/// Compares two layouts; empty when they agree. A Rust struct may be longer than the WGSL one by
/// trailing padding up to the next 16 bytes (uniform blocks are padded that way on the Rust side).
pub fn compare(rust: &StructLayout, wgsl: &StructLayout) -> Vec<LayoutProblem> {
    let mut problems = Vec::new();
    let pair = format!("{} mirrors {}", rust.origin, wgsl.origin);
    let size_ok = rust.size == wgsl.size || rust.size == round_up(wgsl.size, 16);
    if !size_ok {
        problems.push(LayoutProblem(format!(
            "{pair}: Rust size {} bytes, WGSL size {} bytes",
            rust.size, wgsl.size
        )));
    }
    for w in wgsl.fields.iter().filter(|f| !is_padding(&f.name)) {
        let Some(r) = rust.fields.iter().find(|r| r.name == w.name) else {
            problems.push(LayoutProblem(format!(
                "{pair}: field `{}` (WGSL offset {}) is missing on the Rust side",
                w.name, w.offset
            )));
            continue;
        };
        if r.offset != w.offset {
            problems.push(LayoutProblem(format!(
                "{pair}: field `{}` at Rust offset {}, WGSL offset {}",
                w.name, r.offset, w.offset
            )));
        }
        if r.size != w.size {
            problems.push(LayoutProblem(format!(
                "{pair}: field `{}` (offset {}) is {} bytes in Rust, {} bytes in WGSL",
                w.name, w.offset, r.size, w.size
            )));
        }
        if r.scalar != w.scalar {
            problems.push(LayoutProblem(format!(
                "{pair}: field `{}` (offset {}) holds {:?} in Rust, {:?} in WGSL",
                w.name, w.offset, r.scalar, w.scalar
            )));
        }
    }
    for r in rust.fields.iter().filter(|f| !is_padding(&f.name)) {
        if !wgsl.fields.iter().any(|w| w.name == r.name) {
            problems.push(LayoutProblem(format!(
                "{pair}: field `{}` (Rust offset {}) is missing on the WGSL side",
                r.name, r.offset
            )));
        }
    }
    problems
}

/// The layout of WGSL struct `name` in `source` (an expanded stage), as naga lays it out.
pub fn wgsl_struct_layout(source: &str, stage: &str, name: &str) -> Result<StructLayout, LayoutProblem> {
    let origin = format!("`{name}` in shaders/{stage}");
    let module = naga::front::wgsl::parse_str(source)
        .map_err(|error| LayoutProblem(format!("{origin}: cannot parse: {}", error.message())))?;
    let mut layouter = naga::proc::Layouter::default();
    layouter
        .update(module.to_ctx())
        .map_err(|error| LayoutProblem(format!("{origin}: naga cannot lay out the types: {error}")))?;
    let (handle, members) = module
        .types
        .iter()
        .find_map(|(handle, ty)| match &ty.inner {
            naga::TypeInner::Struct { members, .. } if ty.name.as_deref() == Some(name) => Some((handle, members)),
            _ => None,
        })
        .ok_or_else(|| LayoutProblem(format!("{origin}: no such struct")))?;
    let mut fields = Vec::new();
    for member in members {
        let field = member.name.clone().unwrap_or_default();
        let scalar = wgsl_scalar(&module, member.ty)
            .ok_or_else(|| LayoutProblem(format!("{origin}: field `{field}` is not made of u32, i32 or f32")))?;
        fields.push(FieldLayout {
            name: field,
            offset: member.offset,
            size: layouter[member.ty].size,
            scalar,
        });
    }
    Ok(StructLayout {
        origin,
        name: name.to_string(),
        size: layouter[handle].size,
        fields,
    })
}

fn wgsl_scalar(module: &naga::Module, ty: naga::Handle<naga::Type>) -> Option<Scalar> {
    let scalar = match module.types[ty].inner {
        naga::TypeInner::Scalar(scalar) => scalar,
        naga::TypeInner::Vector { scalar, .. } | naga::TypeInner::Matrix { scalar, .. } => scalar,
        naga::TypeInner::Array { base, .. } => return wgsl_scalar(module, base),
        _ => return None,
    };
    match (scalar.kind, scalar.width) {
        (naga::ScalarKind::Uint, 4) => Some(Scalar::U32),
        (naga::ScalarKind::Sint, 4) => Some(Scalar::I32),
        (naga::ScalarKind::Float, 4) => Some(Scalar::F32),
        _ => None,
    }
}

/// The `#[repr(C)]` layout of Rust struct `name` defined in `source` (the text of `file`).
/// Array lengths may be integer literals or `const NAME: usize = <literal>;` items of the file.
pub fn rust_struct_layout(source: &str, file: &str, name: &str) -> Result<StructLayout, LayoutProblem> {
    let origin = format!("`{name}` in {file}");
    let problem = |message: String| LayoutProblem(format!("{origin}: {message}"));
    let text = strip_line_comments(source);
    let (attributes, body) = find_struct(&text, name).ok_or_else(|| problem("no such struct".into()))?;
    if !attributes.replace(' ', "").contains("repr(C)") {
        return Err(problem("is not #[repr(C)]".into()));
    }
    let mut offset = 0u32;
    let mut align = 1u32;
    let mut fields = Vec::new();
    for item in split_top_level(body, ',') {
        let item = strip_attributes(item);
        if item.is_empty() {
            continue;
        }
        let (field, ty) = item
            .split_once(':')
            .ok_or_else(|| problem(format!("cannot read field `{item}`")))?;
        let field = strip_visibility(field.trim());
        let (size, field_align, scalar) =
            rust_type(ty.trim(), &text).map_err(|message| problem(format!("field `{field}`: {message}")))?;
        offset = round_up(offset, field_align);
        align = align.max(field_align);
        fields.push(FieldLayout {
            name: field.to_string(),
            offset,
            size,
            scalar,
        });
        offset += size;
    }
    Ok(StructLayout {
        origin,
        name: name.to_string(),
        size: round_up(offset, align),
        fields,
    })
}

/// Drops `//` comments (doc comments included) so they cannot hide or fake a declaration.
fn strip_line_comments(source: &str) -> String {
    source
        .lines()
        .map(|line| line.split_once("//").map_or(line, |(code, _)| code))
        .collect::<Vec<_>>()
        .join("\n")
}

/// The attributes before `struct name` and the text between its braces.
fn find_struct<'a>(text: &'a str, name: &str) -> Option<(&'a str, &'a str)> {
    let is_ident = |c: char| c.is_ascii_alphanumeric() || c == '_';
    let needle = format!("struct {name}");
    let mut search_from = 0;
    while let Some(found) = text[search_from..].find(&needle) {
        let start = search_from + found;
        let end = start + needle.len();
        search_from = end;
        let before_ok = text[..start].chars().next_back().is_none_or(|c| !is_ident(c));
        let after = &text[end..];
        if !before_ok || after.chars().next().is_some_and(is_ident) {
            continue;
        }
        let open = end + after.find('{')?;
        if !text[end..open].trim().is_empty() {
            continue;
        }
        let close = open + matching_brace(&text[open..])?;
        let item_start = text[..start].rfind(['}', ';']).map_or(0, |at| at + 1);
        return Some((&text[item_start..start], &text[open + 1..close]));
    }
    None
}

fn matching_brace(text: &str) -> Option<usize> {
    let mut depth = 0usize;
    for (at, c) in text.char_indices() {
        match c {
            '{' => depth += 1,
            '}' => {
                depth -= 1;
                if depth == 0 {
                    return Some(at);
                }
            }
            _ => {}
        }
    }
    None
}

fn split_top_level(text: &str, separator: char) -> Vec<&str> {
    let mut parts = Vec::new();
    let mut depth = 0i32;
    let mut start = 0;
    for (at, c) in text.char_indices() {
        match c {
            '[' | '(' | '<' => depth += 1,
            ']' | ')' | '>' => depth -= 1,
            c if c == separator && depth == 0 => {
                parts.push(&text[start..at]);
                start = at + c.len_utf8();
            }
            _ => {}
        }
    }
    parts.push(&text[start..]);
    parts
}

fn strip_attributes(item: &str) -> &str {
    let mut rest = item.trim();
    while rest.starts_with("#[") {
        let Some(close) = matching_bracket(rest) else { break };
        rest = rest[close + 1..].trim();
    }
    rest
}

fn matching_bracket(text: &str) -> Option<usize> {
    let mut depth = 0usize;
    for (at, c) in text.char_indices() {
        match c {
            '[' => depth += 1,
            ']' => {
                depth -= 1;
                if depth == 0 {
                    return Some(at);
                }
            }
            _ => {}
        }
    }
    None
}

fn strip_visibility(field: &str) -> &str {
    let Some(rest) = field.strip_prefix("pub") else {
        return field;
    };
    let rest = rest.trim_start();
    match rest.strip_prefix('(') {
        Some(scoped) => scoped.split_once(')').map_or(rest, |(_, name)| name.trim()),
        None => rest,
    }
}

/// Size, alignment and scalar of a field type: `u32`, `i32`, `f32` or `[T; N]`.
fn rust_type(ty: &str, file_text: &str) -> Result<(u32, u32, Scalar), String> {
    match ty {
        "u32" => return Ok((4, 4, Scalar::U32)),
        "i32" => return Ok((4, 4, Scalar::I32)),
        "f32" => return Ok((4, 4, Scalar::F32)),
        _ => {}
    }
    let inner = ty
        .strip_prefix('[')
        .and_then(|rest| rest.strip_suffix(']'))
        .ok_or_else(|| format!("type `{ty}` is not u32, i32, f32 or an array of them"))?;
    let parts = split_top_level(inner, ';');
    let [element, length] = parts.as_slice() else {
        return Err(format!("type `{ty}` is not an array `[T; N]`"));
    };
    let (size, align, scalar) = rust_type(element.trim(), file_text)?;
    let length = array_length(length.trim(), file_text)?;
    Ok((size * length, align, scalar))
}

fn array_length(length: &str, file_text: &str) -> Result<u32, String> {
    if let Some(value) = parse_integer(length) {
        return Ok(value);
    }
    // A named length: `const NAME: usize = 32;` in the same file.
    let needle = format!("const {length}:");
    file_text
        .match_indices(&needle)
        .find_map(|(at, _)| {
            let declaration = file_text[at..].split(';').next()?;
            parse_integer(declaration.split_once('=')?.1.trim())
        })
        .ok_or_else(|| format!("array length `{length}` is neither a literal nor a `const` of this file"))
}

fn parse_integer(text: &str) -> Option<u32> {
    let digits: String = text.trim_end_matches("usize").chars().filter(|&c| c != '_').collect();
    digits.parse().ok()
}

/// Checks every [`MIRRORS`] entry: reads each Rust file with `read_rust` and finds each WGSL
/// struct in its (already expanded) stage. Returns every problem found.
pub fn check_mirrors(
    mirrors: &[Mirror],
    read_rust: impl Fn(&str) -> Result<String, String>,
    stages: &[ExpandedShader],
) -> Vec<LayoutProblem> {
    let mut problems = Vec::new();
    for mirror in mirrors {
        let rust = read_rust(mirror.rust_file)
            .map_err(LayoutProblem)
            .and_then(|text| rust_struct_layout(&text, mirror.rust_file, mirror.rust_struct));
        let wgsl = stages
            .iter()
            .find(|stage| stage.file == mirror.wgsl_stage)
            .ok_or_else(|| LayoutProblem(format!("shaders/{} is not a stage file", mirror.wgsl_stage)))
            .and_then(|stage| wgsl_struct_layout(&stage.source, &stage.file, mirror.wgsl_struct));
        match (rust, wgsl) {
            (Ok(rust), Ok(wgsl)) => problems.extend(compare(&rust, &wgsl)),
            (rust, wgsl) => problems.extend(rust.err().into_iter().chain(wgsl.err())),
        }
    }
    problems
}

#[cfg(test)]
mod tests {
    use std::collections::BTreeMap;
    use std::path::Path;

    use super::*;

    const WGSL: &str = "
struct Dims {
    rows: u32,
    scale: f32,
    origin: vec3<f32>,
    count: u32,
}
@group(0) @binding(0) var<uniform> dims: Dims;
@compute @workgroup_size(1) fn main() { _ = dims.rows; }
";

    fn wgsl() -> StructLayout {
        wgsl_struct_layout(WGSL, "test.wgsl", "Dims").expect("test WGSL lays out")
    }

    fn rust(fields: &str) -> StructLayout {
        let source = format!("#[repr(C)]\n#[derive(Clone, Copy)]\npub struct Dims {{\n{fields}\n}}\n");
        rust_struct_layout(&source, "test.rs", "Dims").expect("test Rust struct lays out")
    }

    #[test]
    fn a_faithful_mirror_passes() {
        let mirror = rust("pub rows: u32, pub scale: f32, _pad: [u32; 2], pub origin: [f32; 3], pub count: u32,");
        assert_eq!(mirror.size, 32);
        assert_eq!(compare(&mirror, &wgsl()), Vec::new());
    }

    #[test]
    fn a_missing_padding_field_is_caught_with_both_offsets() {
        // Forgetting that vec3 aligns to 16 bytes: `origin` lands at 8 in Rust, 16 in WGSL.
        let mirror = rust("pub rows: u32, pub scale: f32, pub origin: [f32; 3], pub count: u32,");
        let messages: Vec<String> = compare(&mirror, &wgsl()).iter().map(ToString::to_string).collect();
        assert!(
            messages
                .iter()
                .any(|m| m.contains("`Dims` in test.rs")
                    && m.contains("field `origin` at Rust offset 8, WGSL offset 16")),
            "{messages:?}"
        );
        assert!(
            messages
                .iter()
                .any(|m| m.contains("Rust size 24 bytes, WGSL size 32 bytes")),
            "{messages:?}"
        );
    }

    #[test]
    fn swapped_types_and_renamed_fields_are_caught() {
        let mirror = rust("pub rows: f32, pub scale: f32, _pad: [u32; 2], pub origin: [f32; 3], pub total: u32,");
        let messages: Vec<String> = compare(&mirror, &wgsl()).iter().map(ToString::to_string).collect();
        assert!(
            messages
                .iter()
                .any(|m| m.contains("`rows` (offset 0) holds F32 in Rust, U32 in WGSL"))
        );
        assert!(
            messages
                .iter()
                .any(|m| m.contains("`count` (WGSL offset 28) is missing on the Rust side"))
        );
        assert!(
            messages
                .iter()
                .any(|m| m.contains("`total` (Rust offset 28) is missing on the WGSL side"))
        );
    }

    #[test]
    fn named_array_lengths_and_comments_are_read() {
        let source = "const LEVELS: usize = 3;\n/// doc\n#[repr(C)]\nstruct S {\n    // a: u32,\n    a: [[u32; 4]; LEVELS],\n    b: f32, // why\n}\n";
        let layout = rust_struct_layout(source, "s.rs", "S").expect("lays out");
        assert_eq!(layout.size, 52);
        assert_eq!(layout.fields.len(), 2);
        assert_eq!(layout.fields[1].offset, 48);
        let not_c = rust_struct_layout("struct S { a: u32 }", "s.rs", "S");
        assert!(not_c.is_err_and(|problem| problem.0.contains("not #[repr(C)]")));
    }

    fn crate_root() -> &'static Path {
        Path::new(env!("CARGO_MANIFEST_DIR"))
    }

    #[test]
    fn the_crate_mirrors_match_their_shaders() {
        let mut files = BTreeMap::new();
        for entry in std::fs::read_dir(crate_root().join("shaders")).expect("shaders/ lists") {
            let path = entry.expect("shaders/ entry").path();
            if path.extension().is_some_and(|extension| extension == "wgsl") {
                let name = path.file_name().and_then(|name| name.to_str()).expect("UTF-8 name");
                files.insert(name.to_string(), std::fs::read_to_string(&path).expect("shader reads"));
            }
        }
        let stages = crate::gpu::shader_check::check_all(&files).expect("shaders validate");
        let read = |file: &str| std::fs::read_to_string(crate_root().join(file)).map_err(|e| format!("{file}: {e}"));
        assert_eq!(check_mirrors(MIRRORS, read, &stages), Vec::new());
    }

    fn rust_files(dir: &Path, out: &mut Vec<std::path::PathBuf>) {
        for entry in std::fs::read_dir(dir).expect("src/ lists") {
            let path = entry.expect("src/ entry").path();
            if path.is_dir() {
                rust_files(&path, out);
            } else if path.extension().is_some_and(|extension| extension == "rs") {
                out.push(path);
            }
        }
    }

    /// The build only checks the structs in [`MIRRORS`]; this keeps the table complete.
    #[test]
    fn every_repr_c_struct_is_listed() {
        let mut files = Vec::new();
        rust_files(&crate_root().join("src"), &mut files);
        let mut unlisted = Vec::new();
        for path in files {
            let text = strip_line_comments(&std::fs::read_to_string(&path).expect("source reads"));
            let relative = path
                .strip_prefix(crate_root())
                .expect("under the crate")
                .to_string_lossy()
                .replace('\\', "/");
            for (at, _) in text.match_indices("#[repr(C)]") {
                let after = &text[at..];
                let Some(name) = after
                    .split("struct ")
                    .nth(1)
                    .and_then(|rest| rest.split([' ', '{', '<']).next())
                else {
                    continue;
                };
                if relative.ends_with("uniform_layout.rs") {
                    continue;
                }
                if !MIRRORS.iter().any(|m| m.rust_struct == name && m.rust_file == relative) {
                    unlisted.push(format!("{relative}: {name}"));
                }
            }
        }
        assert_eq!(unlisted, Vec::<String>::new(), "add these to uniform_layout::MIRRORS");
    }
}
