//! `crosscal effects`: the catalogue, readable in the tool.

use super::Outcome;
use crate::outln;
use crosscal::model::{catalog, nonlinear_catalog};

/// Options of `effects`.
#[derive(Debug, clap::Args)]
pub struct Args {
    /// Show one effect only.
    id: Option<String>,
}

pub fn run(a: Args) -> anyhow::Result<Outcome> {
    let mut shown = 0;
    for e in catalog() {
        if a.id.as_deref().is_some_and(|id| id != e.id()) {
            continue;
        }
        shown += 1;
        outln!("{} ({}; linear)", e.id(), e.sensor());
        let names: Vec<String> = e.terms().iter().map(|t| format!("{} [{}] × {}", t.name, t.unit, t.key)).collect();
        outln!("  coefficients: {}", names.join(", "));
        if e.needs_temperature() {
            outln!("  needs: a temp column or a run temperature_c");
        }
        outln!("  {}\n", e.explain());
    }
    for e in nonlinear_catalog() {
        if a.id.as_deref().is_some_and(|id| id != e.id()) {
            continue;
        }
        shown += 1;
        let sensor = e.sensor().map_or("gyro and accel".to_string(), |s| s.to_string());
        outln!("{} ({sensor}; nonlinear, fitted by variable projection)", e.id());
        let names: Vec<String> = e.params().iter().map(|p| format!("{} [{}]", p.name, p.unit)).collect();
        outln!("  parameters: {}", names.join(", "));
        outln!("  {}\n", e.explain());
    }
    if shown == 0 {
        anyhow::bail!("unknown effect '{}': run `crosscal effects` for the list", a.id.unwrap_or_default());
    }
    Ok(Outcome::Ok)
}
