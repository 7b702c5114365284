//! The HTML reports (diagnose, noise, batch) open in a browser without scripts or network
//! and have the structure a reader expects: a title, tables, one section per channel with
//! its plots, every plot titled and with labelled axes. Where Chromium is installed
//! (`/usr/bin/chromium`, as `.ci/run` installs it when it can), each report is also rendered
//! headless to a screenshot that must not be blank; elsewhere that part is skipped with a
//! message.

use crate::common::run_in;
use std::path::Path;

fn count(s: &str, pat: &str) -> usize {
    s.matches(pat).count()
}

/// No scripts, no external resources (the only URL allowed is the SVG namespace).
fn self_contained(html: &str, what: &str) {
    assert!(!html.contains("<script"), "{what}: has a script");
    let urls = html.replace("http://www.w3.org/2000/svg", "").replace("http://www.w3.org/1999/xlink", "");
    assert!(!urls.contains("http://") && !urls.contains("https://"), "{what}: refers to the network");
    assert!(html.starts_with("<!DOCTYPE html>") && html.trim_end().ends_with("</html>"), "{what}: a whole page");
    assert_eq!(count(html, "<h1>"), 1, "{what}: one title");
}

/// Every plot has a title (caption) and axis descriptions with units in parentheses.
fn plots_are_labelled(html: &str, what: &str) -> usize {
    let svgs: Vec<&str> = html.split("<svg").skip(1).map(|s| s.split("</svg>").next().unwrap_or_default()).collect();
    for (i, svg) in svgs.iter().enumerate() {
        let texts: Vec<&str> =
            svg.split("<text").skip(1).filter_map(|t| t.split('>').nth(1)?.split("</text").next()).collect();
        assert!(texts.len() >= 4, "{what}: plot {i} has too little text: {texts:?}");
        assert!(
            texts.iter().filter(|t| t.contains('(') && t.contains(')')).count() >= 1,
            "{what}: plot {i} axes without units: {texts:?}"
        );
    }
    svgs.len()
}

/// Renders a page with headless Chromium and checks the screenshot is not blank.
fn render(page: &Path, what: &str) {
    let chromium = Path::new("/usr/bin/chromium");
    if !chromium.is_file() {
        eprintln!("skipped: rendering {what} needs /usr/bin/chromium (apt-get install chromium)");
        return;
    }
    let dir = page.parent().unwrap();
    let shot = dir.join(format!("{what}.png"));
    let profile = tempfile::tempdir().unwrap();
    let out = std::process::Command::new("timeout")
        .arg("120")
        .arg(chromium)
        .args([
            "--headless",
            "--no-sandbox",
            "--disable-gpu",
            "--disable-quic",
            "--no-first-run",
            "--disable-background-networking",
            "--disable-component-update",
            "--disable-sync",
            "--window-size=1200,2400",
        ])
        .arg(format!("--user-data-dir={}", profile.path().display()))
        .arg(format!("--screenshot={}", shot.display()))
        .arg(format!("file://{}", page.display()))
        .output()
        .unwrap();
    assert!(out.status.success(), "chromium failed on {what}: {}", String::from_utf8_lossy(&out.stderr));
    let png = std::fs::read(&shot).unwrap();
    assert_eq!(&png[1..4], b"PNG", "{what}: a PNG screenshot");
    // A blank 1200×2400 page compresses to a few kB; text, tables and plots do not.
    assert!(png.len() > 40_000, "{what}: the screenshot looks blank ({} bytes)", png.len());
}

#[test]
fn diagnose_report_has_a_section_per_channel_and_renders() {
    let d = tempfile::tempdir().unwrap();
    crate::common::simulate_g_sensitive(d.path(), "u", "I1426-0042", 42, 0.00005);
    let (code, _, err) = run_in(d.path(), &["diagnose", "u/session.json", "--report", "d.html", "--figures", "figs"]);
    assert_eq!(code, 0, "{err}");
    let html = std::fs::read_to_string(d.path().join("d.html")).unwrap();
    self_contained(&html, "diagnose report");
    assert!(html.contains("class=\"verdict\"") && html.contains("gyro-g-sensitivity"), "the verdict names the effect");
    assert!(count(&html, "<table") >= 2, "tables: residuals before, after each step");
    for ch in ["gyro x", "gyro y", "gyro z", "accel x", "accel y", "accel z"] {
        assert_eq!(count(&html, &format!("<h2>{ch}</h2>")), 1, "one section for {ch}");
    }
    let plots = plots_are_labelled(&html, "diagnose report");
    assert_eq!(plots, 24, "four plots per channel");
    let figs = std::fs::read_dir(d.path().join("figs")).unwrap().count();
    assert_eq!(figs, 24, "--figures writes the report's plots");
    render(&d.path().join("d.html"), "diagnose");
}

#[test]
fn noise_report_has_a_plot_per_channel_and_renders() {
    let d = tempfile::tempdir().unwrap();
    let (code, _, err) = run_in(
        d.path(),
        &["simulate", "--preset", "static", "--duration", "600", "--arw", "0.15", "--vrw", "0.02", "-o", "still"],
    );
    assert_eq!(code, 0, "{err}");
    let (code, _, err) = run_in(d.path(), &["noise", "still/session.json", "--report", "n.html"]);
    assert_eq!(code, 0, "{err}");
    let html = std::fs::read_to_string(d.path().join("n.html")).unwrap();
    self_contained(&html, "noise report");
    assert_eq!(count(&html, "<h2>"), 6, "one section per channel");
    assert_eq!(plots_are_labelled(&html, "noise report"), 6, "one Allan deviation plot per channel");
    assert!(html.contains("Allan deviation (") && html.contains("cluster time τ (s)"), "axes with units");
    render(&d.path().join("n.html"), "noise");
}

#[test]
fn batch_report_has_its_tables_and_distributions_and_renders() {
    let d = tempfile::tempdir().unwrap();
    for i in 1..=5 {
        let (code, _, err) = run_in(
            d.path(),
            &[
                "simulate",
                "-o",
                &format!("lot/U{i}"),
                "--serial",
                &format!("U{i}"),
                "--seed",
                &i.to_string(),
                "--duration",
                "6",
                "--gyro-noise",
                "0.002",
                "--accel-noise",
                "2e-5",
            ],
        );
        assert_eq!(code, 0, "{err}");
    }
    std::fs::write(
        d.path().join("rules.json"),
        r#"{"format": "crosscal-rules/1", "rules": [{"kind": "coefficient", "select": "gyro.c_*", "max_abs_deviation": 0.02}]}"#,
    )
    .unwrap();
    let (code, _, err) = run_in(d.path(), &["batch", "lot", "--rules", "rules.json"]);
    assert_eq!(code, 0, "{err}");
    let html = std::fs::read_to_string(d.path().join("lot/batch-report.html")).unwrap();
    self_contained(&html, "batch report");
    assert!(count(&html, "<table") >= 1 && count(&html, "<tr") >= 6, "a verdict row per unit");
    assert!(html.contains("coefficients across the batch"));
    assert!(plots_are_labelled(&html, "batch report") >= 30, "a distribution per coefficient");
    render(&d.path().join("lot/batch-report.html"), "batch");
}

/// Renders `page` in headless Chromium with a script (added to a copy, the report itself
/// has none) that measures every text of every plot, and fails when two texts of one plot
/// overlap (tick labels running into each other). Skipped with a message without Chromium.
pub fn no_overlapping_text(page: &Path, what: &str) {
    let chromium = Path::new("/usr/bin/chromium");
    if !chromium.is_file() {
        eprintln!("skipped: measuring {what}'s plots needs /usr/bin/chromium (apt-get install chromium)");
        return;
    }
    const SCRIPT: &str = r#"<script>
const bad = []; let texts = 0;
document.querySelectorAll('svg').forEach((svg, k) => {
  const ts = [...svg.querySelectorAll('text')].filter(t => t.textContent.trim() !== '')
    .map(t => ({ s: t.textContent, r: t.getBoundingClientRect() }));
  texts += ts.length;
  for (let i = 0; i < ts.length; i++) for (let j = i + 1; j < ts.length; j++) {
    const a = ts[i].r, b = ts[j].r;
    const ox = Math.min(a.right, b.right) - Math.max(a.left, b.left);
    const oy = Math.min(a.bottom, b.bottom) - Math.max(a.top, b.top);
    if (ox > 1 && oy > 1) bad.push('plot ' + k + ': "' + ts[i].s + '" over "' + ts[j].s + '"');
  }
});
const p = document.createElement('pre');
p.textContent = 'MEASURED ' + texts + ' OVERLAPS[' + bad.join(' | ') + ']END';
document.body.appendChild(p);
</script></body>"#;
    let html = std::fs::read_to_string(page).unwrap();
    let dir = tempfile::tempdir().unwrap();
    let copy = dir.path().join("measure.html");
    std::fs::write(&copy, html.replace("</body>", SCRIPT)).unwrap();
    let profile = tempfile::tempdir().unwrap();
    let out = std::process::Command::new("timeout")
        .arg("120")
        .arg(chromium)
        .args(["--headless", "--no-sandbox", "--disable-gpu", "--no-first-run", "--disable-background-networking"])
        .arg("--disable-component-update")
        .arg("--window-size=1200,2400")
        .arg(format!("--user-data-dir={}", profile.path().display()))
        .arg("--dump-dom")
        .arg(format!("file://{}", copy.display()))
        .output()
        .unwrap();
    let dom = String::from_utf8_lossy(&out.stdout);
    // The script's own text is in the DOM too: the result is the last occurrence.
    let found = dom.rsplit("OVERLAPS[").next().filter(|_| dom.contains("]END")).and_then(|s| s.split("]END").next());
    let Some(found) = found else {
        panic!("{what}: the measuring script did not run: {}", String::from_utf8_lossy(&out.stderr))
    };
    let measured = dom.rsplit("MEASURED ").next().and_then(|s| s.split(' ').next()).unwrap_or("0");
    println!("{what}: {measured} plot texts measured in Chromium");
    assert!(measured.parse::<usize>().unwrap_or(0) > 20, "{what}: too few texts measured ({measured})");
    assert!(found.is_empty(), "{what}: overlapping texts: {found}");
}

/// A knee no catalogue effect explains: the report draws the shape section (its words, the
/// effects-file entry, the partial-residual plots) with labelled axes and no text running
/// into other text when Chromium renders it.
#[test]
fn diagnose_report_draws_the_shape_of_what_nothing_explains() {
    let d = tempfile::tempdir().unwrap();
    let args = [
        "simulate",
        "--out",
        "k",
        "--serial",
        "KNEE-1",
        "--rates",
        "20,-20,40,-40",
        "--cone-angles",
        "15,30",
        "--duration",
        "20",
        "--rate-hz",
        "50",
        "--gyro-noise",
        "0.002",
        "--accel-noise",
        "2e-5",
        "--seed",
        "36200",
        "--disturb",
        "knee:gyro-x:4:0.03",
    ];
    let (code, _, err) = run_in(d.path(), &args);
    assert_eq!(code, 0, "{err}");
    let (code, out, err) = run_in(d.path(), &["diagnose", "k/session.json", "--report", "k.html", "--figures", "figs"]);
    assert!(code == 0 || code == 1, "{err}");
    assert!(out.contains("a knee"), "{out}");
    let html = std::fs::read_to_string(d.path().join("k.html")).unwrap();
    self_contained(&html, "shape report");
    assert!(html.contains("<h3>shape: gyro x: zero below"), "the shape in words");
    assert!(html.contains("k * max(w_x - w0, 0)"), "the effects-file entry");
    let plots = plots_are_labelled(&html, "shape report");
    assert!(plots > 24, "partial-residual plots beside the channels' four: {plots}");
    let shape_figs = std::fs::read_dir(d.path().join("figs"))
        .unwrap()
        .filter(|e| e.as_ref().is_ok_and(|e| e.file_name().to_string_lossy().contains("-shape-")))
        .count();
    assert!(shape_figs >= 1, "--figures writes the shape plots");
    render(&d.path().join("k.html"), "shape report");
    no_overlapping_text(&d.path().join("k.html"), "shape report");
}
