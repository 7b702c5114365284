//! `crosscal effects`: the catalogue, readable in the tool (and as JSON for the guide).

use super::Outcome;
use crate::outln;
use crosscal::model::{catalog, CatalogEffect, Side};

/// Options of `effects`.
#[derive(Debug, clap::Args)]
#[command(after_help = "Example: crosscal effects accel-lever-arm")]
pub struct Args {
    /// Show one effect only.
    id: Option<String>,
    /// Print the catalogue as JSON (id, sensor, kind, side, inputs, coefficients, explanation).
    #[arg(long)]
    json: bool,
}

/// One effect as `--json` writes it.
fn to_json(e: &CatalogEffect) -> serde_json::Value {
    let i = e.inputs();
    let inputs: Vec<&str> = [
        (i.rate, "rate"),
        (i.ang_accel, "angular_acceleration"),
        (i.force, "specific_force"),
        (i.time, "time"),
        (i.temperature, "temperature"),
    ]
    .iter()
    .filter(|x| x.0)
    .map(|x| x.1)
    .collect();
    serde_json::json!({
        "id": e.id(),
        "sensor": e.sensor().map_or("both".to_string(), |s| s.to_string()),
        "kind": if matches!(e, CatalogEffect::Linear(_)) { "linear" } else { "nonlinear" },
        "side": if e.side() == Side::Input { "input" } else { "output" },
        "inputs": inputs,
        "coefficients": e.coefficients(),
        "explain": e.explain(),
    })
}

pub fn run(a: Args) -> anyhow::Result<Outcome> {
    let chosen: Vec<CatalogEffect> =
        catalog().into_iter().filter(|e| a.id.as_deref().is_none_or(|id| id == e.id())).collect();
    if chosen.is_empty() {
        anyhow::bail!("unknown effect '{}': run `crosscal effects` for the list", a.id.unwrap_or_default());
    }
    if a.json {
        let list: Vec<serde_json::Value> = chosen.iter().map(to_json).collect();
        outln!("{}", serde_json::to_string_pretty(&list)?);
        return Ok(Outcome::Ok);
    }
    for e in &chosen {
        let sensor = e.sensor().map_or("gyro and accel".to_string(), |s| s.to_string());
        let side = if e.side() == Side::Input { "acts on the input, before the scale matrix" } else { "output" };
        match e {
            CatalogEffect::Linear(_) => outln!("{} ({sensor}; linear; {side})", e.id()),
            CatalogEffect::Nonlinear(_) => {
                outln!("{} ({sensor}; nonlinear, fitted by variable projection; {side})", e.id())
            }
        }
        let names: Vec<String> = e
            .coefficients()
            .iter()
            .map(|c| match &c.regressor {
                Some(r) => format!("{} [{}] × {r}", c.name, c.unit),
                None => format!("{} [{}]", c.name, c.unit),
            })
            .collect();
        outln!("  coefficients: {}", names.join(", "));
        if e.needs_temperature() {
            outln!("  needs: a temp column or a run temperature_c");
        }
        outln!("  {}\n", e.explain());
    }
    Ok(Outcome::Ok)
}
