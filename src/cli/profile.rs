//! `crosscal profile list|show|diff`: the per-unit profile store.

use super::{format, Outcome};
use crate::errln;
use crate::{out, outln};
use crosscal::profile::{diff, history, latest, serials, Profile};
use std::path::{Path, PathBuf};

/// Options of `profile`.
#[derive(Debug, clap::Args)]
pub struct Args {
    #[command(subcommand)]
    command: Sub,
}

#[derive(Debug, clap::Subcommand)]
enum Sub {
    /// List units, or one unit's profile history (oldest first).
    #[command(after_help = "Example: crosscal profile list I1426-0042")]
    List {
        /// Unit serial (all units when absent).
        #[arg(value_parser = super::parse_serial)]
        serial: Option<String>,
        /// Profile store.
        #[arg(long, default_value = "calib-profiles")]
        store: PathBuf,
    },
    /// Show the latest profile of a unit (valid at a date with --at).
    #[command(after_help = "Example: crosscal profile show I1426-0042 --at 2026-11-01")]
    Show {
        /// Unit serial.
        #[arg(value_parser = super::parse_serial)]
        serial: String,
        /// The profile in force at this time (RFC 3339 or a date, e.g. 2026-11-23).
        #[arg(long)]
        at: Option<String>,
        /// Profile store.
        #[arg(long, default_value = "calib-profiles")]
        store: PathBuf,
        /// Print the profile JSON.
        #[arg(long)]
        json: bool,
    },
    /// Coefficient changes between two profiles in units of their standard errors (has the unit drifted?).
    #[command(after_help = "Example: crosscal profile diff old.json new.json")]
    Diff {
        /// Older profile (file).
        a: PathBuf,
        /// Newer profile (file).
        b: PathBuf,
        /// |z| above which a change counts as drift.
        #[arg(long, default_value_t = 3.0)]
        threshold: f64,
    },
    /// Export a profile to another tool: imucal, Kalibr, VINS-Fusion, ORB-SLAM3, OpenVINS, ArduPilot, PX4 or a C header.
    #[command(after_help = "Example: crosscal profile export calib-profiles/I1426-0042/P.json --to kalibr -o imu.yaml
Example: crosscal profile export calib-profiles/I1426-0042 --to openvins --openvins-model rpng -o kalibr_imu_chain.yaml
Example: crosscal profile export calib-profiles/I1426-0042 --to ardupilot --imu 2 -o imu2.param
Example: crosscal profile export calib-profiles/I1426-0042 --to c-header -o crosscal_correct.h

What the target cannot hold is listed on stderr and in the file's header.")]
    Export {
        /// Profile file, or a unit's folder of the store (its newest profile).
        profile: PathBuf,
        /// Target format: `imucal`, `kalibr` (imu.yaml), `vins-fusion` or `orb-slam3` (their IMU
        /// noise blocks: continuous-time densities from the profile's noise section), `openvins`
        /// (kalibr_imu_chain.yaml: noise, Tw/Ta/Tg and the rotations), `ardupilot` (.param:
        /// INS_ACCOFFS/INS_ACCSCAL/INS_GYROFFS, and INS_TCALn_* for temperature-bias terms),
        /// `px4` (QGroundControl .params: CAL_ACCn_*OFF, CAL_ACCn_*SCALE, CAL_GYROn_*OFF, and
        /// TC_An_*/TC_Gn_* for temperature-bias terms) or `c-header` (a C99 function correcting
        /// like crosscal's streaming corrector).
        #[arg(long)]
        to: String,
        /// Output file (never overwritten).
        #[arg(short, long)]
        output: PathBuf,
        /// IMU update rate for Kalibr, ORB-SLAM3 and OpenVINS, Hz.
        #[arg(long, default_value_t = 100.0)]
        rate_hz: f64,
        /// OpenVINS IMU model: `kalibr` or `calibrated` (Tw, Ta lower-triangular) or `rpng`
        /// (upper-triangular); the rotations carry the rest of each matrix.
        #[arg(long, default_value = "kalibr")]
        openvins_model: String,
        /// Which autopilot IMU (ArduPilot INS_, INS_ACC2/GYR2, INS_ACC3/GYR3; PX4 slot 0, 1, 2).
        #[arg(long, default_value_t = 1, value_parser = clap::value_parser!(u8).range(1..=3))]
        imu: u8,
    },
    /// Import an imucal Ferraris calibration JSON as a profile of a unit in the store.
    #[command(after_help = "Example: crosscal profile import-imucal cal.json --serial I1426-0042")]
    ImportImucal {
        /// imucal calibration JSON.
        file: PathBuf,
        /// Serial of the unit.
        #[arg(long, value_parser = super::parse_serial)]
        serial: String,
        /// Local gravity (used when imucal's input unit is g), m/s².
        #[arg(long, default_value_t = 9.80665)]
        g: f64,
        /// Profile store.
        #[arg(long, default_value = "calib-profiles")]
        store: PathBuf,
    },
}

fn list(store: &Path, serial: Option<&str>) -> anyhow::Result<()> {
    let units = match serial {
        Some(s) => vec![s.to_string()],
        None => serials(store)?,
    };
    for u in units {
        let h = history(store, &u)?;
        outln!("{u}: {} profile(s)", h.len());
        for (path, p) in h {
            match p {
                Ok(p) => outln!(
                    "  {}  model {:<8} {:>2} runs  {}{}",
                    p.created_utc,
                    p.model,
                    p.runs.len(),
                    path.display(),
                    if p.noise.is_some() { "  (noise)" } else { "" }
                ),
                Err(e) => outln!("  skipped: {}", crosscal::app::chain(&e)),
            }
        }
    }
    Ok(())
}

pub fn run(a: Args) -> anyhow::Result<Outcome> {
    match a.command {
        Sub::List { serial, store } => list(&store, serial.as_deref())?,
        Sub::Show { serial, at, store, json } => {
            let (path, p) = latest(&store, &serial, at.as_deref())?;
            if json {
                out!("{}", p.to_json());
            } else {
                outln!("unit {} profile {} (created {}, model '{}')", p.serial, path.display(), p.created_utc, p.model);
                out!("{}", format::profile_fits(&p));
                out!("{}", format::nonlinear(&p.nonlinear));
                out!("{}", format::stand(&p.stand, p.stand_base.as_ref()));
            }
        }
        Sub::Diff { a, b, threshold } => {
            let (pa, pb) = (Profile::read(&a)?, Profile::read(&b)?);
            if pa.serial != pb.serial {
                anyhow::bail!("{} is unit '{}' but {} is unit '{}'", a.display(), pa.serial, b.display(), pb.serial);
            }
            let changes = diff(&pa, &pb);
            outln!("unit {}: {} → {}", pa.serial, pa.created_utc, pb.created_utc);
            outln!("{:<22} {:>14} {:>14} {:>9}", "coefficient", "before", "after", "z");
            let mut drifted = Vec::new();
            for c in &changes {
                let z = c.z.map_or("-".to_string(), |z| format!("{z:+.2}"));
                outln!(
                    "{:<22} {:>14} {:>14} {:>9}  {}",
                    c.name,
                    format::num(c.before),
                    format::num(c.after),
                    z,
                    c.unit
                );
                if c.z.is_some_and(|z| z.abs() > threshold) {
                    drifted.push(c.name.as_str());
                }
            }
            if drifted.is_empty() {
                outln!("no coefficient moved by more than {threshold} standard errors");
            } else {
                outln!("DRIFTED (|z| > {threshold}): {}", drifted.join(", "));
                return Ok(Outcome::CheckFailed);
            }
        }
        Sub::Export { profile, to, output, rate_hz, openvins_model, imu } => {
            export(&profile, &to, &output, Target { rate_hz, openvins_model: &openvins_model, imu })?
        }
        Sub::ImportImucal { file, serial, g, store } => {
            let text =
                crosscal::atomic::read_text(&file).map_err(|e| anyhow::anyhow!("reading {}: {e}", file.display()))?;
            let p = crosscal::profile::interop::from_imucal(&file, &text, &serial, g)?;
            let path = crosscal::profile::save(&p, &store)?;
            outln!("imported {} as {}", file.display(), path.display());
        }
    }
    Ok(Outcome::Ok)
}

/// The target's settings besides its name.
pub(super) struct Target<'a> {
    pub(super) rate_hz: f64,
    pub(super) openvins_model: &'a str,
    pub(super) imu: u8,
}

fn export(profile: &Path, to: &str, output: &Path, t: Target<'_>) -> anyhow::Result<()> {
    let p = super::read_profile(profile)?;
    let (text, lost) = export_text(&p, to, t)?;
    crosscal::atomic::write_new(output, text.as_bytes())
        .map_err(|e| anyhow::anyhow!("writing {} (never overwritten): {e}", output.display()))?;
    outln!("exported {} to {} ({to})", profile.display(), output.display());
    for l in lost {
        errln!("not represented: {l}");
    }
    Ok(())
}

/// The text of `p` in the format `to` reads, and what it cannot hold.
pub(super) fn export_text(p: &Profile, to: &str, t: Target<'_>) -> anyhow::Result<(String, Vec<String>)> {
    use crosscal::profile::{autopilot, estimators, interop, openvins};
    let imu =
        autopilot::AutopilotImu::new(t.imu).ok_or_else(|| anyhow::anyhow!("--imu {}: expected 1, 2 or 3", t.imu))?;
    let (text, lost) = match to {
        "imucal" => {
            let (v, lost) = interop::to_imucal(p);
            (serde_json::to_string_pretty(&v)? + "\n", lost)
        }
        "kalibr" => interop::to_kalibr(p, t.rate_hz),
        "vins-fusion" => estimators::to_vins_fusion(p, p.g_m_s2),
        "orb-slam3" => estimators::to_orb_slam3(p, t.rate_hz),
        "openvins" => {
            let model = openvins::OpenVinsModel::parse(t.openvins_model).ok_or_else(|| {
                anyhow::anyhow!("--openvins-model {}: expected kalibr, rpng or calibrated", t.openvins_model)
            })?;
            openvins::to_openvins(p, model, t.rate_hz)
        }
        "ardupilot" => autopilot::to_ardupilot(p, imu),
        "px4" => autopilot::to_px4(p, imu),
        "c-header" => crosscal::correct::to_c_header(p)?,
        other => anyhow::bail!(
            "--to {other}: expected imucal, kalibr, vins-fusion, orb-slam3, openvins, ardupilot, px4 or c-header"
        ),
    };
    Ok((text, lost))
}
