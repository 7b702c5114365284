//! A self-contained HTML report (inline SVG, no scripts, no network) of a diagnosis:
//! residual versus time, versus cone phase (binned) and harmonic amplitudes per channel.

use super::{ChannelReport, Diagnosis, RunResiduals, Verdict, HARMONICS};
use crate::html::plot::{bars, lines, loglog};
use crate::html::{esc, page_start, slug, Figure};
use crate::session::MotionSpec;
use crate::stats::systematic;
use crate::units::SensorKind;
use std::fmt::Write;

const CHANNELS: [&str; 6] = ["gyro x", "gyro y", "gyro z", "accel x", "accel y", "accel z"];

fn unit(c: usize) -> (&'static str, f64) {
    let sensor = if c < 3 { SensorKind::Gyro } else { SensorKind::Accel };
    sensor.display_unit()
}

/// Residual of channel `c` against time, runs end to end, averaged in buckets (≤ 1500 points).
fn vs_time(res: &[RunResiduals], c: usize) -> Vec<(f64, f64)> {
    let (_, k) = unit(c);
    let total: usize = res.iter().map(|r| r.r[c].len()).sum();
    let bucket = total.div_ceil(1500).max(1);
    let mut out = Vec::with_capacity(1500);
    let mut offset = 0.0;
    for r in res {
        let t0 = r.t_s.first().copied().unwrap_or(0.0);
        for (ch, tt) in r.r[c].chunks(bucket).zip(r.t_s.chunks(bucket)) {
            let m = ch.iter().sum::<f64>() / ch.len() as f64;
            out.push((offset + tt[0] - t0, m * k));
        }
        offset += r.t_s.last().copied().unwrap_or(t0) - t0;
    }
    out
}

/// Welch PSD of channel `c`'s residual averaged over the runs that share the first run's
/// sampling and length (display units²/Hz), and the white-noise level of the same
/// variance (2σ²/fs).
fn spectrum(res: &[RunResiduals], c: usize) -> Vec<(String, Vec<(f64, f64)>)> {
    let (_, k) = unit(c);
    let mut acc: Option<crate::stats::spectrum::Psd> = None;
    let (mut count, mut var, mut fs_first) = (0usize, 0.0, 0.0);
    for r in res {
        let n = r.r[c].len();
        let span = r.t_s.last().copied().unwrap_or(0.0) - r.t_s.first().copied().unwrap_or(0.0);
        if n < 128 || span <= 0.0 {
            continue;
        }
        let fs = (n - 1) as f64 / span;
        let x: Vec<f64> = r.r[c].iter().map(|v| v * k).collect();
        let Some(p) = crate::stats::spectrum::welch(&x, fs, (n / 8).clamp(64, 8192)) else { continue };
        match &mut acc {
            None => {
                fs_first = fs;
                acc = Some(p);
            }
            Some(a) if a.power.len() == p.power.len() && (a.df_hz / p.df_hz - 1.0).abs() < 1e-3 => {
                a.power.iter_mut().zip(&p.power).for_each(|(s, v)| *s += v);
            }
            Some(_) => continue,
        }
        count += 1;
        var += x.iter().map(|v| v * v).sum::<f64>() / n as f64;
    }
    let Some(a) = acc else { return Vec::new() };
    let pts: Vec<(f64, f64)> =
        a.power.iter().enumerate().skip(1).map(|(i, p)| (i as f64 * a.df_hz, p / count as f64)).collect();
    let white = 2.0 * var / count as f64 / fs_first;
    let fmax = pts.last().map_or(1.0, |p| p.0);
    vec![
        ("residual (Welch, mean over runs)".to_string(), pts),
        ("white noise of the same variance".to_string(), vec![(a.df_hz, white), (fmax, white)]),
    ]
}

/// Mean residual of channel `c` in 36 cone-phase bins over all conic runs.
fn vs_phase(res: &[RunResiduals], c: usize) -> Vec<(f64, f64)> {
    let (_, k) = unit(c);
    let mut sum = [0.0; 36];
    let mut cnt = [0usize; 36];
    for r in res {
        if let Some(th) = &r.theta {
            for (v, t) in r.r[c].iter().zip(th) {
                let b = ((t.to_degrees() / 10.0) as usize).min(35);
                sum[b] += v;
                cnt[b] += 1;
            }
        }
    }
    (0..36).filter(|&b| cnt[b] > 0).map(|b| (b as f64 * 10.0 + 5.0, sum[b] / cnt[b] as f64 * k)).collect()
}

/// RMS over runs of each cone harmonic's amplitude in channel `c`.
fn harmonics(res: &[RunResiduals], motions: &[&MotionSpec], c: usize) -> Vec<(String, f64)> {
    let (_, k) = unit(c);
    let mut acc = [0.0; HARMONICS + 1];
    let mut n = 0usize;
    for (r, m) in res.iter().zip(motions) {
        let s = systematic(&r.r[c], &r.t_s, crate::motion::cone_phase(m), HARMONICS);
        if s.amplitudes.len() == HARMONICS + 1 {
            for (a, v) in acc.iter_mut().zip(&s.amplitudes) {
                *a += v * v;
            }
            n += 1;
        }
    }
    (0..=HARMONICS).map(|h| (format!("{h}"), (acc[h] / n.max(1) as f64).sqrt() * k)).collect()
}

fn channel_table(title: &str, c: &[ChannelReport]) -> String {
    let mut s = format!(
        "<h3>{}</h3><table><tr><th>channel</th><th>residual RMS</th><th>noise floor</th><th>systematic RMS</th><th></th></tr>",
        esc(title)
    );
    for (i, r) in c.iter().enumerate() {
        let (u, k) = unit(i);
        let _ = write!(
            s,
            "<tr><td>{}</td><td>{:.4e} {u}</td><td>{:.4e} {u}</td><td>{:.4e} {u}</td><td>{}</td></tr>",
            CHANNELS[i],
            r.residual_rms * k,
            r.noise_floor * k,
            r.systematic_rms * k,
            if r.systematic { "<b>systematic</b>" } else { "noise" }
        );
    }
    s.push_str("</table>");
    s
}

/// The HTML report of the diagnosis of the session at `session` (its manifest, for the
/// `Fit it with:` command). `after` are the residuals at the end of the ladder, when effects
/// were added.
pub fn html(
    title: &str,
    session: &str,
    d: &Diagnosis,
    before: &[RunResiduals],
    after: Option<&[RunResiduals]>,
    motions: &[&MotionSpec],
) -> String {
    let mut s = page_start(title);
    let verdict = match d.verdict {
        Verdict::Adequate => "The model is adequate: the residuals are at the noise floor; nothing to add.".to_string(),
        Verdict::Explained if d.proposal.is_empty() => {
            "The stand explains the residual; with it, the unit's model is adequate.".to_string()
        }
        Verdict::Explained => format!(
            "Add {}: the residual then sits at the noise floor. Fit it with: <code>{}</code>",
            d.proposal.join(", "),
            esc(&d.fit_command(session))
        ),
        Verdict::Unexplained => {
            format!(
                "A systematic residual remains that no catalogued effect explains:<br>{}",
                d.unexplained.iter().map(|u| esc(u)).collect::<Vec<_>>().join("<br>")
            )
        }
    };
    let _ = write!(s, "<p class=\"verdict\">{verdict}</p>");
    for f in &d.stand {
        let _ = write!(s, "<p class=\"verdict\">{}</p>", esc(&f.message));
    }
    for w in &d.warnings {
        let _ = write!(s, "<p>warning: {}</p>", esc(w));
    }
    s.push_str(&channel_table(&format!("model '{}'", d.model), &d.channels));
    if !d.candidates.is_empty() {
        s.push_str("<h3>candidate effects</h3><table><tr><th>effect</th><th>params</th><th>RSS change</th><th>p-value</th><th>ΔBIC</th><th>left-out-run gain (χ²)</th><th>accepted, or why not</th><th>explanation</th></tr>");
        for c in d.candidates.iter().take(12) {
            let change = if c.rss_before > 0.0 { 100.0 * (c.rss_after / c.rss_before - 1.0) } else { 0.0 };
            let _ = write!(
                s,
                "<tr><td>{}</td><td>{}</td><td>{change:.2} %</td><td>{:.2e}</td><td>{:.1}</td><td>{:.1}</td><td style=\"text-align:left\">{}</td><td style=\"text-align:left\">{}</td></tr>",
                esc(&c.effect),
                c.added_params,
                c.p_value,
                c.delta_bic,
                c.evidence.heldout_gain,
                esc(c.rejected.as_deref().unwrap_or("qualifies")),
                esc(&c.explanation)
            );
        }
        s.push_str("</table>");
    }
    if d.noise.iter().any(|n| n.bias_instability > 0.0 || n.random_walk > 0.0) {
        s.push_str("<h3>slow wander (noise, not a systematic residual)</h3><table><tr><th>channel</th><th>bias instability</th><th>random walk (per √s)</th></tr>");
        for (i, n) in d.noise.iter().enumerate() {
            let (u, k) = unit(i);
            let _ = write!(
                s,
                "<tr><td>{}</td><td>{:.3e} {u}</td><td>{:.3e} {u}</td></tr>",
                CHANNELS[i.min(5)],
                n.bias_instability * k,
                n.random_walk * k
            );
        }
        s.push_str("</table>");
    }
    if !d.tried.is_empty() {
        s.push_str(
            "<h3>catalogued effects tried (none brings the residual to the noise floor, none is proposed)</h3><ul>",
        );
        for t in &d.tried {
            let _ = write!(s, "<li>{}</li>", esc(t));
        }
        s.push_str("</ul>");
    }
    for sh in &d.shapes {
        let _ = write!(s, "<h3>shape: {}</h3>", esc(&sh.words));
        if let Some(t) = &sh.effect_toml {
            let _ = write!(s, "<p>as your own effect (paste into an effects file):</p><pre>{}</pre>", esc(t));
        }
        for f in shape_figures(sh) {
            s.push_str(&f.svg);
        }
    }
    if !d.lines.is_empty() {
        s.push_str("<h3>narrow lines in the residual spectrum</h3><ul>");
        for l in &d.lines {
            let _ = write!(s, "<li>{}</li>", esc(&l.describe()));
        }
        s.push_str("</ul>");
    }
    for (i, st) in d.steps.iter().enumerate() {
        s.push_str(&channel_table(
            &format!("step {}: add {} (ΔBIC {:.1})", i + 1, st.effect, st.score.delta_bic),
            &st.channels,
        ));
    }
    for (c, figs) in figures(before, after, motions).chunks(4).enumerate() {
        let _ = write!(s, "<h2>{}</h2>", CHANNELS[c.min(5)]);
        for f in figs {
            s.push_str(&f.svg);
        }
    }
    s.push_str("</body></html>\n");
    s
}

/// The partial-residual plots of a shape (the three most departing variables): bin means
/// and the band of ±2 standard errors around zero.
pub fn shape_figures(sh: &super::shape::Shape) -> Vec<Figure> {
    let (u, k) = sh.sensor.display_unit();
    sh.plots
        .iter()
        .take(3)
        .map(|p| {
            let kx = p.to_unit;
            let x_label =
                if p.unit.is_empty() { format!("{} (index)", p.label) } else { format!("{} ({})", p.label, p.unit) };
            let mean: Vec<(f64, f64)> = p.bins.iter().map(|b| (b.x * kx, b.mean * k)).collect();
            let hi: Vec<(f64, f64)> = p.bins.iter().map(|b| (b.x * kx, 2.0 * b.se * k)).collect();
            let lo: Vec<(f64, f64)> = p.bins.iter().map(|b| (b.x * kx, -2.0 * b.se * k)).collect();
            let name = format!("{} {}", sh.sensor, sh.axis);
            Figure {
                stem: format!("{}-shape-{}", slug(&name), slug(&p.variable)),
                svg: lines(
                    &format!("{name}: residual against {} (bin means)", p.label),
                    &x_label,
                    &format!("residual ({u})"),
                    &[("bin mean".to_string(), mean), ("+2 SE".to_string(), hi), ("−2 SE".to_string(), lo)],
                ),
            }
        })
        .collect()
}

/// The report's plots, four per channel in channel order (gyro x … accel z): residual
/// against time and against cone phase (before and after the added effects), its spectrum,
/// and its cone-harmonic amplitudes.
pub fn figures(before: &[RunResiduals], after: Option<&[RunResiduals]>, motions: &[&MotionSpec]) -> Vec<Figure> {
    let mut out = Vec::with_capacity(24);
    for c in 0..6 {
        let (u, _) = unit(c);
        let name = CHANNELS[c];
        let fig = |kind: &str, svg: String| Figure { stem: format!("{}-{kind}", slug(name)), svg };
        let mut t = vec![("model".to_string(), vs_time(before, c))];
        let mut p = vec![("model".to_string(), vs_phase(before, c))];
        if let Some(a) = after {
            t.push(("with added effects".to_string(), vs_time(a, c)));
            p.push(("with added effects".to_string(), vs_phase(a, c)));
        }
        out.push(fig(
            "time",
            lines(
                &format!("{name}: residual vs time (runs end to end, bucket means)"),
                "time, runs end to end (s)",
                &format!("residual ({u})"),
                &t,
            ),
        ));
        out.push(fig(
            "phase",
            lines(
                &format!("{name}: residual vs cone phase (10° bins, conic runs)"),
                "cone phase (deg)",
                &format!("residual ({u})"),
                &p,
            ),
        ));
        let spec = spectrum(after.unwrap_or(before), c);
        let spec_svg = if spec.is_empty() {
            String::new()
        } else {
            loglog(
                &format!("{name}: residual spectrum (lines stand out of the continuum)"),
                "frequency (Hz)",
                &format!("PSD (({u})²/Hz)"),
                &[],
                &spec,
            )
        };
        out.push(fig("spectrum", spec_svg));
        out.push(fig(
            "harmonics",
            bars(
                &format!("{name}: residual cone harmonics (RMS over runs)"),
                "harmonic of the cone frequency",
                &format!("amplitude ({u})"),
                &harmonics(before, motions, c),
            ),
        ));
    }
    out
}
