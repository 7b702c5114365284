//! The forward model: [`forward`] at one state, [`scale_matrix`] of a sensor's values, and
//! [`Predictor`], the same sum compiled once for many states.

use super::{Effect, Role, State, TermRef};

/// The sensor's scale/coupling matrix from the values of its `Role::Scale` terms (the
/// identity when the model has none).
pub fn scale_matrix(terms: &[TermRef<'_>], values: &[f64]) -> [[f64; 3]; 3] {
    let mut k = [[0.0; 3]; 3];
    let mut any = false;
    for (t, &v) in terms.iter().zip(values) {
        if let Role::Scale(j) = t.term.role {
            k[t.term.channel][j] += v;
            any = true;
        }
    }
    if !any {
        k = [[1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0]];
    }
    k
}

/// Forward model of one sensor: `u_i = Σ_k θ_k φ_k(state)` over the terms of channel i,
/// input-side terms weighted by the channel's row of the scale matrix
/// (`u_i = K_i·(x + Δ) + …`, see [`Effect::input_components`]).
#[inline]
pub fn forward(terms: &[TermRef<'_>], values: &[f64], s: &State) -> [f64; 3] {
    let mut u = [0.0; 3];
    weighted_regressors(terms, values, |e, k, ch, w| u[ch] += w * e.regressor(k, s));
    u
}

/// Every nonzero term's contribution to the forward model as (effect, regressor index,
/// output channel, weight), in order: an output-side term once with its value; an
/// input-side term once per component of its input perturbation, weighted by the value
/// times the scale matrix's element (`u_i = K_i·(x + Δ)`). Shared by [`forward`] and
/// [`Predictor`].
#[inline]
fn weighted_regressors<'a>(
    terms: &[TermRef<'a>],
    values: &[f64],
    mut visit: impl FnMut(&'a dyn Effect, usize, usize, f64),
) {
    let mut k = None;
    for (t, &v) in terms.iter().zip(values) {
        if v == 0.0 {
            continue;
        }
        let comps = t.input_components();
        if comps.is_empty() {
            visit(t.effect, t.index, t.term.channel, v);
        } else {
            let k = k.get_or_insert_with(|| scale_matrix(terms, values));
            let i = t.term.channel;
            for (j, kj) in comps {
                visit(t.effect, kj, i, v * k[i][j]);
            }
        }
    }
}

/// [`forward`] worked out once for many states: each nonzero term's channel, weight and
/// regressor (an input-side term's components weighted by the scale matrix's row), so that
/// a state costs only the regressors — no input components looked up or scale matrix built
/// per call. [`Predictor::at`] gives [`forward`]'s numbers bit for bit (same terms, same
/// order, the same products).
#[derive(Clone)]
pub struct Predictor<'a> {
    /// (effect, regressor index, output channel, weight) in [`forward`]'s order.
    parts: Vec<(&'a dyn Effect, usize, usize, f64)>,
}

impl<'a> Predictor<'a> {
    /// The predictor of one sensor's `terms` at `values`.
    pub fn new(terms: &[TermRef<'a>], values: &[f64]) -> Self {
        let mut parts = Vec::new();
        weighted_regressors(terms, values, |e, k, ch, w| parts.push((e, k, ch, w)));
        Self { parts }
    }

    /// The quantities of a state this predictor's outputs read (the union of its effects'
    /// [`Effect::inputs`]): outputs at two states that agree in these are equal.
    pub fn reads(&self) -> super::Inputs {
        self.parts.iter().fold(super::Inputs::NONE, |a, (e, ..)| a.and(e.inputs()))
    }

    /// The sensor's three outputs at `s`.
    #[inline]
    pub fn at(&self, s: &State) -> [f64; 3] {
        let mut u = [0.0; 3];
        for &(e, k, ch, w) in &self.parts {
            u[ch] += w * e.regressor(k, s);
        }
        u
    }

    /// The outputs at each of `states` into `out` (same length), term by term over the
    /// whole block (one dynamic call per term and block, [`Effect::regressors`]); `tmp` is
    /// scratch of at least four times the block's length ([`Self::SCRATCH`]): the
    /// regressor, then each output channel's sums kept apart, so that adding a weighted
    /// regressor is one contiguous pass ([`crate::stats::kernels::axpy`]) instead of a
    /// stride of three. The same sums in the same order as [`Self::at`], so the same numbers
    /// bit for bit.
    pub fn block(&self, states: &[State], out: &mut [[f64; 3]], tmp: &mut [f64]) {
        debug_assert!(tmp.len() >= Self::SCRATCH * states.len().min(out.len()), "scratch for the block");
        let n = states.len().min(out.len()).min(tmp.len() / Self::SCRATCH);
        let (reg, sums) = tmp[..Self::SCRATCH * n].split_at_mut(n);
        sums.fill(0.0);
        for &(e, k, ch, w) in &self.parts {
            e.regressors(k, &states[..n], reg);
            crate::stats::kernels::axpy(&mut sums[ch * n..(ch + 1) * n], w, reg);
        }
        for (i, u) in out[..n].iter_mut().enumerate() {
            *u = [sums[i], sums[n + i], sums[2 * n + i]];
        }
    }

    /// Scratch [`Self::block`] needs per state.
    pub const SCRATCH: usize = 4;
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::model::Model;
    use crate::units::SensorKind;

    #[test]
    fn predictor_gives_forwards_numbers_bit_for_bit() {
        let mut m = Model::paper();
        m.add_effect("gyro-hysteresis").unwrap();
        m.add_effect("accel-lever-arm").unwrap();
        for sensor in SensorKind::BOTH {
            let terms = m.terms(sensor);
            let values: Vec<f64> =
                (0..terms.len()).map(|i| if i % 5 == 3 { 0.0 } else { 0.01 * (i as f64 + 1.0).sin() }).collect();
            let p = Predictor::new(&terms, &values);
            let mut states = Vec::new();
            for k in 0..20 {
                let x = k as f64 * 0.37;
                let s = State {
                    t_session_s: x,
                    w: [x.sin(), x.cos(), 0.3 * x],
                    e: [0.1 * x, -x.sin(), 0.2],
                    a: [9.0 * x.cos(), 1.0, -x],
                    temp_c: 20.0,
                    temp_rate_c_s: 0.0,
                };
                assert_eq!(p.at(&s).map(f64::to_bits), forward(&terms, &values, &s).map(f64::to_bits));
                states.push(s);
            }
            let mut out = vec![[f64::NAN; 3]; states.len()];
            p.block(&states, &mut out, &mut vec![0.0; Predictor::SCRATCH * states.len()]);
            for (s, u) in states.iter().zip(&out) {
                assert_eq!(u.map(f64::to_bits), p.at(s).map(f64::to_bits));
            }
        }
    }

    #[test]
    fn a_predictor_reads_what_its_effects_read() {
        let m = Model::paper();
        let terms = m.terms(SensorKind::Gyro);
        let values: Vec<f64> = terms.iter().map(|t| t.term.nominal + 0.01).collect();
        let gyro = Predictor::new(&terms, &values).reads();
        assert!(gyro.rate && gyro.ang_accel && !gyro.force && !gyro.temperature);
        let terms = m.terms(SensorKind::Accel);
        let values: Vec<f64> = terms.iter().map(|t| t.term.nominal + 0.01).collect();
        let accel = Predictor::new(&terms, &values).reads();
        assert!(accel.force && !accel.rate && !accel.ang_accel);
        // All values zero: no term, nothing read.
        let none = Predictor::new(&terms, &vec![0.0; terms.len()]).reads();
        assert!(!none.force && !none.rate);
    }
}
