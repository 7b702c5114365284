//! The layer rule of ARCHITECTURE.md, checked on the source: a module imports only from
//! layers below its own, never from its own layer's siblings or from above.

use std::path::{Path, PathBuf};

/// Top-level modules of the library, lowest layer first; modules in one row are siblings
/// and may not import each other.
const LAYERS: &[&[&str]] = &[
    &["units", "stats", "atomic", "html"],
    &["frames"],
    &["session"],
    &["motion", "noise"],
    &["model"],
    &["estimate", "simulate"],
    &["profile"],
    &["correct"],
    &["check", "plan"],
    &["diagnose"],
    &["app"],
];

fn rank(module: &str) -> Option<usize> {
    LAYERS.iter().position(|row| row.contains(&module))
}

fn rust_files(dir: &Path, out: &mut Vec<PathBuf>) {
    for entry in std::fs::read_dir(dir).expect("read src") {
        let p = entry.expect("entry").path();
        if p.is_dir() {
            rust_files(&p, out);
        } else if p.extension().is_some_and(|e| e == "rs") {
            out.push(p);
        }
    }
}

/// The code of a line without its comment (`//` outside a string literal).
fn code(line: &str) -> &str {
    let mut in_str = false;
    let b = line.as_bytes();
    let mut i = 0;
    while i < b.len() {
        match b[i] {
            b'\\' if in_str => i += 1,
            b'"' => in_str = !in_str,
            b'/' if !in_str && b.get(i + 1) == Some(&b'/') => return &line[..i],
            _ => {}
        }
        i += 1;
    }
    line
}

/// Every `crate::<module>` a line of code names.
fn crate_refs(code: &str) -> Vec<&str> {
    let mut out = Vec::new();
    let mut rest = code;
    while let Some(p) = rest.find("crate::") {
        let before = rest[..p].chars().last();
        let after = &rest[p + 7..];
        let end = after.find(|c: char| !(c.is_ascii_alphanumeric() || c == '_')).unwrap_or(after.len());
        if !before.is_some_and(|c| c.is_ascii_alphanumeric() || c == '_') && end > 0 {
            out.push(&after[..end]);
        }
        rest = &after[end..];
    }
    out
}

#[test]
fn every_import_points_down_the_layers() {
    let src = Path::new(env!("CARGO_MANIFEST_DIR")).join("src");
    let mut files = Vec::new();
    rust_files(&src, &mut files);
    files.sort();
    let mut violations = Vec::new();
    let mut checked = 0;
    for f in &files {
        let rel = f.strip_prefix(&src).expect("under src");
        let top = rel.iter().next().and_then(|c| c.to_str()).unwrap_or("");
        let top = top.strip_suffix(".rs").unwrap_or(top);
        if matches!(top, "lib" | "main" | "cli") {
            continue;
        }
        let Some(mine) = rank(top) else {
            violations
                .push(format!("{}: top-level module '{top}' is not in a layer of ARCHITECTURE.md", rel.display()));
            continue;
        };
        let text = std::fs::read_to_string(f).expect("read");
        for (no, line) in text.lines().enumerate() {
            let code = code(line);
            if code.contains("super::super") {
                violations.push(format!(
                    "{}:{}: `super::super` reaches out of its module: name the layer",
                    rel.display(),
                    no + 1
                ));
            }
            if code.contains("crosscal::") && !code.contains("\"") {
                violations.push(format!("{}:{}: the library names itself as `crosscal::`", rel.display(), no + 1));
            }
            for used in crate_refs(code) {
                checked += 1;
                if used == top {
                    continue;
                }
                match rank(used) {
                    Some(r) if r < mine => {}
                    Some(r) => violations.push(format!(
                        "{}:{}: {top} (layer {mine}) imports {used} (layer {r}): imports must point down",
                        rel.display(),
                        no + 1
                    )),
                    None => violations.push(format!("{}:{}: unknown module crate::{used}", rel.display(), no + 1)),
                }
            }
        }
    }
    assert!(checked > 100, "the scan found only {checked} crate paths: is it reading src/?");
    assert!(violations.is_empty(), "{} upward or sideways imports:\n{}", violations.len(), violations.join("\n"));
}

#[test]
fn the_scanner_sees_paths_and_skips_comments() {
    assert_eq!(crate_refs(code("use crate::model::X; // crate::app")), vec!["model"]);
    assert_eq!(crate_refs(code("let s = \"//\"; crate::stats::median(x)")), vec!["stats"]);
    assert!(crate_refs(code("/// see [`crate::app`]")).is_empty());
    assert!(crate_refs(code("mycrate::x")).is_empty());
}
