//! Include expansion and naga validation of the WGSL files in `shaders/`.
//!
//! This file is compiled twice: by `build.rs` (through `#[path]`, so a broken shader fails
//! `cargo build`) and by the library on native targets (so tests can prove that a broken shader
//! is rejected by the very same code). It therefore depends on nothing but `naga` and `std`;
//! the includer provides `naga` in the parent module (`extern crate naga` in build.rs,
//! `use wgpu::naga` in `gpu/mod.rs`).
//!
//! Conventions (also in `shaders/README.md`):
//! - `name.wgsl` is a stage file: it is validated and embedded as a constant `NAME`.
//! - `_name.wgsl` is a shared snippet: never embedded on its own, pasted where a file has a line
//!   `//!include _name.wgsl`. A snippet is pasted at most once per stage (so two snippets may
//!   include the same third one), and snippets may include snippets.
//! - A stage with a line `//!requires float32-atomics` is validated with that optional device
//!   feature too; Rust runs it only on a device that has it, and keeps a portable stage beside it.
use std::collections::BTreeMap;
use std::fmt;

use super::naga;

const INCLUDE_DIRECTIVE: &str = "//!include ";
const REQUIRES_DIRECTIVE: &str = "//!requires ";

/// Optional device features a stage may declare with `//!requires NAME`, and the naga
/// capability each grants the validator.
const OPTIONAL_FEATURES: [(&str, naga::valid::Capabilities); 1] =
    [("float32-atomics", naga::valid::Capabilities::SHADER_FLOAT32_ATOMIC)];

/// A stage after include expansion, with a map back to the original files for error messages.
#[derive(Debug, Clone)]
pub struct ExpandedShader {
    /// The stage's file name, e.g. `matmul.wgsl`.
    pub file: String,
    /// The WGSL source with every include pasted in.
    pub source: String,
    /// For each line of `source` (0-based), the file and 1-based line it came from.
    origins: Vec<(String, u32)>,
}

impl ExpandedShader {
    /// The original file and 1-based line of a 1-based line of the expanded source.
    pub fn origin_of_line(&self, expanded_line: u32) -> (&str, u32) {
        let index = expanded_line.saturating_sub(1) as usize;
        match self.origins.get(index) {
            Some((file, line)) => (file, *line),
            None => (&self.file, expanded_line),
        }
    }
}

/// What is wrong with a shader, located in the original (unexpanded) file.
#[derive(Debug, Clone)]
pub struct ShaderProblem {
    /// The file the problem is in (a snippet if the error is inside pasted code).
    pub file: String,
    /// The stage being checked when the problem was found.
    pub stage: String,
    /// 1-based line and column in `file`; 0 when naga gave no location.
    pub line: u32,
    pub column: u32,
    /// naga's one-line message.
    pub message: String,
    /// naga's full report with the offending source excerpt (of the expanded stage).
    pub report: String,
}

impl fmt::Display for ShaderProblem {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        if self.line == 0 {
            write!(f, "shaders/{}: {}", self.file, self.message)?;
        } else {
            write!(
                f,
                "shaders/{}:{}:{}: {}",
                self.file, self.line, self.column, self.message
            )?;
        }
        if self.file != self.stage {
            write!(f, " (while checking stage {})", self.stage)?;
        }
        if !self.report.is_empty() {
            write!(f, "\n{}", self.report)?;
        }
        Ok(())
    }
}

impl std::error::Error for ShaderProblem {}

/// True for files that are shared snippets rather than stages.
pub fn is_snippet(file: &str) -> bool {
    file.starts_with('_')
}

/// The Rust constant name for a stage file: `matmul.wgsl` -> `MATMUL`, `ray-march.wgsl` -> `RAY_MARCH`.
pub fn constant_name(file: &str) -> String {
    let stem = file.strip_suffix(".wgsl").unwrap_or(file);
    let mut name: String = stem
        .chars()
        .map(|c| {
            if c.is_ascii_alphanumeric() {
                c.to_ascii_uppercase()
            } else {
                '_'
            }
        })
        .collect();
    if name.starts_with(|c: char| c.is_ascii_digit()) {
        name.insert(0, '_');
    }
    name
}

/// Pastes the snippets a stage includes. `files` maps file names (no directory) to their text.
pub fn expand_includes(stage: &str, files: &BTreeMap<String, String>) -> Result<ExpandedShader, ShaderProblem> {
    let mut expanded = ExpandedShader {
        file: stage.to_string(),
        source: String::new(),
        origins: Vec::new(),
    };
    let mut already_included = Vec::new();
    let mut include_stack = vec![stage.to_string()];
    paste_file(
        stage,
        stage,
        files,
        &mut expanded,
        &mut already_included,
        &mut include_stack,
    )?;
    Ok(expanded)
}

fn paste_file(
    stage: &str,
    file: &str,
    files: &BTreeMap<String, String>,
    out: &mut ExpandedShader,
    already_included: &mut Vec<String>,
    include_stack: &mut Vec<String>,
) -> Result<(), ShaderProblem> {
    let problem = |line: u32, message: String| ShaderProblem {
        file: file.to_string(),
        stage: stage.to_string(),
        line,
        column: 1,
        message,
        report: String::new(),
    };
    let text = files
        .get(file)
        .ok_or_else(|| problem(0, format!("file {file} not found")))?;
    for (index, line) in text.lines().enumerate() {
        let line_number = index as u32 + 1;
        let Some(target) = line.trim().strip_prefix(INCLUDE_DIRECTIVE) else {
            out.source.push_str(line);
            out.source.push('\n');
            out.origins.push((file.to_string(), line_number));
            continue;
        };
        let target = target.trim().trim_matches('"');
        if !is_snippet(target) {
            return Err(problem(
                line_number,
                format!("can only include snippets named _*.wgsl, not `{target}`"),
            ));
        }
        if include_stack.iter().any(|open| open == target) {
            return Err(problem(
                line_number,
                format!("include cycle: {} -> {target}", include_stack.join(" -> ")),
            ));
        }
        if !files.contains_key(target) {
            return Err(problem(
                line_number,
                format!("included snippet `{target}` does not exist in shaders/"),
            ));
        }
        if already_included.iter().any(|done| done == target) {
            continue;
        }
        already_included.push(target.to_string());
        include_stack.push(target.to_string());
        paste_file(stage, target, files, out, already_included, include_stack)?;
        include_stack.pop();
    }
    Ok(())
}

/// What naga may assume of every WebGPU device: the capabilities wgpu derives from the downlevel
/// flags a WebGPU-compliant adapter always has (`wgpu-naga-bridge`), e.g. `unpack2x16float`
/// needs SHADER_FLOAT16_IN_FLOAT32. Nothing that needs an optional device feature (f16, f64,
/// 64-bit integers, float atomics, subgroups).
pub fn webgpu_baseline_capabilities() -> naga::valid::Capabilities {
    naga::valid::Capabilities::SHADER_FLOAT16_IN_FLOAT32
        | naga::valid::Capabilities::MULTISAMPLED_SHADING
        | naga::valid::Capabilities::CUBE_ARRAY_TEXTURES
}

/// What naga may assume of a stage: the WebGPU baseline, plus each optional feature the stage
/// declares with `//!requires NAME`; an unknown name is a problem at its line.
pub fn capabilities_of(shader: &ExpandedShader) -> Result<naga::valid::Capabilities, ShaderProblem> {
    let mut capabilities = webgpu_baseline_capabilities();
    for (index, line) in shader.source.lines().enumerate() {
        let Some(name) = line.trim().strip_prefix(REQUIRES_DIRECTIVE) else {
            continue;
        };
        let name = name.trim();
        let Some((_, capability)) = OPTIONAL_FEATURES.iter().find(|(known, _)| *known == name) else {
            let known: Vec<&str> = OPTIONAL_FEATURES.iter().map(|(known, _)| *known).collect();
            let (file, line) = shader.origin_of_line(index as u32 + 1);
            return Err(ShaderProblem {
                file: file.to_string(),
                stage: shader.file.clone(),
                line,
                column: 1,
                message: format!("unknown optional feature `{name}` (known: {})", known.join(", ")),
                report: String::new(),
            });
        };
        capabilities |= *capability;
    }
    Ok(capabilities)
}

/// Parses and validates an expanded stage with naga, as strictly as WebGPU (see
/// [`webgpu_baseline_capabilities`]), so a shader that passes here needs no native-only feature
/// unless it says so with `//!requires NAME` (one of [`OPTIONAL_FEATURES`]).
pub fn validate(shader: &ExpandedShader) -> Result<(), ShaderProblem> {
    let module = naga::front::wgsl::parse_str(&shader.source).map_err(|error| {
        let location = error.location(&shader.source);
        locate(
            shader,
            location,
            error.message().to_string(),
            error.emit_to_string_with_path(&shader.source, &shader.file),
        )
    })?;
    let capabilities = capabilities_of(shader)?;
    let mut validator = naga::valid::Validator::new(naga::valid::ValidationFlags::all(), capabilities);
    validator.validate(&module).map_err(|error| {
        let location = error.location(&shader.source);
        locate(
            shader,
            location,
            error_chain(error.as_inner()),
            error.emit_to_string_with_path(&shader.source, &shader.file),
        )
    })?;
    Ok(())
}

/// naga's validation errors nest ("function main is invalid" -> "expression 12 is invalid" -> the
/// actual reason); the one-line message should carry the whole chain.
fn error_chain(error: &dyn std::error::Error) -> String {
    let mut message = error.to_string();
    let mut cause = error.source();
    while let Some(next) = cause {
        message.push_str(": ");
        message.push_str(&next.to_string());
        cause = next.source();
    }
    message
}

fn locate(
    shader: &ExpandedShader,
    location: Option<naga::SourceLocation>,
    message: String,
    report: String,
) -> ShaderProblem {
    let (file, line, column) = match location {
        Some(location) => {
            let (file, line) = shader.origin_of_line(location.line_number);
            (file.to_string(), line, location.line_position)
        }
        None => (shader.file.clone(), 0, 0),
    };
    ShaderProblem {
        file,
        stage: shader.file.clone(),
        line,
        column,
        message,
        report,
    }
}

/// Expands and validates every stage in `files`; returns the stages sorted by file name, or every
/// problem found (all of them, so one build shows every broken shader).
pub fn check_all(files: &BTreeMap<String, String>) -> Result<Vec<ExpandedShader>, Vec<ShaderProblem>> {
    let mut stages = Vec::new();
    let mut problems = Vec::new();
    for file in files.keys().filter(|file| !is_snippet(file)) {
        match expand_includes(file, files).and_then(|shader| validate(&shader).map(|()| shader)) {
            Ok(shader) => stages.push(shader),
            Err(problem) => problems.push(problem),
        }
    }
    let mut names: Vec<(String, &str)> = stages
        .iter()
        .map(|s| (constant_name(&s.file), s.file.as_str()))
        .collect();
    names.sort();
    for pair in names.windows(2) {
        if pair[0].0 == pair[1].0 {
            problems.push(ShaderProblem {
                file: pair[1].1.to_string(),
                stage: pair[1].1.to_string(),
                line: 0,
                column: 0,
                message: format!("its constant name {} clashes with that of {}", pair[1].0, pair[0].1),
                report: String::new(),
            });
        }
    }
    if problems.is_empty() { Ok(stages) } else { Err(problems) }
}
