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

use super::{CoefStatus, FitRun};
use crate::model::{Role, State, TermRef};
use crate::units::SensorKind;
use faer::Mat;

/// Samples per block handed to the estimator ([`Samples`]).
pub(crate) const BLOCK: usize = 256;

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

/// Regressor columns of one sensor: unique keys, with the term that evaluates each.
pub(crate) struct Columns {
    /// Index (into the sensor's term list) of the term that evaluates column c.
    pub source: Vec<usize>,
    /// Column of each term.
    pub of_term: Vec<usize>,
    /// Per term on the input side: (input axis, column) of each component of its input
    /// perturbation (empty for output-side terms); see [`super::channel`].
    pub inputs: Vec<Vec<(usize, usize)>>,
}

impl Columns {
    pub(crate) fn new(terms: &[crate::model::TermRef<'_>]) -> Self {
        let mut keys: Vec<crate::model::Key> = Vec::new();
        let mut source = Vec::new();
        let mut of_term = Vec::with_capacity(terms.len());
        for (ti, t) in terms.iter().enumerate() {
            match keys.iter().position(|k| *k == t.term.key) {
                Some(c) => of_term.push(c),
                None => {
                    keys.push(t.term.key);
                    source.push(ti);
                    of_term.push(keys.len() - 1);
                }
            }
        }
        let inputs = terms
            .iter()
            .map(|t| {
                t.input_components()
                    .into_iter()
                    .filter_map(|(j, k)| {
                        let ti = terms.iter().position(|u| std::ptr::addr_eq(u.effect, t.effect) && u.index == k)?;
                        Some((j, of_term[ti]))
                    })
                    .collect()
            })
            .collect();
        Self { source, of_term, inputs }
    }

    pub(crate) fn len(&self) -> usize {
        self.source.len()
    }

    /// Design row of sample k: the regressor columns, then the sensor's three outputs.
    #[inline]
    pub(crate) fn fill_row(
        &self,
        terms: &[crate::model::TermRef<'_>],
        run: &FitRun<'_>,
        sensor: SensorKind,
        k: usize,
        row: &mut [f64],
    ) {
        self.fill_state_row(terms, &run.state(k), &run.output(sensor, k), row);
    }

    /// Design columns of a block of samples, column-major with stride [`BLOCK`]: regressor
    /// column c at `cols[c·BLOCK..][..n]`, then the sensor's three outputs.
    pub(crate) fn fill_block(
        &self,
        terms: &[crate::model::TermRef<'_>],
        states: &[State],
        outputs: &[[f64; 3]],
        cols: &mut [f64],
    ) {
        let n = states.len();
        for (c, &ti) in self.source.iter().enumerate() {
            terms[ti].regressors(states, &mut cols[c * BLOCK..c * BLOCK + n]);
        }
        let q = self.source.len();
        for ch in 0..3 {
            for (o, u) in cols[(q + ch) * BLOCK..(q + ch) * BLOCK + n].iter_mut().zip(outputs) {
                *o = u[ch];
            }
        }
    }

    /// The first sample of a filled block (see [`Columns::fill_block`]) where a user
    /// effect's column is not finite: (effect id, state).
    pub(crate) fn non_finite_user_column(
        &self,
        terms: &[crate::model::TermRef<'_>],
        states: &[State],
        cols: &[f64],
    ) -> Option<(&'static str, State)> {
        let n = states.len();
        for (c, &ti) in self.source.iter().enumerate() {
            if terms[ti].effect.user_definition().is_none() {
                continue;
            }
            if let Some(k) = cols[c * BLOCK..c * BLOCK + n].iter().position(|v| !v.is_finite()) {
                return Some((terms[ti].effect.id(), states[k]));
            }
        }
        None
    }

    /// Design row at a state with the sensor's output.
    #[inline]
    pub(crate) fn fill_state_row(
        &self,
        terms: &[crate::model::TermRef<'_>],
        s: &State,
        output: &[f64; 3],
        row: &mut [f64],
    ) {
        for (c, &ti) in self.source.iter().enumerate() {
            row[c] = terms[ti].regressor(s);
        }
        row[self.source.len()..].copy_from_slice(output);
    }
}

/// The channel's reduced problem `[R_s | z; 0 | ρ]` ((q+1) × (q+1)) from the accumulated R:
/// QR of the plan's columns of R beside the output column minus the plan's known part.
pub(crate) fn reduce(r: &Mat<f64>, plan: &ChannelPlan, p: usize, ch: usize) -> Mat<f64> {
    let rows = r.nrows();
    let q = plan.columns.len();
    let mut m = Mat::<f64>::zeros(rows, q + 1);
    for (a, col) in plan.columns.iter().enumerate() {
        match col.as_slice() {
            // One column as it is (the same bits as before input-side effects existed).
            [(c, w)] if w.to_bits() == 1.0f64.to_bits() => {
                for i in 0..rows {
                    m[(i, a)] = r[(i, *c)];
                }
            }
            _ => {
                for &(c, w) in col {
                    for i in 0..rows {
                        m[(i, a)] += w * r[(i, c)];
                    }
                }
            }
        }
    }
    for i in 0..rows {
        m[(i, q)] = r[(i, p + ch)];
    }
    for &(c, w) in &plan.offset {
        for i in 0..rows {
            m[(i, q)] -= w * r[(i, c)];
        }
    }
    let qr = m.as_ref().qr();
    let mut out = Mat::<f64>::zeros(q + 1, q + 1);
    let rr = qr.thin_R();
    for i in 0..rr.nrows().min(q + 1) {
        for j in i..q + 1 {
            out[(i, j)] = rr[(i, j)];
        }
    }
    // Keep the diagonal of R_s positive so that the residual norm sits in out[(q, q)].
    out[(q, q)] = out[(q, q)].abs();
    out
}

/// The data norm of a plan column `Σ w · column`: ‖R w‖ (R preserves norms); the
/// accumulated norm when it is one column.
pub(crate) fn plan_norm(r: &Mat<f64>, norms: &[f64], col: &[(usize, f64)]) -> f64 {
    match col {
        [(c, w)] if w.to_bits() == 1.0f64.to_bits() => norms[*c],
        _ => (0..r.nrows()).map(|i| col.iter().map(|&(c, w)| w * r[(i, c)]).sum::<f64>().powi(2)).sum::<f64>().sqrt(),
    }
}

/// Solves the reduced problem `[R_s | z; 0 | ρ]`: θ by back substitution, the covariance
/// `σ² R_s⁻¹ R_s⁻ᵀ` with `σ² = ρ²/(n − q)`. Returns (θ, covariance, RSS, σ²).
pub(crate) fn solve_reduced(
    rs: &Mat<f64>,
    q: usize,
    n: u64,
    known_sigma: Option<f64>,
) -> (Vec<f64>, Vec<Vec<f64>>, f64, f64) {
    let mut theta = vec![0.0; q];
    for i in (0..q).rev() {
        let mut acc = rs[(i, q)];
        for j in i + 1..q {
            acc -= rs[(i, j)] * theta[j];
        }
        theta[i] = acc / rs[(i, i)];
    }
    let rss = rs[(q, q)] * rs[(q, q)];
    let sigma2 = rss / (n.saturating_sub(q as u64).max(1)) as f64;
    let mut rinv = vec![vec![0.0; q]; q];
    for col in 0..q {
        for i in (0..=col).rev() {
            let mut acc = if i == col { 1.0 } else { 0.0 };
            for j in i + 1..=col {
                acc -= rs[(i, j)] * rinv[j][col];
            }
            rinv[i][col] = acc / rs[(i, i)];
        }
    }
    let mut cov = vec![vec![0.0; q]; q];
    for i in 0..q {
        for j in 0..q {
            let mut acc = 0.0;
            for k in i.max(j)..q {
                acc += rinv[i][k] * rinv[j][k];
            }
            cov[i][j] = known_sigma.map_or(sigma2, |s| s * s) * acc;
        }
    }
    (theta, cov, rss, sigma2)
}

/// The per-block callback of [`Samples`]: true states, gyro outputs, accelerometer
/// outputs (equal lengths, 1 to [`BLOCK`] samples).
pub(crate) type BlockFn<'f> = dyn FnMut(&[State], &[[f64; 3]], &[[f64; 3]]) + 'f;

/// A sequence of samples for the linear estimator: the true state and both outputs of
/// each, in order, in blocks. In memory ([`FitRun`]) or streamed from a file ([`stream`]);
/// both go through the same arithmetic sample by sample (block boundaries change nothing),
/// so their fits are identical.
pub(crate) trait Samples: Sync {
    /// Calls `f(states, gyro, accel)` for consecutive blocks of samples, in order.
    fn for_each_block(&self, f: &mut BlockFn<'_>) -> Result<(), crate::session::SessionError>;

    /// The run's name (for errors that point at a sample).
    fn run_name(&self) -> &str;
}

impl Samples for FitRun<'_> {
    fn run_name(&self) -> &str {
        self.name
    }

    fn for_each_block(&self, f: &mut BlockFn<'_>) -> Result<(), crate::session::SessionError> {
        let n = self.len();
        let mut states = Vec::with_capacity(BLOCK.min(n));
        let mut k0 = 0;
        while k0 < n {
            let k1 = (k0 + BLOCK).min(n);
            states.clear();
            states.extend((k0..k1).map(|k| self.state(k)));
            f(&states, &self.gyro[k0..k1], &self.accel[k0..k1]);
            k0 = k1;
        }
        Ok(())
    }
}
