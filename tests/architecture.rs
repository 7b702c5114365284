//! The layer rule of ARCHITECTURE.md, checked on the source: a module imports only from
//! layers below its own, never from its own layer's siblings or from above.

use std::path::{Path, PathBuf};

/// Top-level modules of the library, lowest layer first; modules in one row are siblings
/// and may not import each other.
const LAYERS: &[&[&str]] = &[
    &["units", "stats", "atomic", "html", "json"],
    &["frames"],
    &["session"],
    &["motion", "noise"],
    &["model"],
    &["estimate", "simulate"],
    &["profile"],
    &["correct", "datasheet"],
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

/// The lines of a file outside its `#[cfg(test)]` module(s).
fn without_tests(text: &str) -> Vec<&str> {
    let lines: Vec<&str> = text.lines().collect();
    let mut out = Vec::with_capacity(lines.len());
    let mut i = 0;
    while i < lines.len() {
        let next_is_mod = lines.get(i + 1).is_some_and(|l| l.trim_start().starts_with("mod ") && l.contains('{'));
        if lines[i].trim() == "#[cfg(test)]" && next_is_mod {
            let mut depth = 0i64;
            let mut j = i + 1;
            while j < lines.len() {
                depth += lines[j].matches('{').count() as i64 - lines[j].matches('}').count() as i64;
                j += 1;
                if depth == 0 {
                    break;
                }
            }
            i = j;
            continue;
        }
        out.push(lines[i]);
        i += 1;
    }
    out
}

/// Files a newcomer can hold in their head: at most ~700 lines of code outside their tests,
/// no function over ~120 lines (brace-matched from its `fn` line).
#[test]
fn files_and_functions_stay_small() {
    const FILE_LINES: usize = 700;
    const FN_LINES: usize = 120;
    let src = Path::new(env!("CARGO_MANIFEST_DIR")).join("src");
    let mut files = Vec::new();
    rust_files(&src, &mut files);
    let mut too_big = Vec::new();
    for f in &files {
        let text = std::fs::read_to_string(f).expect("read");
        let lines = without_tests(&text);
        let rel = f.strip_prefix(&src).expect("under src").display().to_string();
        let code = lines.iter().filter(|l| !l.trim().is_empty() && !l.trim_start().starts_with("//")).count();
        if code > FILE_LINES {
            too_big.push(format!("{rel}: {code} lines of code (limit {FILE_LINES})"));
        }
        for (i, l) in lines.iter().enumerate() {
            let t = l.trim_start();
            let t = t.strip_prefix("pub(crate) ").or_else(|| t.strip_prefix("pub(super) ")).unwrap_or(t);
            let t = t.strip_prefix("pub ").unwrap_or(t);
            let Some(rest) = t.strip_prefix("fn ") else { continue };
            let name: String = rest.chars().take_while(|c| c.is_alphanumeric() || *c == '_').collect();
            let (mut depth, mut started, mut end) = (0i64, false, i);
            for (j, l) in lines.iter().enumerate().skip(i) {
                depth += l.matches('{').count() as i64 - l.matches('}').count() as i64;
                started |= l.contains('{');
                end = j;
                if (started && depth <= 0) || (!started && l.trim_end().ends_with(';')) {
                    break;
                }
            }
            if started && end + 1 - i > FN_LINES {
                too_big.push(format!("{rel}:{}: fn {name} has {} lines (limit {FN_LINES})", i + 1, end + 1 - i));
            }
        }
    }
    assert!(too_big.is_empty(), "split by responsibility:\n{}", too_big.join("\n"));
}

/// The first segment of each path after `prefix` on a line of code: `super::a::f`,
/// `super::{a, b::C}` give `a` (and `b`, `C`).
fn refs_after<'a>(code: &'a str, prefix: &str) -> Vec<&'a str> {
    let mut out = Vec::new();
    let mut rest = code;
    while let Some(p) = rest.find(prefix) {
        let before = rest[..p].chars().last();
        rest = &rest[p + prefix.len()..];
        if before.is_some_and(|c| c.is_ascii_alphanumeric() || c == '_' || c == ':') {
            continue;
        }
        if let Some(group) = rest.strip_prefix('{') {
            let end = group.find('}').unwrap_or(group.len());
            let mut depth = 0;
            let mut start = 0;
            let inner = &group[..end];
            for (i, c) in inner.char_indices().chain(std::iter::once((inner.len(), ','))) {
                match c {
                    '{' => depth += 1,
                    '}' => depth -= 1,
                    ',' if depth == 0 => {
                        let item = inner[start..i].trim();
                        let seg = item.split("::").next().unwrap_or("").trim();
                        if !seg.is_empty() {
                            out.push(seg);
                        }
                        start = i + 1;
                    }
                    _ => {}
                }
            }
        } else {
            let end = rest.find(|c: char| !(c.is_ascii_alphanumeric() || c == '_')).unwrap_or(rest.len());
            out.push(&rest[..end]);
        }
    }
    out
}

/// The files (and sub-folders) of one module folder as a graph: node = a file's stem or a
/// sub-folder's name (its `mod.rs`, the module's face, is left out), edge = a `super::x` or
/// `crate::<module>::x` path from a file of one node to a sibling node.
fn module_graph(dir: &Path, module_path: &str) -> Vec<(String, Vec<String>)> {
    let mut nodes: Vec<(String, Vec<PathBuf>)> = Vec::new();
    for entry in std::fs::read_dir(dir).expect("read module folder") {
        let p = entry.expect("entry").path();
        if p.is_dir() {
            let mut files = Vec::new();
            rust_files(&p, &mut files);
            nodes.push((p.file_name().unwrap().to_string_lossy().into_owned(), files));
        } else if p.extension().is_some_and(|e| e == "rs") && p.file_stem().is_some_and(|s| s != "mod") {
            nodes.push((p.file_stem().unwrap().to_string_lossy().into_owned(), vec![p.clone()]));
        }
    }
    let names: Vec<String> = nodes.iter().map(|n| n.0.clone()).collect();
    let mut graph = Vec::new();
    for (name, files) in &nodes {
        let mut edges = Vec::new();
        for f in files {
            // `super::` names this folder from its own files and from a sub-folder's mod.rs.
            let parent = f.parent().expect("parent");
            let super_is_here =
                parent == dir || (parent.parent() == Some(dir) && f.file_stem().is_some_and(|s| s == "mod"));
            let text = std::fs::read_to_string(f).expect("read");
            for line in without_tests(&text) {
                let code = code(line);
                let mut used = refs_after(code, &format!("crate::{module_path}::"));
                if super_is_here {
                    used.extend(refs_after(code, "super::"));
                }
                for u in used {
                    if u != name && names.iter().any(|n| n == u) && !edges.iter().any(|e: &String| e == u) {
                        edges.push(u.to_string());
                    }
                }
            }
        }
        graph.push((name.clone(), edges));
    }
    graph
}

/// A cycle of the graph, if any, as the path of node names that closes it.
fn find_cycle(graph: &[(String, Vec<String>)]) -> Option<Vec<String>> {
    fn visit(
        g: &[(String, Vec<String>)],
        n: &str,
        state: &mut std::collections::HashMap<String, u8>,
        path: &mut Vec<String>,
    ) -> Option<Vec<String>> {
        match state.get(n) {
            Some(1) => {
                let i = path.iter().position(|p| p == n).unwrap_or(0);
                let mut cycle = path[i..].to_vec();
                cycle.push(n.to_string());
                return Some(cycle);
            }
            Some(_) => return None,
            None => {}
        }
        state.insert(n.to_string(), 1);
        path.push(n.to_string());
        for e in g.iter().find(|x| x.0 == n).map(|x| x.1.clone()).unwrap_or_default() {
            if let Some(c) = visit(g, &e, state, path) {
                return Some(c);
            }
        }
        path.pop();
        state.insert(n.to_string(), 2);
        None
    }
    let mut state = std::collections::HashMap::new();
    graph.iter().find_map(|(n, _)| visit(graph, n, &mut state, &mut Vec::new()))
}

/// Module folders whose files still import each other in a circle: the debt, named so that
/// it can only shrink (a folder not listed must stay acyclic; a listed one that became
/// acyclic must leave the list).
const CYCLIC_MODULES: &[&str] = &[];

/// Inside a layer too, files call downward: in `estimate` the fit strategies (streamed, in
/// memory, stand, protocol) call the solvers (linear least squares, variable projection,
/// robust reweighting), never back; no folder's files import each other in a circle.
#[test]
fn files_inside_a_module_import_without_cycles() {
    let src = Path::new(env!("CARGO_MANIFEST_DIR")).join("src");
    let mut dirs = Vec::new();
    fn folders(dir: &Path, path: &str, out: &mut Vec<(PathBuf, String)>) {
        for entry in std::fs::read_dir(dir).expect("read src") {
            let p = entry.expect("entry").path();
            if p.is_dir() {
                let name = p.file_name().unwrap().to_string_lossy().into_owned();
                let sub = if path.is_empty() { name } else { format!("{path}::{name}") };
                out.push((p.clone(), sub.clone()));
                folders(&p, &sub, out);
            }
        }
    }
    folders(&src, "", &mut dirs);
    dirs.sort();
    let mut cyclic = Vec::new();
    for (dir, path) in &dirs {
        if path.starts_with("cli") {
            continue;
        }
        if let Some(c) = find_cycle(&module_graph(dir, path)) {
            cyclic.push((path.clone(), c.join(" -> ")));
        }
    }
    let unexpected: Vec<String> = cyclic
        .iter()
        .filter(|(p, _)| !CYCLIC_MODULES.contains(&p.as_str()))
        .map(|(p, c)| format!("{p}: {c}"))
        .collect();
    assert!(unexpected.is_empty(), "files importing each other in a circle:\n{}", unexpected.join("\n"));
    let graph = module_graph(&src.join("estimate"), "estimate");
    let linear = graph.iter().find(|n| n.0 == "linear").expect("estimate/linear.rs");
    assert!(!linear.1.contains(&"nonlinear".to_string()) && !linear.1.contains(&"memory".to_string()));
    for fixed in CYCLIC_MODULES {
        assert!(cyclic.iter().any(|(p, _)| p == fixed), "{fixed} has no cycle any more: remove it from the list");
    }
}

#[test]
fn the_cycle_finder_sees_a_circle_and_a_grouped_import() {
    assert_eq!(refs_after("use super::{linear::Columns, robust, Fit};", "super::"), vec!["linear", "robust", "Fit"]);
    assert_eq!(refs_after("let x = super::channel::plan(a);", "super::"), vec!["channel"]);
    let g = vec![("a".to_string(), vec!["b".to_string()]), ("b".to_string(), vec!["a".to_string()])];
    assert_eq!(find_cycle(&g), Some(vec!["a".into(), "b".into(), "a".into()]));
    let g = vec![("a".to_string(), vec!["b".to_string()]), ("b".to_string(), vec![])];
    assert_eq!(find_cycle(&g), None);
}
