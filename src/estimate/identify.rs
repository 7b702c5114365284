//! Identifiability: naming the coefficients a set of runs cannot determine, and the run
//! that would.

use crate::model::{Key, TermRef};
use crate::units::AXES;
use serde::{Deserialize, Serialize};

/// A combination of coefficients the runs cannot separate.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Unidentifiable {
    /// Output channel.
    pub axis: char,
    /// The coefficient held at its nominal value.
    pub held: String,
    /// Value it was held at.
    pub held_at: f64,
    /// The coefficients in the lost combination with their weights (column-scaled).
    pub combination: Vec<(String, f64)>,
    /// What is wrong, in words.
    pub reason: String,
    /// The kind of run that would identify it.
    pub remedy: String,
}

/// Two estimates that move together.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Correlation {
    /// First coefficient.
    pub a: String,
    /// Second coefficient.
    pub b: String,
    /// Correlation coefficient of the estimates.
    pub correlation: f64,
}

/// A regressor that is zero in every run.
pub fn zero_column(t: &TermRef<'_>, ch: usize) -> Unidentifiable {
    let (reason, remedy) = if let Key::AngAccel(j) = t.term.key {
        let axis = AXES[usize::from(j)];
        (
            format!("the angular acceleration about the sensor's {axis} axis (ε_{axis}) is zero in every run"),
            if axis == 'z' {
                "ε_z ≡ 0 in stand axes for conic motion: add runs with the unit re-mounted so that its z axis lies along a horizontal stand axis, e.g. mount [\"+y\", \"+z\", \"+x\"]".to_string()
            } else {
                format!("add conic runs with the sensor's {axis} axis off the stand's z axis (e.g. the nominal mount)")
            },
        )
    } else {
        let what = match t.term.key {
            Key::Own(..) => format!("the regressor of {}", t.term.name),
            k => format!("its regressor {k}"),
        };
        (
            format!("{what} is zero in every run"),
            "add a run that excites it: a re-mount, another cone angle or a static pose".to_string(),
        )
    };
    Unidentifiable {
        axis: AXES[ch],
        held: t.term.name.clone(),
        held_at: t.term.nominal,
        combination: vec![(t.term.name.clone(), 1.0)],
        reason,
        remedy,
    }
}

/// Describes a lost combination (right singular vector `combo` over `fitted`) and picks
/// the coefficient to hold: among those with a large weight, the highest drop priority.
/// Returns the report and the position in `fitted` to drop.
pub fn lost_combination(terms: &[TermRef<'_>], fitted: &[usize], combo: &[f64], ch: usize) -> (Unidentifiable, usize) {
    let big = combo.iter().map(|v| v.abs()).fold(0.0, f64::max);
    let members: Vec<usize> = (0..fitted.len()).filter(|&a| combo[a].abs() >= 0.2 * big).collect();
    let drop_at = members
        .iter()
        .copied()
        .max_by(|&a, &b| {
            let pa = terms[fitted[a]].term.drop_priority;
            let pb = terms[fitted[b]].term.drop_priority;
            pa.cmp(&pb).then(combo[a].abs().total_cmp(&combo[b].abs()))
        })
        .unwrap_or(0);
    let keys: Vec<Key> = members.iter().map(|&a| terms[fitted[a]].term.key).collect();
    let names: Vec<String> = members.iter().map(|&a| terms[fitted[a]].term.name.clone()).collect();
    let has = |f: fn(&Key) -> bool| keys.iter().any(f);
    let (reason, remedy) = if has(|k| *k == Key::One) && keys.len() > 1 {
        (
            format!(
                "{} are constant together within every run (a bias against an input component that does not vary)",
                names.join(", ")
            ),
            "add a run at another rate, the opposite direction or another cone angle, or re-mount the unit".to_string(),
        )
    } else if has(|k| matches!(k, Key::AngAccel(_))) && has(|k| matches!(k, Key::Rate(_))) {
        (
            format!(
                "{}: within a conic run ε is a fixed multiple of ω (ε_x = ω_s·ω_y, ε_y = −ω_s·ω_x)",
                names.join(", ")
            ),
            "add runs at another stand rate or in the opposite direction".to_string(),
        )
    } else {
        (
            format!("the runs excite {} only in a fixed proportion", names.join(", ")),
            "add a run that excites these inputs differently: another rate, the opposite direction, a second cone angle or a re-mount".to_string(),
        )
    };
    let report = Unidentifiable {
        axis: AXES[ch],
        held: terms[fitted[drop_at]].term.name.clone(),
        held_at: terms[fitted[drop_at]].term.nominal,
        combination: members.iter().map(|&a| (terms[fitted[a]].term.name.clone(), combo[a])).collect(),
        reason,
        remedy,
    };
    (report, drop_at)
}
