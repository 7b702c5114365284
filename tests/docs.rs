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

/// A fenced block of shell commands and the line it starts on (1-based), with the
/// ```` ```text ```` block right after it (only blank lines between), which shows what the
/// commands print.
struct Block {
    line: usize,
    text: String,
    shown: Option<(usize, String)>,
}

/// The ```sh blocks of a Markdown page, in order, each with the output it shows.
fn sh_blocks(md: &str) -> Vec<Block> {
    let mut out: Vec<Block> = Vec::new();
    let mut current: Option<Block> = None;
    // (line of the text block, its text), while inside a ```text block right after a sh block.
    let mut shown: Option<(usize, String)> = None;
    let mut after_sh = false;
    for (i, l) in md.lines().enumerate() {
        let t = l.trim_start();
        if let Some((_, text)) = &mut shown {
            if t.starts_with("```") {
                if let Some(b) = out.last_mut() {
                    b.shown = shown.take();
                }
            } else {
                text.push_str(l);
                text.push('\n');
            }
            continue;
        }
        match &mut current {
            None if t.starts_with("```sh") && t[5..].trim().is_empty() => {
                current = Some(Block { line: i + 1, text: String::new(), shown: None });
            }
            None if after_sh && t.starts_with("```text") && t[7..].trim().is_empty() => {
                shown = Some((i + 1, String::new()));
            }
            None => after_sh = after_sh && t.is_empty(),
            Some(_) if t.starts_with("```") => {
                out.extend(current.take());
                after_sh = true;
                continue;
            }
            Some(b) => {
                b.text.push_str(l);
                b.text.push('\n');
            }
        }
        if current.is_none() && !t.is_empty() {
            after_sh = false;
        }
    }
    assert!(current.is_none() && shown.is_none(), "an unclosed ```sh or ```text block");
    out
}

/// Relative tolerance of the numbers a page shows against those printed: 2e-4, so the last
/// of five significant digits may differ by one or two (rounding across machines), while a
/// drift (2.4893e-3 shown, 2.4942e-3 printed: 2e-3) fails.
const DOC_NUMBER_RTOL: f64 = 2e-4;

/// Whether `printed` is what a page `shown`: line by line; a line `…` stands for any number
/// of lines, `…` inside a line for any text; numbers agree within [`DOC_NUMBER_RTOL`];
/// everything else exactly (spacing aside).
fn same_output(shown: &str, printed: &str) -> Result<(), String> {
    let want: Vec<&str> = shown.lines().map(str::trim_end).collect();
    let got: Vec<&str> = printed.lines().map(str::trim_end).collect();
    fn lines(w: &[&str], g: &[&str]) -> Result<(), String> {
        match w.split_first() {
            None if g.is_empty() => Ok(()),
            None => Err(format!("printed more lines than the page shows, from: {}", g[0])),
            Some((&"…", rest)) => {
                if rest.is_empty() {
                    return Ok(());
                }
                let mut last = Err(String::new());
                for k in 0..=g.len() {
                    last = lines(rest, &g[k..]);
                    if last.is_ok() {
                        return last;
                    }
                }
                last
            }
            Some((l, rest)) => match g.split_first() {
                None => Err(format!("the page shows more lines than printed, from: {l}")),
                Some((p, grest)) => {
                    same_line(l, p).map_err(|e| format!("shown:   {l}\nprinted: {p}\n({e})"))?;
                    lines(rest, grest)
                }
            },
        }
    }
    lines(&want, &got)
}

/// One line: `…` matches any text; numbers within the tolerance; the rest exactly.
fn same_line(shown: &str, printed: &str) -> Result<(), String> {
    if let Some((head, tail)) = shown.split_once('…') {
        let cut = printed.len().min(head.len());
        if !printed.is_char_boundary(cut) {
            return Err(format!("no match for '{head}…'"));
        }
        let (hp, _) = printed.split_at(cut);
        same_line(head, hp)?;
        // The rest must match a suffix of what is left.
        let rest = &printed[hp.len()..];
        return (0..=rest.len())
            .filter(|&k| rest.is_char_boundary(k))
            .find(|&k| same_line(tail, &rest[k..]).is_ok())
            .map(|_| ())
            .ok_or_else(|| format!("no match for '…{tail}'"));
    }
    let (a, b) = (tokens(shown), tokens(printed));
    if a.len() != b.len() {
        return Err(format!("{} pieces shown, {} printed", a.len(), b.len()));
    }
    for (x, y) in a.iter().zip(&b) {
        match (num(x), num(y)) {
            (Some(u), Some(v)) => {
                let tol = DOC_NUMBER_RTOL * u.abs().max(v.abs());
                if (u - v).abs() > tol && !(u == 0.0 && v == 0.0) {
                    return Err(format!("{x} shown, {y} printed"));
                }
            }
            _ if x == y => {}
            _ => return Err(format!("'{x}' shown, '{y}' printed")),
        }
    }
    Ok(())
}

/// A line in pieces: runs of number characters apart from the rest, spaces dropped.
fn tokens(l: &str) -> Vec<String> {
    let mut out: Vec<String> = Vec::new();
    let mut cur = String::new();
    let mut in_num = false;
    let chars: Vec<char> = l.chars().collect();
    for (i, &c) in chars.iter().enumerate() {
        let starts_num = c.is_ascii_digit()
            || ((c == '-' || c == '+' || c == '.') && chars.get(i + 1).is_some_and(|n| n.is_ascii_digit()));
        let continues_num = in_num
            && (c.is_ascii_digit()
                || c == '.'
                || ((c == 'e' || c == 'E')
                    && chars.get(i + 1).is_some_and(|n| n.is_ascii_digit() || *n == '-' || *n == '+'))
                || ((c == '-' || c == '+') && matches!(chars.get(i.wrapping_sub(1)), Some('e' | 'E'))));
        if c.is_whitespace() {
            if !cur.is_empty() {
                out.push(std::mem::take(&mut cur));
            }
            in_num = false;
        } else if continues_num {
            cur.push(c);
        } else if starts_num && !(cur.chars().last().is_some_and(|p| p.is_ascii_alphabetic() || p == '_')) {
            if !cur.is_empty() {
                out.push(std::mem::take(&mut cur));
            }
            cur.push(c);
            in_num = true;
        } else {
            if in_num && !cur.is_empty() {
                out.push(std::mem::take(&mut cur));
            }
            cur.push(c);
            in_num = false;
        }
    }
    if !cur.is_empty() {
        out.push(cur);
    }
    out
}

fn num(s: &str) -> Option<f64> {
    s.parse::<f64>().ok().filter(|x| x.is_finite())
}

#[test]
fn shown_output_is_compared_within_the_tolerance() {
    assert!(same_output("a 2.4893e-3 b\n…\n", "a 2.4893e-3 b\nmore\nlines\n").is_ok());
    assert!(same_output("white 2.4893e-3\n", "white 2.4942e-3\n").is_err());
    assert!(same_output("σ 2.500e-2\n", "σ 2.509e-2\n").is_err());
    assert!(same_output("x 1.23450\n", "x 1.23451\n").is_ok());
    assert!(same_output(
        "error: fitting …/s1/session.json: run 'a'\n",
        "error: fitting /tmp/x/s1/session.json: run 'a'\n"
    )
    .is_ok());
    assert!(same_output("wrote 12 runs\n", "wrote 13 runs\n").is_err());
    assert!(same_output("text a\n", "text b\n").is_err());
    // Text after an in-line … with characters of several bytes: compared, never a panic.
    assert!(same_output("unit U1: … → …\n", "unit U1: 2026-11-24 → 2026-11-25\n").is_ok());
    assert!(same_output("a ×… b\n", "a → b\n").is_err());
    assert!(same_output("one\n", "one\ntwo\n").is_err());
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
                        // A no-op, not an empty line: the block may be wrapped in braces.
                        ":".to_string()
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
        // Standard error with standard output, in order, as a terminal shows them.
        let merged = format!("{{\n{}\n}} 2>&1", script(&b, &bin_dir));
        let out = Command::new("timeout")
            .args(["600", "bash", "-eo", "pipefail", "-c", &merged])
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
        // CROSSCAL_DOCS_DIFF=DIR: every block's printed output and any mismatch go to files
        // there (to update a page by hand) instead of failing the test.
        let diff_dir = std::env::var_os("CROSSCAL_DOCS_DIFF").map(PathBuf::from);
        if let Some((line, shown)) = &b.shown {
            let printed = String::from_utf8_lossy(&out.stdout);
            let verdict = same_output(shown, &printed);
            if let Some(dir) = &diff_dir {
                let stem = format!("{}-{line}", page.replace('/', "_"));
                std::fs::create_dir_all(dir).unwrap();
                std::fs::write(dir.join(format!("{stem}.printed")), printed.as_bytes()).unwrap();
                if let Err(e) = &verdict {
                    std::fs::write(dir.join(format!("{stem}.mismatch")), format!("{e}\n--- shown\n{shown}")).unwrap();
                }
            } else if let Err(e) = verdict {
                panic!("{page}:{line}: the output the page shows is not what the block above prints:\n{e}\n--- printed\n{printed}");
            }
        }
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
