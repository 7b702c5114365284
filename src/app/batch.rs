//! Batch calibration of a production lot: one session per unit, fitted in parallel, each
//! unit's profile stored, every unit judged by acceptance rules, statistical outliers
//! within the batch flagged, and the batch reported as CSV, JSON and self-contained HTML.
//!
//! A unit that cannot be processed (corrupt or missing files, unidentifiable model) fails
//! with its reason; the rest of the batch completes. Profiles are written atomically as
//! each unit finishes, so an interrupted batch keeps every finished profile; with
//! `resume`, a unit whose store already holds a profile fitted on exactly the same files
//! (same SHA-256) is not fitted again.
//!
//! Outliers: for every coefficient, the robust z-score (x − median)/σ over the units that
//! were fitted, σ the small-sample-corrected 1.4826·MAD floored by the units' own standard
//! errors; |z| > 5 flags the unit even when it passes the fixed rules.
//!
//! Datasheet rules: every unit's datasheet (with its stored calibrations) is judged with its
//! uncertainty; an indeterminate unit is counted as such and told which measurement would
//! resolve it ([`super::accept::resolve`]). The lot's capability per datasheet rule and axis
//! (mean, std, Cpk with its 95 % interval, counts) is in the report, and is stored in the
//! profile store (`.lots/`) so that a control chart across the lots of a store
//! ([`crate::datasheet::lot::control_chart`]) flags the lot whose mean or spread shifted.

pub use super::lots::ControlChart;
use crate::check::guarded::Decision;
use crate::check::rules::{evaluate, Evidence, Rule, RuleResult, Rules};
use crate::datasheet::lot::{cpk, Capability};
use crate::estimate::{FitData, FitRequest, ModelChoice};
use crate::model::ModelSpec;
use crate::profile::{history, save, Profile};
use crate::session::Session;
use rayon::prelude::*;
use serde::{Deserialize, Serialize};
use std::path::{Path, PathBuf};

/// Robust z-score above which a unit is an outlier within its batch.
pub const OUTLIER_Z: f64 = 5.0;

/// Settings of a batch.
#[derive(Debug, Clone)]
pub struct BatchOptions {
    /// Model fitted to every unit (`default` is a protocol session's own preset).
    pub model: ModelSpec,
    /// Profile store.
    pub store: PathBuf,
    /// Acceptance rules.
    pub rules: Rules,
    /// Reuse profiles already fitted on the same files.
    pub resume: bool,
    /// Worker threads (0: all cores).
    pub jobs: usize,
    /// Lot name (the batch folder's name): the control chart's label for this lot.
    pub lot: String,
}

/// Verdict of one unit.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum Verdict {
    /// Every rule passed.
    Pass,
    /// A rule failed.
    Fail,
    /// No rule failed, but a datasheet rule could not tell (its value within k·u of a
    /// limit): neither accepted nor rejected until measured better.
    Indeterminate,
    /// The unit could not be processed (files, identifiability).
    Error,
}

/// The result of one unit.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct UnitResult {
    /// The unit's folder.
    pub dir: PathBuf,
    /// Serial (when the manifest could be read).
    pub serial: Option<String>,
    /// Verdict.
    pub verdict: Verdict,
    /// Why it failed or errored (failed rules' names and details, or the error).
    pub reasons: Vec<String>,
    /// Every rule's outcome.
    pub rules: Vec<RuleResult>,
    /// Profile written (or reused).
    pub profile: Option<PathBuf>,
    /// Whether the profile was reused (`resume`).
    pub reused: bool,
    /// Fitted coefficient values by name.
    pub coefficients: Vec<(String, f64)>,
    /// Their standard errors, in the same order (None when held).
    #[serde(default)]
    pub std_errors: Vec<Option<f64>>,
    /// Coefficients where the unit is a batch outlier, with their robust z.
    pub outliers: Vec<(String, f64)>,
    /// The coefficients' units (SI), in the same order.
    #[serde(default)]
    pub units: Vec<String>,
}

/// The whole batch.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct BatchReport {
    /// Units in folder order.
    pub units: Vec<UnitResult>,
    /// Per coefficient: (name, median, robust σ) over the fitted units.
    pub spread: Vec<(String, f64, f64)>,
    /// Per datasheet rule and axis: the lot's capability.
    #[serde(default)]
    pub capability: Vec<Capability>,
    /// Per datasheet rule's quantity and axis: this lot and the store's earlier lots on a
    /// control chart.
    #[serde(default)]
    pub control: Vec<ControlChart>,
    /// What went wrong besides the units (the lot summary could not be stored).
    #[serde(default)]
    pub warnings: Vec<String>,
}

impl BatchReport {
    /// Units that pass.
    pub fn passed(&self) -> usize {
        self.units.iter().filter(|u| u.verdict == Verdict::Pass).count()
    }
}

/// The unit folders of a batch: every sub-folder of `dir` holding a `session.json`, sorted
/// (a sub-folder without one is a unit whose manifest is missing).
pub fn unit_dirs(dir: &Path) -> std::io::Result<Vec<PathBuf>> {
    let mut out: Vec<PathBuf> =
        std::fs::read_dir(dir)?.filter_map(|e| e.ok()).map(|e| e.path()).filter(|p| p.is_dir()).collect();
    out.sort();
    Ok(out)
}

/// A profile already in the store fitted on exactly this session's files.
fn existing(store: &Path, session: &Session) -> Option<(PathBuf, Profile)> {
    let files: Vec<&str> = session.runs.iter().map(|r| r.rec.sha256.as_str()).collect();
    history(store, &session.manifest.serial).ok()?.into_iter().rev().find_map(|(path, p)| {
        let p = p.ok()?;
        let used: Vec<&str> = p.runs.iter().map(|r| r.sha256.as_str()).collect();
        (used == files).then_some((path, p))
    })
}

fn process_unit(dir: &Path, opts: &BatchOptions) -> UnitResult {
    let mut r = UnitResult {
        dir: dir.to_path_buf(),
        serial: None,
        verdict: Verdict::Error,
        reasons: Vec::new(),
        rules: Vec::new(),
        profile: None,
        reused: false,
        coefficients: Vec::new(),
        std_errors: Vec::new(),
        outliers: Vec::new(),
        units: Vec::new(),
    };
    let manifest = dir.join("session.json");
    let session = match Session::load(&manifest) {
        Ok(s) => s,
        Err(e) => {
            r.reasons.push(format!("cannot read the session: {}", super::chain(&e)));
            return r;
        }
    };
    r.serial = Some(session.manifest.serial.clone());
    let (path, profile, reused) = match existing(&opts.store, &session).filter(|_| opts.resume) {
        Some((path, p)) => (path, p, true),
        None => {
            let mut req = FitRequest::new(FitData::Session(&session), ModelChoice::Spec(&opts.model));
            req.strict = true;
            let p = match super::fit::fit_profile(&req, None) {
                Ok(f) => f.profile,
                Err(e) => {
                    r.reasons.push(super::chain(&e));
                    return r;
                }
            };
            match save(&p, &opts.store) {
                Ok(path) => (path, p, false),
                Err(e) => {
                    r.reasons.push(format!("cannot store the profile: {}", super::chain(&e)));
                    return r;
                }
            }
        }
    };
    r.profile = Some(path);
    r.reused = reused;
    r.coefficients = profile
        .gyro
        .coefficients
        .iter()
        .chain(&profile.accel.coefficients)
        .map(|c| (c.name.clone(), c.value))
        .collect();
    r.std_errors = profile.gyro.coefficients.iter().chain(&profile.accel.coefficients).map(|c| c.std_error).collect();
    r.units = profile.gyro.coefficients.iter().chain(&profile.accel.coefficients).map(|c| c.unit.clone()).collect();
    let diagnose = opts.rules.rules.iter().any(|x| matches!(x, crate::check::rules::Rule::Adequate { .. }));
    let acc = match super::accept::acceptance(&profile, &session, diagnose) {
        Ok(a) => a,
        Err(e) => {
            r.reasons.push(format!("check failed: {}", super::chain(&e)));
            return r;
        }
    };
    let sheet = super::datasheet::datasheet_of(&opts.store, r.profile.as_deref(), &profile);
    let ev = Evidence {
        check: acc.check.as_ref(),
        adequacy: acc.adequacy.clone(),
        protocol: acc.protocol,
        datasheet: Some(&sheet),
    };
    r.rules = evaluate(&opts.rules, &profile, &ev);
    super::accept::add_resolutions(&mut r.rules, &opts.rules);
    r.reasons = r.rules.iter().filter(|x| !x.pass).map(|x| format!("{}: {}", x.rule, x.detail)).collect();
    let worst = r.rules.iter().map(RuleResult::decided).max().unwrap_or(Decision::Pass);
    r.verdict = match worst {
        Decision::Pass => Verdict::Pass,
        Decision::Indeterminate => Verdict::Indeterminate,
        Decision::Fail => Verdict::Fail,
    };
    r
}

/// Consistency factor of the MAD for small samples (Croux & Rousseeuw 1992, Table 1 for
/// n ≤ 9, n/(n − 0.8) beyond): without it the MAD of a lot of 5–9 units is biased low and
/// honest units look like outliers.
fn mad_small_sample(n: usize) -> f64 {
    const TABLE: [f64; 8] = [1.196, 1.495, 1.363, 1.206, 1.200, 1.140, 1.129, 1.107];
    match n {
        0 | 1 => 1.0,
        2..=9 => TABLE[n - 2],
        _ => n as f64 / (n as f64 - 0.8),
    }
}

/// The robust spread of one coefficient over the lot: the small-sample-corrected
/// 1.4826·MAD, but never below the median of the units' own standard errors (units cannot
/// agree more closely than their estimates allow).
fn lot_spread(vals: &[f64], std_errors: &[f64]) -> Option<(f64, f64)> {
    let med = crate::stats::median(&mut vals.to_vec())?;
    let mad_sigma = mad_small_sample(vals.len()) * crate::stats::robust_sigma(vals, med)?;
    let floor = crate::stats::median(&mut std_errors.to_vec()).unwrap_or(0.0);
    Some((med, mad_sigma.max(floor)))
}

/// Makes sure the batch can store what it fits before any unit is fitted: the profile store
/// is a folder that exists (created if need be) or the batch does not start.
pub fn prepare(opts: &BatchOptions) -> Result<(), super::AppError> {
    let store = &opts.store;
    let fail = |source| super::AppError::Profile {
        what: format!("store {}", store.display()),
        source: crate::profile::ProfileError::Io { path: store.clone(), source },
    };
    if store.exists() && !store.is_dir() {
        return Err(fail(std::io::Error::new(
            std::io::ErrorKind::NotADirectory,
            "the profile store must be a folder, and this is a file",
        )));
    }
    std::fs::create_dir_all(store).map_err(fail)
}

/// Fits, stores and judges every unit (in parallel), then flags batch outliers.
/// `on_done` is called as each unit finishes (for progress display).
pub fn run(
    dirs: &[PathBuf],
    opts: &BatchOptions,
    on_done: &(dyn Fn(&UnitResult) + Sync),
) -> Result<BatchReport, rayon::ThreadPoolBuildError> {
    let pool = rayon::ThreadPoolBuilder::new().num_threads(opts.jobs).build()?;
    let mut units: Vec<UnitResult> = pool.install(|| {
        dirs.par_iter()
            .map(|d| {
                let r = process_unit(d, opts);
                on_done(&r);
                r
            })
            .collect()
    });
    // Robust spread of every coefficient over the fitted units.
    let mut names: Vec<String> = Vec::new();
    for u in &units {
        for (n, _) in &u.coefficients {
            if !names.contains(n) {
                names.push(n.clone());
            }
        }
    }
    let mut spread = Vec::with_capacity(names.len());
    for name in &names {
        let mut vals = Vec::new();
        let mut ses = Vec::new();
        for u in &units {
            if let Some(i) = u.coefficients.iter().position(|c| &c.0 == name) {
                vals.push(u.coefficients[i].1);
                if let Some(Some(se)) = u.std_errors.get(i) {
                    ses.push(*se);
                }
            }
        }
        if vals.len() < 5 {
            continue;
        }
        let Some((med, sigma)) = lot_spread(&vals, &ses) else { continue };
        spread.push((name.clone(), med, sigma));
        if sigma > 0.0 {
            for u in &mut units {
                if let Some(c) = u.coefficients.iter().find(|c| &c.0 == name) {
                    let z = (c.1 - med) / sigma;
                    if z.abs() > OUTLIER_Z {
                        u.outliers.push((name.clone(), z));
                    }
                }
            }
        }
    }
    let capability = capability(&units, &opts.rules);
    let (control, warning) = super::lots::control(&opts.store, &opts.lot, &capability);
    Ok(BatchReport { units, spread, capability, control, warnings: warning.into_iter().collect() })
}

/// The lot's capability on every datasheet rule and axis, from the units' decided axes.
fn capability(units: &[UnitResult], rules: &Rules) -> Vec<Capability> {
    let mut out = Vec::new();
    for (i, rule) in rules.rules.iter().enumerate() {
        let Rule::Datasheet { quantity, min, max, magnitude, .. } = rule else { continue };
        let results: Vec<&RuleResult> = units.iter().filter_map(|u| u.rules.get(i)).collect();
        let mut axes: Vec<String> = Vec::new();
        for a in results.iter().flat_map(|r| &r.axes) {
            if !axes.contains(&a.axis) {
                axes.push(a.axis.clone());
            }
        }
        let bounds = crate::check::guarded::Bounds {
            min: *min,
            max: *max,
            magnitude: magnitude.unwrap_or(true),
            rule: crate::check::guarded::DecisionRule::Simple,
            k: 0.0,
        };
        let (lsl, usl) = bounds.limits();
        for axis in axes {
            let picked: Vec<_> = results.iter().flat_map(|r| r.axes.iter().find(|a| a.axis == axis)).collect();
            let values: Vec<f64> = picked.iter().map(|a| a.value).collect();
            let count = |d: Decision| picked.iter().filter(|a| a.decision == d).count();
            let Some((mean, std, c)) = cpk(&values, lsl, usl) else { continue };
            out.push(Capability {
                rule: results.first().map_or_else(|| quantity.clone(), |r| r.rule.clone()),
                quantity: quantity.clone(),
                axis,
                unit: crate::datasheet::spec(quantity).map_or_else(String::new, |s| s.unit.to_string()),
                n: values.len(),
                mean,
                std,
                lsl,
                usl,
                cpk: c.map(|c| c[0]),
                cpk_low: c.map(|c| c[1]),
                cpk_high: c.map(|c| c[2]),
                pass: count(Decision::Pass),
                fail: count(Decision::Fail),
                indeterminate: count(Decision::Indeterminate),
            });
        }
    }
    out
}

/// The batch as CSV: one row per unit (quoted by the csv crate where a field needs it).
pub fn to_csv(r: &BatchReport) -> String {
    let mut w = csv::Writer::from_writer(Vec::new());
    let mut rows: Vec<[String; 6]> =
        vec![["unit".into(), "serial".into(), "verdict".into(), "reasons".into(), "outliers".into(), "profile".into()]];
    for u in &r.units {
        let outl: Vec<String> = u.outliers.iter().map(|(n, z)| format!("{n} (z = {z:+.1})")).collect();
        rows.push([
            u.dir.display().to_string(),
            u.serial.clone().unwrap_or_default(),
            format!("{:?}", u.verdict).to_lowercase(),
            u.reasons.join("; "),
            outl.join("; "),
            u.profile.as_ref().map(|p| p.display().to_string()).unwrap_or_default(),
        ]);
    }
    for row in &rows {
        // Writing to memory cannot fail.
        let _ = w.write_record(row);
    }
    w.into_inner().map(|b| String::from_utf8_lossy(&b).into_owned()).unwrap_or_default()
}

/// The batch as a self-contained HTML page: verdict table, the lot's capability on each
/// datasheet rule (table, histogram in datasheet units with the limits drawn and Cpk in the
/// title, control chart across the store's lots), then each coefficient's distribution
/// over the batch (histogram, its unit) with its median and robust σ.
pub fn to_html(r: &BatchReport, title: &str) -> String {
    use crate::html::{esc, page_start};
    use std::fmt::Write;
    let mut s = page_start(title);
    let _ = write!(
        s,
        "<p class=\"verdict\">{} of {} units pass; {} flagged as batch outliers (|robust z| &gt; {OUTLIER_Z}).</p>",
        r.passed(),
        r.units.len(),
        r.units.iter().filter(|u| !u.outliers.is_empty()).count()
    );
    s.push_str("<table><tr><th>unit</th><th>serial</th><th>verdict</th><th>reasons</th><th>outlier</th></tr>");
    for u in &r.units {
        let outl: Vec<String> = u.outliers.iter().map(|(n, z)| format!("{n} (z = {z:+.1})")).collect();
        let colour = match u.verdict {
            Verdict::Pass => "#dfd",
            Verdict::Fail => "#fdd",
            Verdict::Indeterminate => "#ffd",
            Verdict::Error => "#fcc",
        };
        let _ = write!(
            s,
            "<tr style=\"background:{colour}\"><td style=\"text-align:left\">{}</td><td>{}</td><td>{:?}</td><td style=\"text-align:left\">{}</td><td style=\"text-align:left\">{}</td></tr>",
            esc(&u.dir.display().to_string()),
            esc(u.serial.as_deref().unwrap_or("-")),
            u.verdict,
            esc(&u.reasons.join("; ")),
            esc(&outl.join("; "))
        );
    }
    s.push_str("</table>");
    capability_html(&mut s, r);
    s.push_str("<h2>coefficients across the batch</h2>");
    for (name, med, sigma) in &r.spread {
        let mut unit = "1".to_string();
        let vals: Vec<f64> = r
            .units
            .iter()
            .filter_map(|u| {
                let i = u.coefficients.iter().position(|c| &c.0 == name)?;
                if let Some(x) = u.units.get(i) {
                    unit.clone_from(x);
                }
                Some(u.coefficients[i].1)
            })
            .collect();
        s.push_str(&crate::html::plot::histogram(
            &format!("{name} over the lot: median {med:.6e}, robust σ {sigma:.2e}"),
            &format!("{name} ({unit})"),
            &vals,
            &[],
        ));
    }
    s.push_str("</body></html>\n");
    s
}

/// The capability section of the batch page: a table per datasheet rule and axis, each
/// quantity's histogram with its limits and Cpk, each control chart.
fn capability_html(s: &mut String, r: &BatchReport) {
    use crate::html::esc;
    use std::fmt::Write;
    if r.capability.is_empty() {
        return;
    }
    let f = |v: Option<f64>| v.map_or("-".to_string(), |v| format!("{v:.2}"));
    s.push_str("<h2>lot capability on the datasheet rules</h2><table><tr><th>rule</th><th>axis</th><th>n</th><th>mean</th><th>std</th><th>unit</th><th>Cpk</th><th>95 % interval</th><th>pass</th><th>fail</th><th>indeterminate</th></tr>");
    for c in &r.capability {
        let _ = write!(
            s,
            "<tr><td style=\"text-align:left\">{}</td><td>{}</td><td>{}</td><td>{:.4e}</td><td>{:.3e}</td><td>{}</td><td>{}</td><td>{} – {}</td><td>{}</td><td>{}</td><td>{}</td></tr>",
            esc(&c.rule), esc(&c.axis), c.n, c.mean, c.std, esc(&c.unit), f(c.cpk), f(c.cpk_low), f(c.cpk_high), c.pass, c.fail, c.indeterminate
        );
    }
    s.push_str("</table>");
    let indet: Vec<&UnitResult> = r.units.iter().filter(|u| u.verdict == Verdict::Indeterminate).collect();
    if !indet.is_empty() {
        s.push_str("<h3>indeterminate units and what would resolve them</h3><ul>");
        for u in indet {
            let how: Vec<String> =
                u.rules.iter().filter_map(|x| x.resolve.as_ref().map(|h| format!("{}: {h}", x.rule))).collect();
            let _ = write!(s, "<li>{}: {}</li>", esc(&u.dir.display().to_string()), esc(&how.join("; ")));
        }
        s.push_str("</ul>");
    }
    for c in &r.capability {
        let vals: Vec<f64> = r
            .units
            .iter()
            .filter_map(|u| {
                u.rules.iter().find(|x| x.rule == c.rule)?.axes.iter().find(|a| a.axis == c.axis).map(|a| a.value)
            })
            .collect();
        let limits: Vec<(String, f64)> = [("lower limit", c.lsl), ("upper limit", c.usl)]
            .iter()
            .filter_map(|(n, v)| v.map(|v| (format!("{n} {v}"), v)))
            .collect();
        s.push_str(&crate::html::plot::histogram(
            &format!(
                "{} {}: Cpk {} (95 %: {} – {}), n = {}",
                c.quantity,
                c.axis,
                f(c.cpk),
                f(c.cpk_low),
                f(c.cpk_high),
                c.n
            ),
            &format!("{} {} ({})", c.quantity, c.axis, c.unit),
            &vals,
            &limits,
        ));
    }
    for ch in r.control.iter().filter(|c| c.lots.len() > 1) {
        let pts: Vec<(f64, f64, Option<[f64; 2]>, bool)> = ch
            .lots
            .iter()
            .map(|p| (p.point.mean, p.point.std, p.mean_limits.map(|l| [l[0], l[2]]), p.shifted || p.spread_up))
            .collect();
        let flagged: Vec<String> = ch.flagged().map(|p| p.point.lot.clone()).collect();
        let names: Vec<String> =
            ch.lots.iter().enumerate().map(|(i, p)| format!("{} {}", i + 1, p.point.lot)).collect();
        s.push_str(&crate::html::plot::control_chart(
            &format!(
                "{} {} across lots: {}",
                ch.quantity,
                ch.axis,
                if flagged.is_empty() { "in control".to_string() } else { format!("shift at {}", flagged.join(", ")) }
            ),
            &format!("lot mean ± std ({})", ch.unit),
            &pts,
        ));
        let _ = write!(s, "<p>lots: {}</p>", esc(&names.join("; ")));
    }
}
