//! How each coefficient of one output channel enters that channel's least-squares problem,
//! as a combination of the sensor's accumulated design columns.
//!
//! Most coefficients multiply one column. Effects on the sensing element's input (lever
//! arm, hysteresis: [`crate::model::Side::Input`]) make the model bilinear: channel i sees
//! `u_i = K_i·(x + Σ_t θ_t c_t) + …` with `c_t` the input perturbation of coefficient θ_t
//! (its components are columns of the design). It is solved by Gauss–Newton from the
//! accumulated R factor alone: at (K⁰, θ⁰) the linearised problem has the columns
//! `x_j + Σ_t θ⁰_t c_tj` for `K_ij`, `Σ_j K⁰_ij c_tj` for `θ_t`, and the known part
//! `−Σ_tj K⁰_ij θ⁰_t c_tj` moved to the output, so every column is a linear combination of
//! R's columns and no data pass is repeated. Without input-side terms the plan is one
//! column per coefficient and one solve.

use super::linear::Columns;
use super::CoefStatus;
use crate::model::{Role, TermRef};

/// The columns of one channel's problem: per fitted coefficient (in `fitted` order) its
/// column as (design column, weight) pairs, and the known contribution to subtract from
/// the output column.
#[derive(Debug, Clone, PartialEq)]
pub(crate) struct ChannelPlan {
    /// Per fitted coefficient: its column.
    pub columns: Vec<Vec<(usize, f64)>>,
    /// Known contribution (fixed coefficients, the Gauss–Newton offset).
    pub offset: Vec<(usize, f64)>,
    /// Whether the channel has input-side coefficients (the problem is bilinear).
    pub bilinear: bool,
}

/// Row `ch` of the scale matrix from the current values (the identity row when the model
/// has no scale terms).
fn scale_row(terms: &[TermRef<'_>], values: &[f64], ch: usize) -> [f64; 3] {
    let k = crate::model::scale_matrix(terms, values);
    k[ch]
}

/// The plan of channel `ch` at the current `values` (fitted coefficients at their current
/// estimates, held ones at their values).
pub(crate) fn channel_plan(
    terms: &[TermRef<'_>],
    cols: &Columns,
    values: &[f64],
    status: &[CoefStatus],
    fitted: &[usize],
    ch: usize,
) -> ChannelPlan {
    let fits = |ti: usize| status[ti] == CoefStatus::Fitted;
    let mine = |ti: usize| terms[ti].term.channel == ch;
    let inputs: Vec<usize> = (0..terms.len()).filter(|&ti| mine(ti) && !cols.inputs[ti].is_empty()).collect();
    let k0 = scale_row(terms, values, ch);
    let bilinear = !inputs.is_empty();
    let columns = fitted
        .iter()
        .map(|&ti| {
            let own = vec![(cols.of_term[ti], 1.0)];
            match terms[ti].term.role {
                Role::Scale(j) if bilinear => {
                    let mut c = own;
                    for &t in &inputs {
                        c.extend(cols.inputs[t].iter().filter(|(a, _)| *a == j).map(|&(_, col)| (col, values[t])));
                    }
                    c
                }
                _ if !cols.inputs[ti].is_empty() => cols.inputs[ti].iter().map(|&(j, col)| (col, k0[j])).collect(),
                _ => own,
            }
        })
        .collect();
    let mut offset = Vec::new();
    for (ti, t) in terms.iter().enumerate() {
        if !mine(ti) || fits(ti) || values[ti] == 0.0 {
            continue;
        }
        match t.term.role {
            // A held scale term: K_ij (x_j + Σ θ c_j) for the held input terms' θ (fitted
            // ones carry K_ij in their own column).
            Role::Scale(j) => {
                offset.push((cols.of_term[ti], values[ti]));
                for &u in inputs.iter().filter(|&&u| !fits(u)) {
                    offset.extend(
                        cols.inputs[u].iter().filter(|(a, _)| *a == j).map(|&(_, col)| (col, values[ti] * values[u])),
                    );
                }
            }
            // A held input term enters through the scale terms' columns (fitted) or the held
            // scale terms above; without any scale term, through the nominal identity row.
            _ if !cols.inputs[ti].is_empty() => {
                if !terms.iter().any(|x| matches!(x.term.role, Role::Scale(_))) {
                    offset.extend(cols.inputs[ti].iter().map(|&(j, col)| (col, values[ti] * k0[j])));
                }
            }
            _ => offset.push((cols.of_term[ti], values[ti])),
        }
    }
    // The Gauss–Newton offset −K⁰θ⁰c for every (fitted K_ij, fitted θ_t) pair.
    for &t in inputs.iter().filter(|&&t| fits(t)) {
        for &(j, col) in &cols.inputs[t] {
            let scale_fitted =
                terms.iter().enumerate().any(|(s, x)| mine(s) && fits(s) && x.term.role == Role::Scale(j));
            if scale_fitted && values[t] != 0.0 {
                offset.push((col, -k0[j] * values[t]));
            }
        }
    }
    ChannelPlan { columns, offset, bilinear }
}

/// The prediction of every channel at `values`, as (channel, design column, weight)
/// triples in term order (input-side terms expanded over their components with the scale
/// matrix): `u_i = Σ w · column` over the triples of channel i.
pub(crate) fn prediction(terms: &[TermRef<'_>], cols: &Columns, values: &[f64]) -> Vec<(usize, usize, f64)> {
    let k = crate::model::scale_matrix(terms, values);
    let mut out = Vec::new();
    for (ti, t) in terms.iter().enumerate() {
        let v = values[ti];
        if v == 0.0 {
            continue;
        }
        let i = t.term.channel;
        if cols.inputs[ti].is_empty() {
            out.push((i, cols.of_term[ti], v));
        } else {
            out.extend(cols.inputs[ti].iter().map(|&(j, col)| (i, col, v * k[i][j])));
        }
    }
    out
}
