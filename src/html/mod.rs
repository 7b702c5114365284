//! Leaf layer: self-contained HTML pages (inline SVG, no scripts, no network) and the plots
//! drawn into them, shared by every report (diagnose, noise, batch).

pub mod plot;

use std::fmt::Write;

/// The start of a self-contained report page (project style), with its title as heading.
pub fn page_start(title: &str) -> String {
    let mut s = String::with_capacity(1 << 20);
    let _ = write!(
        s,
        "<!DOCTYPE html><html><head><meta charset=\"utf-8\"><title>{t}</title><style>\
         body{{font-family:sans-serif;max-width:1100px;margin:auto;padding:1em}}\
         table{{border-collapse:collapse;margin:0.5em 0}}td,th{{border:1px solid #ccc;padding:3px 8px;text-align:right}}\
         th{{background:#eee}}td:first-child{{text-align:left;white-space:nowrap}}.verdict{{font-size:1.2em;padding:0.5em;background:#f4f4f4}}</style></head><body>\
         <h1>{t}</h1>",
        t = esc(title)
    );
    s
}

/// Escapes text for HTML.
pub fn esc(s: &str) -> String {
    s.replace('&', "&amp;").replace('<', "&lt;").replace('>', "&gt;")
}

/// One plot of a report, also written on its own by `--figures DIR` (the guide's pictures
/// come from there): a file-name stem such as `gyro-x-phase` and the SVG.
#[derive(Debug, Clone)]
pub struct Figure {
    /// File-name stem, without extension.
    pub stem: String,
    /// The plot as an SVG document.
    pub svg: String,
}

/// A file-name stem from a channel's display name (`gyro x` → `gyro-x`).
pub fn slug(name: &str) -> String {
    name.chars().map(|c| if c.is_ascii_alphanumeric() { c.to_ascii_lowercase() } else { '-' }).collect()
}
