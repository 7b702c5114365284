//! The lots of a profile store: each batch's capability summary kept in `STORE/.lots/`
//! (one file per lot run, written atomically, never overwritten; a folder whose name starts
//! with '.' is never taken for a unit), read back in time order for the control chart of
//! every datasheet quantity across lots.

use crate::datasheet::lot::{control_chart, Capability, ChartPoint, LotPoint};
use serde::{Deserialize, Serialize};
use std::path::Path;

/// The control chart of one quantity and axis across the store's lots.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct ControlChart {
    /// Quantity.
    pub quantity: String,
    /// Axis.
    pub axis: String,
    /// Unit.
    pub unit: String,
    /// Lots, oldest first, each against the limits of the ones before it.
    pub lots: Vec<ChartPoint>,
}

impl ControlChart {
    /// The lots flagged (mean shifted or spread up).
    pub fn flagged(&self) -> impl Iterator<Item = &ChartPoint> {
        self.lots.iter().filter(|p| p.shifted || p.spread_up)
    }
}

/// The lot-summary format.
pub const LOT_FORMAT: &str = "crosscal-lot/1";

/// One lot's summary as stored.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct LotSummary {
    /// Always [`LOT_FORMAT`].
    pub format: String,
    /// Lot name.
    pub lot: String,
    /// When it was processed, RFC 3339.
    pub created_utc: String,
    /// Its capability per datasheet rule and axis.
    pub capability: Vec<Capability>,
}

/// Every readable lot summary of the store, oldest first; a lot processed more than once
/// counts with its newest summary. Unreadable files are skipped (they are not lots).
pub fn read_lots(store: &Path) -> Vec<LotSummary> {
    let Ok(rd) = std::fs::read_dir(store.join(".lots")) else { return Vec::new() };
    let mut lots: Vec<LotSummary> = rd
        .filter_map(|e| e.ok())
        .filter(|e| e.path().extension().is_some_and(|x| x == "json"))
        .filter_map(|e| std::fs::read_to_string(e.path()).ok())
        .filter_map(|t| serde_json::from_str::<LotSummary>(&t).ok())
        .filter(|l| l.format == LOT_FORMAT)
        .collect();
    let time = |l: &LotSummary| l.created_utc.parse::<jiff::Timestamp>().ok();
    lots.sort_by(|a, b| time(a).cmp(&time(b)).then_with(|| a.lot.cmp(&b.lot)));
    let mut out: Vec<LotSummary> = Vec::new();
    for l in lots {
        out.retain(|o| o.lot != l.lot);
        out.push(l);
    }
    out
}

/// Stores this lot's summary in `store/.lots/` (never overwriting).
pub fn store_lot(store: &Path, summary: &LotSummary) -> std::io::Result<()> {
    let dir = store.join(".lots");
    std::fs::create_dir_all(&dir)?;
    let stem: String = format!("{}-{}", summary.created_utc, summary.lot)
        .chars()
        .map(|c| if c.is_ascii_alphanumeric() || c == '-' || c == '_' || c == '.' { c } else { '_' })
        .collect();
    let text = serde_json::to_string_pretty(summary).map_err(std::io::Error::other)?;
    for k in 0..1000 {
        let name = if k == 0 { format!("{stem}.json") } else { format!("{stem}-{k}.json") };
        match crate::atomic::write_new(&dir.join(name), text.as_bytes()) {
            Err(e) if e.kind() == std::io::ErrorKind::AlreadyExists => continue,
            other => return other,
        }
    }
    Err(std::io::Error::other("more than 1000 lot summaries with one name"))
}

/// The control charts of the lots in `lots` (oldest first): one per quantity and axis that
/// the newest lot has.
pub fn charts(lots: &[LotSummary]) -> Vec<ControlChart> {
    let Some(last) = lots.last() else { return Vec::new() };
    let mut out: Vec<ControlChart> = Vec::new();
    for c in &last.capability {
        if out.iter().any(|x| x.quantity == c.quantity && x.axis == c.axis) {
            continue;
        }
        let series: Vec<LotPoint> = lots
            .iter()
            .filter_map(|l| {
                let p = l.capability.iter().find(|x| x.quantity == c.quantity && x.axis == c.axis)?;
                Some(LotPoint {
                    lot: l.lot.clone(),
                    created_utc: l.created_utc.clone(),
                    n: p.n,
                    mean: p.mean,
                    std: p.std,
                })
            })
            .collect();
        out.push(ControlChart {
            quantity: c.quantity.clone(),
            axis: c.axis.clone(),
            unit: c.unit.clone(),
            lots: control_chart(&series),
        });
    }
    out
}

/// Stores this lot (`lot`, its capability) in the store and returns the control charts of
/// the store's lots, this one last. With no capability (no datasheet rule), nothing.
pub fn control(store: &Path, lot: &str, capability: &[Capability]) -> (Vec<ControlChart>, Option<String>) {
    if capability.is_empty() {
        return (Vec::new(), None);
    }
    let summary = LotSummary {
        format: LOT_FORMAT.into(),
        lot: lot.to_string(),
        created_utc: crate::profile::now_utc(),
        capability: capability.to_vec(),
    };
    let warning = store_lot(store, &summary)
        .err()
        .map(|e| format!("cannot store the lot summary in {}: {e}", store.join(".lots").display()));
    let mut lots = read_lots(store);
    lots.retain(|l| l.lot != lot);
    lots.push(summary);
    (charts(&lots), warning)
}
