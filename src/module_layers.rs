//! The crate's dependency direction, checked: every top-level module (`src/<name>/` or
//! `src/<name>.rs`) has a layer, and a module may only use modules of lower layers. So no module
//! imports from a module that imports it, and the pipeline reads bottom-up:
//! scene → labels → spread → features / field → eval → app / cli (docs/architecture.md draws it).
//!
//! The check reads the sources as text: every `crate::<module>` path (and `scribblefield::<module>`
//! in the binary's `cli`), including `use crate::{a::.., b::..}` groups, outside `//` comments.

use std::collections::{BTreeMap, BTreeSet};
use std::path::{Path, PathBuf};

/// Lowest first. A module may use modules of strictly lower layers only.
const LAYERS: &[&[&str]] = &[
    // Reading a user's file through caps (regular files only), below everything that reads one.
    &["bounded_read"],
    // Basics that know nothing of the pipeline: the random source, the CPU optimizer, the CPU
    // dense layer, percent-encoding, pausing long work (`pause`), the class palette, the WebGPU
    // plumbing, the safetensors format (feature weights, trainer checkpoints).
    &[
        "rng",
        "adam",
        "dense",
        "percent",
        "colors",
        "pause",
        "gpu",
        "safetensors",
    ],
    // Frames, cameras, ground truth, the labels a scene carries, the archive and importers.
    &["scene"],
    // Annotating: brush, history, share links, autosave, synthetic scribbles, canvas zoom.
    &["labels"],
    // Spreading the strokes over more pixels and frames before training.
    &["spread", "refine"],
    // What learns from labels: pretrained feature extractors, the neural field.
    &["features", "field"],
    // What uses a trained field: evaluation, mask export; the static file server. And the fuzz
    // targets' entry points, which feed the parsers of scene, labels and features.
    &["saved_field"],
    &["eval", "export", "serve", "fuzzing"],
    // The two front ends.
    &["app", "cli"],
    // Crate roots and the wasm entry point.
    &["web", "main", "lib"],
];

fn layer_of(module: &str) -> Option<usize> {
    LAYERS.iter().position(|layer| layer.contains(&module))
}

fn rust_files(dir: &Path, out: &mut Vec<PathBuf>) {
    for entry in std::fs::read_dir(dir).unwrap() {
        let path = entry.unwrap().path();
        if path.is_dir() {
            rust_files(&path, out);
        } else if path.extension().is_some_and(|e| e == "rs") {
            out.push(path);
        }
    }
}

/// The top-level modules a line of code names through `crate::` (or `scribblefield::`, the
/// library as the binary sees it).
fn modules_named(code: &str, roots: &[&str]) -> Vec<String> {
    let mut found = Vec::new();
    let ident = |s: &str| -> String {
        s.chars()
            .take_while(|c| c.is_ascii_alphanumeric() || *c == '_')
            .collect()
    };
    for root in roots {
        let pat = format!("{root}::");
        let mut rest = code;
        while let Some(at) = rest.find(&pat) {
            let before = rest[..at].chars().next_back();
            let after = &rest[at + pat.len()..];
            rest = after;
            if before.is_some_and(|c| c.is_ascii_alphanumeric() || c == '_' || c == '$') {
                continue;
            }
            if let Some(group) = after.strip_prefix('{') {
                // `use crate::{a::x, b::{y, z}}`: the first name of each top-level item.
                let mut depth = 0;
                let mut start = true;
                for (i, c) in group.char_indices() {
                    match c {
                        '{' => depth += 1,
                        '}' if depth == 0 => break,
                        '}' => depth -= 1,
                        ',' if depth == 0 => start = true,
                        c if start && !c.is_whitespace() => {
                            start = false;
                            found.push(ident(&group[i..]));
                        }
                        _ => {}
                    }
                }
            } else {
                found.push(ident(after));
            }
        }
    }
    found.retain(|m| !m.is_empty() && m != "self");
    found
}

/// Edges `from -> to` between top-level modules, each with the places that make it.
fn module_graph(src: &Path) -> BTreeMap<(String, String), Vec<String>> {
    let mut files = Vec::new();
    rust_files(src, &mut files);
    files.sort();
    let mut edges: BTreeMap<(String, String), Vec<String>> = BTreeMap::new();
    for file in files {
        let rel = file.strip_prefix(src).unwrap();
        let top = rel.iter().next().unwrap().to_string_lossy();
        let top = top.strip_suffix(".rs").unwrap_or(&top).to_string();
        if top == "module_layers" {
            continue; // this file's examples are not imports
        }
        // The binary (main.rs, cli/) reaches the library as `scribblefield::`.
        let roots: &[&str] = if top == "main" || top == "cli" {
            &["scribblefield"]
        } else {
            &["crate"]
        };
        // Multi-line `use crate::{..}` groups: join each statement onto one line first.
        let text = std::fs::read_to_string(&file).unwrap();
        let mut statement = String::new();
        let mut first_line = 0;
        for (n, line) in text.lines().enumerate() {
            let code = line.split("//").next().unwrap();
            if statement.is_empty() {
                first_line = n + 1;
            }
            statement.push_str(code);
            statement.push(' ');
            let t = statement.trim_start();
            let is_use = ["use ", "pub use ", "pub(crate) use ", "pub(super) use "]
                .iter()
                .any(|u| t.starts_with(u));
            if is_use && statement.matches('{').count() > statement.matches('}').count() {
                continue;
            }
            for module in modules_named(&statement, roots) {
                if module != top {
                    let place = format!("src/{}:{first_line}", rel.display());
                    edges.entry((top.clone(), module)).or_default().push(place);
                }
            }
            statement.clear();
        }
    }
    edges
}

/// A cycle through the graph, if there is one, as the modules along it.
fn find_cycle(edges: &BTreeMap<(String, String), Vec<String>>) -> Option<Vec<String>> {
    let mut next: BTreeMap<&str, Vec<&str>> = BTreeMap::new();
    for (from, to) in edges.keys() {
        next.entry(from).or_default().push(to);
    }
    fn visit<'a>(
        node: &'a str,
        next: &BTreeMap<&'a str, Vec<&'a str>>,
        path: &mut Vec<&'a str>,
        done: &mut BTreeSet<&'a str>,
    ) -> Option<Vec<String>> {
        if let Some(at) = path.iter().position(|n| *n == node) {
            let mut cycle: Vec<String> = path[at..].iter().map(|s| s.to_string()).collect();
            cycle.push(node.to_string());
            return Some(cycle);
        }
        if !done.insert(node) {
            return None;
        }
        path.push(node);
        for to in next.get(node).into_iter().flatten() {
            if let Some(cycle) = visit(to, next, path, done) {
                return Some(cycle);
            }
        }
        path.pop();
        None
    }
    let mut done = BTreeSet::new();
    for start in next.keys() {
        if let Some(cycle) = visit(start, &next, &mut Vec::new(), &mut done) {
            return Some(cycle);
        }
    }
    None
}

fn src_dir() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("src")
}

#[test]
fn no_module_imports_from_a_module_that_imports_it() {
    let edges = module_graph(&src_dir());
    if let Some(cycle) = find_cycle(&edges) {
        let mut msg = format!("module cycle: {}\n", cycle.join(" -> "));
        for pair in cycle.windows(2) {
            let places = &edges[&(pair[0].clone(), pair[1].clone())];
            msg += &format!("  {} -> {}: {}\n", pair[0], pair[1], places.join(", "));
        }
        panic!("{msg}");
    }
}

#[test]
fn every_module_uses_only_lower_layers() {
    let edges = module_graph(&src_dir());
    assert!(
        edges.len() > 10,
        "the scan found too few imports to be reading the sources: {edges:?}"
    );
    let mut problems = Vec::new();
    let mut modules: BTreeSet<&str> = BTreeSet::new();
    for ((from, to), places) in &edges {
        modules.insert(from);
        modules.insert(to);
        match (layer_of(from), layer_of(to)) {
            (Some(f), Some(t)) if t < f => {}
            (Some(_), Some(_)) => problems.push(format!(
                "{from} uses {to}, which is not in a lower layer ({})",
                places.join(", ")
            )),
            _ => {}
        }
    }
    for m in modules {
        if layer_of(m).is_none() {
            problems.push(format!(
                "module `{m}` has no layer: add it to LAYERS in src/module_layers.rs"
            ));
        }
    }
    assert!(problems.is_empty(), "{}", problems.join("\n"));
}

#[test]
fn the_scan_reads_paths_groups_and_skips_comments() {
    let named = |s: &str| modules_named(s, &["crate"]);
    assert_eq!(named("use crate::scene::Scene;"), ["scene"]);
    assert_eq!(
        named("use crate::{labels::LabelSet, scene::{Frame, Scene}};"),
        ["labels", "scene"]
    );
    assert_eq!(
        named("fn f(s: &crate::scene::Scene) -> crate::rng::SplitMix64"),
        ["scene", "rng"]
    );
    assert_eq!(
        named("pub(crate) fn f() {} $crate::x notcrate::y"),
        Vec::<String>::new()
    );
    // A cycle is found, and an acyclic graph has none.
    let graph = |pairs: &[(&str, &str)]| {
        pairs
            .iter()
            .map(|(a, b)| ((a.to_string(), b.to_string()), vec![]))
            .collect::<BTreeMap<_, _>>()
    };
    assert_eq!(
        find_cycle(&graph(&[("a", "b"), ("b", "c"), ("c", "a")])),
        Some(vec!["a".into(), "b".into(), "c".into(), "a".into()])
    );
    assert_eq!(find_cycle(&graph(&[("a", "b"), ("b", "c"), ("a", "c")])), None);
}
