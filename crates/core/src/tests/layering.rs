//! The crate's module layering (`lib.rs` and `transport/mod.rs` say it in words), checked on the source: every
//! module refers (`crate::a::b`, `super::`) only to modules of a lower layer, so the module graph has no circles.

use std::path::Path;

/// Modules from the bottom up: each may refer to those before it. `lib.rs` and the `mod.rs` files that only
/// declare their children are above all of them; the tests in `src/tests` are not checked.
const LAYERS: &[&str] = &[
    "cache",
    "pages",
    "spans",
    "transport::bricks",
    "transport::label_bricks",
    "transport::mask",
    "transport::sampling",
    "transport::rng",
    "transport::light",
    "transport::normals",
    "transport::medium",
    "transport::band",
    "transport::distance",
    "transport::scene",
    "transport::path",
    "transport::grid",
    "transport::flight",
    "transport::trace",
    "transport::estimate",
    "transport::packet",
    "transport::packet::step",
    "transport::render",
    "transport::sums",
    "transport::grad",
    "transport::hero",
    "transport::hero_lanes",
    "transport::hero_pass",
    "kernels::blocks",
    "kernels::diffuse",
    "kernels::counts",
    "kernels::adaptive",
    "kernels::feature",
    "kernels::simplex",
    "kernels::smooth",
    "kernels::step",
];

/// Modules that only declare their children (and document them).
const DECLARING: &[&str] = &["", "transport", "kernels"];

/// The module path of a source file below `src` (`transport/packet/mod.rs` -> `transport::packet`).
fn module_of(rel: &Path) -> String {
    let mut parts: Vec<String> = rel.iter().map(|p| p.to_string_lossy().into_owned()).collect();
    let last = parts.pop().unwrap();
    let stem = last.trim_end_matches(".rs");
    if stem != "mod" && stem != "lib" {
        parts.push(stem.to_string());
    }
    parts.join("::")
}

/// The source's code: line comments dropped, and the file's `#[cfg(test)]` module (at its end) cut off.
fn code(text: &str) -> String {
    let text = text.split("#[cfg(test)]\nmod tests").next().unwrap();
    text.lines().map(|l| l.split("//").next().unwrap()).collect::<Vec<_>>().join("\n")
}

/// The module paths the code refers to: the longest known module prefix of every `crate::...` path, and the
/// parent for `super::`.
fn references(module: &str, code: &str) -> Vec<String> {
    let mut out = vec![];
    for (i, _) in code.match_indices("crate::") {
        let rest = &code[i + "crate::".len()..];
        let path: String = rest.chars().take_while(|c| c.is_alphanumeric() || *c == '_' || *c == ':').collect();
        let segs: Vec<&str> = path.split("::").filter(|s| !s.is_empty()).collect();
        let found = (1..=segs.len()).rev().map(|k| segs[..k].join("::")).find(|p| LAYERS.contains(&p.as_str()));
        out.push(found.unwrap_or_else(|| format!("<unresolved crate::{path}>")));
    }
    if code.contains("super::") {
        out.push(module.rsplit_once("::").map(|(p, _)| p.to_string()).unwrap_or_default());
    }
    out
}

fn sources(dir: &Path, root: &Path, out: &mut Vec<(String, String)>) {
    for entry in std::fs::read_dir(dir).unwrap() {
        let path = entry.unwrap().path();
        let rel = path.strip_prefix(root).unwrap();
        if path.is_dir() {
            if rel != Path::new("tests") {
                sources(&path, root, out);
            }
        } else if path.extension().is_some_and(|e| e == "rs") {
            out.push((module_of(rel), std::fs::read_to_string(&path).unwrap()));
        }
    }
}

#[test]
fn modules_refer_only_to_lower_layers() {
    let root = Path::new(env!("CARGO_MANIFEST_DIR")).join("src");
    let mut files = vec![];
    sources(&root, &root, &mut files);
    let mut problems = vec![];
    for (module, text) in &files {
        if DECLARING.contains(&module.as_str()) {
            continue;
        }
        let Some(rank) = LAYERS.iter().position(|m| m == module) else {
            problems.push(format!("{module} is in no layer of tests/layering.rs"));
            continue;
        };
        for dep in references(module, &code(text)) {
            if dep == *module {
                continue;
            }
            match LAYERS.iter().position(|m| *m == dep) {
                Some(r) if r < rank => {}
                _ => problems.push(format!("{module} refers to {dep}, which is not below it")),
            }
        }
    }
    assert!(files.len() > LAYERS.len(), "found {} source files", files.len());
    assert!(problems.is_empty(), "{}", problems.join("\n"));
}
