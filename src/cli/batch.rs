//! `crosscal batch`: calibrate and accept a production lot.

use super::Outcome;
use crate::errln;
use crate::outln;
use anyhow::Context;
use crosscal::app::batch::{run as run_batch, to_csv, to_html, unit_dirs, BatchOptions, UnitResult, Verdict};
use crosscal::check::rules::Rules;
use std::io::IsTerminal;
use std::path::PathBuf;

/// Options of `batch`.
#[derive(Debug, clap::Args)]
pub struct Args {
    /// Folder with one sub-folder per unit, each holding that unit's session.json and CSVs.
    dir: PathBuf,
    /// Acceptance rules (JSON, crosscal-rules/1).
    #[arg(long)]
    rules: PathBuf,
    /// Profile store.
    #[arg(long, default_value = "calib-profiles")]
    out: PathBuf,
    /// Folder for batch-report.{csv,json,html} (default: DIR).
    #[arg(long)]
    report_dir: Option<PathBuf>,
    /// The model (for `check`: fitted with --holdout / --cross-validate).
    #[command(flatten)]
    model: super::ModelArgs,
    /// Skip units whose profile was already fitted on the same files (after an interruption).
    #[arg(long)]
    resume: bool,
    /// Worker threads (default: all cores).
    #[arg(long, default_value_t = 0)]
    jobs: usize,
}

pub fn run(a: Args) -> anyhow::Result<Outcome> {
    let rules = Rules::read(&a.rules)?;
    let model = a.model.spec(&[]);
    model.build()?;
    let dirs = unit_dirs(&a.dir).with_context(|| format!("reading batch folder {}", a.dir.display()))?;
    if dirs.is_empty() {
        anyhow::bail!("{}: no unit folders (expected one sub-folder per unit with its session.json)", a.dir.display());
    }
    let lot = std::fs::canonicalize(&a.dir)
        .ok()
        .and_then(|d| d.file_name().map(|n| n.to_string_lossy().into_owned()))
        .unwrap_or_else(|| a.dir.display().to_string());
    let opts = BatchOptions { model, store: a.out.clone(), rules, resume: a.resume, jobs: a.jobs, lot };
    // Where the results go is settled before the first unit is fitted.
    crosscal::app::batch::prepare(&opts)?;
    let rdir = a.report_dir.clone().unwrap_or_else(|| a.dir.clone());
    std::fs::create_dir_all(&rdir).with_context(|| format!("creating the report folder {}", rdir.display()))?;
    let tty = std::io::stderr().is_terminal();
    let bar = tty.then(|| {
        let b = indicatif::ProgressBar::new(dirs.len() as u64);
        if let Ok(style) =
            indicatif::ProgressStyle::with_template("{bar:40} {pos}/{len} units  {elapsed} (eta {eta}) {msg}")
        {
            b.set_style(style);
        }
        b
    });
    let log = |u: &UnitResult| {
        let line = format!(
            "{} {}: {:?}{}{}",
            u.dir.display(),
            u.serial.as_deref().unwrap_or("?"),
            u.verdict,
            if u.reused { " (profile reused)" } else { "" },
            if u.reasons.is_empty() { String::new() } else { format!(" — {}", u.reasons.join("; ")) }
        );
        match &bar {
            Some(b) => {
                if u.verdict != Verdict::Pass {
                    b.println(line);
                }
                b.inc(1);
            }
            None => errln!("{line}"),
        }
    };
    let report = run_batch(&dirs, &opts, &log)?;
    if let Some(b) = &bar {
        b.finish_and_clear();
    }
    let write = |name: &str, text: String| -> anyhow::Result<()> {
        let path = rdir.join(name);
        crosscal::atomic::write_atomic(&path, true, |w| std::io::Write::write_all(w, text.as_bytes()))
            .with_context(|| format!("writing {}", path.display()))
    };
    write("batch-report.csv", to_csv(&report))?;
    write("batch-report.json", serde_json::to_string_pretty(&report)? + "\n")?;
    write("batch-report.html", to_html(&report, &format!("crosscal batch: {}", a.dir.display())))?;
    let outliers: Vec<&UnitResult> = report.units.iter().filter(|u| !u.outliers.is_empty()).collect();
    outln!(
        "{} units: {} pass, {} fail, {} indeterminate, {} could not be processed; {} batch outlier(s); reports in {}",
        report.units.len(),
        report.passed(),
        report.units.iter().filter(|u| u.verdict == Verdict::Fail).count(),
        report.units.iter().filter(|u| u.verdict == Verdict::Indeterminate).count(),
        report.units.iter().filter(|u| u.verdict == Verdict::Error).count(),
        outliers.len(),
        rdir.display()
    );
    for u in outliers {
        let o: Vec<String> = u.outliers.iter().map(|(n, z)| format!("{n} z = {z:+.1}")).collect();
        outln!("outlier: {} ({})", u.dir.display(), o.join(", "));
    }
    for u in report.units.iter().filter(|u| u.verdict == Verdict::Indeterminate) {
        let how: Vec<String> =
            u.rules.iter().filter_map(|r| r.resolve.as_ref().map(|h| format!("{}: {h}", r.rule))).collect();
        outln!("indeterminate: {} ({})", u.dir.display(), how.join("; "));
    }
    for c in &report.capability {
        outln!(
            "capability {} {}: mean {:.4e} {}, std {:.3e}, Cpk {} [{}, {}]; {} pass, {} fail, {} indeterminate",
            c.rule,
            c.axis,
            c.mean,
            c.unit,
            c.std,
            c.cpk.map_or("-".into(), |v| format!("{v:.2}")),
            c.cpk_low.map_or("-".into(), |v| format!("{v:.2}")),
            c.cpk_high.map_or("-".into(), |v| format!("{v:.2}")),
            c.pass,
            c.fail,
            c.indeterminate
        );
    }
    for ch in &report.control {
        for p in ch.flagged() {
            outln!(
                "process shift: {} {} at lot {} (mean {:.4e}, std {:.3e} {} against the earlier lots' limits {})",
                ch.quantity,
                ch.axis,
                p.point.lot,
                p.point.mean,
                p.point.std,
                ch.unit,
                p.mean_limits.map_or("-".into(), |l| format!("{:.4e}..{:.4e}", l[0], l[2]))
            );
        }
    }
    for w in &report.warnings {
        eprintln!("warning: {w}");
    }
    Ok(if report.passed() == report.units.len() { Outcome::Ok } else { Outcome::CheckFailed })
}
