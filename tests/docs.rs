//! The README and the guide (`docs/`) cannot silently go wrong: every ```sh block of a page
//! runs, in order, in a fresh folder with the built `crosscal` on PATH (and `../shared` the
//! shared recordings, when present); every picture a page shows is made by the page's own
//! commands; generated reference pages equal what the tool prints; relative links resolve.
//!
//! `CROSSCAL_DOCS_UPDATE=1 cargo test --release --test main docs::` (what
//! `docs/make-images.sh` runs) also copies the pictures the commands made into `docs/images/`.

use std::path::{Path, PathBuf};
use std::process::Command;

fn root() -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR"))
}

fn shared() -> PathBuf {
    root().join("../shared")
}

/// A fenced block of shell commands and the line it starts on (1-based).
struct Block {
    line: usize,
    text: String,
}

/// The ```sh blocks of a Markdown page, in order.
fn sh_blocks(md: &str) -> Vec<Block> {
    let mut out = Vec::new();
    let mut current: Option<Block> = None;
    for (i, l) in md.lines().enumerate() {
        let t = l.trim_start();
        match &mut current {
            None if t.starts_with("```sh") && t[5..].trim().is_empty() => {
                current = Some(Block { line: i + 1, text: String::new() });
            }
            None => {}
            Some(_) if t.starts_with("```") => out.extend(current.take()),
            Some(b) => {
                b.text.push_str(l);
                b.text.push('\n');
            }
        }
    }
    assert!(current.is_none(), "an unclosed ```sh block");
    out
}

/// The file names of the pictures a page shows from `images/`.
fn images(md: &str) -> Vec<String> {
    let mut out = Vec::new();
    let mut rest = md;
    while let Some(i) = rest.find("](images/") {
        rest = &rest[i + 9..];
        if let Some(end) = rest.find(')') {
            out.push(rest[..end].to_string());
        }
    }
    out
}

/// The page's shell text as run: `cargo run --release -- ARGS` is `crosscal ARGS` (the same
/// binary), `cargo run --release --example NAME -- ARGS` the example `cargo test` built
/// beside it, and `cargo test`/`cargo bench`/`bash .ci/run` lines are skipped (they are what
/// CI runs).
fn script(b: &Block, bin_dir: &Path) -> String {
    b.text
        .lines()
        .filter(|l| !["cargo test", "cargo bench", "bash .ci/run"].iter().any(|c| l.trim_start().starts_with(c)))
        .map(|l| {
            let l = l.replace("cargo run --release -- ", "crosscal ");
            match l.split_once("cargo run --release --example ") {
                Some((head, rest)) => {
                    let (name, args) = rest.split_once(" -- ").unwrap_or((rest, ""));
                    let exe = bin_dir.join("examples").join(name.trim());
                    if exe.is_file() {
                        format!("{head}{} {args}", exe.display())
                    } else {
                        // `cargo test` builds the examples; a filtered run (`--test main`) does not.
                        eprintln!("skipped: {} is not built (run the whole `cargo test`)", exe.display());
                        String::new()
                    }
                }
                None => l,
            }
        })
        .collect::<Vec<_>>()
        .join("\n")
}

fn find_file(dir: &Path, name: &str) -> Option<PathBuf> {
    for e in std::fs::read_dir(dir).ok()?.flatten() {
        let p = e.path();
        if p.is_dir() && !p.is_symlink() {
            if let Some(f) = find_file(&p, name) {
                return Some(f);
            }
        } else if p.file_name().and_then(|n| n.to_str()) == Some(name) {
            return Some(p);
        }
    }
    None
}

/// Runs every ```sh block of `page` (relative to the repository) and checks its pictures.
fn run_page(page: &str) {
    let path = root().join(page);
    let md = std::fs::read_to_string(&path).unwrap_or_else(|e| panic!("reading {page}: {e}"));
    if md.contains("../shared") && !shared().is_dir() {
        eprintln!("skipped: {page} reads ../shared, which is not beside this checkout");
        return;
    }
    let tmp = tempfile::tempdir().unwrap();
    let work = tmp.path().join("work");
    std::fs::create_dir(&work).unwrap();
    if shared().is_dir() {
        std::os::unix::fs::symlink(shared().canonicalize().unwrap(), tmp.path().join("shared")).unwrap();
    }
    let bin_dir = Path::new(env!("CARGO_BIN_EXE_crosscal")).parent().unwrap().to_path_buf();
    let path_var = format!("{}:{}", bin_dir.display(), std::env::var("PATH").unwrap_or_default());
    for b in sh_blocks(&md) {
        let out = Command::new("timeout")
            .args(["600", "bash", "-eo", "pipefail", "-c", &script(&b, &bin_dir)])
            .current_dir(&work)
            .env("PATH", &path_var)
            .env("NO_COLOR", "1")
            .output()
            .unwrap();
        assert!(
            out.status.success(),
            "{page}:{}: the block failed ({}):\n{}\n--- stdout\n{}\n--- stderr\n{}",
            b.line,
            out.status,
            b.text,
            String::from_utf8_lossy(&out.stdout),
            String::from_utf8_lossy(&out.stderr)
        );
    }
    let update = std::env::var_os("CROSSCAL_DOCS_UPDATE").is_some();
    for img in images(&md) {
        let made = find_file(&work, &img)
            .unwrap_or_else(|| panic!("{page}: no command of the page makes images/{img} (the picture it shows)"));
        let stored = root().join("docs/images").join(&img);
        if update {
            std::fs::create_dir_all(stored.parent().unwrap()).unwrap();
            std::fs::copy(&made, &stored).unwrap();
        }
        assert!(stored.is_file(), "{page}: docs/images/{img} is missing: run docs/make-images.sh");
    }
}

macro_rules! pages {
    ($($name:ident => $page:literal),* $(,)?) => {
        $(#[test] fn $name() { run_page($page); })*
        /// Every page of the guide has a test above.
        const PAGES: &[&str] = &[$($page),*];
    };
}

pages! {
    readme => "README.md",
    guide_index => "docs/README.md",
    tutorial_stand => "docs/tutorial-stand.md",
    tutorial_diagnose => "docs/tutorial-diagnose.md",
    tutorial_no_stand => "docs/tutorial-no-stand.md",
    tutorial_noise => "docs/tutorial-noise.md",
    tutorial_production => "docs/tutorial-production.md",
    tutorial_use_profile => "docs/tutorial-use-profile.md",
    reference_session => "docs/reference-session.md",
    reference_profile => "docs/reference-profile.md",
    reference_rules => "docs/reference-rules.md",
    reference_datasheet => "docs/reference-datasheet.md",
    reference_effects => "docs/reference-effects.md",
    reference_exit_codes => "docs/reference-exit-codes.md",
    reference_conventions => "docs/reference-conventions.md",
    background => "docs/background.md",
    performance => "docs/performance.md",
    python => "docs/python.md",
    your_own_effect => "docs/your-own-effect.md",
}

#[test]
fn every_page_of_the_guide_is_run() {
    let mut found: Vec<String> = std::fs::read_dir(root().join("docs"))
        .unwrap()
        .flatten()
        .filter_map(|e| e.file_name().to_str().map(str::to_string))
        .filter(|n| n.ends_with(".md"))
        .map(|n| format!("docs/{n}"))
        .collect();
    found.sort();
    for f in &found {
        assert!(PAGES.contains(&f.as_str()), "{f} has no test in tests/docs.rs: add it to `pages!`");
    }
}

#[test]
fn relative_links_resolve_and_the_readme_is_a_front_page() {
    for page in PAGES {
        let path = root().join(page);
        let md = std::fs::read_to_string(&path).unwrap();
        let mut rest = md.as_str();
        while let Some(i) = rest.find("](") {
            rest = &rest[i + 2..];
            let Some(end) = rest.find(')') else { break };
            let target = rest[..end].split('#').next().unwrap_or_default();
            if target.is_empty() || target.contains("://") || target.starts_with("mailto:") {
                continue;
            }
            let resolved = path.parent().unwrap().join(target);
            assert!(resolved.exists(), "{page}: link to {target}, which does not exist");
        }
    }
    let readme = std::fs::read_to_string(root().join("README.md")).unwrap();
    let n = readme.lines().count();
    assert!(n <= 160, "README.md has {n} lines: it is the front page, details belong in docs/");
    assert!(readme.contains("docs/images/"), "the README shows a picture");
}

fn crosscal(args: &[&str]) -> String {
    let out = Command::new(env!("CARGO_BIN_EXE_crosscal")).args(args).output().unwrap();
    assert!(out.status.success(), "crosscal {args:?}: {}", String::from_utf8_lossy(&out.stderr));
    String::from_utf8(out.stdout).unwrap()
}

#[test]
fn the_effect_catalogue_page_is_the_tools() {
    let page = std::fs::read_to_string(root().join("docs/reference-effects.md")).unwrap();
    assert!(
        page == crosscal(&["effects", "--markdown"]),
        "docs/reference-effects.md differs from `crosscal effects --markdown`: regenerate it with\n  \
         crosscal effects --markdown > docs/reference-effects.md"
    );
    let ids: Vec<String> = serde_json::from_str::<serde_json::Value>(&crosscal(&["effects", "--json"]))
        .unwrap()
        .as_array()
        .unwrap()
        .iter()
        .map(|e| e["id"].as_str().unwrap().to_string())
        .collect();
    for id in ids {
        assert!(page.contains(&format!("\n## {id}\n")), "{id} has no section");
    }
}

#[test]
fn help_has_an_example_for_every_command_and_topics_print() {
    let top = crosscal(&["--help"]);
    assert!(top.contains("Example: crosscal "), "{top}");
    let commands: Vec<String> = top
        .split("Commands:")
        .nth(1)
        .unwrap()
        .split("Options:")
        .next()
        .unwrap()
        .lines()
        .filter_map(|l| l.split_whitespace().next().map(str::to_string))
        .collect();
    assert!(commands.len() >= 15, "{commands:?}");
    let subcommands = |help: &str| -> Vec<String> {
        help.split("Commands:")
            .nth(1)
            .map(|s| s.split("Options:").next().unwrap_or_default())
            .map(|s| s.split("Arguments:").next().unwrap_or_default())
            .unwrap_or_default()
            .lines()
            .filter_map(|l| l.split_whitespace().next().map(str::to_string))
            .filter(|c| c != "help")
            .collect()
    };
    for c in &commands {
        let help = crosscal(&[c, "--help"]);
        assert!(help.contains(&format!("Example: crosscal {c}")), "`crosscal {c} --help` has no example line:\n{help}");
        for sub in subcommands(&help) {
            let h = crosscal(&[c, &sub, "--help"]);
            assert!(
                h.contains(&format!("Example: crosscal {c} {sub}")),
                "`crosscal {c} {sub} --help`: no example line"
            );
        }
    }
    for (topic, page) in [
        ("session", "reference-session.md"),
        ("profile-format", "reference-profile.md"),
        ("rules", "reference-rules.md"),
        ("catalogue", "reference-effects.md"),
        ("conventions", "reference-conventions.md"),
        ("errors", "reference-exit-codes.md"),
        ("quantities", "reference-datasheet.md"),
    ] {
        let text = std::fs::read_to_string(root().join("docs").join(page)).unwrap();
        assert!(
            crosscal(&["help", topic]) == text,
            "`crosscal help {topic}` differs from docs/{page} (built into the binary)"
        );
    }
    for command in &commands {
        let help = crosscal(&["help", command]);
        assert!(
            help.contains(&format!("Usage: crosscal {command}")),
            "`crosscal help {command}` is the command's help"
        );
    }
    let bad = Command::new(env!("CARGO_BIN_EXE_crosscal")).args(["help", "no-such"]).output().unwrap();
    assert_eq!(bad.status.code(), Some(2));
    assert!(String::from_utf8_lossy(&bad.stderr).contains("topics are"));
}

#[test]
fn the_guides_rust_example_is_the_one_cargo_builds() {
    let page = std::fs::read_to_string(root().join("docs/tutorial-use-profile.md")).unwrap();
    let example = std::fs::read_to_string(root().join("examples/correct_stream.rs")).unwrap();
    assert!(page.contains(&example), "docs/tutorial-use-profile.md shows examples/correct_stream.rs verbatim");
}
